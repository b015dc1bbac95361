// Consensus matching: node pairs found by geometry when descriptors cannot pair them.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <random>
#include <set>

#include "sglc/consensus.hpp"
#include "sglc/io.hpp"
#include "sglc/pipeline.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

// Uniform in [lo, hi) from mt19937's raw output, which the standard fixes on every platform (its
// distributions it does not).
float uniform(std::mt19937& rng, float lo, float hi) {
  return lo + (hi - lo) * static_cast<float>(rng() >> 8) / static_cast<float>(1u << 24);
}

// n nodes of three classes spread over 60 m x 60 m, poles and trunks thin, vehicles car-sized.
std::vector<Node> scene(int n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<Node> nodes(n);
  for (int k = 0; k < n; ++k) {
    const float x = uniform(rng, -30, 30), y = uniform(rng, -30, 30), z = uniform(rng, 0, 2);
    nodes[k].center = Vec3f(x, y, z);
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
  std::vector<std::pair<Node, int>> seen;  // node, query index (-1: only in the candidate)
  for (int k = 0; k < kept; ++k) {
    Node m = p.query[k];
    m.center = (inv.topLeftCorner<3, 3>() * m.center.cast<double>() + inv.topRightCorner<3, 1>()).cast<float>() +
               Vec3f(uniform(rng, -0.05f, 0.05f), uniform(rng, -0.05f, 0.05f), uniform(rng, -0.05f, 0.05f));
    seen.emplace_back(m, k);
  }
  for (const auto& o : others) seen.emplace_back(o, -1);
  for (std::size_t e = seen.size(); e > 1; --e) std::swap(seen[e - 1], seen[rng() % e]);  // portable shuffle
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
  // The first true pair's candidate node becomes 2.5 m wider: beyond d_b, it may not be paired any more.
  p.candidate[p.truth.front().second].size += Vec3f(0.0f, 2.5f, 0.0f);
  // The second one's class changes (a pole where the query has a trunk, or the reverse; a car becomes a pole).
  auto& changed = p.candidate[p.truth[1].second];
  changed.cls = static_cast<std::uint8_t>(changed.cls == 1 ? 2 : 1);
  changed.size = Vec3f(0.4f, 0.3f, 4.0f);
  const auto got = consensusMatches(p.query, flat(p.query.size()), p.candidate, flat(p.candidate.size()), MatchConfig{},
                                    RansacConfig{});
  const std::vector<Match> expected(p.truth.begin() + 2, p.truth.end());
  EXPECT_EQ(got, expected);
}

TEST(Consensus, WorksWhicheverGraphIsSmaller) {
  // The candidate scan is the smaller one here: candidates are then chosen per candidate node.
  const auto p = makePair(30, 7, 2, 13);
  ASSERT_LT(p.candidate.size(), p.query.size());
  const auto got = consensusMatches(p.query, flat(p.query.size()), p.candidate, flat(p.candidate.size()), MatchConfig{},
                                    RansacConfig{});
  EXPECT_EQ(got, p.truth);
}

TEST(Consensus, PairsEachNodeOnce) {
  auto p = makePair(12, 6, 4, 17);
  // A twin 0.3 m beside every true candidate node: each could align, but a node is paired once.
  const auto n = p.candidate.size();
  for (const auto& [i, j] : p.truth) {
    Node twin = p.candidate[j];
    twin.center += Vec3f(0.3f, 0.0f, 0.0f);
    p.candidate.push_back(twin);
  }
  const auto got = consensusMatches(p.query, flat(p.query.size()), p.candidate, flat(p.candidate.size()), MatchConfig{},
                                    RansacConfig{});
  ASSERT_EQ(got.size(), p.truth.size());
  std::set<int> is, js;
  for (const auto& [i, j] : got) {
    EXPECT_TRUE(is.insert(i).second);
    EXPECT_TRUE(js.insert(j).second);
  }
  EXPECT_GT(n, 0u);
}

TEST(Consensus, TheBudgetAndThePerNodeLimitBoundTheSearch) {
  const auto p = makePair(16, 7, 30, 9);
  MatchConfig m;
  m.consensus_per_node = 32;  // every same-class partner (about 12 per node here)
  const auto all = consensusMatches(p.query, flat(p.query.size()), p.candidate, flat(p.candidate.size()), m, {});
  EXPECT_EQ(all, p.truth);
  // One triple examined: among hundreds of agreeing decoy triples, it is not the true motion.
  m.consensus_max_hypotheses = 1;
  EXPECT_LT(consensusMatches(p.query, flat(p.query.size()), p.candidate, flat(p.candidate.size()), m, {}).size(),
            p.truth.size());
  // One partner per node, the first of equal (flat) descriptors: most true partners are cut.
  m.consensus_max_hypotheses = MatchConfig{}.consensus_max_hypotheses;
  m.consensus_per_node = 1;
  EXPECT_LT(consensusMatches(p.query, flat(p.query.size()), p.candidate, flat(p.candidate.size()), m, {}).size(),
            p.truth.size());
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

// The pipeline's use of it: two views of a synthetic street whose descriptor matches are all forbidden
// (min_cosine above any cosine), so only consensus can pair the nodes.
class ConsensusInVerify : public ::testing::Test {
 protected:
  void SetUp() override {
    const LabelledScan world = test::makeStreetWorld();
    truth_ = test::makeT(8.0, 3.0, 0.5, 0.0);  // maps view b into view a
    a_ = test::viewFrom(world, Mat4d::Identity(), 30.0);
    b_ = test::viewFrom(world, truth_, 30.0);
  }
  static Config config() {
    Config c;
    c.match.min_cosine = 1.0;
    return c;
  }
  LabelledScan a_, b_;
  Mat4d truth_;
};

TEST_F(ConsensusInVerify, VerifiesWhatDescriptorsCannotPair) {
  const Pipeline p(config());
  const auto a = p.fingerprint(a_), b = p.fingerprint(b_);
  ASSERT_TRUE(consensusApplies(p.config().match, a.nodes.size(), b.nodes.size()));
  auto r = p.verify(a, b);
  ASSERT_TRUE(r.is_loop) << r.reason;
  EXPECT_GE(r.inliers, 3);
  EXPECT_EQ(r.inlier_pairs.size(), static_cast<std::size_t>(r.inliers));
  EXPECT_LT(test::translationError(r.T, truth_), 0.5);
  Config off = config();
  off.match.consensus_max_nodes = 0;
  EXPECT_STREQ(Pipeline(off).verify(a, b, /*background=*/false).reason, "fewer than 3 node matches");
}

// A pose from landmarks paired by geometry is named as such in the evidence (the loop model weighs the source),
// and like every hypothesis it is a loop only at verify.min_probability; refused, the reason says so.
TEST_F(ConsensusInVerify, ConsensusPoseIsJudgedByTheModelLikeAnyOther) {
  const Pipeline p(config());
  const auto r = p.verify(p.fingerprint(a_), p.fingerprint(b_));
  EXPECT_EQ(r.evidence.source, PoseSource::kConsensus);
  EXPECT_EQ(r.score, r.probability);
  Config strict = config();
  strict.verify.min_probability = 1.0;
  const Pipeline q(strict);
  const auto refused = q.verify(q.fingerprint(a_), q.fingerprint(b_));
  EXPECT_FALSE(refused.is_loop);
  EXPECT_EQ(refused.probability, r.probability);
  EXPECT_NE(std::string(refused.reason).find("loop probability below verify.min_probability"), std::string::npos)
      << refused.reason;
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
    EXPECT_FALSE(off.verify(a, b, /*background=*/false).is_loop);
    auto r = on.verify(a, b, /*background=*/false);
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
