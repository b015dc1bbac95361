// Poses and their information on the wire (sglc.v1.Transform, Candidate.information), and the names of maps,
// robots and sessions. Failures throw WireError (INVALID_ARGUMENT) with a message that says what is wrong.
#pragma once

#include <optional>
#include <string>

#include "sglc/types.hpp"
#include "sglc/v1/sglc.pb.h"
#include "sglc/wire/error.hpp"

namespace sglc::wire {

// Row-major 4x4 -> Transform.m (16 doubles).
void toTransform(const Mat4d& T, v1::Transform* out);
v1::Transform toTransform(const Mat4d& T);
// Transform.m -> 4x4, when it has exactly 16 finite values (no other check: a client reading what a server sent).
Mat4d toMatrix(const v1::Transform& t);
// What a server accepts as a pose: 16 values forming a rigid motion (sglc/rigid.hpp), returned
// re-orthonormalised; the message names `what` ("odometry_pose") and the failed check.
Mat4d decodeRigidTransform(const v1::Transform& t, const std::string& what);
// An absent optional transform (e.g. GetScanResponse.odometry_pose when none was stored) has no values.
inline bool isSet(const v1::Transform& t) { return t.m_size() > 0; }

// A loop pose's 6x6 information <-> Candidate.information (36 values, row-major); nullopt when it has not 36.
void encodeInformation(const Mat6d& information, v1::Candidate* out);
std::optional<Mat6d> decodeInformation(const v1::Candidate& c);

// Throws unless `name` is a valid map, robot or session name (sglc/names.hpp); the message starts with `what`.
void checkName(const std::string& what, const std::string& name);

}  // namespace sglc::wire
