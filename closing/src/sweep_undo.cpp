#include "sglc/closing/sweep_undo.hpp"

#include <cmath>

namespace sglc::closing {
namespace {

// The twist from the session's previous stored scan to this one, or why there is none.
std::optional<Twist> constantVelocity(const storage::MapStore& store, const IngestInput& in, std::string* why) {
  if (!in.stamp || !in.odometry_pose) {
    *why = "the request has no twist, and no stamp and odometry_pose to take one from the previous scan";
    return std::nullopt;
  }
  const auto& key = in.key;
  const auto previous_id = store.previousScan(key.map, key.robot, key.session, key.seq);
  const auto previous = previous_id ? store.scanInfo(*previous_id) : std::nullopt;
  if (!previous) {
    *why = "the request has no twist and the session has no earlier scan to take one from";
    return std::nullopt;
  }
  if (!previous->stamp || !previous->odometry_pose) {
    *why = "the request has no twist and the session's previous scan (seq " + std::to_string(previous->seq) +
           ") has no stamp or odometry pose";
    return std::nullopt;
  }
  const double gap = *in.stamp - *previous->stamp;
  if (!(gap > 0) || gap > kMaxSweepGap) {
    *why = "the request has no twist and the session's previous scan (seq " + std::to_string(previous->seq) + ") is " +
           std::to_string(gap) + " s before it (needs 0 to " + std::to_string(kMaxSweepGap) + " s)";
    return std::nullopt;
  }
  const TimedPose before{*previous->stamp, *previous->odometry_pose};
  const TimedPose now{*in.stamp, *in.odometry_pose};
  const Twist twist = sweepTwist(&before, now, nullptr);
  if (const auto error = twistError(twist); !error.empty()) {
    *why = "the motion from the session's previous scan (seq " + std::to_string(previous->seq) + "): " + error;
    return std::nullopt;
  }
  return twist;
}

}  // namespace

SweepOutcome undoSweep(const ScanSweep& sweep, LabelledScan& scan, const storage::MapStore* store,
                       const IngestInput* input) {
  SweepOutcome out;
  if (sweep.point_times.empty()) return out;
  std::string why = "the query has no twist (a scan that is not stored has no previous scan to take one from)";
  std::optional<Twist> twist = sweep.twist;
  if (!twist && store && input) twist = constantVelocity(*store, *input, &why);
  if (!twist) {
    out.warning = "not de-skewed: " + why;
    return out;
  }
  deskew(scan.points, sweep.point_times, *twist);
  out.deskewed = true;
  return out;
}

}  // namespace sglc::closing
