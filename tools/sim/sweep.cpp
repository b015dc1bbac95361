// The sensor's pose within one sweep, for rolling-shutter (motion) distortion.
#include "sim/sensor.hpp"

namespace sglc::sim {

SweepMotion::SweepMotion(const std::vector<Mat4d>& poses, int index) {
  const int n = static_cast<int>(poses.size());
  if (index < 0 || index >= n) throw InputError("sweep: frame " + std::to_string(index) + " outside the trajectory");
  start_ = poses[index];
  step_ = Mat4d::Identity();
  // One frame's motion, in the frame's own axes; the last frame continues its predecessor's motion.
  if (n >= 2) {
    const int a = index + 1 < n ? index : index - 1;
    step_ = poses[a].inverse() * poses[a + 1];
  }
  rotation_ = Eigen::Quaterniond(Mat3d(step_.topLeftCorner<3, 3>())).normalized();
}

Mat4d SweepMotion::at(double alpha) const {
  if (alpha == 0.0) return start_;
  Mat4d partial = Mat4d::Identity();
  partial.topLeftCorner<3, 3>() = Eigen::Quaterniond::Identity().slerp(alpha, rotation_).toRotationMatrix();
  partial.topRightCorner<3, 1>() = alpha * step_.topRightCorner<3, 1>();
  return start_ * partial;
}

}  // namespace sglc::sim
