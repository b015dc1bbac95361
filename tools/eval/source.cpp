#include "source.hpp"

#include <algorithm>
#include <filesystem>
#include <iostream>
#include <map>
#include <mutex>
#include <sstream>

#include "sglc/bag_drive.hpp"
#include "sglc/closing/sweep_undo.hpp"
#include "sglc/deskew.hpp"
#include "sglc/frame_selection.hpp"
#include "sglc/io.hpp"
#include "sglc/sequence.hpp"
#include "sim/simulator.hpp"

namespace sglc::eval {
namespace {

namespace fs = std::filesystem;

class SimSource final : public FrameSource {
 public:
  explicit SimSource(const SimSourceOptions& o) : sim_(trajectory(o), config(o)) {
    frames_ = FrameSelection::parse(o.frames).frames(sim_.numFrames());
    std::ostringstream d;
    d << sim_.trajectory().source << ", " << o.beams << " beams, seed " << o.seed << ", label noise "
      << o.label_noise * 100 << " %";
    describe_ = d.str();
  }
  const std::vector<int>& frames() const override { return frames_; }
  bool hasPose(int f) const override { return f >= 0 && f < sim_.numFrames(); }
  Mat4d pose(int f) const override { return sim_.trajectory().poses.at(static_cast<std::size_t>(f)); }
  LabelledScan scan(int f) const override { return sim_.render(f).scan; }
  std::string describe() const override { return "simulated: " + describe_; }

 private:
  static sim::Trajectory trajectory(const SimSourceOptions& o) {
    if (o.poses.empty()) return sim::loopRoute();
    if (o.calib.empty()) throw InputError("--poses needs --calib (the Tr line converts camera to LiDAR poses)");
    return sim::loadKittiTrajectory(o.poses, o.calib);
  }
  static sim::SimConfig config(const SimSourceOptions& o) {
    sim::SimConfig c;
    c.seed = o.seed;
    c.label_noise = sim::LabelNoise::fromRate(o.label_noise);
    c.sensor = sim::SensorConfig::preset(o.beams);
    c.threads = 1;  // frames are rendered in parallel instead
    return c;
  }
  sim::Simulator sim_;
  std::vector<int> frames_;
  std::string describe_;
};

class DirSource final : public FrameSource {
 public:
  DirSource(const std::string& dir, const std::string& spec, DeskewMotion deskew) : dir_(dir), deskew_(deskew) {
    // Every frame's files and pose (pair files may name frames outside the selection), the selected ones in order.
    // KITTI camera poses come as LiDAR poses (calib.txt's Tr; sglc/sequence.hpp).
    const auto seq = openSequence(dir);
    for (const auto& w : seq.warnings) std::cerr << "warning: " << w << "\n";
    const auto selection = FrameSelection::parse(spec);
    for (const auto& f : seq.frames) {
      const int number = static_cast<int>(f.number);
      files_[number] = {f.scan_path, f.label_path, f.point_times_path};
      if (f.pose) poses_[number] = *f.pose;
      if (f.pose && f.stamp) timed_.push_back({number, {*f.stamp, *f.pose}});
      if (selection.contains(f.number)) frames_.push_back(number);
    }
    if (frames_.empty()) throw InputError(dir + ": no frame matches --frames '" + spec + "'");
  }
  const std::vector<int>& frames() const override { return frames_; }
  bool hasPose(int f) const override { return poses_.count(f) > 0; }
  Mat4d pose(int f) const override { return poses_.at(f); }
  LabelledScan scan(int f) const override {
    const auto it = files_.find(f);
    if (it == files_.end()) throw InputError(dir_ + ": no frame " + std::to_string(f));
    LabelledScan s = readScan(it->second.scan, it->second.labels);
    if (deskew_ == DeskewMotion::kOff || it->second.times.empty()) return s;
    if (const auto motion = twist(f)) deskew(s.points, readPointTimes(it->second.times, s.points.size()), *motion);
    return s;
  }
  std::string describe() const override { return "sequence directory " + dir_; }

 private:
  // The sweep's motion from the poses and stamps of the frames around f (sglc/deskew.hpp sweepTwist); none for
  // the server's model where the server would have none.
  std::optional<Twist> twist(int f) const {
    const auto it = std::find_if(timed_.begin(), timed_.end(), [&](const auto& t) { return t.first == f; });
    if (it == timed_.end())
      throw InputError(dir_ + ": frame " + std::to_string(f) +
                       " has point times but no pose and stamp to de-skew with");
    if (deskew_ == DeskewMotion::kPreviousKeyframe) {
      const auto sel = std::lower_bound(frames_.begin(), frames_.end(), f);
      if (sel == frames_.begin()) return std::nullopt;
      const auto prev = std::find_if(timed_.begin(), it, [&](const auto& t) { return t.first == *(sel - 1); });
      if (prev == it || it->second.stamp - prev->second.stamp > closing::kMaxSweepGap) return std::nullopt;
      return sweepTwist(&prev->second, it->second, nullptr);
    }
    const TimedPose* prev = it == timed_.begin() ? nullptr : &(it - 1)->second;
    const TimedPose* next = it + 1 == timed_.end() ? nullptr : &(it + 1)->second;
    return sweepTwist(prev, it->second, next);
  }
  struct Files {
    std::string scan, labels, times;
  };
  std::string dir_;
  DeskewMotion deskew_;
  std::vector<int> frames_;
  std::map<int, Files> files_;
  std::map<int, Mat4d> poses_;
  std::vector<std::pair<int, TimedPose>> timed_;  // frames with pose and stamp, ascending
};

// A bag's drive (sglc/bag_drive.hpp): every cloud of the topic that has a pose (keyframes by index on the
// topic), the odometry as the poses the protocols compare with.
class BagSource final : public FrameSource {
 public:
  BagSource(const std::string& path, const BagDriveOptions& o, const std::string& spec)
      : path_(path), drive_(path, options(o)) {
    for (const auto& w : drive_.warnings()) std::cerr << "warning: " << w << "\n";
    const auto selection = FrameSelection::parse(spec);
    for (std::size_t i = 0; i < drive_.frames().size(); ++i) {
      const auto& f = drive_.frames()[i];
      const int number = static_cast<int>(f.number);
      index_[number] = i;
      if (f.pose) poses_[number] = *f.pose;
      if (selection.contains(f.number)) frames_.push_back(number);
    }
    if (frames_.empty()) throw InputError(path + ": no cloud matches --frames '" + spec + "'");
  }
  const std::vector<int>& frames() const override { return frames_; }
  bool hasPose(int f) const override { return poses_.count(f) > 0; }
  Mat4d pose(int f) const override { return poses_.at(f); }
  LabelledScan scan(int f) const override {
    const auto it = index_.find(f);
    if (it == index_.end()) throw InputError(path_ + ": no cloud " + std::to_string(f));
    const std::lock_guard lock(mutex_);  // the bag reads through one file and one chunk cache
    return {drive_.cloud(it->second).points, {}};
  }
  std::string describe() const override { return "bag " + path_; }

 private:
  static const BagDriveOptions& options(const BagDriveOptions& o) {
    if (o.points_topic.empty()) throw InputError("a bag needs --points-topic");
    if (o.odom_topic.empty() && o.tf_frame.empty())
      throw InputError("the protocols need poses: give --odom-topic or --tf for the bag");
    return o;
  }
  std::string path_;
  mutable BagDrive drive_;
  mutable std::mutex mutex_;
  std::vector<int> frames_;
  std::map<int, std::size_t> index_;
  std::map<int, Mat4d> poses_;
};

class UnlabelledSource final : public FrameSource {
 public:
  explicit UnlabelledSource(std::unique_ptr<FrameSource> inner) : inner_(std::move(inner)) {}
  const std::vector<int>& frames() const override { return inner_->frames(); }
  bool hasPose(int f) const override { return inner_->hasPose(f); }
  Mat4d pose(int f) const override { return inner_->pose(f); }
  LabelledScan scan(int f) const override {
    auto s = inner_->scan(f);
    s.labels.clear();
    s.labels.shrink_to_fit();
    return s;
  }
  std::string describe() const override { return inner_->describe() + ", labels removed"; }

 private:
  std::unique_ptr<FrameSource> inner_;
};

}  // namespace

std::unique_ptr<FrameSource> withoutLabels(std::unique_ptr<FrameSource> source) {
  return std::make_unique<UnlabelledSource>(std::move(source));
}

std::unique_ptr<FrameSource> simulatedSource(const SimSourceOptions& options) {
  return std::make_unique<SimSource>(options);
}

std::unique_ptr<FrameSource> directorySource(const std::string& dir, const std::string& frames, DeskewMotion deskew,
                                             const BagDriveOptions& bag) {
  if (isBag(dir)) {
    BagDriveOptions o = bag;
    o.deskew = deskew != DeskewMotion::kOff;
    return std::make_unique<BagSource>(dir, o, frames);
  }
  return std::make_unique<DirSource>(dir, frames, deskew);
}

}  // namespace sglc::eval
