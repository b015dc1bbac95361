#include "sglc/log/json_lines.hpp"

#include <spdlog/spdlog.h>

#include <chrono>
#include <ctime>
#include <nlohmann/json.hpp>
#include <string>

namespace sglc::logging {
namespace {

// RFC 3339, UTC, microseconds: 2026-11-24T13:47:15.065595Z
std::string timestamp(std::chrono::system_clock::time_point t) {
  const auto us = std::chrono::duration_cast<std::chrono::microseconds>(t.time_since_epoch()).count();
  const std::time_t seconds = static_cast<std::time_t>(us / 1'000'000);
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  char out[40];
  const auto n = std::strftime(out, sizeof out, "%Y-%m-%dT%H:%M:%S", &utc);
  std::snprintf(out + n, sizeof out - n, ".%06lldZ", static_cast<long long>(us % 1'000'000));
  return out;
}

std::string dump(const nlohmann::ordered_json& j) {
  return j.dump(-1, ' ', false, nlohmann::ordered_json::error_handler_t::replace);
}

}  // namespace

void JsonLineFormatter::format(const spdlog::details::log_msg& msg, spdlog::memory_buf_t& dest) {
  const std::string_view text(msg.payload.data(), msg.payload.size());
  const auto level = spdlog::level::to_string_view(msg.level);
  nlohmann::ordered_json head = {{"ts", timestamp(msg.time)}, {"level", std::string(level.data(), level.size())}};
  std::string line;
  // A JSON object as logLine() writes it: parse it (it must be one object), then put ts and level first.
  auto body = nlohmann::ordered_json::parse(text.begin(), text.end(), nullptr, false);
  if (!body.is_discarded() && body.is_object()) {
    for (auto& [key, value] : body.items())
      if (key != "ts" && key != "level") head[key] = std::move(value);
  } else {
    head["msg"] = std::string(text);
  }
  line = dump(head);
  line += '\n';
  dest.append(line.data(), line.data() + line.size());
}

std::unique_ptr<spdlog::formatter> JsonLineFormatter::clone() const { return std::make_unique<JsonLineFormatter>(); }

void useJsonLines() { spdlog::set_formatter(std::make_unique<JsonLineFormatter>()); }

}  // namespace sglc::logging
