#include <Eigen/Geometry>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <numbers>

#include "sglc/io.hpp"
#include "sim/simulator.hpp"

namespace sglc::sim {

Trajectory kittiTrajectory(const std::vector<Mat4d>& camera_poses, const Mat4d& Tr, std::string source) {
  const Mat3d R = Tr.topLeftCorner<3, 3>();
  if ((R.transpose() * R - Mat3d::Identity()).norm() > 1e-3 || std::abs(R.determinant() - 1.0) > 1e-3)
    throw InputError("calibration Tr is not a rigid transform (its rotation is not orthonormal)");
  Trajectory t;
  t.Tr = Tr;
  t.source = std::move(source);
  const Mat4d Tr_inv = Tr.inverse();
  t.poses.reserve(camera_poses.size());
  for (const auto& P : camera_poses) t.poses.push_back(Tr_inv * P * Tr);
  return t;
}

Trajectory loadKittiTrajectory(const std::string& poses_path, const std::string& calib_path) {
  const auto poses = readPoses(poses_path);
  if (poses.empty()) throw InputError(poses_path + ": no poses");
  return kittiTrajectory(poses, readCalibTr(calib_path), poses_path);
}

namespace {

using Vec2 = Eigen::Vector2d;

// Ground of the built-in route (flat at the start, so that frame 0's LiDAR frame is level).
double routeGround(double x, double y) {
  return 0.8 * std::cos(2 * std::numbers::pi * x / 230.0) + 0.5 * std::cos(2 * std::numbers::pi * y / 170.0) - 1.3;
}
Vec2 routeGroundGradient(double x, double y) {
  return {-0.8 * 2 * std::numbers::pi / 230.0 * std::sin(2 * std::numbers::pi * x / 230.0),
          -0.5 * 2 * std::numbers::pi / 170.0 * std::sin(2 * std::numbers::pi * y / 170.0)};
}

constexpr double kStep = 0.05;  // spacing of the route's samples (m)

// A point of the route, kStep apart from the next.
struct RouteSample {
  Vec2 p;
  double heading;
  bool curve;  // on a rounded corner (the car slows down there)
};

// The centreline through the street corners, each turning corner rounded with a 10 m radius; corners
// driven straight through (intersections) stay as they are.
std::vector<RouteSample> roundedCentreline(const std::vector<Vec2>& corners) {
  constexpr double kRadius = 10.0;
  std::vector<RouteSample> centre;
  auto straight = [&](const Vec2& a, const Vec2& b) {
    const Vec2 d = b - a;
    const double len = d.norm();
    const double h = std::atan2(d.y(), d.x());
    for (double s = 0; s < len; s += kStep) centre.push_back({a + d * (s / len), h, false});
  };
  Vec2 cursor = corners.front();
  for (std::size_t i = 1; i + 1 < corners.size(); ++i) {
    const Vec2 din = (corners[i] - corners[i - 1]).normalized(), dout = (corners[i + 1] - corners[i]).normalized();
    const double turn = std::atan2(din.x() * dout.y() - din.y() * dout.x(), din.dot(dout));
    if (std::abs(turn) < 1e-9) continue;  // straight on through the intersection
    const double tl = kRadius * std::tan(std::abs(turn) / 2);
    const Vec2 a = corners[i] - din * tl;
    straight(cursor, a);
    const double sgn = turn > 0 ? 1.0 : -1.0;
    const Vec2 centre_pt = a + sgn * kRadius * Vec2(-din.y(), din.x());
    const double h0 = std::atan2(din.y(), din.x());
    const double arc = std::abs(turn) * kRadius;
    for (double s = 0; s < arc; s += kStep) {
      const double h = h0 + sgn * s / kRadius;
      const Vec2 p = centre_pt + sgn * kRadius * Vec2(std::sin(h), -std::cos(h));
      centre.push_back({p, h, true});
    }
    cursor = corners[i] + dout * tl;
  }
  straight(cursor, corners.back());
  return centre;
}

// Speed at each sample: 9 m/s on straights, 5 m/s in bends, with linear ramps over the 15 m (arc length
// `s`) before and after a bend.
std::vector<double> routeSpeeds(const std::vector<RouteSample>& centre, const std::vector<double>& s) {
  std::vector<double> speed(centre.size());
  for (std::size_t k = 0; k < centre.size(); ++k) {
    double v = 9.0;
    for (std::size_t j = k; j-- > 0 && s[k] - s[j] < 15.0;)
      if (centre[j].curve) v = std::min(v, 5.0 + 4.0 * (s[k] - s[j]) / 15.0);
    for (std::size_t j = k; j < centre.size() && s[j] - s[k] < 15.0; ++j)
      if (centre[j].curve) v = std::min(v, 5.0 + 4.0 * (s[j] - s[k]) / 15.0);
    speed[k] = v;
  }
  return speed;
}

// The LiDAR pose at point p of the lane heading h: yawed along the lane, pitched and rolled with the ground's
// slope, the sensor 1.73 m (KITTI's mounting height) above the ground.
Mat4d lanePose(const Vec2& p, double h) {
  constexpr double kSensorHeight = 1.73;
  const Vec2 fwd(std::cos(h), std::sin(h)), left(-std::sin(h), std::cos(h));
  const Vec2 g = routeGroundGradient(p.x(), p.y());
  const double pitch = std::atan(g.dot(fwd)), roll = std::atan(g.dot(left));
  Mat4d T = Mat4d::Identity();
  T.topLeftCorner<3, 3>() = (Eigen::AngleAxisd(h, Vec3d::UnitZ()) * Eigen::AngleAxisd(-pitch, Vec3d::UnitY()) *
                             Eigen::AngleAxisd(roll, Vec3d::UnitX()))
                                .toRotationMatrix();
  T.topRightCorner<3, 1>() = Vec3d(p.x(), p.y(), routeGround(p.x(), p.y()) + kSensorHeight);
  return T;
}

}  // namespace

Trajectory loopRoute() {
  // Street corners of the driven centreline.
  const std::vector<Vec2> corners = {{0, 0},     {200, 0},   {200, 120}, {0, 120},   {0, 0},   {200, 0}, {200, 120},
                                     {200, 180}, {140, 180}, {140, 120}, {200, 120}, {200, 0}, {0, 0}};
  constexpr double kLane = 1.2;
  const std::vector<RouteSample> centre = roundedCentreline(corners);

  // Drive in the right-hand lane: offset the centreline to the right of the heading; s is arc length on it.
  std::vector<Vec2> lane(centre.size());
  std::vector<double> s(centre.size(), 0.0);
  for (std::size_t k = 0; k < centre.size(); ++k) {
    const double h = centre[k].heading;
    lane[k] = centre[k].p + kLane * Vec2(std::sin(h), -std::cos(h));
    if (k > 0) s[k] = s[k - 1] + (lane[k] - lane[k - 1]).norm();
  }
  const std::vector<double> speed = routeSpeeds(centre, s);

  // One pose per frame: advance along the lane by the local speed times the frame time.
  Trajectory t;
  t.frame_dt = 0.1;
  t.source = "built-in loop route";
  std::size_t k = 0;
  double pos = 0.0;
  std::vector<Mat4d> poses;
  while (true) {
    while (k + 1 < s.size() && s[k + 1] <= pos) ++k;
    if (k + 1 >= s.size()) break;
    const double u = (pos - s[k]) / std::max(1e-9, s[k + 1] - s[k]);
    const Vec2 p = lane[k] * (1 - u) + lane[k + 1] * u;
    poses.push_back(lanePose(p, std::atan2(lane[k + 1].y() - lane[k].y(), lane[k + 1].x() - lane[k].x())));
    pos += speed[k] * t.frame_dt;
  }
  // World = LiDAR frame of frame 0.
  const Mat4d first_inv = poses.front().inverse();
  for (auto& P : poses) t.poses.push_back(first_inv * P);
  return t;
}

}  // namespace sglc::sim
