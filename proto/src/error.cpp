#include "sglc/wire/error.hpp"

#include <array>
#include <string_view>

namespace sglc::wire {

std::string statusCodeName(grpc::StatusCode code) {
  // Indexed by the code's value, which gRPC fixes at 0..16.
  static constexpr std::array<std::string_view, 17> kNames = {
      "OK",        "CANCELLED",      "UNKNOWN",           "INVALID_ARGUMENT",   "DEADLINE_EXCEEDED",
      "NOT_FOUND", "ALREADY_EXISTS", "PERMISSION_DENIED", "RESOURCE_EXHAUSTED", "FAILED_PRECONDITION",
      "ABORTED",   "OUT_OF_RANGE",   "UNIMPLEMENTED",     "INTERNAL",           "UNAVAILABLE",
      "DATA_LOSS", "UNAUTHENTICATED"};
  const auto i = static_cast<int>(code);
  if (i < 0 || i >= static_cast<int>(kNames.size())) return "STATUS_" + std::to_string(i);
  return std::string(kNames[static_cast<std::size_t>(i)]);
}

}  // namespace sglc::wire
