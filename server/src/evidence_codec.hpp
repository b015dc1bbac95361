// The loop model's evidence record (sglc/evidence.hpp) as the wire's Evidence message, sent on request
// (QueryOptions.include_evidence).
#pragma once

#include "sglc/evidence.hpp"
#include "sglc/v1/sglc.pb.h"

namespace sglc::server {

v1::EvidenceSource toWire(PoseSource source);
void toWire(const Evidence& evidence, v1::Evidence* out);

}  // namespace sglc::server
