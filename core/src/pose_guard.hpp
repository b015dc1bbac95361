// How far a refinement moved a pose: the guards of the fine, refine and alignment stages.
#pragma once

#include <algorithm>
#include <cmath>
#include <numbers>

#include "sglc/types.hpp"

namespace sglc::detail {

inline double rotationAngleDeg(const Mat3d& R) {
  return std::acos(std::clamp((R.trace() - 1.0) / 2.0, -1.0, 1.0)) * 180.0 / std::numbers::pi;
}

// Whether `to` lies less than max_shift_m and max_turn_deg from `from` (both map the candidate into the query
// frame): the one guard of every stage that may move a pose.
inline bool movedWithin(const Mat4d& from, const Mat4d& to, double max_shift_m, double max_turn_deg) {
  const Mat4d d = from.inverse() * to;
  return d.topRightCorner<3, 1>().norm() < max_shift_m && rotationAngleDeg(d.topLeftCorner<3, 3>()) < max_turn_deg;
}

}  // namespace sglc::detail
