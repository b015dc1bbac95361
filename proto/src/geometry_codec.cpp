#include "sglc/wire/geometry_codec.hpp"

#include <cmath>

#include "sglc/names.hpp"
#include "sglc/rigid.hpp"

namespace sglc::wire {

void toTransform(const Mat4d& T, v1::Transform* out) {
  out->clear_m();
  out->mutable_m()->Reserve(16);
  for (int k = 0; k < 16; ++k) out->add_m(T(k / 4, k % 4));
}

v1::Transform toTransform(const Mat4d& T) {
  v1::Transform out;
  toTransform(T, &out);
  return out;
}

Mat4d toMatrix(const v1::Transform& t) {
  if (t.m_size() != 16)
    throw WireError("transform has " + std::to_string(t.m_size()) + " values, expected 16 (row-major 4x4)");
  Mat4d T;
  for (int k = 0; k < 16; ++k) {
    if (!std::isfinite(t.m(k))) throw WireError("transform value " + std::to_string(k) + " is not finite");
    T(k / 4, k % 4) = t.m(k);
  }
  return T;
}

Mat4d decodeRigidTransform(const v1::Transform& t, const std::string& what) {
  if (t.m_size() != 16)
    throw WireError(what + " must have 16 values (row-major 4x4), got " + std::to_string(t.m_size()));
  Mat4d T;
  for (int k = 0; k < 16; ++k) T(k / 4, k % 4) = t.m(k);
  if (const auto error = rigidMotionError(T)) throw WireError(what + " is not a rigid motion: " + *error);
  return orthonormalised(T);
}

void encodeInformation(const Mat6d& information, v1::Candidate* out) {
  out->clear_information();
  out->mutable_information()->Reserve(36);
  for (int k = 0; k < 36; ++k) out->add_information(information(k / 6, k % 6));
}

std::optional<Mat6d> decodeInformation(const v1::Candidate& c) {
  if (c.information_size() != 36) return std::nullopt;
  Mat6d I;
  for (int k = 0; k < 36; ++k) I(k / 6, k % 6) = c.information(k);
  return I;
}

void checkName(const std::string& what, const std::string& name) {
  if (const auto error = nameError(name)) throw WireError(what + " " + *error);
}

}  // namespace sglc::wire
