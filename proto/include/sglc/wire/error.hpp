// The wire codec's one error type, and the canonical names of gRPC status codes.
#pragma once

#include <grpcpp/support/status_code_enum.h>

#include <string>

#include "sglc/types.hpp"

namespace sglc::wire {

// Bytes or values from the wire that cannot be used. An InputError (a caller that only cares that the input was
// bad catches that), carrying the gRPC status a server answers with: INVALID_ARGUMENT, or RESOURCE_EXHAUSTED when
// the input is well-formed but larger than allowed. The message says what is wrong.
class WireError : public InputError {
 public:
  explicit WireError(const std::string& message, grpc::StatusCode code = grpc::StatusCode::INVALID_ARGUMENT)
      : InputError(message), code_(code) {}
  grpc::StatusCode code() const { return code_; }

 private:
  grpc::StatusCode code_;
};

// "OK", "CANCELLED", ..., "UNAUTHENTICATED"; "STATUS_<n>" for a code gRPC does not define.
std::string statusCodeName(grpc::StatusCode code);

}  // namespace sglc::wire
