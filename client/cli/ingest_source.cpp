#include "ingest_source.hpp"

#include <algorithm>
#include <filesystem>
#include <iostream>

#include "common.hpp"
#include "sglc/bag_drive.hpp"
#include "sglc/deskew.hpp"
#include "sglc/frame_selection.hpp"
#include "sglc/io.hpp"
#include "sglc/sequence.hpp"

namespace sglc::cli {
namespace {

class SequenceSource final : public IngestSource {
 public:
  explicit SequenceSource(const SourceOptions& o)
      : seq_(openSequence(o.path, FrameSelection::parse(o.frames), o.every, {o.poses, parsePosesFrame(o.poses_frame)})),
        label_field_(o.label_field),
        deskew_(o.bag.deskew) {
    if (seq_.poses_from_camera)
      std::cerr << "sglc ingest: " << seq_.poses_path
                << ": KITTI camera poses, turned into LiDAR poses with calib.txt's Tr\n";
    for (const auto& w : seq_.warnings) std::cerr << "sglc ingest: warning: " << w << "\n";
    for (const auto& f : seq_.frames) frames_.push_back({f.name, f.number, f.stamp, f.pose});
    const bool timed = std::any_of(seq_.frames.begin(), seq_.frames.end(),
                                   [](const SequenceFrame& f) { return !f.point_times_path.empty(); });
    if (timed && deskew_ && !(seq_.has_poses && seq_.has_stamps)) {
      std::cerr << "sglc ingest: warning: " << o.path << " has point_times/ but no poses and stamps to de-skew with: "
                << "scans are sent as they are\n";
      deskew_ = false;
    }
    if (timed && deskew_)
      std::cerr << "sglc ingest: scans with point_times/ are de-skewed (--no-deskew: as they are)\n";
  }
  const std::vector<IngestFrame>& frames() const override { return frames_; }
  LabelledScan scan(std::size_t i) override {
    const auto& f = seq_.frames.at(i);
    LabelledScan s = readScan(f.scan_path, f.label_path, label_field_);
    if (deskew_ && !f.point_times_path.empty()) {
      // The sweep's motion: on to the next frame sent, or from the previous one at the end.
      auto timed = [&](std::size_t k) { return TimedPose{*seq_.frames[k].stamp, *seq_.frames[k].pose}; };
      const TimedPose cur = timed(i);
      const std::optional<TimedPose> next = i + 1 < seq_.frames.size() ? std::optional(timed(i + 1)) : std::nullopt;
      const std::optional<TimedPose> prev = i > 0 ? std::optional(timed(i - 1)) : std::nullopt;
      deskew(s.points, readPointTimes(f.point_times_path, s.points.size()),
             sweepTwist(prev ? &*prev : nullptr, cur, next ? &*next : nullptr));
    }
    return s;
  }
  const std::string& name() const override { return seq_.name; }

 private:
  Sequence seq_;
  std::string label_field_;
  bool deskew_;
  std::vector<IngestFrame> frames_;
};

class BagSource final : public IngestSource {
 public:
  explicit BagSource(const SourceOptions& o) : drive_(o.path, driveOptions(o)) {
    if (o.poses != "" || o.poses_frame != "auto")
      throw UsageError(
          "--poses and --poses-frame are for sequence directories; a bag's poses come from "
          "--odom-topic or --tf");
    for (const auto& w : drive_.warnings()) std::cerr << "sglc ingest: warning: " << w << "\n";
    if (o.every < 1) throw UsageError("--every must be at least 1");
    const auto selection = FrameSelection::parse(o.frames);
    std::size_t kept = 0;
    for (std::size_t i = 0; i < drive_.frames().size(); ++i) {
      const auto& f = drive_.frames()[i];
      if (!selection.contains(f.number) || kept++ % static_cast<std::size_t>(o.every) != 0) continue;
      index_.push_back(i);
      frames_.push_back({std::to_string(f.number), f.number, static_cast<double>(f.stamp_ns) * 1e-9, f.pose});
    }
    if (frames_.empty()) throw InputError(o.path + ": no keyframe in frame selection '" + selection.text() + "'");
    std::cerr << "sglc ingest: " << o.path << ": " << frames_.size() << " keyframes of " << drive_.clouds()
              << " clouds on " << o.bag.points_topic << "\n";
    name_ = std::filesystem::path(o.path).lexically_normal().filename().stem().string();
  }
  const std::vector<IngestFrame>& frames() const override { return frames_; }
  LabelledScan scan(std::size_t i) override {
    RosCloud c = drive_.cloud(index_.at(i));
    if (c.points.empty()) throw InputError(o_path() + ": cloud " + frames_[i].name + " has no finite point");
    return {std::move(c.points), {}};
  }
  const std::string& name() const override { return name_; }

 private:
  static const BagDriveOptions& driveOptions(const SourceOptions& o) {
    if (o.bag.points_topic.empty()) throw UsageError("a bag needs --points-topic (its PointCloud2 topic)");
    return o.bag;
  }
  std::string o_path() const { return drive_.bag().path(); }
  BagDrive drive_;
  std::vector<std::size_t> index_;
  std::vector<IngestFrame> frames_;
  std::string name_;
};

}  // namespace

std::unique_ptr<IngestSource> openSource(const SourceOptions& o) {
  if (isBag(o.path)) return std::make_unique<BagSource>(o);
  if (!o.bag.points_topic.empty() || !o.bag.odom_topic.empty() || !o.bag.tf_frame.empty())
    throw UsageError(o.path +
                     ": --points-topic, --odom-topic and --tf are for bags, and this is not one (an MCAP file, "
                     "a .db3 file or a rosbag2 directory with metadata.yaml)");
  return std::make_unique<SequenceSource>(o);
}

}  // namespace sglc::cli
