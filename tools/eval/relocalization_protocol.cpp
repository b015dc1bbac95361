// The relocalization protocol: a map from one drive, queried by every frame of another drive through the same
// world (later, or with another sensor), as a robot finds where it is in a map saved days earlier.
#include <time.h>

#include <algorithm>
#include <fstream>
#include <iomanip>
#include <limits>

#include "calibration.hpp"
#include "progress.hpp"
#include "protocols.hpp"
#include "sglc/elapsed.hpp"

namespace sglc::eval {
namespace {

// CPU time of the calling thread, ms.
double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

Eigen::Vector3d positionOf(const FrameSource& source, int frame) {
  if (!source.hasPose(frame)) throw InputError("frame " + std::to_string(frame) + " has no ground-truth pose");
  return source.pose(frame).block<3, 1>(0, 3);
}

// Distance from each query frame to the nearest map frame.
std::vector<double> nearestMapFrame(const FrameSource& queries, const FrameSource& map) {
  std::vector<Eigen::Vector3d> places;
  for (int m : map.frames()) places.push_back(positionOf(map, m));
  std::vector<double> nearest;
  for (int f : queries.frames()) {
    const Eigen::Vector3d p = positionOf(queries, f);
    double best = std::numeric_limits<double>::infinity();
    for (const auto& q : places) best = std::min(best, (q - p).norm());
    nearest.push_back(best);
  }
  return nearest;
}

struct Tally {
  std::vector<Decision> decisions;
  std::vector<std::vector<bool>> ranked;
  std::vector<RegistrationResult> poses;  // of the true verified top-1 candidates
  std::vector<double> cpu_ms;             // each query's CPU time on this thread
  std::size_t verified_true = 0, verified_false = 0, in_band = 0;
};

// Scores one query's answer and writes its row of relocalization.csv and, for a true place, of pose_errors.csv.
void judge(Tally& t, const Run& run, const FrameSource& map, const SequenceOptions& o, int f, double nearest,
           const std::vector<Candidate>& cands, std::ofstream& rows, std::ofstream& pose_rows) {
  const Eigen::Vector3d p = positionOf(run.source, f);
  const bool has_true = nearest < o.positive_m;
  std::vector<bool> r;
  for (const auto& c : cands) r.push_back((positionOf(map, c.frame) - p).norm() < o.positive_m);
  t.ranked.push_back(r);
  Decision d{0.0, false, has_true};
  if (!cands.empty() && cands[0].verified) {
    const auto& c = cands[0];
    const double dist = (positionOf(map, c.frame) - p).norm();
    const bool band = !r[0] && dist < o.negative_m;
    rows << f << "," << c.frame << "," << c.score << "," << dist << "," << nearest << ","
         << (band   ? "between"
             : r[0] ? "true"
                    : "false")
         << "\n";
    t.in_band += band;
    if (!band) {
      d = {c.score, r[0], has_true};
      (r[0] ? t.verified_true : t.verified_false) += 1;
    }
    if (r[0]) {
      RegistrationResult res;
      res.registered = c.refined;
      res.verified = true;
      if (c.refined) res.error = poseError(c.T, run.source.pose(f).inverse() * map.pose(c.frame));
      t.poses.push_back(res);
      pose_rows << f << "," << c.frame << "," << int(res.registered) << ",1," << res.error.rte_m << ","
                << res.error.rre_deg << "\n";
    }
  } else {
    rows << f << ",-1,0,-1," << nearest << ",none\n";
  }
  t.decisions.push_back(d);
}

Tally queryAll(Run& run, const FrameSource& map, const LoopQuery& query, const SequenceOptions& o,
               const std::vector<double>& nearest, CalibrationLog& log) {
  std::ofstream rows(run.out + "/relocalization.csv");
  rows << "frame,match_frame,score,distance_m,nearest_map_m,outcome\n" << std::setprecision(6);
  std::ofstream pose_rows(run.out + "/pose_errors.csv");
  pose_rows << "i,j,registered,verified,rte_m,rre_deg\n" << std::setprecision(9);
  Tally t;
  const auto& frames = run.source.frames();
  Prefetch pre(run.source, frames, run.threads);
  Progress bar("relocalize", frames.size());
  for (std::size_t q = 0; q < frames.size(); ++q) {
    auto [f, scan] = pre.next();
    StageTimes times;
    const double cpu0 = threadCpuMs();
    const auto cands = run.backend.query(scan, query, &times);
    t.cpu_ms.push_back(threadCpuMs() - cpu0);
    run.timings.add(times);
    judge(t, run, map, o, f, nearest[q], cands, rows, pose_rows);
    for (const auto& c : cands) {
      const Mat4d gt = run.source.pose(f).inverse() * map.pose(c.frame);
      log.add(f, c, &gt);
    }
    bar.step(q + 1);
  }
  return t;
}

}  // namespace

void relocalizationProtocol(Run& run, const FrameSource& map, const LoopQuery& query, const SequenceOptions& o) {
  const auto nearest = nearestMapFrame(run.source, map);
  storeFrames(run, map, map.frames());
  CalibrationLog log(run.out + "/evidence.csv");
  const Tally t = queryAll(run, map, query, o, nearest, log);
  log.summarise(run.summary);
  std::vector<bool> has_true;
  for (double d : nearest) has_true.push_back(d < o.positive_m);
  const auto with_place = static_cast<std::size_t>(std::count(has_true.begin(), has_true.end(), true));
  const auto curve = detectionCurve(t.decisions);
  writeCurve(run.out + "/pr.csv", curve);
  curveSummary(run.summary, curve);
  const auto best = f1Max(curve);
  auto& s = run.summary;
  s["map_source"] = map.describe();
  s["map_frames"] = map.frames().size();
  s["queries"] = run.source.frames().size();
  s["queries_with_true_place"] = with_place;
  // Relocalized: the top-1 candidate is verified and at the true place.
  s["recall_at_1"] = with_place ? static_cast<double>(t.verified_true) / static_cast<double>(with_place) : 0.0;
  s["recall_at_1_ranked"] = recallAtN(t.ranked, has_true, 1);  // the first candidate, verified or not
  s["precision"] = best.precision;                             // at the F1max threshold (operating_threshold)
  s["operating_threshold"] = best.threshold;
  const std::size_t verified = t.verified_true + t.verified_false;
  if (verified)
    s["precision_all_verified"] = static_cast<double>(t.verified_true) / static_cast<double>(verified);
  else
    s["precision_all_verified"] = nullptr;  // no verified answer: undefined
  s["verified_true"] = t.verified_true;
  s["verified_false"] = t.verified_false;
  s["top1_in_band"] = t.in_band;
  s["positive_m"] = o.positive_m;
  s["negative_m"] = o.negative_m;
  registrationSummary(s, t.poses);
  s["rr_note"] = "pose errors of the verified top-1 candidates at the true place";
  // A query's CPU time, fingerprint to refined poses: the whole query runs on this thread in process (a remote
  // backend's server time is not in it, so it is left out there).
  if (run.backend.name() == "in-process")
    s["query_cpu"] = {
        {"median_ms", percentile(t.cpu_ms, 0.5)}, {"p90_ms", percentile(t.cpu_ms, 0.9)}, {"n", t.cpu_ms.size()}};
}

}  // namespace sglc::eval
