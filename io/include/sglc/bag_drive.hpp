// A drive recorded in a bag, laid out as the keyframes a SLAM front end would send: the clouds of one
// PointCloud2 topic, each with the sensor's pose at its stamp (from nav_msgs/Odometry, or from /tf to a
// fixed frame), keeping a cloud when the sensor has moved keyframe_m or turned keyframe_deg since the last
// one kept. Clouds are decoded only when asked for.
//
// Poses are the sensor's: odometry gives the pose of its child frame (a robot's base), and the extrinsic from
// that frame to the cloud's frame comes from /tf_static when the bag has it (identity, with a warning, when
// not). Between two odometry or tf messages the pose is interpolated (linear in position, slerp in rotation);
// clouds more than 0.2 s outside the poses' time span are skipped (counted in warnings).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "sglc/bag.hpp"
#include "sglc/deskew.hpp"
#include "sglc/ros_messages.hpp"

namespace sglc {

struct BagDriveOptions {
  std::string points_topic;  // sensor_msgs/PointCloud2 (required)
  std::string odom_topic;    // nav_msgs/Odometry; or
  std::string tf_frame;      // the fixed frame to look the cloud's frame up in, over /tf and /tf_static
  // A cloud is a keyframe when the sensor moved this far or turned this much since the last keyframe; both 0:
  // every cloud. Without poses every cloud is a keyframe.
  double keyframe_m = 1.0;
  double keyframe_deg = 10.0;
  std::size_t max_points = 0;  // per cloud; 0: kMaxScanPoints
  // Clouds with per-point times are de-skewed (sglc/deskew.hpp) with the sensor's motion over the 0.1 s after
  // their stamp (or before it, at the end of the poses), from the same poses.
  bool deskew = true;
};

struct BagFrame {
  std::int64_t number = 0;  // the cloud's index on its topic
  std::int64_t stamp_ns = 0;
  std::optional<Mat4d> pose;   // the sensor's pose in the odometry's (or tf_frame's) frame
  std::optional<Twist> twist;  // the sensor's motion around the stamp, when the poses give it
  BagMessage message;
};

class BagDrive {
 public:
  BagDrive(const std::string& path, const BagDriveOptions& options);
  const std::vector<BagFrame>& frames() const { return frames_; }  // the keyframes, in stamp order
  std::size_t clouds() const { return clouds_; }                   // clouds on the topic
  const std::vector<std::string>& warnings() const { return warnings_; }
  const Bag& bag() const { return *bag_; }
  // Keyframe i decoded: NaN points dropped; per-point times in seconds after its stamp where the cloud has them,
  // and then de-skewed (options.deskew) when its twist is known.
  RosCloud cloud(std::size_t i);

 private:
  std::unique_ptr<Bag> bag_;
  BagDriveOptions options_;
  MessageEncoding encoding_ = MessageEncoding::kCdr;
  std::vector<BagFrame> frames_;
  std::size_t clouds_ = 0;
  std::vector<std::string> warnings_;
};

}  // namespace sglc
