// One JSON object per log line: values are escaped by the JSON library, never spliced into a format string.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

namespace sglc::logging {

// logLine({{"event", "optimised"}, {"map", name}, {"ms", 12.5}}) -> {"event":"optimised","map":"...","ms":12.5}
// Bytes that are not UTF-8 are replaced, so a line is always valid JSON.
inline std::string logLine(const nlohmann::ordered_json& fields) {
  return fields.dump(-1, ' ', false, nlohmann::ordered_json::error_handler_t::replace);
}

}  // namespace sglc::logging
