// A failure inside a call that becomes its gRPC status (call.cpp maps it, and every other exception type).
#pragma once

#include <grpcpp/grpcpp.h>

#include <stdexcept>
#include <string>

namespace sglc::server {

class RpcError : public std::runtime_error {
 public:
  RpcError(grpc::StatusCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  grpc::StatusCode code() const { return code_; }

 private:
  grpc::StatusCode code_;
};

}  // namespace sglc::server
