// What every RPC shares: exceptions turned into statuses, one JSON log line per call, the deadline check, and
// requests parsed from raw bytes so a message that is not valid protobuf gets INVALID_ARGUMENT saying so.
#pragma once

#include <grpcpp/grpcpp.h>
#include <grpcpp/impl/codegen/proto_utils.h>
#include <grpcpp/support/byte_buffer.h>
#include <grpcpp/support/server_interceptor.h>

#include <chrono>
#include <exception>
#include <memory>
#include <string>

#include "rpc_error.hpp"
#include "sglc/elapsed.hpp"

namespace sglc::server {

// Who and what a log line is about.
struct CallLog {
  const char* method;
  std::string map, robot;
  Clock::time_point start = Clock::now();
  long messages = -1;  // streams: requests processed (-1: not a stream)
};

// Status messages (and the log's map and robot fields) are cut to this many bytes, control characters escaped.
inline constexpr std::size_t kMaxStatusMessageBytes = 1024;

// The status for an exception thrown by a handler (RpcError, StorageError, InputError, bad_alloc, other).
// Storage failures below the service (I/O, damage, constraint) are answered without internals (no SQL, no
// paths); `detail` receives what the log should say.
grpc::Status statusOf(std::exception_ptr error, std::string* detail);
// Writes the call's log line (warning level when not OK) and returns `status`.
grpc::Status logCall(const grpc::ServerContextBase& ctx, const CallLog& log, const grpc::Status& status,
                     const std::string& detail = "");

// Runs body(log), turning exceptions into the status, and logs the call.
template <typename F>
grpc::Status run(const grpc::ServerContextBase* ctx, CallLog log, F&& body) {
  grpc::Status status;
  std::string detail;
  try {
    body(log);
  } catch (...) {
    status = statusOf(std::current_exception(), &detail);
  }
  return logCall(*ctx, log, status, detail);
}

// Throws DEADLINE_EXCEEDED / CANCELLED when the call's deadline passed or the client went away.
void checkAlive(const grpc::ServerContextBase* ctx);

// `what` ("request", "message 3 of the stream") parsed as a T; throws RpcError(INVALID_ARGUMENT) when the bytes
// are not a valid T.
template <typename T>
T parseMessage(const grpc::ByteBuffer& bytes, const std::string& what) {
  grpc::ByteBuffer copy(bytes);  // shares the slices
  T message;
  if (!grpc::SerializationTraits<T>::Deserialize(&copy, &message).ok())
    throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, what + " is not a valid " + T::descriptor()->full_name() +
                                                           " message (" + std::to_string(bytes.Length()) + " bytes)");
  return message;
}

template <typename T>
void serializeMessage(const T& message, grpc::ByteBuffer* out) {
  bool own = false;
  out->Clear();  // the serialiser wants an empty buffer
  grpc::SerializationTraits<T>::Serialize(message, out, &own);
}

// Answers a unary request that gRPC could not parse (it would say INTERNAL with an empty message) with
// INVALID_ARGUMENT naming the method. Register with ServerBuilder::experimental().SetInterceptorCreators.
std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> makeBadRequestInterceptorFactory();

}  // namespace sglc::server
