#include "sglc/sequence.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "poses_frame.hpp"
#include "sglc/io.hpp"

namespace sglc {

namespace fs = std::filesystem;

namespace {

bool allDigits(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](unsigned char c) { return std::isdigit(c); });
}

// Index into a per-frame file (poses.txt, times.txt) for each frame, per the rule in sequence.hpp.
enum class Indexing { kByNumber, kByPosition };

Indexing chooseIndexing(const std::string& path, std::size_t lines, std::int64_t max_frame, std::size_t frames) {
  if (lines > static_cast<std::size_t>(max_frame)) return Indexing::kByNumber;
  if (lines == frames) return Indexing::kByPosition;
  throw InputError(path + ": " + std::to_string(lines) + " lines, but frames go up to " + std::to_string(max_frame) +
                   " (" + std::to_string(frames) +
                   " scans in the directory); expected one line per frame number or per scan");
}

// labels/NAME.label, else labels/NAME.npy; the .label path when neither exists (checked later).
std::string labelFileOf(const fs::path& root, const std::string& name) {
  std::error_code ec;
  const fs::path npy = root / "labels" / (name + ".npy");
  const fs::path label = root / "labels" / (name + ".label");
  return (!fs::exists(label, ec) && fs::exists(npy, ec)) ? npy.string() : label.string();
}

// The poses file (DIR/poses.txt or the one given: KITTI 12 columns or TUM 8, told apart by the first line) and
// times.txt. A TUM file's stamps serve as the frames' stamps when there is no times.txt. KITTI camera poses are
// turned into LiDAR poses per sglc/sequence.hpp.
void attachPoses(const fs::path& root, std::vector<SequenceFrame>& all, Sequence& seq, const PoseOptions& opt) {
  std::error_code ec;
  const std::int64_t max_frame = all.back().number;
  auto index = [&](Indexing how, std::size_t i) { return how == Indexing::kByNumber ? std::size_t(all[i].number) : i; };
  const fs::path poses_path = opt.file.empty() ? root / "poses.txt" : fs::path(opt.file);
  if (!opt.file.empty() && !fs::is_regular_file(poses_path, ec))
    throw InputError(opt.file + ": no such poses file (--poses)");
  int columns = -1;
  if (fs::exists(poses_path, ec)) {
    columns = posesColumns(poses_path.string());
    if (columns == 8) {
      const auto poses = readTumPoses(poses_path.string());
      const auto how = chooseIndexing(poses_path.string(), poses.size(), max_frame, all.size());
      for (std::size_t i = 0; i < all.size(); ++i) {
        all[i].pose = poses[index(how, i)].pose;
        all[i].stamp = poses[index(how, i)].stamp;
      }
      seq.has_stamps = true;
    } else if (columns == 12 || columns == 0) {
      const auto poses = readPoses(poses_path.string());
      const auto how = chooseIndexing(poses_path.string(), poses.size(), max_frame, all.size());
      for (std::size_t i = 0; i < all.size(); ++i) all[i].pose = poses[index(how, i)];
    } else {
      throw InputError(poses_path.string() + ": " + std::to_string(columns) +
                       " numbers per line; expected 12 (KITTI 3x4) or 8 (TUM t tx ty tz qx qy qz qw)");
    }
    seq.has_poses = true;
    seq.poses_path = poses_path.string();
  } else if (opt.frame == PosesFrame::kCamera) {
    throw InputError(root.string() + ": --poses-frame camera, but there is no poses.txt (give --poses FILE)");
  }
  if (seq.has_poses) {
    const fs::path calib = root / "calib.txt";
    const bool kitti = columns == 12 || columns == 0;
    const bool camera =
        opt.frame == PosesFrame::kCamera || (opt.frame == PosesFrame::kAuto && kitti && fs::exists(calib, ec));
    if (camera) {
      if (!fs::exists(calib, ec))
        throw InputError(calib.string() + ": missing; --poses-frame camera needs KITTI's calib.txt (its Tr line)");
      Mat4d Tr;
      try {
        Tr = readCalibTr(calib.string());
      } catch (const InputError& e) {
        throw InputError(std::string(e.what()) + " (the poses are taken as KITTI camera poses because calib.txt is " +
                         "there; give --poses-frame lidar to take them as LiDAR poses)");
      }
      const Eigen::Matrix3d R = Tr.topLeftCorner<3, 3>();
      if (!((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() < 1e-3 && R.determinant() > 0))
        throw InputError(calib.string() + ": its Tr is not a rotation and a shift (R^T R differs from I by " +
                         std::to_string((R.transpose() * R - Eigen::Matrix3d::Identity()).norm()) + ")");
      // An identity Tr (the simulator's) says the camera frame is the LiDAR's: nothing to turn.
      if (!Tr.isApprox(Mat4d::Identity(), 1e-12)) {
        std::vector<Mat4d*> poses;
        for (auto& f : all) poses.push_back(&*f.pose);
        cameraToLidarPoses(poses, Tr);
        seq.poses_from_camera = true;
      }
    }
    std::vector<const Mat4d*> poses;
    for (const auto& f : all) poses.push_back(&*f.pose);
    if (auto w = zMotionWarning(poses, poses_path.string())) seq.warnings.push_back(*w);
  }
  const fs::path times_path = root / "times.txt";
  if (fs::exists(times_path, ec)) {
    const auto stamps = readStamps(times_path.string());
    const auto how = chooseIndexing(times_path.string(), stamps.size(), max_frame, all.size());
    for (std::size_t i = 0; i < all.size(); ++i) all[i].stamp = stamps[index(how, i)];
    seq.has_stamps = true;
  }
}

}  // namespace

PosesFrame parsePosesFrame(const std::string& text) {
  if (text == "auto") return PosesFrame::kAuto;
  if (text == "lidar") return PosesFrame::kLidar;
  if (text == "camera") return PosesFrame::kCamera;
  throw InputError("--poses-frame '" + text + "': expected auto, lidar or camera");
}

Sequence openSequence(const std::string& dir, const FrameSelection& selection, int every, const PoseOptions& poses) {
  if (every < 1) throw InputError("--every must be at least 1 (got " + std::to_string(every) + ")");
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw InputError(dir + ": not a directory");
  const fs::path root(dir);
  const fs::path velodyne = root / "velodyne";
  if (!fs::is_directory(velodyne, ec))
    throw InputError(
        dir + ": no velodyne/ directory (expected SemanticKITTI layout: velodyne/NNNNNN.bin, labels/NNNNNN.label)");

  Sequence seq;
  seq.dir = dir;
  seq.name = fs::weakly_canonical(root, ec).filename().string();
  if (ec || seq.name.empty() || seq.name == "." || seq.name == "..")
    seq.name = root.lexically_normal().filename().string();

  std::vector<SequenceFrame> all;
  std::string format;  // the extension every scan shares
  for (const auto& entry : fs::directory_iterator(velodyne, ec)) {
    const fs::path& p = entry.path();
    if (!isScanFile(p.string()) || !allDigits(p.stem().string())) continue;
    if (format.empty()) format = p.extension().string();
    if (p.extension() != format)
      throw InputError(velodyne.string() + ": holds both " + format + " and " + p.extension().string() +
                       " scans; a sequence uses one format");
    SequenceFrame f;
    f.name = p.stem().string();
    if (f.name.size() > 12) continue;
    f.number = std::stoll(f.name);
    f.scan_path = p.string();
    f.label_path = labelFileOf(root, f.name);
    std::error_code absent;  // not `ec`: that one reports the listing's own failure below
    if (fs::is_regular_file(root / "point_times" / (f.name + ".bin"), absent))
      f.point_times_path = (root / "point_times" / (f.name + ".bin")).string();
    all.push_back(std::move(f));
  }
  if (ec) throw InputError(velodyne.string() + ": cannot list (" + ec.message() + ")");
  if (all.empty()) throw InputError(velodyne.string() + ": no NNNNNN scans (formats: " + kScanFormats + ")");
  std::sort(all.begin(), all.end(), [](const auto& a, const auto& b) { return a.number < b.number; });
  for (std::size_t i = 1; i < all.size(); ++i)
    if (all[i].number == all[i - 1].number)
      throw InputError(velodyne.string() + ": " + all[i - 1].name + format + " and " + all[i].name + format +
                       " have the same frame number");
  seq.frames_in_dir = all.size();
  const std::int64_t max_frame = all.back().number;

  attachPoses(root, all, seq, poses);
  std::size_t in_range = 0;
  for (auto& f : all) {
    if (!selection.contains(f.number)) continue;
    if (in_range++ % static_cast<std::size_t>(every) == 0) seq.frames.push_back(std::move(f));
  }
  if (seq.frames.empty()) {
    throw InputError(velodyne.string() + ": no scans in frame selection '" + selection.text() +
                     "' (scans there go from " + std::to_string(all.front().number) + " to " +
                     std::to_string(max_frame) + ")");
  }
  // Labels are all there or all absent (a directory with velodyne/ only is sent unlabelled: the server's
  // labeller labels it); a sequence with some label files missing is an error.
  std::size_t labelled = 0;
  for (const auto& f : seq.frames) labelled += fs::is_regular_file(f.label_path, ec);
  if (labelled == 0) {
    for (auto& f : seq.frames) f.label_path.clear();
  } else if (labelled != seq.frames.size()) {
    for (const auto& f : seq.frames)
      if (!fs::is_regular_file(f.label_path, ec))
        throw InputError(f.label_path + ": missing (some scans of the sequence have labels, this one has none)");
  }
  return seq;
}

}  // namespace sglc
