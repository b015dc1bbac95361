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

// poses.txt (KITTI 12 columns or TUM 8 columns, told apart by the first line) and times.txt. A TUM file's
// stamps serve as the frames' stamps when there is no times.txt.
void attachPoses(const fs::path& root, std::vector<SequenceFrame>& all, Sequence& seq) {
  std::error_code ec;
  const std::int64_t max_frame = all.back().number;
  auto index = [&](Indexing how, std::size_t i) { return how == Indexing::kByNumber ? std::size_t(all[i].number) : i; };
  const fs::path poses_path = root / "poses.txt";
  if (fs::exists(poses_path, ec)) {
    const int columns = posesColumns(poses_path.string());
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

Sequence openSequence(const std::string& dir, const FrameSelection& selection, int every) {
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

  attachPoses(root, all, seq);
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
