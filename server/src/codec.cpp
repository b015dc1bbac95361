#include "codec.hpp"

#include <cmath>
#include <cstring>

#include "sglc/rigid.hpp"

namespace sglc::server {

static_assert(sizeof(Vec3f) == 12, "scan decoding copies packed float triples");

LabelledScan decodeScan(const std::string& points, const std::string& labels, std::size_t max_points) {
  if (points.size() % 12 != 0)
    throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "scan.points has " + std::to_string(points.size()) +
                                                           " bytes, not a multiple of 12 (float32 x, y, z per point)");
  if (labels.size() % 4 != 0)
    throw RpcError(grpc::StatusCode::INVALID_ARGUMENT,
                   "scan.labels has " + std::to_string(labels.size()) + " bytes, not a multiple of 4 (uint32 per point)");
  const std::size_t n = points.size() / 12;
  if (!labels.empty() && labels.size() / 4 != n)
    throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "scan has " + std::to_string(n) + " points but " +
                                                           std::to_string(labels.size() / 4) + " labels");
  if (n == 0) throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "scan is empty");
  if (n > max_points)
    throw RpcError(grpc::StatusCode::RESOURCE_EXHAUSTED, "scan has " + std::to_string(n) +
                                                             " points, the server accepts at most " +
                                                             std::to_string(max_points));
  LabelledScan scan;
  scan.points.resize(n);
  scan.labels.resize(labels.size() / 4);  // none: the engine's labeller labels the scan
  std::memcpy(static_cast<void*>(scan.points.data()), points.data(), points.size());  // packed float triples
  if (!labels.empty()) std::memcpy(scan.labels.data(), labels.data(), labels.size());
  for (std::size_t i = 0; i < n; ++i)
    if (!scan.points[i].allFinite())
      throw RpcError(grpc::StatusCode::INVALID_ARGUMENT,
                     "scan point " + std::to_string(i) + " has a non-finite coordinate (NaN or inf)");
  return scan;
}

Mat4d decodeTransform(const v1::Transform& t, const std::string& what) {
  if (t.m_size() != 16)
    throw RpcError(grpc::StatusCode::INVALID_ARGUMENT,
                   what + " must have 16 values (row-major 4x4), got " + std::to_string(t.m_size()));
  Mat4d T;
  for (int k = 0; k < 16; ++k) T(k / 4, k % 4) = t.m(k);
  if (const auto error = rigidMotionError(T))
    throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, what + " is not a rigid motion: " + *error);
  return orthonormalised(T);
}

void encodeTransform(const Mat4d& T, v1::Transform* out) {
  out->clear_m();
  for (int k = 0; k < 16; ++k) out->add_m(T(k / 4, k % 4));
}

void encodeInformation(const Mat6d& information, v1::Candidate* out) {
  out->clear_information();
  for (int k = 0; k < 36; ++k) out->add_information(information(k / 6, k % 6));
}

std::optional<Mat6d> decodeInformation(const v1::Candidate& c) {
  if (c.information_size() != 36) return std::nullopt;
  Mat6d I;
  for (int k = 0; k < 36; ++k) I(k / 6, k % 6) = c.information(k);
  return I;
}

void checkName(const std::string& what, const std::string& name) {
  if (name.empty()) throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, what + " is empty");
  if (name.size() > 256) throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, what + " is longer than 256 bytes");
  for (unsigned char c : name)
    if (c < 0x20 || c == 0x7f) throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, what + " has a control character");
}

}  // namespace sglc::server
