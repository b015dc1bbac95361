// The loop exports of sglc/client/export_formats.hpp: g2o layout and information conversion, CSV precision
// and quoting, JSON fields.
#include <gtest/gtest.h>

#include <algorithm>
#include <sstream>

#include "sglc/client/export_formats.hpp"
#include "sglc/wire/geometry_codec.hpp"

namespace sglc::client {
namespace {

v1::LoopEdge edge(std::int64_t id, std::int64_t query, std::int64_t candidate, bool with_information) {
  v1::LoopEdge e;
  e.set_id(id);
  e.mutable_query()->set_scan_id(query);
  e.mutable_query()->set_robot("r,\"1\"");
  e.mutable_candidate()->set_scan_id(candidate);
  Mat4d T = Mat4d::Identity();
  T(0, 3) = 0.1 + 1e-16;  // needs 17 significant digits to come back
  wire::toTransform(T, e.mutable_t_query_candidate());
  if (with_information)
    for (int k = 0; k < 36; ++k) e.add_information(k / 6 == k % 6 ? 10.0 * (k / 6 + 1) : 0.0);
  return e;
}

std::vector<std::vector<std::string>> linesOf(const std::string& text) {
  std::vector<std::vector<std::string>> out;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    std::istringstream words(line);
    out.emplace_back();
    for (std::string w; words >> w;) out.back().push_back(w);
  }
  return out;
}

TEST(ExportFormats, CsvQuotesNamesAndKeepsFullPrecision) {
  std::ostringstream out;
  writeLoopsCsv({edge(5, 1, 2, false)}, out);
  std::istringstream in(out.str());
  std::string header, row;
  std::getline(in, header);
  std::getline(in, row);
  EXPECT_EQ(header.rfind("id,query_scan,query_robot,", 0), 0u);
  EXPECT_NE(row.find(",\"r,\"\"1\"\"\","), std::string::npos) << row;  // RFC 4180
  // T03 reads back to the same double. A naive split by ',' sees the quoted robot name as two cells.
  auto split = [](const std::string& text) {
    std::vector<std::string> cells;
    std::istringstream cells_in(text);
    for (std::string c; std::getline(cells_in, c, ',');) cells.push_back(c);
    return cells;
  };
  const auto names = split(header), cells = split(row);
  const auto t03 = std::find(names.begin(), names.end(), "T03") - names.begin();
  ASSERT_EQ(cells.size(), names.size() + 1);
  EXPECT_EQ(std::stod(cells[t03 + 1]), 0.1 + 1e-16) << row;
  const auto j = loopJson(edge(5, 1, 2, true));
  EXPECT_EQ(j["id"], 5);
  EXPECT_EQ(j["query"]["robot"], "r,\"1\"");
  EXPECT_EQ(j["information"].size(), 36u);
  EXPECT_DOUBLE_EQ(j["T"][3].get<double>(), 0.1 + 1e-16);
}

// The loop model's probability: a column beside the score (empty when unknown) and a JSON field (null).
TEST(ExportFormats, ProbabilityInCsvAndJsonAndUnknownStaysEmpty) {
  auto known = edge(5, 1, 2, false);
  known.set_probability(0.1 + 1e-16);
  const auto unknown = edge(6, 1, 3, false);
  std::ostringstream out;
  writeLoopsCsv({known, unknown}, out);
  std::istringstream in(out.str());
  std::string header, row1, row2;
  std::getline(in, header);
  std::getline(in, row1);
  std::getline(in, row2);
  EXPECT_NE(header.find(",score,probability,inliers,"), std::string::npos) << header;
  // The robot name holds one quoted comma: a naive split has one cell more than the header, before the column.
  auto cell = [&](const std::string& text, const std::string& name) {
    std::vector<std::string> names, cells;
    std::istringstream hs(header), cs(text);
    for (std::string c; std::getline(hs, c, ',');) names.push_back(c);
    for (std::string c; std::getline(cs, c, ',');) cells.push_back(c);
    return cells.at(static_cast<std::size_t>(std::find(names.begin(), names.end(), name) - names.begin()) + 1);
  };
  EXPECT_EQ(std::stod(cell(row1, "probability")), 0.1 + 1e-16) << row1;
  EXPECT_EQ(cell(row2, "probability"), "") << row2;
  EXPECT_DOUBLE_EQ(loopJson(known)["probability"].get<double>(), 0.1 + 1e-16);
  EXPECT_TRUE(loopJson(unknown)["probability"].is_null());
}

}  // namespace
}  // namespace sglc::client
