// Every line spdlog writes through JsonLineFormatter is one JSON object with ts and level first.
#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <vector>

#include "sglc/log/json_lines.hpp"
#include "sglc/log/log_line.hpp"

namespace sglc::logging {
namespace {

std::vector<nlohmann::ordered_json> logLines(const std::function<void(spdlog::logger&)>& write) {
  std::ostringstream out;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(out);
  spdlog::logger logger("test", sink);
  logger.set_formatter(std::make_unique<JsonLineFormatter>());
  logger.set_level(spdlog::level::trace);
  write(logger);
  logger.flush();
  std::vector<nlohmann::ordered_json> lines;
  std::istringstream in(out.str());
  for (std::string line; std::getline(in, line);) {
    auto j = nlohmann::ordered_json::parse(line, nullptr, false);
    EXPECT_FALSE(j.is_discarded()) << "not JSON: " << line;
    lines.push_back(j);
  }
  return lines;
}

TEST(JsonLines, ObjectsGetTimestampAndLevelFirst) {
  const auto lines = logLines([](spdlog::logger& log) {
    log.info("{}", logLine({{"event", "serving"}, {"maps", 3}, {"ms", 12.5}}));
    log.warn("{}", logLine({{"ts", "forged"}, {"level", "forged"}, {"code", "NOT_FOUND"}}));
  });
  ASSERT_EQ(lines.size(), 2u);
  const auto& a = lines[0];
  ASSERT_TRUE(a.is_object());
  EXPECT_EQ(a.begin().key(), "ts");
  EXPECT_TRUE(std::regex_match(a["ts"].get<std::string>(), std::regex(R"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{6}Z)")))
      << a["ts"];
  EXPECT_EQ(a["level"], "info");
  EXPECT_EQ(a["event"], "serving");
  EXPECT_EQ(a["maps"], 3);
  EXPECT_EQ(a["ms"], 12.5);
  EXPECT_EQ(lines[1]["level"], "warning");
  EXPECT_NE(lines[1]["ts"], "forged") << "a message cannot forge the time or level";
  EXPECT_EQ(lines[1]["code"], "NOT_FOUND");
}

TEST(JsonLines, PlainTextIsEscapedIntoMsg) {
  const std::string hostile = "quote \" backslash \\ newline \n tab \t bell \x07 bad utf8 \xff\xfe end";
  const auto lines = logLines([&](spdlog::logger& log) {
    log.error("{}", hostile);
    log.info("{}", "{\"unterminated\": ");  // looks like JSON, is not
    log.info("{}", "[1, 2]");               // JSON, not an object
  });
  ASSERT_EQ(lines.size(), 3u) << "a newline inside a message must not split the line";
  EXPECT_EQ(lines[0]["level"], "error");
  const auto msg = lines[0]["msg"].get<std::string>();
  EXPECT_NE(msg.find("quote \" backslash \\ newline \n tab"), std::string::npos) << msg;
  EXPECT_NE(msg.find("end"), std::string::npos);
  EXPECT_EQ(lines[1]["msg"], "{\"unterminated\": ");
  EXPECT_EQ(lines[2]["msg"], "[1, 2]");
}

}  // namespace
}  // namespace sglc::logging
