#include "poses_frame.hpp"

#include <cmath>
#include <cstdio>

namespace sglc {

void cameraToLidarPoses(std::vector<Mat4d*>& poses, const Mat4d& Tr) {
  const Mat4d inv = Tr.inverse();
  for (Mat4d* T : poses) *T = inv * *T * Tr;
}

std::optional<std::string> zMotionWarning(const std::vector<const Mat4d*>& poses, const std::string& file) {
  if (poses.empty()) return std::nullopt;
  const Mat4d& first = *poses.front();
  for (std::size_t i = 1; i < poses.size(); ++i) {
    const Eigen::Vector3d d =
        first.topLeftCorner<3, 3>().transpose() * (poses[i]->topRightCorner<3, 1>() - first.topRightCorner<3, 1>());
    if (d.norm() < 1.0) continue;
    if (std::abs(d.z()) <= d.head<2>().norm()) return std::nullopt;
    char buf[160];
    std::snprintf(buf, sizeof buf,
                  "moves %.2f m along the sensor's z and %.2f m across it from its first to its %zu-th pose",
                  std::abs(d.z()), d.head<2>().norm(), i + 1);
    return file + " " + buf +
           ": a LiDAR on a ground robot moves in its x-y plane, a camera along its z. If these are camera poses, give "
           "calib.txt (KITTI, its Tr line) and --poses-frame camera; if they are LiDAR poses of a robot that climbs, "
           "ignore this";
  }
  return std::nullopt;
}

}  // namespace sglc
