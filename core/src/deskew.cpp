#include "sglc/deskew.hpp"

#include <cmath>
#include <cstdio>
#include <string>

namespace sglc {

std::string twistError(const Twist& twist) {
  if (!twist.linear.allFinite() || !twist.angular.allFinite()) return "the twist is not finite";
  char buf[160];
  if (const double v = twist.linear.stableNorm(); v > kMaxSweepSpeed) {
    std::snprintf(buf, sizeof buf, "the twist's speed %.6g m/s exceeds %.6g m/s", v, kMaxSweepSpeed);
    return buf;
  }
  if (const double w = twist.angular.stableNorm(); w > kMaxSweepTurnRate) {
    std::snprintf(buf, sizeof buf, "the twist's turn rate %.6g rad/s exceeds %.6g rad/s", w, kMaxSweepTurnRate);
    return buf;
  }
  return "";
}

Twist twistBetween(const Mat4d& from, const Mat4d& to, double dt) {
  if (!(dt > 0) || !std::isfinite(dt))
    throw InputError("de-skew: the poses around the scan are " + std::to_string(dt) + " s apart; need a positive gap");
  const Mat4d step = from.inverse() * to;
  const Eigen::AngleAxisd aa(Eigen::Matrix3d(step.topLeftCorner<3, 3>()));
  Twist t;
  t.linear = step.topRightCorner<3, 1>() / dt;
  t.angular = aa.axis() * (aa.angle() / dt);
  return t;
}

Twist sweepTwist(const TimedPose* previous, const TimedPose& current, const TimedPose* next) {
  if (next) return twistBetween(current.pose, next->pose, next->stamp - current.stamp);
  if (previous) return twistBetween(previous->pose, current.pose, current.stamp - previous->stamp);
  throw InputError(
      "de-skew: a scan's motion needs the pose of the scan before or after it (one pose alone: send a twist)");
}

Mat4d motionAt(const Twist& twist, double t) {
  Mat4d M = Mat4d::Identity();
  const double angle = twist.angular.norm() * t;
  if (twist.angular.norm() > 0)
    M.topLeftCorner<3, 3>() = Eigen::AngleAxisd(angle, twist.angular.normalized()).toRotationMatrix();
  M.topRightCorner<3, 1>() = twist.linear * t;
  return M;
}

void deskew(Points& points, const std::vector<float>& times, const Twist& twist) {
  if (times.size() != points.size())
    throw InputError("de-skew: " + std::to_string(times.size()) + " point times for " + std::to_string(points.size()) +
                     " points");
  if (const auto error = twistError(twist); !error.empty()) throw InputError("de-skew: " + error);
  // Every time is checked before any point moves: a refused scan is left as it was.
  for (std::size_t i = 0; i < times.size(); ++i)
    if (!std::isfinite(times[i]) || std::abs(times[i]) > 1.0f)
      throw InputError("de-skew: point " + std::to_string(i) + "'s time " + std::to_string(times[i]) +
                       " s is not within 1 s of the stamp");
  // Points of one column share a time: reuse the motion while the time stays the same.
  float last = std::nanf("");
  Eigen::Matrix3f R = Eigen::Matrix3f::Identity();
  Eigen::Vector3f s = Eigen::Vector3f::Zero();
  for (std::size_t i = 0; i < points.size(); ++i) {
    const float t = times[i];
    if (!(t == last)) {
      const Mat4d M = motionAt(twist, t);
      R = M.topLeftCorner<3, 3>().cast<float>();
      s = M.topRightCorner<3, 1>().cast<float>();
      last = t;
    }
    points[i] = R * points[i] + s;
  }
}

}  // namespace sglc
