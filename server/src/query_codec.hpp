// The loop query's messages <-> the use case's plain types (sglc/closing/loop_query.hpp).
#pragma once

#include <cstdint>
#include <vector>

#include "sglc/closing/loop_query.hpp"
#include "sglc/v1/sglc.pb.h"

namespace sglc::server {

// QueryOptions.exclude_recent when a client leaves it unset (documented in sglc.proto).
inline constexpr std::int64_t kDefaultExcludeRecent = 50;

// A scope this server does not know becomes Scope::kUnknown (the finder refuses it).
closing::QueryOptions fromWire(const v1::QueryOptions& options);
// Each loop as a Candidate, with its probability; with `include_evidence` its evidence record too.
void toWire(const std::vector<closing::FoundLoop>& loops, google::protobuf::RepeatedPtrField<v1::Candidate>* out,
            bool include_evidence);
void toWire(const closing::QueryTiming& timing, v1::Timing* out);

}  // namespace sglc::server
