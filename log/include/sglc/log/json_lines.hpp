// Log output as JSON lines: every line the process logs through spdlog is one JSON object,
// {"ts":"2026-11-24T13:47:15.065595Z","level":"info", ...}, whatever the message was.
#pragma once

#include <spdlog/formatter.h>

#include <memory>

namespace sglc::logging {

// A message that is a JSON object (as logLine() makes) gets "ts" and "level" put first; any other text becomes
// {"ts":...,"level":...,"msg":"<the text, escaped>"}. Bytes that are not UTF-8 are replaced.
class JsonLineFormatter final : public spdlog::formatter {
 public:
  void format(const spdlog::details::log_msg& msg, spdlog::memory_buf_t& dest) override;
  std::unique_ptr<spdlog::formatter> clone() const override;
};

// Makes every spdlog logger of the process (the default one included) write JSON lines.
void useJsonLines();

}  // namespace sglc::logging
