// The ROS messages a drive is read from, decoded from a bag's bytes (ROS 2 CDR or ROS 1): sensor_msgs
// PointCloud2, nav_msgs Odometry and tf2_msgs TFMessage. Bytes from outside: every size is checked and every
// failure is an InputError naming `what` (file, topic, message index) and the field.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "sglc/bag.hpp"
#include "sglc/types.hpp"

namespace sglc {

// sensor_msgs/PointCloud2 with any field layout: x, y, z as float32 or float64 (required); intensity if
// present; a per-point time in the conventions drivers use, turned into seconds after the header stamp:
//   t            uint32 ns after the stamp (Ouster)
//   time         float32 s after the stamp (Velodyne; may be negative)
//   offset_time  uint32 ns after the stamp (Livox)
//   timestamp    float64, absolute: ns when above 1e14 (Livox), s when above 1e6 (Hesai); else s after the stamp
// Organised or not, either byte order. Points with a non-finite coordinate are dropped and counted.
struct RosCloud {
  std::int64_t stamp_ns = 0;
  std::string frame_id;
  Points points;
  std::vector<float> intensities;  // empty without an intensity field
  std::vector<float> times;        // seconds after stamp_ns; empty without a time field
  std::string time_field;          // the field the times came from ("" when none)
  std::size_t dropped = 0;         // points with NaN or infinite coordinates (as float32)
  bool deskewed = false;           // moved into the sensor's frame at the stamp (sglc/bag_drive.hpp)
  std::uint32_t width = 0, height = 0;
};
// Refuses clouds claiming more than max_points points.
RosCloud decodePointCloud2(const std::vector<std::uint8_t>& bytes, MessageEncoding encoding, std::size_t max_points,
                           const std::string& what);

// nav_msgs/Odometry: the pose of child_frame in frame_id, and the twist (in child_frame).
struct RosOdometry {
  std::int64_t stamp_ns = 0;
  std::string frame_id, child_frame;
  Mat4d pose = Mat4d::Identity();
  Eigen::Vector3d linear = Eigen::Vector3d::Zero(), angular = Eigen::Vector3d::Zero();
};
RosOdometry decodeOdometry(const std::vector<std::uint8_t>& bytes, MessageEncoding encoding, const std::string& what);

// tf2_msgs/TFMessage: each transform is the pose of child_frame in frame_id.
struct RosTransform {
  std::int64_t stamp_ns = 0;
  std::string frame_id, child_frame;
  Mat4d T = Mat4d::Identity();
};
std::vector<RosTransform> decodeTfMessage(const std::vector<std::uint8_t>& bytes, MessageEncoding encoding,
                                          const std::string& what);

// The header stamp (ns) of a message that starts with a std_msgs/Header, from its first bytes
// (BagMessage::head); throws InputError when they are too few.
std::int64_t headerStampOf(const BagMessage& m, MessageEncoding encoding, const std::string& what);

}  // namespace sglc
