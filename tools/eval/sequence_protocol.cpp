// The sequence protocol: each frame queries the frames stored before it, then is stored, as a robot's loop
// closing runs online.
#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <stdexcept>

#include "calibration.hpp"
#include "progress.hpp"
#include "protocols.hpp"

namespace sglc::eval {
namespace {

// Which frame pairs are true loops, and which lie in the band between true and false that counts as neither.
class LoopTruth {
 public:
  LoopTruth(const FrameSource& source, const SequenceOptions& o) : source_(source), o_(o) {
    if (!o.gt_list)
      for (int f : source.frames())
        if (!source.hasPose(f))
          throw InputError("frame " + std::to_string(f) + " has no ground-truth pose (give poses or --gt-list)");
    if (o.gt_list)
      for (const auto& r : *o.gt_list)
        if (r.label == 1) listed_.insert({std::min(r.i, r.j), std::max(r.i, r.j)});
  }
  double distance(int a, int b) const {
    return (source_.pose(a).block<3, 1>(0, 3) - source_.pose(b).block<3, 1>(0, 3)).norm();
  }
  bool isTrue(int a, int b) const {
    if (o_.gt_list) return listed_.count({std::min(a, b), std::max(a, b)}) > 0;
    return distance(a, b) < o_.positive_m;
  }
  bool inBand(int a, int b) const { return !o_.gt_list && !isTrue(a, b) && distance(a, b) < o_.negative_m; }
  // Per query: a frame it may match (stored before it, not among the recent ones) is a true loop.
  std::vector<bool> queriesWithTrueLoop(const std::vector<int>& frames, int exclude_recent) const {
    std::vector<bool> has_true(frames.size(), false);
    for (std::size_t q = 0; q < frames.size(); ++q)
      for (std::size_t e = 0; e < q && !has_true[q]; ++e)
        if (frames[q] - frames[e] >= exclude_recent && isTrue(frames[q], frames[e])) has_true[q] = true;
    return has_true;
  }

 private:
  const FrameSource& source_;
  SequenceOptions o_;
  std::set<std::pair<int, int>> listed_;
};

// What the queries gave, in query order.
struct Outcome {
  std::vector<Decision> decisions;
  std::vector<std::vector<bool>> ranked;  // per query: is each ranked candidate a true loop
  std::vector<Candidate> top;             // the detection of each query (frame -1: none)
  std::vector<RegistrationResult> poses;  // pose errors of the true detections
  std::size_t in_band = 0;
  std::size_t verified_true = 0, verified_false = 0;  // verified top-1 candidates outside the band
};

// Every query's verified top-1 candidate, whatever its score, goes to top1.csv: where false loops come from.
void writeTop1(std::ofstream& top1, const Run& run, const LoopTruth& truth, int f, const Candidate& c, bool is_true) {
  const int m = c.frame;
  const bool band = truth.inBand(f, m);
  top1 << f << "," << m << "," << c.score << ","
       << (run.source.hasPose(f) && run.source.hasPose(m) ? truth.distance(f, m) : -1.0) << ","
       << (band      ? "between"
           : is_true ? "true"
                     : "false")
       << "\n";
}

// Scores the query's candidates against the truth and records its decision.
void judge(Outcome& o, const Run& run, const LoopTruth& truth, int f, bool has_true,
           const std::vector<Candidate>& cands) {
  std::vector<bool> r;
  for (const auto& c : cands) r.push_back(truth.isTrue(f, c.frame));
  Decision d{0.0, false, has_true};
  Candidate top;
  top.frame = -1;
  if (!cands.empty() && cands[0].verified) {
    o.in_band += truth.inBand(f, cands[0].frame);
    if (!truth.inBand(f, cands[0].frame)) {
      ++(r[0] ? o.verified_true : o.verified_false);
      top = cands[0];
      d.score = top.score;
      d.predicted_true = r[0];
      if (r[0] && run.source.hasPose(f) && run.source.hasPose(top.frame)) {
        const Mat4d gt = run.source.pose(f).inverse() * run.source.pose(top.frame);
        o.poses.push_back({true, poseError(top.T, gt)});
      }
    }
  }
  o.ranked.push_back(std::move(r));
  o.decisions.push_back(d);
  o.top.push_back(top);
}

Outcome queryAll(Run& run, const LoopQuery& query, const LoopTruth& truth, const std::vector<bool>& has_true,
                 CalibrationLog& log) {
  const auto& frames = run.source.frames();
  Outcome o;
  std::ofstream top1(run.out + "/top1.csv");
  top1 << "frame,match_frame,score,distance_m,outcome\n" << std::setprecision(6);
  Prefetch pre(run.source, frames, run.threads);
  Progress bar("query", frames.size());
  for (std::size_t q = 0; q < frames.size(); ++q) {
    auto [f, scan] = pre.next();
    if (run.stored.count(f)) throw std::logic_error("the sequence protocol must run first");
    StageTimes t;
    const auto cands = run.backend.queryThenAdd(f, scan, query, &t);
    run.stored.insert(f);
    run.timings.add(t);
    if (!cands.empty() && cands[0].verified) writeTop1(top1, run, truth, f, cands[0], truth.isTrue(f, cands[0].frame));
    judge(o, run, truth, f, has_true[q], cands);
    for (const auto& c : cands)
      if (run.source.hasPose(f) && run.source.hasPose(c.frame)) {
        const Mat4d gt = run.source.pose(f).inverse() * run.source.pose(c.frame);
        log.add(f, c, &gt);
      }
    bar.step(q + 1);
  }
  return o;
}

// Trajectory with the detections at the F1max threshold: 1 = true loop, 2 = false loop.
void writeTrajectory(Run& run, const Outcome& o, const std::vector<bool>& has_true, const std::vector<PrPoint>& curve) {
  const auto& frames = run.source.frames();
  const double thr = f1Max(curve).threshold;
  std::ofstream csv(run.out + "/trajectory.csv");
  csv << "frame,x,y,has_true_loop,detection,match_frame\n" << std::setprecision(9);
  std::size_t tp = 0, fp = 0;
  for (std::size_t q = 0; q < frames.size(); ++q) {
    const auto& d = o.decisions[q];
    const bool detected = !curve.empty() && d.score >= thr && d.score > 0;
    const int kind = detected ? (d.predicted_true ? 1 : 2) : 0;
    tp += kind == 1;
    fp += kind == 2;
    const Mat4d P = run.source.hasPose(frames[q]) ? run.source.pose(frames[q]) : Mat4d::Identity();
    csv << frames[q] << "," << P(0, 3) << "," << P(1, 3) << "," << int(has_true[q]) << "," << kind << ","
        << (detected ? o.top[q].frame : -1) << "\n";
  }
  run.summary["at_f1max"] = {{"true_loops", tp}, {"false_loops", fp}};
}

}  // namespace

void sequenceProtocol(Run& run, const LoopQuery& query, const SequenceOptions& options) {
  const auto& frames = run.source.frames();
  const LoopTruth truth(run.source, options);
  const auto has_true = truth.queriesWithTrueLoop(frames, query.exclude_recent);
  CalibrationLog log(run.out + "/evidence.csv");
  const Outcome o = queryAll(run, query, truth, has_true, log);
  log.summarise(run.summary);
  const auto curve = detectionCurve(o.decisions);
  writeCurve(run.out + "/pr.csv", curve);
  curveSummary(run.summary, curve);
  const std::size_t one_pct = std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(0.01 * frames.size())));
  run.summary["recall_at_1"] = recallAtN(o.ranked, has_true, 1);
  run.summary["recall_at_1pct"] = recallAtN(o.ranked, has_true, one_pct);
  run.summary["recall_at_1pct_n"] = one_pct;
  run.summary["queries"] = frames.size();
  run.summary["queries_with_true_loop"] = std::count(has_true.begin(), has_true.end(), true);
  run.summary["top1_in_band"] = o.in_band;
  // What a pose graph would receive if it took every verified answer, whatever its score: false loops wreck it.
  const std::size_t verified = o.verified_true + o.verified_false;
  run.summary["verified_true"] = o.verified_true;
  run.summary["verified_false"] = o.verified_false;
  if (verified)
    run.summary["precision_all_verified"] = static_cast<double>(o.verified_true) / static_cast<double>(verified);
  else
    run.summary["precision_all_verified"] = nullptr;  // no verified answer: undefined
  registrationSummary(run.summary, o.poses);
  run.summary["rr_note"] = "pose errors of the true top-1 detections (any score)";
  writeTrajectory(run, o, has_true, curve);
}

}  // namespace sglc::eval
