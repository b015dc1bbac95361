#include "sglc/bag_drive.hpp"

#include <cmath>

#include "pose_track.hpp"

namespace sglc {
namespace {

constexpr std::int64_t kSlackNs = 200000000;  // 0.2 s beyond the first or last pose

bool isType(const BagTopic& t, const char* name) {
  // "sensor_msgs/msg/PointCloud2" (ROS 2) or "sensor_msgs/PointCloud2" (ROS 1)
  const std::string n(name);
  const auto slash = n.find('/');
  return t.type == n || t.type == n.substr(0, slash) + "/msg" + n.substr(slash);
}

void needType(const Bag& bag, std::size_t topic, const char* type) {
  const BagTopic& t = bag.topics()[topic];
  if (!isType(t, type))
    throw InputError(bag.path() + ": topic " + t.name + " carries " + (t.type.empty() ? "no named type" : t.type) +
                     ", not " + type);
}

// /tf and /tf_static (whichever the bag has) into a tree.
TfTree readTf(Bag& bag, bool dynamic) {
  TfTree tree;
  for (const char* name : {"/tf_static", "/tf"}) {
    const bool fixed = std::string(name) == "/tf_static";
    if (!fixed && !dynamic) continue;
    std::size_t topic = 0;
    bool found = false;
    for (std::size_t i = 0; i < bag.topics().size(); ++i)
      if (bag.topics()[i].name == name) topic = i, found = true;
    if (!found) continue;
    needType(bag, topic, "tf2_msgs/TFMessage");
    for (const auto& m : bag.messages({topic}))
      for (const auto& t : decodeTfMessage(bag.read(m), bag.topics()[topic].encoding, bag.where(m))) {
        if (fixed)
          tree.addStatic(t.frame_id, t.child_frame, t.T);
        else
          tree.addDynamic(t.frame_id, t.child_frame, t.stamp_ns, t.T);
      }
  }
  tree.sort();
  return tree;
}

}  // namespace

BagDrive::BagDrive(const std::string& path, const BagDriveOptions& options) : bag_(openBag(path)), options_(options) {
  if (options_.points_topic.empty()) throw InputError(path + ": give the PointCloud2 topic (--points-topic)");
  if (!options_.odom_topic.empty() && !options_.tf_frame.empty())
    throw InputError("give --odom-topic or --tf, not both");
  if (!(options_.keyframe_m >= 0) || !(options_.keyframe_deg >= 0))
    throw InputError("--keyframe-m and --keyframe-deg must be at least 0");
  if (options_.max_points == 0) options_.max_points = kMaxScanPoints;
  const std::size_t points = bag_->topic(options_.points_topic);
  needType(*bag_, points, "sensor_msgs/PointCloud2");
  encoding_ = bag_->topics()[points].encoding;
  const auto messages = bag_->messages({points});
  clouds_ = messages.size();
  if (messages.empty()) throw InputError(path + ": topic " + options_.points_topic + " has no messages");

  // Where the sensor is at a stamp, in the frame of the odometry (or tf_frame).
  PoseTrack odometry;
  TfTree tree;
  std::string base;  // the odometry's child frame
  const bool have_odometry = !options_.odom_topic.empty();
  if (have_odometry) {
    const std::size_t topic = bag_->topic(options_.odom_topic);
    needType(*bag_, topic, "nav_msgs/Odometry");
    for (const auto& m : bag_->messages({topic})) {
      const auto o = decodeOdometry(bag_->read(m), bag_->topics()[topic].encoding, bag_->where(m));
      odometry.add(o.stamp_ns, o.pose);
      base = o.child_frame;
    }
    odometry.sort();
    if (odometry.empty()) throw InputError(path + ": topic " + options_.odom_topic + " has no messages");
    tree = readTf(*bag_, false);
  } else if (!options_.tf_frame.empty()) {
    tree = readTf(*bag_, true);
    if (!tree.has(options_.tf_frame))
      throw InputError(path + ": frame " + options_.tf_frame + " is in no /tf or /tf_static transform");
  }

  std::optional<Mat4d> extrinsic;               // base -> cloud frame, found once
  constexpr std::int64_t kSweepNs = 100000000;  // the motion over 0.1 s (a 10 Hz sweep) around a stamp
  std::string warned_frame;
  std::size_t outside = 0;
  const double min_turn = options_.keyframe_deg * M_PI / 180.0;
  std::optional<Mat4d> last;
  for (const auto& m : messages) {
    BagFrame f;
    f.number = static_cast<std::int64_t>(m.index);
    f.message = m;
    f.stamp_ns = headerStampOf(m, encoding_, bag_->where(m));
    if (have_odometry || !options_.tf_frame.empty()) {
      // The cloud's frame id is needed for the extrinsic: decode the header only (cheap: the bytes up front).
      std::optional<Mat4d> pose;
      if (have_odometry) {
        pose = odometry.at(f.stamp_ns, kSlackNs);
        if (pose && !extrinsic) {
          const RosCloud c = decodePointCloud2(bag_->read(m), encoding_, options_.max_points, bag_->where(m));
          if (c.frame_id == base || base.empty()) {
            extrinsic = Mat4d::Identity();
          } else if (tree.has(c.frame_id) && tree.has(base)) {
            extrinsic = tree.lookup(base, c.frame_id, f.stamp_ns, kSlackNs);
          }
          if (!extrinsic) {
            extrinsic = Mat4d::Identity();
            warnings_.push_back("the clouds' frame " + c.frame_id + " is not linked to the odometry's child frame " +
                                base + " in /tf_static: taken as the same frame (the odometry is the sensor's)");
          }
        }
        if (pose) pose = *pose * *extrinsic;
      } else {
        if (warned_frame.empty())
          warned_frame = decodePointCloud2(bag_->read(m), encoding_, options_.max_points, bag_->where(m)).frame_id;
        pose = tree.lookup(options_.tf_frame, warned_frame, f.stamp_ns, kSlackNs);
      }
      if (!pose) {
        ++outside;
        continue;
      }
      f.pose = pose;
      // The motion over the sweep: on to 0.1 s later, or (at the end of the poses) from 0.1 s before. The
      // extrinsic is the same at both ends, so base poses give the sensor's motion.
      auto at = [&](std::int64_t t) -> std::optional<Mat4d> {
        if (have_odometry) {
          const auto p = odometry.at(t, 0);
          return p ? std::optional<Mat4d>(*p * *extrinsic) : std::nullopt;
        }
        return tree.lookup(options_.tf_frame, warned_frame, t, 0);
      };
      if (const auto later = at(f.stamp_ns + kSweepNs))
        f.twist = twistBetween(*pose, *later, kSweepNs * 1e-9);
      else if (const auto earlier = at(f.stamp_ns - kSweepNs))
        f.twist = twistBetween(*earlier, *pose, kSweepNs * 1e-9);
      if (last) {
        const Mat4d d = last->inverse() * *pose;
        const double moved = d.topRightCorner<3, 1>().norm();
        const double turned = Eigen::AngleAxisd(Eigen::Matrix3d(d.topLeftCorner<3, 3>())).angle();
        const bool every = options_.keyframe_m == 0 && options_.keyframe_deg == 0;
        if (!every && moved < options_.keyframe_m && turned < min_turn) continue;
      }
      last = pose;
    }
    frames_.push_back(f);
  }
  if (outside)
    warnings_.push_back(std::to_string(outside) + " of " + std::to_string(clouds_) +
                        " clouds lie more than 0.2 s outside the poses' time span: skipped");
  if (frames_.empty()) throw InputError(path + ": no cloud of " + options_.points_topic + " has a pose");
}

RosCloud BagDrive::cloud(std::size_t i) {
  const BagFrame& f = frames_.at(i);
  RosCloud c = decodePointCloud2(bag_->read(f.message), encoding_, options_.max_points, bag_->where(f.message));
  if (options_.deskew && !c.times.empty() && f.twist) {
    deskew(c.points, c.times, *f.twist);
    c.deskewed = true;
  }
  return c;
}

}  // namespace sglc
