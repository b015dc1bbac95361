// The pair and pose protocols: listed pairs verified, or registered as known loops.
#include <fstream>
#include <iomanip>
#include <map>

#include "calibration.hpp"
#include "progress.hpp"
#include "protocols.hpp"

namespace sglc::eval {
namespace {

std::vector<PairRow> usablePairs(Run& run, const std::vector<PairRow>& rows, bool need_pose) {
  const std::set<int> selected(run.source.frames().begin(), run.source.frames().end());
  std::vector<PairRow> out;
  for (const auto& r : rows) {
    if (!selected.count(r.i) || !selected.count(r.j) || r.i == r.j) continue;
    if (need_pose && !r.T && !(run.source.hasPose(r.i) && run.source.hasPose(r.j))) continue;
    out.push_back(r);
  }
  run.summary["pairs_in_file"] = rows.size();
  run.summary["pairs_used"] = out.size();
  if (out.empty()) throw InputError("no pair of the file has both frames in the data (check --frames / --data)");
  return out;
}

std::vector<int> framesOf(const std::vector<PairRow>& rows) {
  std::set<int> f;
  for (const auto& r : rows) f.insert({r.i, r.j});
  return {f.begin(), f.end()};
}

// Ground truth of a pose pair: T_est maps j's points into i's frame; a file's T (LCR-Net lists) maps i's points
// into j's frame.
Mat4d groundTruth(const Run& run, const PairRow& r, bool gt_from_file) {
  if (gt_from_file || !(run.source.hasPose(r.i) && run.source.hasPose(r.j))) {
    if (!r.T) throw InputError("pair " + std::to_string(r.i) + " " + std::to_string(r.j) + " has no pose");
    return r.T->inverse();
  }
  return run.source.pose(r.i).inverse() * run.source.pose(r.j);
}

}  // namespace

void storeFrames(Run& run, const FrameSource& source, const std::vector<int>& wanted) {
  std::vector<int> frames;
  for (int f : wanted)
    if (run.stored.insert(f).second) frames.push_back(f);
  if (frames.empty()) return;
  Prefetch pre(source, frames, run.threads);
  Progress bar("store", frames.size());
  std::size_t n = 0;
  while (!pre.done()) {
    auto [f, scan] = pre.next();
    StageTimes t;
    run.backend.add(f, scan, &t);
    run.timings.add(t);
    bar.step(++n);
  }
}

void pairProtocol(Run& run, const std::vector<PairRow>& file_rows) {
  const auto rows = usablePairs(run, file_rows, false);
  storeFrames(run, run.source, framesOf(rows));
  std::map<int, std::vector<std::size_t>> by_query;
  for (std::size_t k = 0; k < rows.size(); ++k) by_query[rows[k].i].push_back(k);
  std::vector<Decision> decisions(rows.size());
  Progress bar("verify", rows.size());
  std::size_t n = 0;
  Timings verify_times;
  CalibrationLog log(run.out + "/evidence.csv");
  for (const auto& [q, ks] : by_query) {
    std::vector<int> cands;
    for (auto k : ks) cands.push_back(rows[k].j);
    StageTimes t;
    const auto result = run.backend.verify(q, cands, Refine::none, &t);
    verify_times.add(t);
    std::map<int, Candidate> by_frame;
    for (const auto& c : result) by_frame[c.frame] = c;
    for (auto k : ks) {
      const auto& c = by_frame.at(rows[k].j);
      decisions[k] = {c.verified ? c.score : 0.0, rows[k].label == 1, rows[k].label == 1};
      // A listed negative is no loop at any pose; a positive's poses are judged where its ground truth is known.
      if (rows[k].label != 1)
        log.addFalse(q, c);
      else if (rows[k].T || (run.source.hasPose(rows[k].i) && run.source.hasPose(rows[k].j))) {
        const Mat4d gt = groundTruth(run, rows[k], false);
        log.add(q, c, &gt);
      }
    }
    bar.step(n += ks.size());
  }
  const auto curve = detectionCurve(decisions);
  writeCurve(run.out + "/pr.csv", curve);
  curveSummary(run.summary, curve);
  std::size_t pos = 0;
  for (const auto& d : decisions) pos += d.has_true_loop;
  run.summary["positives"] = pos;
  run.summary["negatives"] = decisions.size() - pos;
  run.summary["verify_timings"] = verify_times.json();
  log.summarise(run.summary);
}

void poseProtocol(Run& run, const std::vector<PairRow>& file_rows, bool gt_from_file) {
  std::vector<PairRow> positives;
  for (const auto& r : file_rows)
    if (r.label == 1) positives.push_back(r);
  const auto rows = usablePairs(run, positives, true);
  storeFrames(run, run.source, framesOf(rows));
  std::vector<RegistrationResult> results;
  std::ofstream csv(run.out + "/pose_errors.csv");
  csv << "i,j,registered,verified,rte_m,rre_deg\n" << std::setprecision(9);
  Progress bar("register", rows.size());
  Timings reg_times;
  CalibrationLog log(run.out + "/evidence.csv");
  for (std::size_t k = 0; k < rows.size(); ++k) {
    const auto& r = rows[k];
    const Mat4d gt = groundTruth(run, r, gt_from_file);
    StageTimes t;
    // The pairs are known loops: a pose is estimated whether or not verification accepts the pair (as the
    // paper's protocol registers every listed pair); `verified` keeps the loop decision.
    const auto c = run.backend.verify(r.i, {r.j}, Refine::known_loops, &t).at(0);
    reg_times.add(t);
    log.add(r.i, c, &gt);
    RegistrationResult res;
    res.registered = c.refined;
    res.verified = c.verified;
    if (c.refined) res.error = poseError(c.T, gt);
    results.push_back(res);
    csv << r.i << "," << r.j << "," << int(res.registered) << "," << int(res.verified) << "," << res.error.rte_m << ","
        << res.error.rre_deg << "\n";
    bar.step(k + 1);
  }
  registrationSummary(run.summary, results);
  run.summary["pose_gt"] = gt_from_file ? "pair file" : "poses";
  run.summary["register_timings"] = reg_times.json();
  log.summarise(run.summary);
}

}  // namespace sglc::eval
