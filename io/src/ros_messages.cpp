// nav_msgs/Odometry, tf2_msgs/TFMessage and header stamps (sglc/ros_messages.hpp).
#include <cmath>

#include "ros_reader.hpp"
#include "sglc/ros_messages.hpp"

namespace sglc {
namespace {

Eigen::Vector3d vec3(RosReader& r, const char* field) {
  Eigen::Vector3d v;
  for (int i = 0; i < 3; ++i) v[i] = r.get<double>(field);
  if (!v.allFinite()) throw InputError(r.what() + ": " + field + " is not finite");
  return v;
}

// Position and orientation (x y z w) as a pose; the quaternion must be near unit length.
Mat4d pose(RosReader& r, const char* position, const char* orientation) {
  const Eigen::Vector3d t = vec3(r, position);
  double q[4];
  for (double& v : q) v = r.get<double>(orientation);
  Eigen::Quaterniond quat(q[3], q[0], q[1], q[2]);
  const double norm = quat.norm();
  if (!std::isfinite(norm) || std::abs(norm - 1.0) > 0.01)
    throw InputError(r.what() + ": " + orientation + " has norm " + std::to_string(norm) + " (expected 1)");
  Mat4d T = Mat4d::Identity();
  T.topLeftCorner<3, 3>() = quat.normalized().toRotationMatrix();
  T.topRightCorner<3, 1>() = t;
  return T;
}

}  // namespace

RosOdometry decodeOdometry(const std::vector<std::uint8_t>& bytes, MessageEncoding encoding, const std::string& what) {
  RosReader r(bytes.data(), bytes.size(), encoding, what);
  RosOdometry o;
  o.stamp_ns = r.header(&o.frame_id);
  o.child_frame = r.string("child_frame_id");
  o.pose = pose(r, "pose.pose.position", "pose.pose.orientation");
  for (int i = 0; i < 36; ++i) r.get<double>("pose.covariance");
  o.linear = vec3(r, "twist.twist.linear");
  o.angular = vec3(r, "twist.twist.angular");
  return o;
}

std::vector<RosTransform> decodeTfMessage(const std::vector<std::uint8_t>& bytes, MessageEncoding encoding,
                                          const std::string& what) {
  RosReader r(bytes.data(), bytes.size(), encoding, what);
  std::vector<RosTransform> out(r.count("transforms", 60));
  for (auto& t : out) {
    t.stamp_ns = r.header(&t.frame_id);
    t.child_frame = r.string("child_frame_id");
    t.T = pose(r, "transform.translation", "transform.rotation");
  }
  return out;
}

std::int64_t headerStampOf(const BagMessage& m, MessageEncoding encoding, const std::string& what) {
  RosReader r(m.head.data(), m.head_size, encoding, what);
  if (r.ros1()) r.get<std::uint32_t>("header.seq");
  const auto sec = r.ros1() ? std::int64_t(r.get<std::uint32_t>("header.stamp.sec"))
                            : std::int64_t(r.get<std::int32_t>("header.stamp.sec"));
  const auto nsec = r.get<std::uint32_t>("header.stamp.nanosec");
  if (nsec >= 1000000000u)
    throw InputError(what + ": header.stamp.nanosec " + std::to_string(nsec) + " is not below 1e9");
  return sec * 1000000000LL + nsec;
}

}  // namespace sglc
