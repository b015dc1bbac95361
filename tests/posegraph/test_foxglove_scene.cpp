// The Foxglove messages the export and the live view share (posegraph/foxglove_scene.hpp).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <nlohmann/json.hpp>

#include "sglc/posegraph/foxglove_scene.hpp"

namespace sglc::posegraph {
namespace {

std::vector<float> decodeBase64Floats(const std::string& text) {
  std::string bytes;
  int bits = 0;
  std::uint32_t acc = 0;
  for (const char c : text) {
    const char* const alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    const char* at = std::strchr(alphabet, c);
    if (c == '=' || !at) continue;
    acc = (acc << 6) | static_cast<std::uint32_t>(at - alphabet);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      bytes += static_cast<char>((acc >> bits) & 0xFF);
    }
  }
  std::vector<float> out(bytes.size() / sizeof(float));
  std::memcpy(out.data(), bytes.data(), out.size() * sizeof(float));
  return out;
}

TEST(FoxgloveScene, TopicNamesEncodeSlashAndPercentOnly) {
  EXPECT_EQ(topicName("robot/1 %x"), "robot%2F1 %25x");
  EXPECT_EQ(topicName("ünï"), "ünï");
}

TEST(FoxgloveScene, SchemasAreJsonNamedByTheirTitle) {
  for (const char* name :
       {"foxglove.PosesInFrame", "foxglove.SceneUpdate", "foxglove.PointCloud", "sglc.LoopList", "sglc.MapEvent"}) {
    const auto schema = nlohmann::json::parse(foxgloveSchema(name));
    EXPECT_EQ(schema["title"], name);
  }
  EXPECT_THROW(foxgloveSchema("foxglove.Grid"), std::invalid_argument);
}

TEST(FoxgloveScene, PointCloudKeepsOnePointPerVoxelInOrderAndDropsTheUnplaceable) {
  Points points;
  for (int i = 0; i < 100; ++i) points.emplace_back(0.01F * static_cast<float>(i % 10), 0.0F, 0.0F);  // one voxel
  points.emplace_back(5.0F, -3.25F, 1.5F);
  points.emplace_back(std::nanf(""), 0.0F, 0.0F);
  points.emplace_back(1e9F, 0.0F, 0.0F);   // 1000 km: beyond the voxel grid
  points.emplace_back(5.1F, -3.2F, 1.6F);  // the same voxel as (5, -3.25, 1.5)
  Mat4d pose = Mat4d::Identity();
  pose(0, 3) = 10;
  const auto cloud = nlohmann::json::parse(foxglovePointCloud(points, pose, 1'500'000'000ULL, 0.5, 1000));
  EXPECT_EQ(cloud["frame_id"], "map");
  EXPECT_EQ(cloud["timestamp"]["sec"], 1);
  EXPECT_EQ(cloud["timestamp"]["nsec"], 500000000);
  EXPECT_EQ(cloud["pose"]["position"]["x"], 10.0);
  EXPECT_EQ(cloud["point_stride"], 12);
  EXPECT_EQ(decodeBase64Floats(cloud["data"]), (std::vector<float>{0, 0, 0, 5.0F, -3.25F, 1.5F}));
  const auto capped = nlohmann::json::parse(foxglovePointCloud(points, pose, 0, 0.001, 3));
  EXPECT_EQ(decodeBase64Floats(capped["data"]).size(), 9U);
  EXPECT_THROW(foxglovePointCloud(points, pose, 0, 0.0, 10), std::invalid_argument);
}

TEST(FoxgloveScene, SceneHasEachRobotsPathsAndEveryLoopOnce) {
  ExportedGraph g;
  for (int i = 0; i < 4; ++i) {
    ExportedGraph::Node n;
    n.scan_id = i + 1;
    n.robot = i < 2 ? "a" : "b/2";
    n.session = "s";
    n.seq = i;
    n.pose(0, 3) = i;
    n.odometry(0, 3) = i * 1.1;
    g.nodes.push_back(n);
  }
  ExportedGraph::Edge odometry;
  odometry.from = 0;
  odometry.to = 1;
  g.edges.push_back(odometry);
  for (const auto& [from, to, p] : {std::tuple<std::size_t, std::size_t, double>{0, 1, 0.9}, {1, 3, 0.7}}) {
    ExportedGraph::Edge e;
    e.from = from;
    e.to = to;
    e.loop_id = static_cast<std::int64_t>(from * 10 + to);
    e.probability = p;
    e.score = 0.5;
    g.edges.push_back(e);
  }
  const auto scene = foxgloveScene(g, 0);
  std::map<std::string, nlohmann::json> by_topic;
  for (const auto& t : scene) by_topic[t.topic] = nlohmann::json::parse(t.message);
  ASSERT_EQ(by_topic.size(), 6U);
  EXPECT_EQ(by_topic["trajectory/a"]["poses"].size(), 2U);
  EXPECT_EQ(by_topic["trajectory/b%2F2"]["poses"][1]["position"]["x"], 3.0);
  // Odometry as sent, its session placed where its first scan is: 2 + (3.3 - 2.2).
  EXPECT_NEAR(by_topic["odometry/b%2F2"]["poses"][1]["position"]["x"].get<double>(), 3.1, 1e-12);
  const auto& entities = by_topic["loops"]["entities"];
  EXPECT_EQ(entities[0]["lines"][0]["points"].size(), 2U);  // intra-robot: one loop
  EXPECT_EQ(entities[1]["lines"][0]["points"].size(), 2U);  // inter-robot: one loop
  EXPECT_EQ(entities[1]["metadata"][1]["value"], "0.700");
  const auto& loops = by_topic["loop_list"]["loops"];
  ASSERT_EQ(loops.size(), 2U);
  EXPECT_EQ(loops[1]["inter_robot"], true);
  EXPECT_EQ(loops[1]["to"]["robot"], "b/2");
  EXPECT_EQ(loops[0]["score"], 0.5);
}

}  // namespace
}  // namespace sglc::posegraph
