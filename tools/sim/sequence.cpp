#include "sim/sequence.hpp"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "sglc/io.hpp"

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

std::vector<double> row12(const Mat4d& T) {
  std::vector<double> v;
  for (int k = 0; k < 12; ++k) v.push_back(T(k / 4, k % 4));
  return v;
}

// Per-class IoU of the written labels against the true ones (SemanticKITTI single-scan scoring: moving
// classes count as static ones); classes absent from both are left out.
nlohmann::ordered_json labelIouJson(const LabelIouCounts& counts) {
  nlohmann::ordered_json iou = nlohmann::ordered_json::object();
  for (int k = 0; k < kEvalClasses; ++k)
    if (counts.present(k)) iou[kEvalClassTable[k].name] = counts.iou(k);
  return iou;
}

}  // namespace

SequenceSummary writeSequence(const Simulator& sim, const SequenceOptions& opt) {
  if (opt.out_dir.empty()) throw InputError("no output directory given");
  if (opt.frames.empty()) throw InputError("no frames selected");
  for (std::size_t k = 0; k < opt.frames.size(); ++k) {
    if (opt.frames[k] < 0 || opt.frames[k] >= sim.numFrames())
      throw InputError("frame " + std::to_string(opt.frames[k]) + " is outside the trajectory");
    if (k > 0 && opt.frames[k] <= opt.frames[k - 1]) throw InputError("frames must be ascending");
  }
  const fs::path out(opt.out_dir);
  std::error_code ec;
  // Scans of an earlier run (6-digit names) are refused or, with overwrite, removed.
  for (const char* sub : {"velodyne", "labels"}) {
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

  const Trajectory& traj = sim.trajectory();
  const int n = static_cast<int>(opt.frames.size());
  std::vector<Mat4d> poses;
  for (int f : opt.frames) poses.push_back(traj.poses[f]);

  // ---- poses, calibration, times, frame map
  writePoses((out / "poses.txt").string(), poses);
  {
    auto f = openText(out / "calib.txt");
    for (const char* key : {"P0", "P1", "P2", "P3"}) f << key << ": 1 0 0 0 0 1 0 0 0 0 1 0\n";
    f << "Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n";
    closeText(f, out / "calib.txt");
  }
  {
    auto times = openText(out / "times.txt");
    auto frames = openText(out / "frames.txt");
    char buf[64];
    for (int f : opt.frames) {
      std::snprintf(buf, sizeof buf, "%.6e\n", f * traj.frame_dt);
      times << buf;
      frames << f << '\n';
    }
    closeText(times, out / "times.txt");
    closeText(frames, out / "frames.txt");
  }

  // ---- ground truth
  SequenceSummary summary;
  {
    const auto pairs = distancePairs(poses, opt.frames, opt.pairs);
    auto f = openText(out / "pairs_distance.txt");
    f << "# i j label: output frames (i later, j earlier); 1 = loop (horizontal distance < " << opt.pairs.positive_m
      << " m and trajectory frames more than " << opt.pairs.min_gap << " apart), 0 = non-loop (> "
      << opt.pairs.negative_m << " m, sampled)\n";
    char buf[64];
    for (const auto& p : pairs) {
      std::snprintf(buf, sizeof buf, "%06d %06d %d\n", p.query, p.database, p.loop ? 1 : 0);
      f << buf;
      ++(p.loop ? summary.positives : summary.negatives);
    }
    closeText(f, out / "pairs_distance.txt");
  }
  {
    const auto rows = loopPoses(poses, opt.frames, opt.loop_pose_m, opt.pairs.min_gap);
    auto f = openText(out / "loop_distance4.txt");
    f << "# i j T (row-major 3x4): output frames, i earlier, j later, 3-D distance < " << opt.loop_pose_m
      << " m, trajectory frames more than " << opt.pairs.min_gap
      << " apart. T maps LiDAR points of frame i into the LiDAR frame of frame j: p_j = T * p_i = inv(P_j) * P_i * "
         "p_i\n";
    char buf[64];
    for (const auto& r : rows) {
      f << r.first << ' ' << r.second;
      for (double v : row12(r.T)) {
        std::snprintf(buf, sizeof buf, " %.6f", v);
        f << buf;
      }
      f << '\n';
      if (headingDifferenceDeg(poses[r.first], poses[r.second]) > 90.0) ++summary.reverse_loop_rows;
    }
    summary.loop_rows = rows.size();
    closeText(f, out / "loop_distance4.txt");
  }
  if (opt.odometry.any())
    writePoses((out / "odometry.txt").string(), driftingOdometry(poses, opt.frames, opt.odometry, sim.config().seed));

  // ---- frames, rendered in parallel; each worker holds one frame at a time
  const auto t0 = std::chrono::steady_clock::now();
  auto seconds = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  std::atomic<int> next{0}, done{0};
  std::atomic<bool> failed{false};
  std::atomic<std::uint64_t> points{0};
  std::exception_ptr error;
  std::mutex mutex;
  std::condition_variable cv;
  auto worker = [&] {
    Frame frame;
    LabelIouCounts iou;  // merged once at the end, so workers never wait on each other
    while (!failed) {
      const int k = next.fetch_add(1);
      if (k >= n) break;
      try {
        sim.render(opt.frames[k], frame, 1);
        writeKittiBin((out / "velodyne" / (frameName(k) + ".bin")).string(), frame.scan.points, frame.intensity);
        writeLabels((out / "labels" / (frameName(k) + ".label")).string(), frame.scan.labels);
        points += frame.scan.points.size();
        if (frame.clean_labels.empty())
          iou.addExact(frame.scan.labels);
        else
          iou.add(frame.clean_labels, frame.scan.labels);
      } catch (...) {
        std::lock_guard lock(mutex);
        if (!error) error = std::current_exception();
        failed = true;
      }
      ++done;
      cv.notify_one();
    }
    std::lock_guard lock(mutex);
    summary.label_iou.merge(iou);
  };
  const int threads = std::clamp(opt.threads, 1, n);
  std::vector<std::thread> pool;
  for (int k = 0; k < threads; ++k) pool.emplace_back(worker);
  double last_report = 0.0;
  {
    std::unique_lock lock(mutex);
    while (done < n && !failed) {
      cv.wait_for(lock, std::chrono::milliseconds(100));
      if (opt.progress && done < n && seconds() - last_report >= 0.5) {
        last_report = seconds();
        lock.unlock();
        opt.progress(done, n, last_report);
        lock.lock();
      }
    }
  }
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
  summary.frames = n;
  summary.points = points;
  summary.bytes = points * 20;
  summary.seconds = seconds();
  summary.frames_per_second = n / std::max(summary.seconds, 1e-9);
  if (opt.progress) opt.progress(n, n, summary.seconds);

  // ---- sim_info.json
  const SimConfig& cfg = sim.config();
  const World& world = sim.world();
  nlohmann::ordered_json info;
  info["generator"] = "sglc-sim";
  info["format_version"] = 1;
  info["seed"] = cfg.seed;
  info["source"] = traj.source;
  info["Tr"] = row12(traj.Tr);
  info["frame_dt"] = traj.frame_dt;
  info["trajectory_frames"] = sim.numFrames();
  info["selection"] = opt.selection_spec;
  info["frames"] = n;
  const auto& s = cfg.sensor;
  info["sensor"] = {{"name", s.name},
                    {"beams", s.beams()},
                    {"elevation_deg", s.elevation_deg},
                    {"columns", s.columns},
                    {"max_range", s.max_range},
                    {"min_range", s.min_range},
                    {"range_noise", s.range_noise},
                    {"dropout", s.dropout},
                    {"far_dropout", s.far_dropout},
                    {"grazing_dropout", s.grazing_dropout},
                    {"glass_dropout", s.glass_dropout},
                    {"intensity_noise", s.intensity_noise}};
  // Realism knobs (render.cpp, sensor.hpp); a rosette's beams x columns are its pseudo range image.
  info["sensor"]["laser_offsets"] = s.laser_offsets;
  info["sensor"]["mixed_pixel_rate"] = s.mixed_pixel_rate;
  info["sensor"]["motion_distortion"] = s.motion_distortion;
  if (s.isRosette())
    info["sensor"]["rosette"] = {
        {"rays", s.rosette_rays}, {"fov_h_deg", s.rosette_fov_h_deg}, {"fov_v_deg", s.rosette_fov_v_deg}};
  const auto& st = world.style();
  const auto& ws = world.stats();
  info["world"] = {{"sensor_height", cfg.world.sensor_height},
                   {"moving_objects", cfg.world.moving_objects},
                   {"path_extension", cfg.world.path_extension},
                   {"turnover", cfg.world.turnover},
                   {"epoch", cfg.world.epoch},
                   {"aliasing", cfg.world.aliasing},
                   {"parking_slots", ws.parking_slots},
                   {"temporary_sites", ws.temporary_sites},
                   {"aliased_lots", ws.aliased_lots},
                   {"lane_width", st.lane_width},
                   {"road_half_width", st.road_half_width},
                   {"parking_width", st.parking_width},
                   {"sidewalk_width", st.sidewalk_width},
                   {"path_length_m", ws.path_length_m},
                   {"primitives", ws.primitives},
                   {"buildings", ws.buildings},
                   {"fences", ws.fences},
                   {"hedges", ws.hedges},
                   {"trees", ws.trees},
                   {"bushes", ws.bushes},
                   {"poles", ws.poles},
                   {"signs", ws.signs},
                   {"parked_vehicles", ws.parked_vehicles},
                   {"moving_agents", ws.moving_agents},
                   {"memory_bytes", ws.memory_bytes},
                   {"build_seconds", ws.build_seconds},
                   {"content_hash", world.contentHash()}};
  info["label_noise"] = {{"model", cfg.label_noise.modelName()},
                         {"confusion", cfg.label_noise.confusion},
                         {"bleed", cfg.label_noise.bleed},
                         {"miss", cfg.label_noise.miss}};
  info["label_iou"] = labelIouJson(summary.label_iou);
  info["label_miou"] = summary.label_iou.meanIou();
  info["odometry_noise"] = {{"translation", opt.odometry.translation},
                            {"rotation_deg_per_m", opt.odometry.rotation_deg_per_m}};
  info["pairs_distance"] = {
      {"positive_m", opt.pairs.positive_m}, {"negative_m", opt.pairs.negative_m},
      {"min_gap", opt.pairs.min_gap},       {"negatives_per_positive", opt.pairs.negatives_per_positive},
      {"positives", summary.positives},     {"negatives", summary.negatives}};
  info["loop_distance4"] = {
      {"max_m", opt.loop_pose_m}, {"rows", summary.loop_rows}, {"reverse_rows", summary.reverse_loop_rows}};
  info["conventions"] = {
      {"points", "sensor (LiDAR) frame: x forward, y left, z up; float32 x y z intensity"},
      {"labels",
       "SemanticKITTI raw class id in the low 16 bits, instance id in the high 16 bits (vehicles, "
       "persons, trunks, poles, traffic signs)"},
      {"poses", "LiDAR -> world, world = LiDAR frame of trajectory frame 0; row k = output frame k"},
      {"loop_distance4", "p_j = T * p_i (T maps points of the earlier frame i into the later frame j)"},
      {"pairs_distance", "i later, j earlier; horizontal (x, y) distance"}};
  info["summary"] = {{"points", summary.points},
                     {"points_per_frame", static_cast<double>(summary.points) / n},
                     {"seconds", summary.seconds},
                     {"frames_per_second", summary.frames_per_second}};
  auto f = openText(out / "sim_info.json");
  f << info.dump(2) << '\n';
  closeText(f, out / "sim_info.json");
  return summary;
}

}  // namespace sglc::sim
