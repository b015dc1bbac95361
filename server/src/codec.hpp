// Conversions between the wire types (sglc.v1) and the engine's plain types, with validation.
#pragma once

#include <grpcpp/grpcpp.h>

#include <optional>
#include <stdexcept>
#include <string>

#include "sglc/types.hpp"
#include "sglc/v1/sglc.pb.h"

namespace sglc::server {

// A failure that becomes the call's gRPC status.
class RpcError : public std::runtime_error {
 public:
  RpcError(grpc::StatusCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  grpc::StatusCode code() const { return code_; }

 private:
  grpc::StatusCode code_;
};

// Decodes and checks a scan: byte lengths, equal counts (or no labels at all), not empty, at most max_points,
// finite coordinates.
LabelledScan decodeScan(const std::string& points, const std::string& labels, std::size_t max_points);

// 16 values that form a rigid motion (sglc/rigid.hpp) -> that motion, re-orthonormalised; throws
// RpcError(INVALID_ARGUMENT) naming `what` and the failed check otherwise.
Mat4d decodeTransform(const v1::Transform& t, const std::string& what);
void encodeTransform(const Mat4d& T, v1::Transform* out);

// A loop pose's 6x6 information <-> Candidate.information (36 values, row-major); nullopt when it has not 36.
void encodeInformation(const Mat6d& information, v1::Candidate* out);
std::optional<Mat6d> decodeInformation(const v1::Candidate& c);

// Names of maps, robots and sessions: 1..256 printable bytes.
void checkName(const std::string& what, const std::string& name);

}  // namespace sglc::server
