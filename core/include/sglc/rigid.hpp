// Rigid motions from outside: a 4x4 matrix that claims to be a pose is checked before anything uses it.
//
// A pose from a client (an odometry pose, a stored pose read back) is accepted when it is a rigid motion to
// within a tolerance: every entry finite, the rotation block orthonormal (max |R'R - I| <= kRigidTolerance) with
// determinant +1 (within the same tolerance), the last row 0 0 0 1 (within 1e-9), and a translation below
// kMaxTranslationM. Within the tolerance the rotation is re-orthonormalised, so a pose written with float
// precision is accepted and everything downstream works on an exact rotation.
#pragma once

#include <optional>
#include <string>

#include "sglc/types.hpp"

namespace sglc {

inline constexpr double kRigidTolerance = 1e-3;
inline constexpr double kMaxTranslationM = 1e8;  // UTM northings are ~1e7 m

// Why T is not a rigid motion ("rotation block is not orthonormal (max |R'R - I| = 1, tolerance 0.001)"), or
// nullopt when it is one.
std::optional<std::string> rigidMotionError(const Mat4d& T, double tolerance = kRigidTolerance);

// The nearest rigid motion (rotation by SVD projection, last row 0 0 0 1). Call on matrices that passed
// rigidMotionError.
Mat4d orthonormalised(const Mat4d& T);

}  // namespace sglc
