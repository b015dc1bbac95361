// De-skewing a spinning LiDAR's sweep: each point was measured from where the sensor was when its ray fired,
// not from where it was at the scan's stamp. Given each point's time after the stamp and the sensor's motion
// (a twist held constant over the sweep), every point is moved into the sensor's frame at the stamp.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "sglc/types.hpp"

namespace sglc {

// The sensor's velocity in its own frame at the stamp: linear (m/s) and angular (rad/s, axis times rate).
struct Twist {
  Eigen::Vector3d linear = Eigen::Vector3d::Zero();
  Eigen::Vector3d angular = Eigen::Vector3d::Zero();
};

// The fastest motion a sweep is de-skewed with: 1000 m/s and 100 rad/s (about 16 turns a second). Beyond
// them a twist is a unit mistake or a jump of the odometry, not a vehicle.
inline constexpr double kMaxSweepSpeed = 1000.0, kMaxSweepTurnRate = 100.0;
// Why a twist cannot de-skew a sweep (not finite, or beyond the limits above), or "" when it can.
std::string twistError(const Twist& twist);

// The constant twist that moves the sensor from pose `from` to pose `to` (both sensor -> world) in `dt`
// seconds: the rotation's axis-angle and the translation (in `from`'s axes), each divided by dt. Throws
// InputError when dt is not positive and finite.
Twist twistBetween(const Mat4d& from, const Mat4d& to, double dt);

// What a scan may carry for de-skew: one time per point (s after the stamp) and, when its sender knows it,
// the sensor's twist over the sweep.
struct ScanSweep {
  std::vector<float> point_times;
  std::optional<Twist> twist;
};

// A pose with its time (s).
struct TimedPose {
  double stamp = 0;
  Mat4d pose = Mat4d::Identity();
};
// The twist over the sweep that starts at `current`: the motion on to the next pose when there is one (a
// recorded drive knows it; the sweep runs forward from the stamp), else on from the previous one (constant
// velocity, as a robot knows it live). Throws InputError when neither is given.
Twist sweepTwist(const TimedPose* previous, const TimedPose& current, const TimedPose* next);

// The sensor's pose t seconds after the stamp, relative to its pose at the stamp: rotation exp(t w) and
// translation t v (the motion model of the simulator's sweeps and of a constant-velocity front end).
Mat4d motionAt(const Twist& twist, double t);

// Moves each point i from the sensor's frame at times[i] into its frame at the stamp: p <- motionAt(t_i) p.
// Throws InputError when the sizes differ, a time is not finite or beyond 1 s of the stamp, or the twist has a
// twistError.
void deskew(Points& points, const std::vector<float>& times, const Twist& twist);

}  // namespace sglc
