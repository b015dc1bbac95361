#include "sim/sequence.hpp"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <thread>

#include "sglc/io.hpp"
#include "sim/sequence_info.hpp"

namespace sglc::sim {
namespace {

namespace fs = std::filesystem;

std::ofstream openText(const fs::path& path) {
  std::ofstream out(path, std::ios::trunc);
  if (!out) throw InputError(path.string() + ": cannot create");
  return out;
}

void closeText(std::ofstream& out, const fs::path& path) {
  out.close();
  if (!out) throw InputError(path.string() + ": write failed");
}

std::string frameName(int k) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%06d", k);
  return buf;
}

// Frames must lie on the trajectory and ascend (output frame k is the k-th selected frame).
void checkFrames(const Simulator& sim, const SequenceOptions& opt) {
  if (opt.out_dir.empty()) throw InputError("no output directory given");
  if (opt.frames.empty()) throw InputError("no frames selected");
  for (std::size_t k = 0; k < opt.frames.size(); ++k) {
    if (opt.frames[k] < 0 || opt.frames[k] >= sim.numFrames())
      throw InputError("frame " + std::to_string(opt.frames[k]) + " is outside the trajectory");
    if (k > 0 && opt.frames[k] <= opt.frames[k - 1]) throw InputError("frames must be ascending");
  }
}

// Creates velodyne/ and labels/. Scans of an earlier run (6-digit names) are refused or, with overwrite,
// removed, so that a folder never mixes two runs.
void prepareFolders(const fs::path& out, const SequenceOptions& opt) {
  std::error_code ec;
  for (const char* sub : {"velodyne", "labels", "point_times"}) {
    if (!fs::is_directory(out / sub, ec)) continue;
    std::vector<fs::path> old;
    for (const auto& e : fs::directory_iterator(out / sub, ec)) {
      const std::string stem = e.path().stem().string(), ext = e.path().extension().string();
      if (stem.size() == 6 && stem.find_first_not_of("0123456789") == std::string::npos &&
          (ext == ".bin" || ext == ".label"))
        old.push_back(e.path());
    }
    if (old.empty()) continue;
    if (!opt.overwrite)
      throw InputError((out / sub).string() + " already holds " + std::to_string(old.size()) +
                       " scans from an earlier run; choose another --out or use --overwrite");
    for (const auto& p : old) fs::remove(p, ec);
  }
  fs::create_directories(out / "velodyne", ec);
  if (!ec) fs::create_directories(out / "labels", ec);
  if (ec) throw InputError(opt.out_dir + ": cannot create the output directories (" + ec.message() + ")");
}

// calib.txt (identity: poses.txt is already in the LiDAR frame), times.txt and frames.txt.
void writeCalibAndTimes(const fs::path& out, const std::vector<int>& frames, double frame_dt) {
  {
    auto f = openText(out / "calib.txt");
    for (const char* key : {"P0", "P1", "P2", "P3"}) f << key << ": 1 0 0 0 0 1 0 0 0 0 1 0\n";
    f << "Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n";
    closeText(f, out / "calib.txt");
  }
  auto times = openText(out / "times.txt");
  auto frame_map = openText(out / "frames.txt");
  char buf[64];
  for (int f : frames) {
    std::snprintf(buf, sizeof buf, "%.6e\n", f * frame_dt);
    times << buf;
    frame_map << f << '\n';
  }
  closeText(times, out / "times.txt");
  closeText(frame_map, out / "frames.txt");
}

// pairs_distance.txt: loop / non-loop pairs by horizontal distance; counts them into the summary.
void writeDistancePairs(const fs::path& out, const std::vector<Mat4d>& poses, const SequenceOptions& opt,
                        SequenceSummary& summary) {
  const auto pairs = distancePairs(poses, opt.frames, opt.pairs);
  auto f = openText(out / "pairs_distance.txt");
  f << "# i j label: output frames (i later, j earlier); 1 = loop (horizontal distance < " << opt.pairs.positive_m
    << " m and trajectory frames more than " << opt.pairs.min_gap << " apart), 0 = non-loop (> " << opt.pairs.negative_m
    << " m, sampled)\n";
  char buf[64];
  for (const auto& p : pairs) {
    std::snprintf(buf, sizeof buf, "%06d %06d %d\n", p.query, p.database, p.loop ? 1 : 0);
    f << buf;
    ++(p.loop ? summary.positives : summary.negatives);
  }
  closeText(f, out / "pairs_distance.txt");
}

// loop_distance4.txt: revisits within loop_pose_m with their relative pose; counts rows (and reverse
// revisits, heading more than 90 degrees apart) into the summary.
void writeLoopPoses(const fs::path& out, const std::vector<Mat4d>& poses, const SequenceOptions& opt,
                    SequenceSummary& summary) {
  const auto rows = loopPoses(poses, opt.frames, opt.loop_pose_m, opt.pairs.min_gap);
  auto f = openText(out / "loop_distance4.txt");
  f << "# i j T (row-major 3x4): output frames, i earlier, j later, 3-D distance < " << opt.loop_pose_m
    << " m, trajectory frames more than " << opt.pairs.min_gap
    << " apart. T maps LiDAR points of frame i into the LiDAR frame of frame j: p_j = T * p_i = inv(P_j) * P_i * "
       "p_i\n";
  char buf[64];
  for (const auto& r : rows) {
    f << r.first << ' ' << r.second;
    for (double v : poseRow12(r.T)) {
      std::snprintf(buf, sizeof buf, " %.6f", v);
      f << buf;
    }
    f << '\n';
    if (headingDifferenceDeg(poses[r.first], poses[r.second]) > 90.0) ++summary.reverse_loop_rows;
  }
  summary.loop_rows = rows.size();
  closeText(f, out / "loop_distance4.txt");
}

// Renders the selected frames on opt.threads workers and writes their scans and labels. Each worker pulls the
// next frame index, holds one frame at a time and keeps its own label IoU counts, merged once at the end, so
// workers never wait on each other; the calling thread only reports progress. The first error stops all.
class FrameWriter {
 public:
  FrameWriter(const Simulator& sim, const SequenceOptions& opt, const fs::path& out)
      : sim_(sim), opt_(opt), out_(out), n_(static_cast<int>(opt.frames.size())) {}

  void run(SequenceSummary& summary) {
    const int threads = std::clamp(opt_.threads, 1, n_);
    std::vector<std::thread> pool;
    for (int k = 0; k < threads; ++k) pool.emplace_back([this] { work(); });
    reportProgress();
    for (auto& t : pool) t.join();
    if (error_) std::rethrow_exception(error_);
    summary.frames = n_;
    summary.points = points_;
    summary.bytes = points_ * 20;
    summary.seconds = seconds();
    summary.frames_per_second = n_ / std::max(summary.seconds, 1e-9);
    summary.label_iou.merge(iou_);
    if (opt_.progress) opt_.progress(n_, n_, summary.seconds);
  }

 private:
  double seconds() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count(); }

  void work() {
    Frame frame;
    LabelIouCounts iou;
    while (!failed_) {
      const int k = next_.fetch_add(1);
      if (k >= n_) break;
      try {
        sim_.render(opt_.frames[k], frame, 1);
        writeKittiBin((out_ / "velodyne" / (frameName(k) + ".bin")).string(), frame.scan.points, frame.intensity);
        writeLabels((out_ / "labels" / (frameName(k) + ".label")).string(), frame.scan.labels);
        if (!frame.point_time.empty()) {
          std::error_code ec;
          fs::create_directories(out_ / "point_times", ec);
          writePointTimes((out_ / "point_times" / (frameName(k) + ".bin")).string(), frame.point_time);
        }
        points_ += frame.scan.points.size();
        if (frame.clean_labels.empty())
          iou.addExact(frame.scan.labels);
        else
          iou.add(frame.clean_labels, frame.scan.labels);
      } catch (...) {
        std::lock_guard lock(mutex_);
        if (!error_) error_ = std::current_exception();
        failed_ = true;
      }
      ++done_;
      cv_.notify_one();
    }
    std::lock_guard lock(mutex_);
    iou_.merge(iou);
  }

  // Waits for the workers, calling opt.progress about twice a second (outside the lock).
  void reportProgress() {
    double last_report = 0.0;
    std::unique_lock lock(mutex_);
    while (done_ < n_ && !failed_) {
      cv_.wait_for(lock, std::chrono::milliseconds(100));
      if (opt_.progress && done_ < n_ && seconds() - last_report >= 0.5) {
        last_report = seconds();
        lock.unlock();
        opt_.progress(done_, n_, last_report);
        lock.lock();
      }
    }
  }

  const Simulator& sim_;
  const SequenceOptions& opt_;
  const fs::path& out_;
  const int n_;
  const std::chrono::steady_clock::time_point t0_ = std::chrono::steady_clock::now();
  std::atomic<int> next_{0}, done_{0};
  std::atomic<bool> failed_{false};
  std::atomic<std::uint64_t> points_{0};
  std::exception_ptr error_;
  std::mutex mutex_;
  std::condition_variable cv_;
  LabelIouCounts iou_;  // all workers' counts, merged as each finishes
};

}  // namespace

SequenceSummary writeSequence(const Simulator& sim, const SequenceOptions& opt) {
  checkFrames(sim, opt);
  const fs::path out(opt.out_dir);
  prepareFolders(out, opt);
  const Trajectory& traj = sim.trajectory();
  std::vector<Mat4d> poses;
  for (int f : opt.frames) poses.push_back(traj.poses[f]);

  // Poses and ground truth, then the scans, then sim_info.json (which records how the scans went).
  writePoses((out / "poses.txt").string(), poses);
  writeCalibAndTimes(out, opt.frames, traj.frame_dt);
  SequenceSummary summary;
  writeDistancePairs(out, poses, opt, summary);
  writeLoopPoses(out, poses, opt, summary);
  if (opt.odometry.any())
    writePoses((out / "odometry.txt").string(), driftingOdometry(poses, opt.frames, opt.odometry, sim.config().seed));

  FrameWriter(sim, opt, out).run(summary);
  writeSimInfo((out / "sim_info.json").string(), sim, opt, summary);
  return summary;
}

}  // namespace sglc::sim
