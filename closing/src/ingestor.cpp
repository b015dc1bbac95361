#include "sglc/closing/ingestor.hpp"

#include <algorithm>
#include <cmath>

#include "sglc/elapsed.hpp"
#include "sglc/fingerprint.hpp"
#include "sglc/rigid.hpp"

namespace sglc::closing {
namespace {

using storage::StorageError;

}  // namespace

void Ingestor::requireSameScan(std::int64_t id, const Fingerprint& fp, const IngestInput& input) const {
  const auto& key = input.key;
  const auto info = store_.scanInfo(id);
  const auto stored = store_.fingerprint(id);
  const auto& pose = input.odometry_pose;
  const bool same = info && stored && sameScan(*stored, fp) && info->stamp == input.stamp &&
                    info->odometry_pose.has_value() == pose.has_value() && (!pose || *info->odometry_pose == *pose) &&
                    info->has_raw == input.store_raw;
  if (!same)
    throw StorageError(StorageError::Code::kAlreadyExists,
                       "robot '" + key.robot + "' session '" + key.session + "' seq " + std::to_string(key.seq) +
                           " already holds a different scan (scan " + std::to_string(id) +
                           "); an identical retry would answer OK");
}

PendingScan Ingestor::compute(const LabelledScan& scan, IngestInput input, const Execution& exec,
                              const ReportListener& on_report) const {
  if (input.stamp && !std::isfinite(*input.stamp)) throw InputError("stamp is not finite");
  PendingScan p;
  p.input = std::move(input);
  const auto& key = p.input.key;
  const auto t0 = Clock::now();
  p.fingerprint = pipeline_.fingerprint(scan, &p.outcome.report);
  p.outcome.timing.fingerprint_ms = msSince(t0);
  if (on_report) on_report(p.outcome.report);
  // A retry of a stored scan answers as the first call did (its loops exclude the stored copy of itself).
  p.stored = store_.findScan(key.map, key.robot, key.session, key.seq);
  if (p.stored) requireSameScan(*p.stored, p.fingerprint, p.input);
  if (p.input.query) {
    const QueryOrigin who{key.map, key.robot, key.session, key.seq, p.input.stamp, p.stored.value_or(0)};
    p.outcome.loops = finder_.find(p.fingerprint, who, p.input.query_options, exec, &p.outcome.timing.query);
  }
  return p;
}

Ingested Ingestor::commit(PendingScan p, const LabelledScan& scan) const {
  auto& out = p.outcome;
  const auto& in = p.input;
  const auto t0 = Clock::now();
  if (!p.stored) {
    storage::NewScan ns;
    ns.map = in.key.map;
    ns.robot = in.key.robot;
    ns.session = in.key.session;
    ns.seq = in.key.seq;
    ns.stamp = in.stamp;
    ns.odometry_pose = in.odometry_pose;
    ns.fingerprint = &p.fingerprint;
    ns.raw = in.store_raw ? &scan : nullptr;
    try {
      out.scan_id = store_.addScan(ns);
    } catch (const StorageError& e) {
      // The same request on another connection (a client retrying before its first call answered) may have
      // stored it first.
      if (e.code() != StorageError::Code::kAlreadyExists) throw;
      p.stored = store_.findScan(in.key.map, in.key.robot, in.key.session, in.key.seq);
      if (!p.stored) throw;
      requireSameScan(*p.stored, p.fingerprint, in);
      std::erase_if(out.loops, [&](const FoundLoop& l) { return l.scan_id == *p.stored; });
    }
  }
  if (p.stored) {
    out.scan_id = *p.stored;
    out.already_stored = true;
  }
  out.timing.store_ms = msSince(t0);
  if (loops_recorded_) recordLoops(out, in);
  if (lifelong_.enabled() && !out.already_stored) recordPlace(out, in);
  return std::move(out);
}

// The scan joins the place of its surest verified loop's candidate, or founds one. The scan is stored: a failure
// here must not fail the call (the next compaction places it).
void Ingestor::recordPlace(Ingested& out, const IngestInput& in) const {
  std::vector<PlaceTie> ties;
  for (const auto& loop : out.loops) {
    if (!loop.result.is_loop) continue;
    const auto& res = loop.result;
    ties.push_back({loop.scan_id, res.probability > 0.0 ? std::optional(res.probability) : std::nullopt,
                    res.T.block<3, 1>(0, 3).norm()});
  }
  const PlaceLookup lookup{[&](std::int64_t id) { return store_.placeOf(id); },
                           [&](std::int64_t place) { return store_.placeVersions(in.key.map, place); }};
  try {
    const auto records = placeScan(out.scan_id, ties, lifelong_, lookup);
    store_.setPlaces(in.key.map, records);
    out.place = records.back();
  } catch (const StorageError& e) {
    out.report.warnings.push_back(std::string("place not recorded (the next compaction places it): ") + e.what());
  }
}

// Verified loops join the map's pose graph. The scan is stored: a failure here must not fail the call. A loop
// recorded again for the same pair replaces the first.
void Ingestor::recordLoops(Ingested& out, const IngestInput& in) const {
  bool added = false;
  for (const auto& loop : out.loops) {
    if (!loop.result.is_loop) continue;
    try {
      // The engine's own pose; the rigid check guards the pose graph from a numerical accident.
      const auto& res = loop.result;
      if (const auto error = rigidMotionError(res.T)) throw InputError("loop is not a rigid motion: " + *error);
      storage::LoopRecord r;
      r.query_scan = out.scan_id;
      r.candidate_scan = loop.scan_id;
      r.T = orthonormalised(res.T);
      r.score = res.score;
      r.inliers = res.inliers;
      r.fitness = res.fitness;
      r.rmse = res.rmse;
      // A verified loop always has a pose hypothesis, so the loop model gives it a probability above 0; 0 means no
      // model judged it (a verifier without one): unknown, which the pose graph treats as loops always were.
      if (res.probability > 0.0) r.probability = res.probability;
      if (res.refined && !res.information.isZero()) r.information = res.information;
      store_.addLoop(in.key.map, r);
      added = true;
    } catch (const std::exception& e) {
      out.unrecorded_loops.emplace_back(e.what());
    }
  }
  if (added) loops_recorded_(in.key.map);
}

}  // namespace sglc::closing
