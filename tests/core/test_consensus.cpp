// Consensus matching: node pairs found by geometry when descriptors cannot pair them.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <random>

#include "sglc/consensus.hpp"
#include "sglc/io.hpp"
#include "sglc/pipeline.hpp"

namespace sglc {
namespace {

// n nodes of three classes spread over 60 m x 60 m, poles and trunks thin, vehicles car-sized.
std::vector<Node> scene(int n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> xy(-30.0f, 30.0f), z(0.0f, 2.0f);
  std::vector<Node> nodes(n);
  for (int k = 0; k < n; ++k) {
    nodes[k].center = Vec3f(xy(rng), xy(rng), z(rng));
    nodes[k].cls = static_cast<std::uint8_t>(k % 3);
    nodes[k].size = nodes[k].cls == 0 ? Vec3f(4.2f, 1.8f, 1.5f) : Vec3f(0.4f, 0.3f, 4.0f);
  }
  return nodes;
}

Mat4d motion() {
  Mat4d T = Mat4d::Identity();
  T.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.7, Vec3d::UnitZ()).toRotationMatrix();
  T.topRightCorner<3, 1>() = Vec3d(3.0, -4.0, 0.1);
  return T;
}

// The candidate scan sees `kept` of the query's nodes (moved by T^-1, so query ~ T * candidate, with a few
// centimetres of noise) plus `extra` nodes of its own, shuffled.
struct Pair {
  std::vector<Node> query, candidate;
  std::vector<Match> truth;  // sorted by query node
};

Pair makePair(int n, int kept, int extra, std::uint32_t seed) {
  Pair p;
  p.query = scene(n, seed);
  const auto others = scene(extra, seed + 1000);
  const Mat4d inv = motion().inverse();
  std::mt19937 rng(seed + 1);
  std::normal_distribution<float> noise(0.0f, 0.05f);
  std::vector<std::pair<Node, int>> seen;  // node, query index (-1: only in the candidate)
  for (int k = 0; k < kept; ++k) {
    Node m = p.query[k];
    m.center = (inv.topLeftCorner<3, 3>() * m.center.cast<double>() + inv.topRightCorner<3, 1>()).cast<float>() +
               Vec3f(noise(rng), noise(rng), noise(rng));
    seen.emplace_back(m, k);
  }
  for (const auto& o : others) seen.emplace_back(o, -1);
  std::shuffle(seen.begin(), seen.end(), rng);
  for (int j = 0; j < static_cast<int>(seen.size()); ++j) {
    p.candidate.push_back(seen[j].first);
    if (seen[j].second >= 0) p.truth.emplace_back(seen[j].second, j);
  }
  std::sort(p.truth.begin(), p.truth.end());
  return p;
}

// Descriptors that carry no information: every node looks like every other of its class.
Eigen::MatrixXf flat(std::size_t n) { return Eigen::MatrixXf::Ones(static_cast<Eigen::Index>(n), 4); }

TEST(Consensus, FindsTheTrueNodePairsWhereDescriptorsSayNothing) {
  const auto p = makePair(12, 6, 8, 3);
  const auto got = consensusMatches(p.query, flat(p.query.size()), p.candidate, flat(p.candidate.size()), MatchConfig{},
                                    RansacConfig{});
  EXPECT_EQ(got, p.truth);
}

TEST(Consensus, KeepsOnlyNodesOfEqualClassAndSize) {
  auto p = makePair(12, 6, 8, 5);
  // The first true pair's candidate node becomes a vehicle-sized pole: it may not be paired any more.
  auto& node = p.candidate[p.truth.front().second];
  node.size = Vec3f(5.0f, 2.5f, 4.0f);
  const auto got = consensusMatches(p.query, flat(p.query.size()), p.candidate, flat(p.candidate.size()), MatchConfig{},
                                    RansacConfig{});
  EXPECT_EQ(std::count(got.begin(), got.end(), p.truth.front()), 0);
  EXPECT_EQ(got.size(), p.truth.size() - 1);
}

TEST(Consensus, UnrelatedScenesAgreeOnFewerNodesThanTrueOnes) {
  // Twelve against twenty unrelated nodes: chance alignments exist but are smaller than a real overlap.
  const auto q = scene(12, 21), c = scene(20, 77);
  const auto got = consensusMatches(q, flat(q.size()), c, flat(c.size()), MatchConfig{}, RansacConfig{});
  EXPECT_LT(got.size(), 6u);
}

TEST(Consensus, IsDeterministicAndBounded) {
  const auto p = makePair(16, 7, 30, 9);
  MatchConfig m;
  const auto a = consensusMatches(p.query, flat(p.query.size()), p.candidate, flat(p.candidate.size()), m, {});
  const auto b = consensusMatches(p.query, flat(p.query.size()), p.candidate, flat(p.candidate.size()), m, {});
  EXPECT_EQ(a, b);
  // One hypothesis: the first agreeing triple only, which need not be the best.
  m.consensus_max_hypotheses = 1;
  const auto one = consensusMatches(p.query, flat(p.query.size()), p.candidate, flat(p.candidate.size()), m, {});
  EXPECT_LE(one.size(), a.size());
}

TEST(Consensus, AppliesToSmallGraphsOnly) {
  MatchConfig m;
  EXPECT_TRUE(consensusApplies(m, 16, 200));
  EXPECT_TRUE(consensusApplies(m, 40, 9));
  EXPECT_FALSE(consensusApplies(m, 17, 17));
  m.consensus_max_nodes = 0;
  EXPECT_FALSE(consensusApplies(m, 3, 3));
}

TEST(Consensus, TooFewCandidatesGiveNothing) {
  const auto q = scene(2, 1), c = scene(2, 1);
  EXPECT_TRUE(consensusMatches(q, flat(2), c, flat(2), MatchConfig{}, RansacConfig{}).empty());
}

// Real HDL-32E scans (nuScenes scene 1072, 4 m apart): consecutive scans whose few nodes the descriptors
// cannot pair are verified through consensus, at a pose near the recorded one; far scans stay apart.
class RealSparseScans : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::path(SGLC_SHARED_DATA) / "nuscenes_scene1072";
    if (!std::filesystem::is_directory(dir_ / "velodyne"))
      GTEST_SKIP() << "real data not found: " << dir_.string() << " is absent (nuScenes is not part of the repository)";
    poses_ = readPoses((dir_ / "poses.txt").string());
  }
  Fingerprint load(const Pipeline& p, int k) const {
    char name[16];
    std::snprintf(name, sizeof name, "%06d", k);
    LabelledScan scan;
    scan.points = readKittiBin((dir_ / "velodyne" / (std::string(name) + ".bin")).string());
    scan.labels = readLabels((dir_ / "labels" / (std::string(name) + ".label")).string(), scan.points.size());
    return p.fingerprint(scan);
  }
  static Config config(int consensus_max_nodes) {
    Config c;
    c.labels = labelPreset("nuscenes");
    c.match.consensus_max_nodes = consensus_max_nodes;
    return c;
  }
  std::filesystem::path dir_;
  std::vector<Mat4d> poses_;
};

TEST_F(RealSparseScans, ConsecutiveScansVerifyThroughConsensusOnly) {
  const Pipeline on(config(16)), off(config(0));
  for (const int i : {24, 29, 30}) {
    SCOPED_TRACE("scans " + std::to_string(i) + " and " + std::to_string(i + 1));
    const auto a = load(on, i), b = load(on, i + 1);
    ASSERT_LE(std::min(a.nodes.size(), b.nodes.size()), 16u);
    EXPECT_FALSE(off.verify(a, b).is_loop);
    auto r = on.verify(a, b);
    ASSERT_TRUE(r.is_loop) << r.reason;
    on.refine(a, b, r);
    const Mat4d recorded = poses_[i].inverse() * poses_[i + 1];  // maps scan i+1 into scan i
    const Mat4d d = recorded.inverse() * r.T;
    EXPECT_LT((d.topRightCorner<3, 1>().norm()), 0.5);  // the recorded poses are ~0.15 m off a dense registration
    EXPECT_LT(Eigen::AngleAxisd(Mat3d(d.topLeftCorner<3, 3>())).angle() * 180.0 / M_PI, 1.0);
  }
}

TEST_F(RealSparseScans, ScansFarApartStayApart) {
  const Pipeline on(config(16));
  std::vector<Fingerprint> f;
  for (int k = 0; k < 40; k += 3) f.push_back(load(on, k));
  // 3 frames ~ 13 m: every pair at least 9 frames (~35 m) apart.
  for (std::size_t i = 0; i < f.size(); ++i)
    for (std::size_t j = i + 3; j < f.size(); ++j) EXPECT_FALSE(on.verify(f[i], f[j]).is_loop) << i << " " << j;
}

}  // namespace
}  // namespace sglc
