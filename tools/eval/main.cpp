// sglc-eval: loop-closure metrics computed the way the paper's protocols define them (docs/METHOD.md),
// on a SemanticKITTI-layout sequence or on a simulated one, with the engine in-process or through a server.
//
//   sglc-eval --protocol pairs|sequence|pose|all [--data DIR | --sim [--poses P --calib C] [--seed N]
//             [--label-noise X]] [--frames SPEC] [--pairs FILE] [--pose-pairs FILE] [--server ADDR] --out DIR
//
// "all" runs the sequence protocol, then the pair and pose protocols on the frames it stored (each frame is
// rendered and fingerprinted once), into DIR/sequence, DIR/pairs and DIR/pose.
//
// Writes DIR/summary.json and, through tools/eval/plot.py, the figures (pr_curve.png, trajectory.png,
// pose_errors.png) from the CSV files it writes beside them.
#include <unistd.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <filesystem>
#include <fstream>
#include <future>
#include <iomanip>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <thread>

#include "backend.hpp"
#include "metrics.hpp"
#include "sglc/client/client.hpp"
#include "sglc/config/engine_file.hpp"
#include "sim/ground_truth.hpp"
#include "source.hpp"

#ifndef SGLC_EVAL_PLOT_SCRIPT
#define SGLC_EVAL_PLOT_SCRIPT "tools/eval/plot.py"
#endif

namespace {

namespace fs = std::filesystem;
using namespace sglc;
using namespace sglc::eval;
using Clock = std::chrono::steady_clock;
using nlohmann::ordered_json;

double seconds(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// A one-line progress bar with rate and ETA on stderr (a line per 10 % when stderr is not a terminal).
class Progress {
 public:
  Progress(std::string label, std::size_t total) : label_(std::move(label)), total_(total), tty_(isatty(2)) {}
  void step(std::size_t done) {
    const double t = seconds(start_);
    const bool last = done == total_;
    if (tty_ ? (t - shown_ < 0.25 && !last) : (done * 10 / std::max<std::size_t>(total_, 1) == tenth_ && !last)) return;
    shown_ = t;
    tenth_ = done * 10 / std::max<std::size_t>(total_, 1);
    const double rate = t > 0 ? static_cast<double>(done) / t : 0;
    const double eta = rate > 0 ? static_cast<double>(total_ - done) / rate : 0;
    const int width = 30;
    const int fill =
        static_cast<int>(width * static_cast<double>(done) / static_cast<double>(std::max<std::size_t>(total_, 1)));
    std::ostringstream line;
    line << label_ << " [" << std::string(fill, '#') << std::string(width - fill, '.') << "] " << done << "/" << total_
         << "  " << std::fixed << std::setprecision(1) << rate << "/s  ETA " << static_cast<int>(eta) / 60 << "m"
         << std::setw(2) << std::setfill('0') << static_cast<int>(eta) % 60 << "s";
    std::cerr << (tty_ ? "\r" : "") << line.str() << (tty_ && !last ? "" : "\n") << std::flush;
  }

 private:
  std::string label_;
  std::size_t total_;
  bool tty_;
  Clock::time_point start_ = Clock::now();
  double shown_ = -1;
  std::size_t tenth_ = 0;
};

// Loads frames ahead of use on background threads, in order.
class Prefetch {
 public:
  Prefetch(const FrameSource& source, std::vector<int> frames, int ahead)
      : source_(source), frames_(std::move(frames)), ahead_(std::max(1, ahead)) {}
  bool done() const { return next_ == frames_.size() && pending_.empty(); }
  std::pair<int, LabelledScan> next() {
    while (pending_.size() < static_cast<std::size_t>(ahead_) && next_ < frames_.size()) {
      const int f = frames_[next_++];
      pending_.emplace_back(f, std::async(std::launch::async, [this, f] { return source_.scan(f); }));
    }
    auto [f, fut] = std::move(pending_.front());
    pending_.pop_front();
    return {f, fut.get()};
  }

 private:
  const FrameSource& source_;
  std::vector<int> frames_;
  int ahead_;
  std::size_t next_ = 0;
  std::deque<std::pair<int, std::future<LabelledScan>>> pending_;
};

struct Timings {
  std::map<std::string, std::vector<double>> stages;
  void add(const StageTimes& t) {
    for (const auto& [name, v] : {std::pair{"fingerprint", t.fingerprint},
                                  {"search", t.search},
                                  {"verify", t.verify},
                                  {"refine", t.refine},
                                  {"store", t.store},
                                  {"total", t.total}})
      stages[name].push_back(v);
  }
  static double pct(std::vector<double> v, double p) {
    if (v.empty()) return 0;
    std::sort(v.begin(), v.end());
    return v[static_cast<std::size_t>(p * static_cast<double>(v.size() - 1) + 0.5)];
  }
  ordered_json json() const {
    ordered_json out;
    for (const auto& [name, v] : stages)
      out[name] = {{"median_ms", pct(v, 0.5)}, {"p90_ms", pct(v, 0.9)}, {"n", v.size()}};
    return out;
  }
};

// Rows of a pair file: "i j", "i j label" or "i j T(12 numbers, row-major 3x4)". Comment lines start with #.
struct PairRow {
  int i = 0, j = 0;
  int label = 1;
  std::optional<Mat4d> T;
};
std::vector<PairRow> readPairs(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path + ": cannot read the pair file");
  std::vector<PairRow> rows;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    std::vector<double> v;
    for (double x; ss >> x;) v.push_back(x);
    if (!ss.eof() || (v.size() != 2 && v.size() != 3 && v.size() != 14))
      throw InputError(path + ":" + std::to_string(n) + ": expected 'i j', 'i j label' or 'i j' + 12 numbers");
    PairRow r;
    r.i = static_cast<int>(v[0]);
    r.j = static_cast<int>(v[1]);
    if (v[0] != r.i || v[1] != r.j || r.i < 0 || r.j < 0)
      throw InputError(path + ":" + std::to_string(n) + ": frame numbers must be non-negative integers");
    if (v.size() == 3) {
      if (v[2] != 0 && v[2] != 1) throw InputError(path + ":" + std::to_string(n) + ": label must be 0 or 1");
      r.label = static_cast<int>(v[2]);
    }
    if (v.size() == 14) {
      Mat4d T = Mat4d::Identity();
      for (int k = 0; k < 12; ++k) T(k / 4, k % 4) = v[2 + static_cast<std::size_t>(k)];
      r.T = T;
    }
    rows.push_back(r);
  }
  if (rows.empty()) throw InputError(path + ": no pairs");
  return rows;
}

void writeCurve(const std::string& path, const std::vector<PrPoint>& curve) {
  std::ofstream out(path);
  out << "threshold,precision,recall\n" << std::setprecision(9);
  for (const auto& p : curve) out << p.threshold << "," << p.precision << "," << p.recall << "\n";
}

void curveSummary(ordered_json& s, const std::vector<PrPoint>& curve) {
  const auto best = f1Max(curve);
  s["f1max"] = best.f1;
  s["f1max_threshold"] = best.threshold;
  s["f1max_precision"] = best.precision;
  s["f1max_recall"] = best.recall;
  s["ep"] = extendedPrecision(curve);
  s["auc"] = prAuc(curve);
}

void registrationSummary(ordered_json& s, const std::vector<RegistrationResult>& results) {
  const auto r = registrationRecall(results);
  s["rr"] = r.rr;
  s["rr_verified"] = r.rr_verified;
  s["registered"] = r.successes;
  s["pose_pairs"] = r.pairs;
  s["rte_mean"] = r.rte_mean;
  s["rre_mean"] = r.rre_mean;
  s["rte_median"] = r.rte_median;
  s["rre_median"] = r.rre_median;
}

// Detections that fail verification carry score 0: they are never a detection, so the curve's point at a
// threshold of 0 (where they would all count) is left out.
std::vector<PrPoint> detectionCurve(const std::vector<Decision>& decisions) {
  auto curve = prCurve(decisions);
  std::erase_if(curve, [](const PrPoint& p) { return p.threshold <= 0; });
  return curve;
}

struct Run {
  const FrameSource& source;
  Backend& backend;
  int threads;
  std::set<int>& stored;  // frames the back-end holds (shared by the protocols of one invocation)
  ordered_json summary;
  Timings timings;
  std::string out;
};

// Stores the given frames that are not stored yet, in order (loading ahead).
void storeFrames(Run& run, const std::vector<int>& wanted) {
  std::vector<int> frames;
  for (int f : wanted)
    if (run.stored.insert(f).second) frames.push_back(f);
  if (frames.empty()) return;
  Prefetch pre(run.source, frames, run.threads);
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

void pairProtocol(Run& run, const std::vector<PairRow>& file_rows) {
  const auto rows = usablePairs(run, file_rows, false);
  storeFrames(run, framesOf(rows));
  std::map<int, std::vector<std::size_t>> by_query;
  for (std::size_t k = 0; k < rows.size(); ++k) by_query[rows[k].i].push_back(k);
  std::vector<Decision> decisions(rows.size());
  Progress bar("verify", rows.size());
  std::size_t n = 0;
  Timings verify_times;
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
}

void poseProtocol(Run& run, const std::vector<PairRow>& file_rows, bool gt_from_file) {
  std::vector<PairRow> positives;
  for (const auto& r : file_rows)
    if (r.label == 1) positives.push_back(r);
  const auto rows = usablePairs(run, positives, true);
  storeFrames(run, framesOf(rows));
  std::vector<RegistrationResult> results;
  std::ofstream csv(run.out + "/pose_errors.csv");
  csv << "i,j,registered,verified,rte_m,rre_deg\n" << std::setprecision(9);
  Progress bar("register", rows.size());
  Timings reg_times;
  for (std::size_t k = 0; k < rows.size(); ++k) {
    const auto& r = rows[k];
    // T_est maps j's points into i's frame. The file's T (LCR-Net loop lists) maps i's points into j's frame.
    Mat4d gt;
    if (gt_from_file || !(run.source.hasPose(r.i) && run.source.hasPose(r.j))) {
      if (!r.T) throw InputError("pair " + std::to_string(r.i) + " " + std::to_string(r.j) + " has no pose");
      gt = r.T->inverse();
    } else {
      gt = run.source.pose(r.i).inverse() * run.source.pose(r.j);
    }
    StageTimes t;
    // The pairs are known loops: a pose is estimated whether or not verification accepts the pair (as the
    // paper's protocol registers every listed pair); `verified` keeps the loop decision.
    const auto c = run.backend.verify(r.i, {r.j}, Refine::known_loops, &t).at(0);
    reg_times.add(t);
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
}

// A top-1 candidate farther than positive_m but nearer than negative_m (the band the pair lists leave out) is
// neither a true nor a false loop: it counts as no detection (a miss when the query has a true loop).
void sequenceProtocol(Run& run, const LoopQuery& query, double positive_m, double negative_m,
                      const std::vector<PairRow>* gt_list) {
  const auto& frames = run.source.frames();
  if (!gt_list)
    for (int f : frames)
      if (!run.source.hasPose(f))
        throw InputError("frame " + std::to_string(f) + " has no ground-truth pose (give poses or --gt-list)");
  std::set<std::pair<int, int>> listed;
  if (gt_list)
    for (const auto& r : *gt_list)
      if (r.label == 1) listed.insert({std::min(r.i, r.j), std::max(r.i, r.j)});
  auto distance = [&](int a, int b) {
    return (run.source.pose(a).block<3, 1>(0, 3) - run.source.pose(b).block<3, 1>(0, 3)).norm();
  };
  auto isTrue = [&](int a, int b) {
    if (gt_list) return listed.count({std::min(a, b), std::max(a, b)}) > 0;
    return distance(a, b) < positive_m;
  };
  auto inBand = [&](int a, int b) { return !gt_list && !isTrue(a, b) && distance(a, b) < negative_m; };
  // A query has a true loop when a frame it may match (stored before it, not among the recent ones) is one.
  std::vector<bool> has_true(frames.size(), false);
  for (std::size_t q = 0; q < frames.size(); ++q)
    for (std::size_t e = 0; e < q && !has_true[q]; ++e)
      if (frames[q] - frames[e] >= query.exclude_recent && isTrue(frames[q], frames[e])) has_true[q] = true;

  std::vector<Decision> decisions;
  std::vector<std::vector<bool>> ranked;
  std::vector<Candidate> top(frames.size());
  std::vector<RegistrationResult> poses;
  std::size_t in_band = 0;
  // Every query's verified top-1 candidate, whatever its score: where false loops come from.
  std::ofstream top1(run.out + "/top1.csv");
  top1 << "frame,match_frame,score,distance_m,outcome\n" << std::setprecision(6);
  Prefetch pre(run.source, frames, run.threads);
  Progress bar("query", frames.size());
  for (std::size_t q = 0; q < frames.size(); ++q) {
    auto [f, scan] = pre.next();
    StageTimes t;
    if (run.stored.count(f)) throw std::logic_error("the sequence protocol must run first");
    const auto cands = run.backend.queryThenAdd(f, scan, query, &t);
    run.stored.insert(f);
    run.timings.add(t);
    std::vector<bool> r;
    for (const auto& c : cands) r.push_back(isTrue(f, c.frame));
    ranked.push_back(r);
    Decision d{0.0, false, has_true[q]};
    if (!cands.empty() && cands[0].verified) {
      const int m = cands[0].frame;
      const bool band = inBand(f, m);
      in_band += band;
      top1 << f << "," << m << "," << cands[0].score << ","
           << (run.source.hasPose(f) && run.source.hasPose(m) ? distance(f, m) : -1.0) << ","
           << (band   ? "between"
               : r[0] ? "true"
                      : "false")
           << "\n";
    }
    if (!cands.empty() && cands[0].verified && !inBand(f, cands[0].frame)) {
      top[q] = cands[0];
      d.score = cands[0].score;
      d.predicted_true = r[0];
      if (r[0] && run.source.hasPose(f) && run.source.hasPose(cands[0].frame)) {
        const Mat4d gt = run.source.pose(f).inverse() * run.source.pose(cands[0].frame);
        poses.push_back({true, poseError(cands[0].T, gt)});
      }
    }
    decisions.push_back(d);
    bar.step(q + 1);
  }
  const auto curve = detectionCurve(decisions);
  writeCurve(run.out + "/pr.csv", curve);
  curveSummary(run.summary, curve);
  const std::size_t one_pct = std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(0.01 * frames.size())));
  run.summary["recall_at_1"] = recallAtN(ranked, has_true, 1);
  run.summary["recall_at_1pct"] = recallAtN(ranked, has_true, one_pct);
  run.summary["recall_at_1pct_n"] = one_pct;
  run.summary["queries"] = frames.size();
  run.summary["queries_with_true_loop"] = std::count(has_true.begin(), has_true.end(), true);
  run.summary["top1_in_band"] = in_band;
  registrationSummary(run.summary, poses);
  run.summary["rr_note"] = "pose errors of the true top-1 detections (any score)";

  // Trajectory with the detections at the F1max threshold.
  const double thr = f1Max(curve).threshold;
  std::ofstream csv(run.out + "/trajectory.csv");
  csv << "frame,x,y,has_true_loop,detection,match_frame\n" << std::setprecision(9);
  std::size_t tp = 0, fp = 0;
  for (std::size_t q = 0; q < frames.size(); ++q) {
    const bool detected = !curve.empty() && decisions[q].score >= thr && decisions[q].score > 0;
    const int kind = detected ? (decisions[q].predicted_true ? 1 : 2) : 0;
    tp += kind == 1;
    fp += kind == 2;
    const Mat4d P = run.source.hasPose(frames[q]) ? run.source.pose(frames[q]) : Mat4d::Identity();
    csv << frames[q] << "," << P(0, 3) << "," << P(1, 3) << "," << int(has_true[q]) << "," << kind << ","
        << (detected ? top[q].frame : -1) << "\n";
  }
  run.summary["at_f1max"] = {{"true_loops", tp}, {"false_loops", fp}};
}

// The map's first converged pose-graph event covering at least `nodes` scans and `loops` loops, or the last event
// seen when `timeout` passes first (converged() false then).
v1::MapEvent waitForSettledGraph(const client::Client& cl, const std::string& map, std::int64_t nodes,
                                 std::int64_t loops, std::chrono::seconds timeout) {
  auto stub = v1::PoseGraph::NewStub(cl.channel());
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + timeout);
  v1::WatchMapRequest req;
  req.set_map(map);
  auto reader = stub->WatchMap(&ctx, req);
  v1::MapEvent last, e;
  while (reader->Read(&e)) {
    last = e;
    if (e.converged() && !e.failed() && e.nodes() >= nodes && e.loops() >= loops) {
      ctx.TryCancel();
      break;
    }
  }
  reader->Finish();  // cancelled or deadline: the event decides
  if (last.failed() || !(last.converged() && last.nodes() >= nodes && last.loops() >= loops)) last.set_converged(false);
  return last;
}

// SLAM protocol: the frames go to a running server as one or two robots with drifting odometry and loop
// queries; the server's pose graph corrects them. Two robots: the first drives the first 60 % of the frames,
// the second the last 60 %, with its odometry in an unrelated frame.
struct SlamOptions {
  double odom_noise = 0.01;
  int robots = 1;
  std::uint64_t seed = 7;
  bool keep_map = false;  // leave the map on the server (--keep-maps)
};

void slamProtocol(Run& run, const std::string& server, const std::string& token, const std::string& map,
                  const SlamOptions& o, int exclude_recent) {
  const auto& frames = run.source.frames();
  for (int f : frames)
    if (!run.source.hasPose(f)) throw InputError("frame " + std::to_string(f) + " has no ground-truth pose");
  const std::size_t n = frames.size();
  struct Robot {
    std::string name;
    std::vector<int> frames;
    std::vector<Mat4d> gt, odom;
  };
  std::vector<Robot> robots;
  const sim::OdometryNoise noise{o.odom_noise, 0.5 * o.odom_noise};  // as sglc-sim --odom-noise
  auto makeRobot = [&](const std::string& name, std::size_t first, std::size_t last, const Mat4d& frame) {
    Robot r{name, {}, {}, {}};
    for (auto k = first; k < last; ++k) {
      r.frames.push_back(frames[k]);
      r.gt.push_back(run.source.pose(frames[k]));
    }
    const auto drift = sim::driftingOdometry(r.gt, r.frames, noise, o.seed + robots.size());
    const Mat4d to_frame = frame * drift.front().inverse();
    for (const auto& T : drift) r.odom.push_back(to_frame * T);
    robots.push_back(std::move(r));
  };
  if (o.robots == 1) {
    makeRobot("r0", 0, n, run.source.pose(frames.front()));
  } else {
    makeRobot("r0", 0, n * 6 / 10, run.source.pose(frames.front()));
    Mat4d unrelated = Mat4d::Identity();
    unrelated.block<3, 3>(0, 0) = Eigen::AngleAxisd(1.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    unrelated.block<3, 1>(0, 3) = Eigen::Vector3d(50, -20, 3);
    makeRobot("r1", n * 4 / 10, n, unrelated);
  }
  const auto cl = client::Client::connect(server, {.token = token, .default_deadline = std::chrono::minutes(5)});
  cl.createMap(map);
  std::size_t loops = 0, done = 0, total = 0;
  for (const auto& r : robots) total += r.frames.size();
  Progress bar("ingest", total);
  for (const auto& r : robots) {
    Prefetch pre(run.source, r.frames, run.threads);
    for (std::size_t k = 0; k < r.frames.size(); ++k) {
      auto [f, scan] = pre.next();
      client::IngestOptions io;
      io.odometry_pose = r.odom[k];
      io.query = true;
      io.query_options.set_exclude_recent(exclude_recent);
      io.query_options.set_top_k(3);
      const auto resp = cl.ingest(client::makeKey(map, r.name, "run", f), scan, io);
      for (const auto& c : resp.loops()) loops += c.verified();
      StageTimes t;
      t.fingerprint = resp.timing().fingerprint_ms();
      t.search = resp.timing().search_ms();
      t.verify = resp.timing().verify_ms();
      t.refine = resp.timing().refine_ms();
      t.store = resp.timing().store_ms();
      t.total = resp.timing().total_ms();
      run.timings.add(t);
      bar.step(++done);
    }
  }
  // The server optimises off the request path: wait for its converged solve of every scan and loop.
  const auto settled = waitForSettledGraph(cl, map, static_cast<std::int64_t>(total), static_cast<std::int64_t>(loops),
                                           std::chrono::minutes(5));
  if (!settled.converged())
    std::cerr << "warning: the pose graph did not settle within 5 minutes (last version " << settled.graph_version()
              << ", " << settled.nodes() << " nodes, " << settled.loops() << " loops)\n";
  const std::int64_t version = settled.graph_version();
  run.summary["graph_converged"] = settled.converged();
  run.summary["loops_reported"] = loops;
  run.summary["graph_version"] = version;
  run.summary["odom_noise"] = o.odom_noise;
  run.summary["robots"] = o.robots;

  std::vector<Mat4d> all_opt, all_gt;
  double odom_sq = 0;
  std::ofstream csv(run.out + "/slam.csv");
  csv << "frame,robot,gt_x,gt_y,odom_x,odom_y,opt_x,opt_y\n" << std::setprecision(9);
  ordered_json per_robot = ordered_json::array();
  for (const auto& r : robots) {
    std::map<std::int64_t, Mat4d> opt;
    for (const auto& p : cl.getPoses(map, r.name)) {
      opt[p.seq()] = client::toMatrix(p.t_map_scan());
    }
    std::vector<Mat4d> est;
    for (int f : r.frames) {
      if (!opt.count(f))
        throw std::runtime_error("the server has no pose for " + r.name + " frame " + std::to_string(f));
      est.push_back(opt[f]);
    }
    std::vector<Eigen::Vector3d> odom_aligned;
    const double ate_odom = absoluteTrajectoryError(r.odom, r.gt, &odom_aligned);
    odom_sq += ate_odom * ate_odom * static_cast<double>(r.frames.size());
    per_robot.push_back({{"robot", r.name},
                         {"frames", r.frames.size()},
                         {"ate_odometry", ate_odom},
                         {"ate_optimised", absoluteTrajectoryError(est, r.gt)}});
    for (std::size_t k = 0; k < r.frames.size(); ++k)
      csv << r.frames[k] << "," << r.name << "," << r.gt[k](0, 3) << "," << r.gt[k](1, 3) << "," << odom_aligned[k].x()
          << "," << odom_aligned[k].y() << "," << est[k](0, 3) << "," << est[k](1, 3) << "\n";
    all_opt.insert(all_opt.end(), est.begin(), est.end());
    all_gt.insert(all_gt.end(), r.gt.begin(), r.gt.end());
  }
  // Odometry: each robot aligned on its own (its best case); optimised: all robots with one alignment, so a
  // robot left in the wrong frame counts.
  run.summary["ate_odometry"] = std::sqrt(odom_sq / static_cast<double>(all_gt.size()));
  run.summary["ate_optimised"] = absoluteTrajectoryError(all_opt, all_gt);
  run.summary["per_robot"] = per_robot;
  if (robots.size() == 2) {
    // The map frame is r0's odometry frame, which starts at r0's true first pose (the world frame): r1's frame
    // truly sits at gt(first) * inverse(odom(first)).
    const auto frames_resp = cl.getSessionFrames(map);
    for (const auto& s : frames_resp.sessions()) {
      if (s.robot() != "r1") continue;
      const Mat4d T = client::toMatrix(s.t_map_session());
      const Mat4d truth = robots[1].gt.front() * robots[1].odom.front().inverse();
      const auto e = poseError(T, truth);
      run.summary["frame_alignment_error"] = {{"m", e.rte_m}, {"deg", e.rre_deg}, {"connected", s.connected()}};
    }
  }
  run.summary["server_map_kept"] = o.keep_map;
  if (!o.keep_map) cl.deleteMap(map);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Loop-closure evaluation: F1max, EP, AUC, Recall@1, registration recall, pose errors, timing."};
  std::string protocol, data, poses, calib, frames, pairs, server, token, out, config_path, gt_list, title;
  bool sim = false, no_plots = false, gt_from_file = false, no_labels = false;
  int beams = 64;
  std::uint64_t seed = 7;
  double label_noise = 0, positive_m = 3.0, negative_m = 20.0;
  int threads = 2;
  LoopQuery query;
  app.add_option("--protocol", protocol,
                 "pairs, sequence, pose, or all (sequence, then pairs and pose on the same frames)")
      ->required()
      ->check(CLI::IsMember({"pairs", "sequence", "pose", "all", "slam"}));
  app.add_option("--data", data, "SemanticKITTI-layout sequence directory (velodyne/, labels/, poses.txt, calib.txt)");
  app.add_flag("--sim", sim, "render a simulated sequence in memory");
  app.add_option("--poses", poses, "with --sim: KITTI poses file to follow (default: the built-in route)");
  app.add_option("--calib", calib, "with --sim --poses: KITTI calib.txt (Tr)");
  app.add_option("--seed", seed, "with --sim: world and sensor seed");
  app.add_option("--label-noise", label_noise, "with --sim: label noise rate (0..1)")->check(CLI::Range(0.0, 1.0));
  app.add_option("--beams", beams, "with --sim: sensor with 32 (HDL-32E-like), 64 (HDL-64E-like) or 128 beams")
      ->check(CLI::IsMember({32, 64, 128}));
  app.add_flag("--no-labels", no_labels,
               "send points only (labels removed from any source): the engine's labeller labels them");
  app.add_option("--frames", frames, "frame selection 'a:b:s,...' (default: all)");
  app.add_option("--pairs", pairs, "pair file: 'i j label' (pairs), 'i j [T 3x4]' (pose)");
  std::string pose_pairs;
  app.add_option("--pose-pairs", pose_pairs, "with --protocol all: the pose protocol's pair file");
  app.add_option("--gt-list", gt_list, "sequence: true loops from this pair file instead of distances");
  app.add_flag("--gt-from-pairs", gt_from_file, "pose: ground truth from the pair file's T (maps i into j)");
  app.add_option("--positive-m", positive_m, "sequence: a true loop is closer than this (m)");
  app.add_option("--negative-m", negative_m, "sequence: a false loop is farther than this (m); between: ignored");
  app.add_option("--exclude-recent", query.exclude_recent, "sequence: skip this many most recent frames");
  app.add_option("--candidates", query.candidates,
                 "sequence: descriptor neighbours verified per query (at least 1% of frames)");
  SlamOptions slam;
  app.add_option("--odom-noise", slam.odom_noise, "slam: odometry drift (translation sigma per metre; 0.01 = 1 %)")
      ->check(CLI::Range(0.0, 0.2));
  app.add_option("--robots", slam.robots, "slam: 1, or 2 robots on overlapping parts of the path")
      ->check(CLI::IsMember({1, 2}));
  app.add_option("--server", server, "measure a running sglc-server instead of the in-process engine");
  app.add_option("--token", token, "bearer token for --server");
  bool keep_maps = false;
  app.add_flag("--keep-maps", keep_maps,
               "with --server: leave the maps this run creates (default: deleted at the end)");
  app.add_option("--config", config_path, "engine configuration (YAML, as sglc-pair --config)");
  app.add_option("--threads", threads, "frames loaded or rendered ahead")->check(CLI::Range(1, 64));
  app.add_option("--title", title, "figure title");
  app.add_flag("--no-plots", no_plots, "write summary.json and the CSV files only");
  app.add_option("--out", out, "output directory")->required();
  CLI11_PARSE(app, argc, argv);

  try {
    if (sim == !data.empty()) throw InputError("give exactly one of --data DIR and --sim");
    if (!sim && (!poses.empty() || !calib.empty() || label_noise > 0 || beams != 64))
      throw InputError("--poses, --calib, --label-noise and --beams belong to --sim");
    if (no_labels && label_noise > 0) throw InputError("--label-noise has no effect with --no-labels");
    if (protocol == "slam" && server.empty())
      throw InputError("--protocol slam measures a server's pose graph: give --server ADDR");
    if (protocol != "sequence" && protocol != "slam" && pairs.empty())
      throw InputError("--protocol " + protocol + " needs --pairs FILE");
    if (protocol == "all" && pose_pairs.empty()) throw InputError("--protocol all needs --pose-pairs FILE");
    if (query.exclude_recent < 0 || query.candidates < 1 || query.candidates > 100)
      throw InputError("--exclude-recent must be >= 0 and --candidates 1..100");
    Config config;
    if (!config_path.empty()) config = loadConfig(config_path);
    if (no_labels && server.empty() && config.labeller.mode == "off")
      throw InputError("--no-labels needs the labeller: labeller.mode is off in --config");
    fs::create_directories(out);

    std::unique_ptr<FrameSource> source;
    if (sim)
      source = simulatedSource({poses, calib, frames, seed, label_noise, beams});
    else
      source = directorySource(data, frames);
    if (no_labels) source = withoutLabels(std::move(source));
    if (protocol == "sequence" || protocol == "all") {
      const auto n = static_cast<int>(std::ceil(0.01 * static_cast<double>(source->frames().size())));
      query.candidates = std::min(100, std::max(query.candidates, n));
    }
    std::unique_ptr<Backend> backend;
    const std::string map_name = "eval-" + std::to_string(std::time(nullptr)) + "-" + std::to_string(::getpid());
    if (server.empty())
      backend = inProcessBackend(config, out + "/scratch");
    else
      backend = serverBackend(server, token, map_name, keep_maps);
    slam.keep_map = keep_maps;

    std::set<int> stored;
    // One invocation may run several protocols over the same stored frames ("all": sequence first, then
    // pairs and pose on what it stored), each into its own directory.
    const std::vector<std::string> protocols =
        protocol == "all" ? std::vector<std::string>{"sequence", "pairs", "pose"} : std::vector<std::string>{protocol};
    ordered_json combined;
    int status = 0;
    for (const auto& name : protocols) {
      const std::string dir = protocol == "all" ? out + "/" + name : out;
      fs::create_directories(dir);
      Run run{*source, *backend, threads, stored, {}, {}, dir};
      run.summary["protocol"] = name;
      run.summary["title"] = (title.empty() ? name : title + " - " + name) + ": " + source->describe();
      run.summary["source"] = source->describe();
      run.summary["backend"] = backend->name();
      run.summary["labels_sent"] = no_labels ? "none" : "given";
      if (server.empty()) {  // a server's own configuration decides there (GetServerInfo)
        run.summary["label_preset"] = config.labels.preset;
        run.summary["labeller_mode"] = config.labeller.mode;
      }
      if (sim) run.summary["beams"] = beams;
      if (!server.empty()) {
        run.summary["server_map"] = map_name;
        run.summary["server_map_kept"] = keep_maps;
      }
      run.summary["frames"] = source->frames().size();
      if (name == "sequence") {
        run.summary["exclude_recent"] = query.exclude_recent;
        run.summary["candidates"] = query.candidates;
        if (gt_list.empty()) {
          run.summary["positive_m"] = positive_m;
          run.summary["negative_m"] = negative_m;
        } else {
          run.summary["gt_list"] = gt_list;
        }
      }
      const auto t0 = Clock::now();
      if (name == "slam") {
        slam.seed = seed;
        slamProtocol(run, server, token, map_name + "-slam", slam, query.exclude_recent);
      } else if (name == "pairs") {
        run.summary["pairs_file"] = pairs;
        pairProtocol(run, readPairs(pairs));
      } else if (name == "pose") {
        const auto& file = protocol == "all" ? pose_pairs : pairs;
        run.summary["pairs_file"] = file;
        poseProtocol(run, readPairs(file), gt_from_file);
      } else {
        std::vector<PairRow> list;
        if (!gt_list.empty()) list = readPairs(gt_list);
        if (!(negative_m >= positive_m)) throw InputError("--negative-m must be >= --positive-m");
        sequenceProtocol(run, query, positive_m, negative_m, gt_list.empty() ? nullptr : &list);
      }
      run.summary["wall_s"] = seconds(t0);
      run.summary["timings"] = run.timings.json();
      {
        std::ofstream js(dir + "/summary.json");
        js << run.summary.dump(2) << "\n";
        if (!js) throw std::runtime_error(dir + "/summary.json: write failed");
      }
      combined[name] = run.summary;
      if (!no_plots) {
        const std::string cmd = "/usr/bin/python3 '" + std::string(SGLC_EVAL_PLOT_SCRIPT) + "' '" + dir + "' 1>&2";
        if (std::system(cmd.c_str()) != 0) {
          std::cerr << "sglc-eval: plotting failed (" << cmd << "); summary.json and the CSV files are written\n";
          status = 3;
        }
      }
    }
    if (server.empty()) fs::remove_all(out + "/scratch");
    if (protocol == "all") {
      std::ofstream js(out + "/summary.json");
      js << combined.dump(2) << "\n";
    }
    std::cout << (protocol == "all" ? combined : combined[protocol]).dump(2) << std::endl;
    return status;
  } catch (const std::exception& e) {
    std::cerr << "sglc-eval: error: " << e.what() << std::endl;
    return 1;
  }
}
