// The whole pipeline: real SemanticKITTI loop / non-loop pairs, synthetic views, edge cases, determinism and
// thread safety.
#include <gtest/gtest.h>

#include <functional>

#include <fstream>
#include <map>
#include <numbers>
#include <sstream>
#include <thread>
#include <utility>

#include "dense_registration.hpp"
#include "sglc/background.hpp"
#include "sglc/io.hpp"
#include "sglc/pipeline.hpp"
#include "sglc/registration.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

using test::rotationErrorDeg;
using test::translationError;

struct PairRow {
  std::string seq, a, b;
  bool is_loop = false;
  Mat4d T_a_b = Mat4d::Identity();  // p_a = T_a_b * p_b
};

// pairs.txt: seq frame_a frame_b is_loop dist_kittigt_m dist_semkitti_m gap, then T_a_b as 12 values
// (row-major 3x4), "nan" where there is no loop.
std::vector<PairRow> readPairs(const std::string& path) {
  std::ifstream in(path);
  std::vector<PairRow> rows;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    PairRow r;
    std::string loop, d1, d2, gap;
    ss >> r.seq >> r.a >> r.b >> loop >> d1 >> d2 >> gap;
    r.is_loop = loop == "1";
    for (int k = 0; k < 12; ++k) {
      std::string v;
      ss >> v;
      if (r.is_loop) r.T_a_b(k / 4, k % 4) = std::stod(v);
    }
    rows.push_back(r);
  }
  return rows;
}

bool identical(const LoopResult& a, const LoopResult& b) {
  return a.is_loop == b.is_loop && a.score == b.score && a.matches == b.matches && a.inliers == b.inliers &&
         a.graph_similarity == b.graph_similarity && a.background_similarity == b.background_similarity &&
         (a.T.array() == b.T.array()).all() && a.refined == b.refined && a.fitness == b.fitness && a.rmse == b.rmse &&
         a.inlier_pairs == b.inlier_pairs;
}

void expectSane(const LoopResult& r) {
  EXPECT_TRUE(std::isfinite(r.score));
  EXPECT_GE(r.score, 0.0);
  EXPECT_LE(r.score, 1.0);
  EXPECT_TRUE(r.T.allFinite());
  EXPECT_TRUE(std::isfinite(r.graph_similarity));
  EXPECT_TRUE(std::isfinite(r.background_similarity));
  EXPECT_TRUE(std::isfinite(r.fitness));
  EXPECT_TRUE(std::isfinite(r.rmse));
  if (r.is_loop) {
    EXPECT_STREQ(r.reason, "");
    EXPECT_EQ(static_cast<int>(r.inlier_pairs.size()), r.inliers);
    // A loop from the background alone has no node inliers and the planes' (refined) pose.
    if (r.inliers == 0)
      EXPECT_TRUE(r.refined);
    else
      EXPECT_GE(r.inliers, 3);
    EXPECT_LE(r.inliers, r.matches);
  } else {
    EXPECT_STRNE(r.reason, "");
  }
}

// Real scans: fingerprints computed once for the whole suite.
class RealPipeline : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const std::string root = test::scansDir();
    if (root.empty()) return;
    pipeline_ = new Pipeline();
    fps_ = new std::map<std::string, Fingerprint>();
    auto load = [&](const std::string& key, const std::string& dir, const std::string& frame) {
      (*fps_)[key] =
          pipeline_->fingerprint(readScan(dir + "/velodyne/" + frame + ".bin", dir + "/labels/" + frame + ".label"));
    };
    for (const char* f : {"000052", "000088", "000850", "004501"})
      load(std::string("00/") + f, root + "/sequences/00", f);
    for (const char* f : {"000000", "000001", "000002", "000003"})
      load(std::string("demo/") + f, root + "/extra/segnet4d_demo", f);
    pairs_ = new std::vector<PairRow>(readPairs(root + "/pairs.txt"));
  }
  static void TearDownTestSuite() {
    delete pipeline_;
    delete fps_;
    delete pairs_;
    pipeline_ = nullptr;
    fps_ = nullptr;
    pairs_ = nullptr;
  }
  void SetUp() override { SGLC_REQUIRE_REAL_DATA(); }
  static const Fingerprint& fp(const std::string& key) { return fps_->at(key); }
  // A frame of the real sequence 00, read again from disk.
  static LabelledScan scan00(const std::string& frame) {
    const std::string dir = test::scansDir() + "/sequences/00";
    return readScan(dir + "/velodyne/" + frame + ".bin", dir + "/labels/" + frame + ".label");
  }
  // T within max_m / max_deg of ref; the errors are recorded as test properties `property`_m and _deg.
  static void expectPoseWithin(const Mat4d& T, const Mat4d& ref, double max_m, double max_deg,
                               const std::string& property) {
    const double dt = translationError(T, ref), dr = rotationErrorDeg(T, ref);
    RecordProperty(property + "_m", std::to_string(dt));
    RecordProperty(property + "_deg", std::to_string(dr));
    EXPECT_LT(dt, max_m) << property << "\n" << T << "\nreference\n" << ref;
    EXPECT_LT(dr, max_deg) << property << "\n" << T << "\nreference\n" << ref;
  }
  static const PairRow& loopRow() {
    for (const auto& r : *pairs_)
      if (r.seq == "00" && r.a == "000052" && r.b == "004501") return r;
    throw std::runtime_error("pairs.txt has no 00 000052 004501 row");
  }

  static Pipeline* pipeline_;
  static std::map<std::string, Fingerprint>* fps_;
  static std::vector<PairRow>* pairs_;
};
Pipeline* RealPipeline::pipeline_ = nullptr;
std::map<std::string, Fingerprint>* RealPipeline::fps_ = nullptr;
std::vector<PairRow>* RealPipeline::pairs_ = nullptr;

TEST_F(RealPipeline, PairsFileParsed) {
  ASSERT_EQ(pairs_->size(), 6u);
  const PairRow& r = loopRow();
  EXPECT_TRUE(r.is_loop);
  // The reference pose is a rotation (independent sanity check of the parsing).
  const Mat3d R = r.T_a_b.topLeftCorner<3, 3>();
  EXPECT_NEAR((R.transpose() * R - Mat3d::Identity()).norm(), 0.0, 1e-4);
  EXPECT_NEAR((r.T_a_b.block(0, 3, 3, 1).norm()), 3.0, 0.01);  // dist_semkitti_m column: 3.00
}

TEST_F(RealPipeline, LoopPairMatchesReferencePose) {
  const PairRow& row = loopRow();
  const LoopResult r = pipeline_->match(fp("00/000052"), fp("00/004501"));
  expectSane(r);
  ASSERT_TRUE(r.is_loop) << r.reason;
  EXPECT_TRUE(r.refined);
  expectPoseWithin(r.T, row.T_a_b, 0.10, 0.5, "loop_error");
  // The refined loop carries its information: symmetric, positive definite; the verified-only one none.
  const Eigen::SelfAdjointEigenSolver<Mat6d> eig(r.information);
  EXPECT_LT((r.information - r.information.transpose()).norm(), 1e-6 * r.information.norm());
  EXPECT_GT(eig.eigenvalues()[0], 0.0) << r.information;
  EXPECT_TRUE(pipeline_->verify(fp("00/000052"), fp("00/004501")).information.isZero());
}

// pairs.txt's pose comes from SemanticKITTI's trajectory (a few cm). A dense point-to-plane registration of the
// two full scans is a sharper reference: it ends at the same pose from pairs.txt's pose and from the engine's,
// and the engine's compact fingerprints land within 1.5 cm / 0.15 deg of it (measured: 6 mm / 0.10 deg, while
// pairs.txt is 36 mm / 0.12 deg from it).
TEST_F(RealPipeline, LoopPairAgreesWithDenseRegistration) {
  const PairRow& row = loopRow();
  const test::DenseRegistration dense(test::DenseRegistration::staticPoints(scan00("000052")));
  const auto source = test::DenseRegistration::staticPoints(scan00("004501"));
  const LoopResult r = pipeline_->match(fp("00/000052"), fp("00/004501"));
  ASSERT_TRUE(r.is_loop) << r.reason;
  const Mat4d from_reference = dense.align(source, row.T_a_b);
  const Mat4d from_engine = dense.align(source, r.T);
  EXPECT_LT(translationError(from_reference, from_engine), 0.002);
  EXPECT_LT(rotationErrorDeg(from_reference, from_engine), 0.01);
  RecordProperty("pairs_txt_vs_dense_m", std::to_string(translationError(row.T_a_b, from_reference)));
  expectPoseWithin(r.T, from_reference, 0.015, 0.15, "engine_vs_dense");
}

// The same real loop with the candidate's landmarks unlabelled (no node matches). From the landmarks alone
// verification rejects it, and a caller who knows it is a loop still gets its pose, from the background views
// and planes; with loops from the background allowed (the default), verification accepts it with that pose.
TEST_F(RealPipeline, LoopWithoutLandmarksIsFoundFromTheBackground) {
  const PairRow& row = loopRow();
  LabelledScan bare = scan00("004501");
  const LabelMap labels(pipeline_->config().labels);
  for (auto& l : bare.labels)
    if (labels.nodeClass(l) >= 0) l = 0;
  const Fingerprint b = pipeline_->fingerprint(bare);
  ASSERT_TRUE(b.nodes.empty());
  LoopResult r = pipeline_->verify(fp("00/000052"), b, /*background=*/false);
  ASSERT_FALSE(r.is_loop);
  pipeline_->refine(fp("00/000052"), b, r, /*known_loop=*/true);
  ASSERT_TRUE(r.refined);
  EXPECT_FALSE(r.is_loop);
  expectPoseWithin(r.T, row.T_a_b, 0.10, 0.5, "background_only_error");
  const LoopResult found = pipeline_->match(fp("00/000052"), b);
  ASSERT_TRUE(found.is_loop) << found.reason;
  EXPECT_TRUE(found.refined);
  EXPECT_EQ(found.inliers, 0);
  EXPECT_GT(found.score, 0.0);
  expectPoseWithin(found.T, row.T_a_b, 0.10, 0.5, "background_loop_error");
  // Its information matrix is the planes' (the pose graph weighs the loop with it).
  EXPECT_GT(found.information.trace(), 0.0);
  // Switched off (no background-only loops; or no BEV search, or no plane stage, which it needs): rejected.
  for (const auto off :
       {+[](Config& c) { c.verify.background_max_nodes = 0; }, +[](Config& c) { c.bev_search.enabled = false; },
        +[](Config& c) { c.refine.enabled = false; }}) {
    Config config = pipeline_->config();
    off(config);
    EXPECT_FALSE(Pipeline(config).match(fp("00/000052"), b).is_loop);
  }
}

// A narrow field of view (a solid-state sensor's 70 deg) is not trusted for a loop from the background alone at
// the walls' headings: walls seen in a wedge overlay on too many other streets (simulated rosette queries, seed 3:
// 2 of their 9 background-only loops false). Its overlay is searched only at the heading its view context gives
// (view_search), and without view_search it gets none. The stripped loop's candidate, cut to a 70 deg wedge 45 deg
// right of ahead, verifies at the right pose that way; the wedge 45 deg left, whose context's best shift is about
// 65 deg off on these real labels, gets no loop rather than a wrong one, though the walls' headings would give it
// the right pose once verify.background_min_view_deg lets them. (Straight ahead, the wedge holds too few of the
// walls this pair shares for a loop either way: it would test nothing.)
TEST_F(RealPipeline, NarrowViewGetsBackgroundOnlyLoopsAtItsViewHeadingOnly) {
  const LabelledScan scan = scan00("004501");
  const LabelMap labels(pipeline_->config().labels);
  auto wedge = [&](double towards_deg) {
    LabelledScan cut;
    for (std::size_t i = 0; i < scan.points.size(); ++i) {
      const auto& p = scan.points[i];
      const double off_axis =
          std::remainder(std::atan2(p.y(), p.x()) - test::deg2rad(towards_deg), 2 * std::numbers::pi);
      if (labels.nodeClass(scan.labels[i]) >= 0 || std::abs(off_axis) > test::deg2rad(35.0)) continue;
      cut.points.push_back(p);
      cut.labels.push_back(scan.labels[i]);
    }
    return pipeline_->fingerprint(cut);
  };
  const Fingerprint& full = fp("00/000052");
  const Fingerprint right = wedge(-45.0), left = wedge(45.0);
  EXPECT_LE(viewSpanDeg(right.background, right.background_cell), 90.0);
  EXPECT_LE(viewSpanDeg(left.background, left.background_cell), 90.0);
  EXPECT_GE(viewSpanDeg(full.background, full.background_cell), 300.0);

  const LoopResult at_view = pipeline_->match(full, right);
  ASSERT_TRUE(at_view.is_loop) << at_view.reason;
  EXPECT_EQ(at_view.inliers, 0);  // from the background alone
  // A wedge's planes hold the heading less tightly than a full turn's: 0.52 and 0.55 deg off here.
  expectPoseWithin(at_view.T, loopRow().T_a_b, 0.10, 1.0, "narrow_view_background_loop_error");
  const LoopResult reverse = pipeline_->match(right, full);  // the narrow scan as the query
  ASSERT_TRUE(reverse.is_loop) << reverse.reason;
  expectPoseWithin(reverse.T, loopRow().T_a_b.inverse(), 0.10, 1.0, "narrow_view_reverse_error");
  EXPECT_FALSE(pipeline_->match(full, left).is_loop);
  // Two wedges of one scan (both narrow views) get no background hypotheses, however much they share: the
  // model was fitted on narrow scans against full ones, and rosette scans against rosette scans gave false loops.
  const LoopResult wedges = pipeline_->verify(right, wedge(-40.0));
  EXPECT_FALSE(wedges.is_loop);
  EXPECT_NE(std::string(wedges.reason).find("two narrow views"), std::string::npos) << wedges.reason;
  // The query's view made once (Pipeline::viewRanking, as a LoopFinder hands it to every candidate) gives the
  // same answers as computing it per pair, whichever scan is the narrow one.
  for (const auto& [query, candidate] : {std::pair{&right, &full}, std::pair{&full, &right}, std::pair{&full, &left}}) {
    const auto view = pipeline_->viewRanking(*query);
    const LoopResult alone = pipeline_->verify(*query, *candidate);
    const LoopResult given = pipeline_->verify(*query, *candidate, true, &view);
    EXPECT_EQ(alone.is_loop, given.is_loop);
    EXPECT_EQ(alone.probability, given.probability);
    EXPECT_TRUE(alone.T == given.T);
    EXPECT_EQ(alone.evidence.context_similarity, given.evidence.context_similarity);
  }
  // A view made for another scan is ignored, not trusted: the answer is the one computed from the query itself.
  const auto others = pipeline_->viewRanking(left);
  const LoopResult own = pipeline_->verify(right, full);
  const LoopResult misled = pipeline_->verify(right, full, true, &others);
  EXPECT_EQ(own.probability, misled.probability);
  EXPECT_TRUE(own.T == misled.T);

  Config off = pipeline_->config();
  off.view_search.enabled = false;
  const LoopResult refused = Pipeline(off).match(full, right);
  EXPECT_FALSE(refused.is_loop);
  EXPECT_NE(std::string(refused.reason).find("view_search"), std::string::npos) << refused.reason;
  Config open = pipeline_->config();
  open.verify.background_min_view_deg = 0;
  const LoopResult walls = Pipeline(open).match(full, left);
  ASSERT_TRUE(walls.is_loop) << walls.reason;
  expectPoseWithin(walls.T, loopRow().T_a_b, 0.10, 0.5, "wedge_background_loop_error");
}

// A narrow view's background-only loop is judged by the one model over its evidence: the pose comes from the
// view context's heading, the agreement is judged over the wedge's own field (were its sectors mirrored or turned,
// the wedge's structure would fall outside them), and the loop stands only at verify.min_probability. Wedges of the
// real non-loop scans, in eight directions, landmarks kept as a solid-state sensor sees them, get no loop against
// the other scan, either way round.
TEST_F(RealPipeline, NarrowViewBackgroundLoopsAreJudgedByTheirEvidence) {
  const LabelMap labels(pipeline_->config().labels);
  auto wedge = [&](const LabelledScan& scan, double towards_deg, bool landmarks) {
    LabelledScan cut;
    for (std::size_t i = 0; i < scan.points.size(); ++i) {
      const auto& p = scan.points[i];
      const double off_axis =
          std::remainder(std::atan2(p.y(), p.x()) - test::deg2rad(towards_deg), 2 * std::numbers::pi);
      if ((!landmarks && labels.nodeClass(scan.labels[i]) >= 0) || std::abs(off_axis) > test::deg2rad(35.0)) continue;
      cut.points.push_back(p);
      cut.labels.push_back(scan.labels[i]);
    }
    return pipeline_->fingerprint(cut);
  };
  const Fingerprint& full = fp("00/000052");
  const Fingerprint right = wedge(scan00("004501"), -45.0, false);
  const LoopResult loop = pipeline_->match(full, right);
  ASSERT_TRUE(loop.is_loop) << loop.reason;
  EXPECT_EQ(loop.evidence.source, PoseSource::kViewHeadings);
  EXPECT_TRUE(loop.evidence.narrow);
  EXPECT_LT(loop.evidence.field_deg, pipeline_->config().verify.background_min_view_deg);
  EXPECT_GT(loop.evidence.context_similarity, 0.0);
  EXPECT_EQ(loop.score, loop.probability);
  EXPECT_EQ(loop.probability, pipeline_->model().probability(loop.evidence));
  Config stricter = pipeline_->config();
  stricter.verify.min_probability = std::nextafter(loop.probability, 1.0);
  const LoopResult refused = Pipeline(stricter).match(full, right);
  EXPECT_FALSE(refused.is_loop);
  EXPECT_NE(std::string(refused.reason).find("weakest evidence"), std::string::npos) << refused.reason;

  int wedges = 0;
  for (const auto& row : *pairs_) {
    if (row.is_loop || row.seq != "00") continue;
    const LabelledScan b = scan00(row.b);
    for (int k = 0; k < 8; ++k) {
      const Fingerprint w = wedge(b, 45.0 * k, true);
      ASSERT_LT(viewSpanDeg(w.background, w.background_cell), pipeline_->config().verify.background_min_view_deg);
      const Fingerprint& a = fp(row.seq + "/" + row.a);
      // Few enough landmarks that the background may speak.
      ASSERT_LE(static_cast<int>(std::min(a.nodes.size(), w.nodes.size())),
                pipeline_->config().verify.background_max_nodes);
      const LoopResult ab = pipeline_->match(a, w), ba = pipeline_->match(w, a);
      EXPECT_FALSE(ab.is_loop) << row.a << " vs " << row.b << " at " << 45 * k << " deg, p " << ab.probability;
      EXPECT_FALSE(ba.is_loop) << row.b << " at " << 45 * k << " deg vs " << row.a << ", p " << ba.probability;
      ++wedges;
    }
  }
  EXPECT_GE(wedges, 8);
}

TEST_F(RealPipeline, LoopPairReverseDirection) {
  const PairRow& row = loopRow();
  const LoopResult r = pipeline_->match(fp("00/004501"), fp("00/000052"));
  expectSane(r);
  ASSERT_TRUE(r.is_loop) << r.reason;
  expectPoseWithin(r.T, row.T_a_b.inverse(), 0.10, 0.5, "reverse_error");  // maps 52 into 4501
}

TEST_F(RealPipeline, VerifyAloneGivesCoarsePose) {
  const PairRow& row = loopRow();
  const LoopResult r = pipeline_->verify(fp("00/000052"), fp("00/004501"));
  expectSane(r);
  ASSERT_TRUE(r.is_loop) << r.reason;
  EXPECT_FALSE(r.refined);
  EXPECT_GE(r.probability, pipeline_->config().verify.min_probability);
  EXPECT_EQ(r.evidence.source, PoseSource::kLandmarks);
  // The coarse (node-centre) pose is already close to the reference.
  EXPECT_LT(translationError(r.T, row.T_a_b), 1.0);
  EXPECT_LT(rotationErrorDeg(r.T, row.T_a_b), 3.0);
  // refine() on it gives the same as match().
  LoopResult refined = r;
  pipeline_->refine(fp("00/000052"), fp("00/004501"), refined);
  EXPECT_TRUE(identical(refined, pipeline_->match(fp("00/000052"), fp("00/004501"))));
}

TEST_F(RealPipeline, StagesCanBeDisabled) {
  const Fingerprint& a = fp("00/000052");
  const Fingerprint& b = fp("00/004501");
  const LoopResult coarse = pipeline_->verify(a, b);
  ASSERT_TRUE(coarse.is_loop);
  // Without the plane stage there is no plane evidence, and the probability stays under the default bar; the
  // decision is not under test here, so these configurations take every hypothesis as a loop.
  Config none;
  none.verify.min_probability = 0.0;
  none.fine.enabled = false;
  none.refine.enabled = false;
  const LoopResult n = Pipeline(none).match(a, b);
  EXPECT_TRUE(n.refined);
  // Nothing moved the coarse pose: not the fine or plane stage, nor the plane alignment in verification (it is
  // the plane stage's too).
  const LoopResult unaligned = Pipeline(none).verify(a, b);
  ASSERT_TRUE(unaligned.is_loop);
  EXPECT_TRUE((n.T.array() == unaligned.T.array()).all());
  Config no_align;
  no_align.verify.min_probability = 0.0;
  no_align.verify.fit_max_shift_m = 0;
  EXPECT_TRUE((Pipeline(no_align).verify(a, b).T.array() == unaligned.T.array()).all());
  EXPECT_FALSE((coarse.T.array() == unaligned.T.array()).all());  // by default, verification aligns it
  // Fine stage only: fitness / rmse are the instance ICP's (header: "with the plane stage disabled").
  Config fine_only;
  fine_only.verify.min_probability = 0.0;
  fine_only.refine.enabled = false;
  const LoopResult f = Pipeline(fine_only).match(a, b);
  ASSERT_TRUE(f.is_loop);
  EXPECT_GT(f.fitness, 0.0);
  EXPECT_LE(f.fitness, 1.0);
  EXPECT_GT(f.rmse, 0.0);
  EXPECT_LT(f.rmse, fine_only.fine.max_corr_end_m);
  EXPECT_LT(translationError(f.T, loopRow().T_a_b), 0.2);
}

TEST_F(RealPipeline, NegativesRejectedBothWays) {
  int negatives = 0;
  for (const auto& row : *pairs_) {
    if (row.is_loop) continue;
    ++negatives;
    const Fingerprint& a = fp(row.seq + "/" + row.a);
    const Fingerprint& b = fp(row.seq + "/" + row.b);
    const LoopResult ab = pipeline_->match(a, b), ba = pipeline_->match(b, a);
    expectSane(ab);
    expectSane(ba);
    EXPECT_FALSE(ab.is_loop) << row.a << " vs " << row.b << " score " << ab.score;
    EXPECT_FALSE(ba.is_loop) << row.b << " vs " << row.a << " score " << ba.score;
  }
  EXPECT_EQ(negatives, 5);
}

// Background-only loops must not open a door to false ones: the real non-loop pairs, with every landmark's label
// removed from both scans (so only the background can speak), are still rejected both ways, while the true pair
// stripped the same way is found.
TEST_F(RealPipeline, WithoutLandmarksNegativesStayRejected) {
  const LabelMap labels(pipeline_->config().labels);
  std::map<std::string, Fingerprint> bare;
  for (const char* frame : {"000052", "000088", "000850", "004501"}) {
    LabelledScan s = scan00(frame);
    for (auto& l : s.labels)
      if (labels.nodeClass(l) >= 0) l = 0;
    bare.emplace(frame, pipeline_->fingerprint(s));
  }
  int negatives = 0;
  for (const auto& row : *pairs_) {
    if (row.seq != "00" || !bare.count(row.a) || !bare.count(row.b)) continue;
    const LoopResult ab = pipeline_->match(bare.at(row.a), bare.at(row.b));
    const LoopResult ba = pipeline_->match(bare.at(row.b), bare.at(row.a));
    if (row.is_loop) {
      EXPECT_TRUE(ab.is_loop) << ab.reason;
      EXPECT_TRUE(ba.is_loop) << ba.reason;
      continue;
    }
    ++negatives;
    EXPECT_FALSE(ab.is_loop) << row.a << " vs " << row.b << " score " << ab.score;
    EXPECT_FALSE(ba.is_loop) << row.b << " vs " << row.a << " score " << ba.score;
  }
  EXPECT_EQ(negatives, 5);
}

TEST_F(RealPipeline, TrueLoopOutscoresNegatives) {
  const double loop = pipeline_->verify(fp("00/000052"), fp("00/004501")).score;
  for (const char* other : {"00/000088", "00/000850"})
    EXPECT_GT(loop, pipeline_->verify(fp("00/000052"), fp(other)).score) << other;
}

TEST_F(RealPipeline, ConsecutiveFramesAreLoops) {
  for (int k = 0; k < 3; ++k) {
    char a[16], b[16];
    std::snprintf(a, sizeof a, "demo/%06d", k);
    std::snprintf(b, sizeof b, "demo/%06d", k + 1);
    const LoopResult r = pipeline_->match(fp(a), fp(b));
    expectSane(r);
    EXPECT_TRUE(r.is_loop) << a << " vs " << b << ": " << r.reason;
    // Consecutive KITTI frames (10 Hz): well under 0.5 m and 3 degrees apart.
    EXPECT_LT((r.T.block(0, 3, 3, 1).norm()), 0.5) << a << " vs " << b << "\n" << r.T;
    EXPECT_LT(rotationErrorDeg(r.T, Mat4d::Identity()), 3.0) << a << " vs " << b;
  }
}

TEST_F(RealPipeline, SelfMatchIsIdentity) {
  const LoopResult r = pipeline_->match(fp("00/000052"), fp("00/000052"));
  ASSERT_TRUE(r.is_loop) << r.reason;
  EXPECT_LT((r.T.block(0, 3, 3, 1).norm()), 1e-3) << r.T;
  EXPECT_LT(rotationErrorDeg(r.T, Mat4d::Identity()), 0.01);
  EXPECT_DOUBLE_EQ(r.background_similarity, 1.0);
}

TEST_F(RealPipeline, RepeatedRunsBitIdentical) {
  const LoopResult a = pipeline_->match(fp("00/000052"), fp("00/004501"));
  const LoopResult b = pipeline_->match(fp("00/000052"), fp("00/004501"));
  EXPECT_TRUE(identical(a, b));
  EXPECT_TRUE((a.T.array() == b.T.array()).all());
  EXPECT_EQ(a.score, b.score);
  // A second Pipeline object with the same config agrees too.
  const Pipeline other;
  EXPECT_TRUE(identical(a, other.match(fp("00/000052"), fp("00/004501"))));
}

TEST_F(RealPipeline, FingerprintIsDeterministic) {
  const std::string dir = test::scansDir() + "/sequences/00";
  const Fingerprint again =
      pipeline_->fingerprint(readScan(dir + "/velodyne/004501.bin", dir + "/labels/004501.label"));
  EXPECT_EQ(serialize(again), serialize(fp("00/004501")));
}

TEST_F(RealPipeline, SerializedFingerprintsGiveIdenticalResult) {
  const Fingerprint a = deserialize(serialize(fp("00/000052")));
  const Fingerprint b = deserialize(serialize(fp("00/004501")));
  const LoopResult original = pipeline_->match(fp("00/000052"), fp("00/004501"));
  const LoopResult loaded = pipeline_->match(a, b);
  EXPECT_TRUE(identical(original, loaded));
  EXPECT_TRUE((original.T.array() == loaded.T.array()).all());
  EXPECT_EQ(original.score, loaded.score);
  // Mixed: a loaded query against an original candidate.
  EXPECT_TRUE(identical(original, pipeline_->match(a, fp("00/004501"))));
}

TEST_F(RealPipeline, ConcurrentMatchesIdentical) {
  const LoopResult expected = pipeline_->match(fp("00/000052"), fp("00/004501"));
  ASSERT_TRUE(expected.is_loop);
  constexpr int kThreads = 4;
  std::vector<LoopResult> results(kThreads);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t)
    threads.emplace_back([&, t] { results[t] = pipeline_->match(fp("00/000052"), fp("00/004501")); });
  for (auto& th : threads) th.join();
  for (int t = 0; t < kThreads; ++t) EXPECT_TRUE(identical(results[t], expected)) << "thread " << t;
}

// ---- Synthetic scenes: ground truth by construction ----

TEST(SyntheticPipeline, TwoViewsOfTheSameStreet) {
  const LabelledScan world = test::makeStreetWorld();
  const Mat4d pose_a = test::makeT(0.0, 0.0, 0.0, 0.0);
  const Mat4d pose_b = test::makeT(25.0, 4.0, 1.5, 0.0);
  const Mat4d T_a_b = pose_a.inverse() * pose_b;  // p_a = T_a_b * p_b
  const Pipeline p;
  const Fingerprint a = p.fingerprint(test::viewFrom(world, pose_a));
  const Fingerprint b = p.fingerprint(test::viewFrom(world, pose_b));
  const LoopResult r = p.match(a, b);
  expectSane(r);
  ASSERT_TRUE(r.is_loop) << r.reason;
  EXPECT_LT(translationError(r.T, T_a_b), 0.05) << r.T;
  EXPECT_LT(rotationErrorDeg(r.T, T_a_b), 0.3) << r.T;
  // The inlier node pairs are the same physical objects: their centres agree under the true pose.
  for (const auto& [i, j] : r.inlier_pairs)
    EXPECT_LT((test::apply(T_a_b, b.nodes[j].center) - a.nodes[i].center).norm(), 0.3) << i << "," << j;
}

// Building against vegetation is evidence only between views whose classes were given: once either view's
// classes are the built-in labeller's (labeller_structure), verification compares structure against road. Here
// the candidate's structure classes are swapped (building <-> vegetation), as an unrepeatable labeller may.
TEST(SyntheticPipeline, LabellerClassesAreComparedAsStructure) {
  const LabelledScan world = test::makeStreetWorld();
  const Pipeline p;
  const Fingerprint a = p.fingerprint(test::viewFrom(world, test::makeT(0.0, 0.0, 0.0, 0.0)));
  const Fingerprint b = p.fingerprint(test::viewFrom(world, test::makeT(25.0, 4.0, 1.5, 0.0)));
  const LoopResult given = p.verify(a, b);
  ASSERT_TRUE(given.is_loop) << given.reason;
  Fingerprint swapped = b;
  int changed = 0;
  for (auto& c : swapped.background) {
    const auto building = static_cast<std::uint8_t>(Background::kBuilding),
               vegetation = static_cast<std::uint8_t>(Background::kVegetation);
    if (c.cls == building || c.cls == vegetation) {
      c.cls = c.cls == building ? vegetation : building;
      ++changed;
    }
  }
  ASSERT_GT(changed, 50);
  const LoopResult compared = p.verify(a, swapped);
  EXPECT_LT(compared.background_similarity, given.background_similarity - 0.3);
  EXPECT_FALSE(compared.is_loop);
  for (const bool query_side : {false, true}) {
    Fingerprint q = a, c = swapped;
    (query_side ? q : c).labeller_structure = true;
    const LoopResult merged = p.verify(q, c);
    EXPECT_TRUE(merged.is_loop) << merged.reason;
    EXPECT_GE(merged.background_similarity, given.background_similarity);
  }
}

// The guards of the fine and plane stages are parameters: a stage whose move exceeds its limit is dropped and
// the coarse pose stays; with the default limits each stage moves it. (Verification's own plane alignment is
// off here, so that the pose it hands on is RANSAC's.)
TEST(SyntheticPipeline, StageGuardsAreParameters) {
  const LabelledScan world = test::makeStreetWorld();
  Config base;
  base.verify.fit_max_shift_m = 0;
  base.verify.min_probability = 0.0;  // without the plane fit p stays under the default bar; not under test here
  const Pipeline p(base);
  const Fingerprint a = p.fingerprint(test::viewFrom(world, test::makeT(0.0, 0.0, 0.0, 0.0)));
  const Fingerprint b = p.fingerprint(test::viewFrom(world, test::makeT(25.0, 4.0, 1.5, 0.0)));
  const LoopResult coarse = p.verify(a, b);
  ASSERT_TRUE(coarse.is_loop) << coarse.reason;
  auto poseWith = [&](const std::function<void(Config&)>& edit) {
    Config c = base;
    edit(c);
    return Pipeline(c).match(a, b).T;
  };
  const auto same = [&](const Mat4d& T) { return (T.array() == coarse.T.array()).all(); };
  EXPECT_FALSE(same(poseWith([](Config& c) { c.refine.enabled = false; })));
  EXPECT_TRUE(same(poseWith([](Config& c) {
    c.refine.enabled = false;
    c.fine.max_shift_m = 1e-9;
  })));
  EXPECT_TRUE(same(poseWith([](Config& c) {
    c.refine.enabled = false;
    c.fine.max_turn_deg = 1e-9;
  })));
  EXPECT_FALSE(same(poseWith([](Config& c) { c.fine.enabled = false; })));
  EXPECT_TRUE(same(poseWith([](Config& c) {
    c.fine.enabled = false;
    c.refine.max_shift_m = 1e-9;
  })));
}

// A street with 22 poles; `jitter` moves each pole by that much in a seeded direction, as a segmentation
// network's errors move cluster centres between two visits.
LabelledScan poleStreet(double jitter) {
  LabelledScan w;
  std::mt19937 rng(11), shift(99);
  std::uniform_real_distribution<double> u(-1.0, 1.0), angle(0.0, 2.0 * std::numbers::pi);
  test::addPoints(w, test::makeFloor(-45, 45, -7, 7, -1.7, 0.4), test::kRoad);
  test::addPoints(w, test::makeWall(-45, 9, 45, 9, -1.7, 6, 0.4), test::kBuilding);
  test::addPoints(w, test::makeWall(-45, -12, 45, -12, -1.7, 6, 0.4), test::kBuilding);
  test::addPoints(w, test::makeWall(-20, -30, -20, 30, -1.7, 6, 0.4), test::kFence);
  for (int k = 0; k < 22; ++k) {
    const double a = angle(shift);
    const double x = -40 + k * 3.9 + 1.0 * u(rng) + jitter * std::cos(a);
    const double y = (k % 2 ? 7.0 : -7.5) + 0.8 * u(rng) + jitter * std::sin(a);
    test::addPoints(w, test::makePole(x, y, -1.7, 3.0 + u(rng)), test::kPole);
  }
  return w;
}

// When triangle pruning rejects every match of a true loop (here each landmark moved by 0.3 m between the
// visits and a triangle tolerance of 3 cm, so hardly any local triangle agrees), RANSAC gets the unpruned matches
// (match.prune_min_kept).
TEST(SyntheticPipeline, PruningThatKeepsTooFewFallsBackToAllMatches) {
  const Mat4d T_a_b = test::makeT(2.0, 3.0, 0.5, 0.0);
  const LabelledScan a_scan = poleStreet(0.0);
  const LabelledScan b_scan = test::viewFrom(poleStreet(0.3), T_a_b);
  Config fallback;
  fallback.match.triangle_tol = 0.03;
  Config strict = fallback;
  strict.match.prune_min_kept = 0;  // the reference: whatever pruning keeps
  const Pipeline p_strict(strict), p(fallback);
  const Fingerprint a = p.fingerprint(a_scan), b = p.fingerprint(b_scan);
  const LoopResult rs = p_strict.verify(a, b, /*background=*/false);
  ASSERT_LT(rs.matches, 3) << "pruning should reject the jittered matches";
  EXPECT_FALSE(rs.is_loop);
  const LoopResult r = p.match(a, b);
  EXPECT_GE(r.matches, 15);
  ASSERT_TRUE(r.is_loop) << r.reason;
  EXPECT_LT(translationError(r.T, T_a_b), 0.05) << r.T;
  EXPECT_LT(rotationErrorDeg(r.T, T_a_b), 0.3) << r.T;
}

// The score is the loop model's probability, and a pair is a loop exactly when it reaches
// verify.min_probability.
TEST(SyntheticPipeline, TheDecisionIsTheProbabilityAgainstItsBar) {
  const LabelledScan world = test::makeStreetWorld();
  const Pipeline p;
  const Fingerprint q = p.fingerprint(test::viewFrom(world, Mat4d::Identity()));
  const Fingerprint c = p.fingerprint(test::viewFrom(world, test::makeT(1.0, 8.0, 0.5, 0.0)));
  const LoopResult r = p.verify(q, c);
  ASSERT_TRUE(r.is_loop) << r.reason;
  EXPECT_EQ(r.score, r.probability);
  EXPECT_GT(r.probability, 0.0);
  EXPECT_LT(r.probability, 1.0);
  EXPECT_EQ(r.probability, p.model().probability(r.evidence));
  ASSERT_FALSE(r.considered.empty());
  for (const auto& h : r.considered) EXPECT_LE(h.probability, r.probability);
  for (const double bar : {r.probability, std::nextafter(r.probability, 1.0)}) {
    Config c2;
    c2.verify.min_probability = bar;
    EXPECT_EQ(Pipeline(c2).verify(q, c).is_loop, bar == r.probability) << bar;
  }
}

// The street world with facades across it (a cross street's corners), so that its planes fix the position
// along the street too.
LabelledScan streetWithCrossFacades() {
  LabelledScan world = test::makeStreetWorld();
  test::addPoints(world, test::makeWall(30, -12, 30, -20, -1.7, 6, 0.4), test::kBuilding);
  test::addPoints(world, test::makeWall(30, 9, 30, 20, -1.7, 6, 0.4), test::kBuilding);
  test::addPoints(world, test::makeWall(-25, 9, -25, 20, -1.7, 6, 0.4), test::kBuilding);
  return world;
}

// The planes speak for or against every hypothesis. The candidate below shows the same street with both facades
// moved 0.8 m towards its middle: the nodes still agree, but no rigid motion fits both facades' planes, so the
// plane evidence is weaker than for the same street and so is the probability.
TEST(SyntheticPipeline, PlanesThatDoNotFitLowerTheProbability) {
  const LabelledScan world = streetWithCrossFacades();
  LabelledScan squeezed = world;
  for (std::size_t i = 0; i < squeezed.points.size(); ++i)
    if (squeezed.labels[i] == test::kBuilding) squeezed.points[i].y() += squeezed.points[i].y() > 0 ? -0.8f : 0.8f;
  const Mat4d T = test::makeT(1.0, 2.0, 0.5, 0.0);
  const Pipeline p;
  const Fingerprint fq = p.fingerprint(test::viewFrom(world, Mat4d::Identity()));
  const Fingerprint fc = p.fingerprint(test::viewFrom(world, T));
  const Fingerprint fs = p.fingerprint(test::viewFrom(squeezed, T));
  const LoopResult same = p.verify(fq, fc);
  EXPECT_TRUE(same.is_loop) << same.reason;
  const LoopResult squeezed_loop = p.verify(fq, fs);
  EXPECT_EQ(static_cast<int>(squeezed_loop.inlier_pairs.size()), squeezed_loop.inliers);
  const auto &e = same.evidence, &s = squeezed_loop.evidence;
  EXPECT_GT(e.plane_overlap * (1.0 / (1.0 + std::pow(e.plane_rmse_m / 0.05, 2))),
            s.plane_overlap * (1.0 / (1.0 + std::pow(s.plane_rmse_m / 0.05, 2))));
  EXPECT_LT(squeezed_loop.probability, same.probability);
}

// Planes of a straight street (facades along it only) fit at any shift along it, so they cannot pin a loop's
// position: the horizontal constraint is near 0 there and well above it once cross facades pin the shift, and
// the probability follows.
TEST(SyntheticPipeline, AStraightStreetPinsLessThanACrossing) {
  const Mat4d T = test::makeT(1.0, 2.0, 0.5, 0.0);
  const Pipeline p;
  auto judged = [&](const LabelledScan& world) {
    const Fingerprint fq = p.fingerprint(test::viewFrom(world, Mat4d::Identity()));
    const Fingerprint fc = p.fingerprint(test::viewFrom(world, T));
    return p.verify(fq, fc);
  };
  const LoopResult in_corridor = judged(test::makeStreetWorld());
  const LoopResult at_crossing = judged(streetWithCrossFacades());
  EXPECT_LT(in_corridor.evidence.constraint, 0.5);
  EXPECT_GT(at_crossing.evidence.constraint, 4.0);
  EXPECT_TRUE(at_crossing.is_loop) << at_crossing.reason;
  EXPECT_LT(in_corridor.probability, at_crossing.probability);
}

// The street's road and facades only (its landmarks, fence and vegetation removed), with bushes at irregular
// places along it or without them.
LabelledScan corridor(bool bushes) {
  const LabelledScan street = test::makeStreetWorld();
  LabelledScan out;
  for (std::size_t i = 0; i < street.points.size(); ++i)
    if (street.labels[i] == test::kRoad || street.labels[i] == test::kBuilding) {
      out.points.push_back(street.points[i]);
      out.labels.push_back(street.labels[i]);
    }
  if (bushes)
    for (const auto& [x, y] :
         std::vector<std::pair<double, double>>{{-33, 7.9}, {-21, -9.6}, {-4, 7.9}, {6, -9.6}, {17, -9.6}, {29, 7.9}})
      test::addPoints(out, test::makeBoxSurface({x, y, -0.9}, {1.5, 0.8, 0.8}, 0.0, 0.2), test::kVegetation);
  return out;
}

// A background-only hypothesis in a corridor: the street's landmarks, fence and vegetation removed, its facades
// run along x, so the planes leave the shift along the street free (horizontal constraint near 0, weak_shift
// along x). Bushes at irregular places along it pin that shift in the bird's-eye view: the agreement falls when
// the overlay moves 2 or 4 m along the street (the evidence's pin), the most probable hypothesis is the place, and
// it is more probable than the plain street's. A street of facades alone looks the same at every shift along it:
// no pin, and no loop. (With landmarks and fence removed the bushes street does not reach the default bar.)
TEST(SyntheticPipeline, ACorridorIsPinnedByWhatChangesAlongIt) {
  // 3 m along the street and a 15 deg turn, so that the frames differ: probing in the candidate's frame instead
  // of the query's fails this test (tried).
  const Mat4d T = test::makeT(15.0, 3.0, 0.4, 0.0);
  const Pipeline p;
  double pins[2] = {0, 0}, probabilities[2] = {0, 0};
  for (const bool plain : {false, true}) {
    SCOPED_TRACE(plain ? "facades only" : "facades and bushes");
    const LabelledScan world = corridor(!plain);
    const Fingerprint fq = p.fingerprint(test::viewFrom(world, Mat4d::Identity()));
    const Fingerprint fc = p.fingerprint(test::viewFrom(world, T));
    ASSERT_TRUE(fq.nodes.empty());
    const auto planes =
        refinePlanes(fq.planes, *planeIndexOf(fq, p.config().refine.max_corr_m), fc.planes, {}, T, p.config().refine);
    EXPECT_LT(planes.horizontal_constraint, 0.5);
    EXPECT_NEAR(std::abs(planes.weak_shift.x()), 1.0, 0.01) << planes.weak_shift.transpose();
    const LoopResult r = p.match(fq, fc);
    double best_pin = -1.0;
    const LoopResult::Judged* best = nullptr;
    for (const auto& h : r.considered) {
      best_pin = std::max(best_pin, h.evidence.pin);
      if (!best || h.probability > best->probability) best = &h;
    }
    pins[plain] = best_pin;
    probabilities[plain] = r.probability;
    if (plain) {
      EXPECT_FALSE(r.is_loop) << "a street that looks the same at every shift along it was pinned";
      continue;
    }
    // The most probable hypothesis is the place, from the walls' overlay.
    ASSERT_NE(best, nullptr);
    EXPECT_EQ(best->evidence.source, PoseSource::kWallHeadings);
    EXPECT_EQ(best->evidence.landmarks, 0);
    EXPECT_LT(translationError(best->T, T), 0.3) << best->T;
    EXPECT_LT(rotationErrorDeg(best->T, T), 0.5) << best->T;
  }
  EXPECT_GT(probabilities[0], probabilities[1]);
  EXPECT_GT(pins[0], pins[1] + 0.05);
}

// A known loop in the same corridor that verification refuses (no probability reaches 1): the pose comes from
// the background overlays and the plane stage, and must land at the place although the facades fit at any shift
// along the street. (Here plane fitness alone would also find it; the pairs where it did not, on a street whose
// facades repeat, need the simulator: Revisit.KnownLoopsOnARepeatedStreetArePosedAtThePlace.)
TEST(SyntheticPipeline, AKnownLoopInACorridorIsPosedAtThePlace) {
  const Mat4d T = test::makeT(15.0, 3.0, 0.4, 0.0);
  Config off;
  off.verify.min_probability = 1.0;
  const Pipeline p(off);
  const LabelledScan world = corridor(true);
  const Fingerprint fq = p.fingerprint(test::viewFrom(world, Mat4d::Identity()));
  const Fingerprint fc = p.fingerprint(test::viewFrom(world, T));
  LoopResult r = p.verify(fq, fc);
  ASSERT_FALSE(r.is_loop);
  p.refine(fq, fc, r, /*known_loop=*/true);
  ASSERT_TRUE(r.refined);
  EXPECT_LT(translationError(r.T, T), 0.3) << r.T;
  EXPECT_LT(rotationErrorDeg(r.T, T), 0.5) << r.T;
}

LabelledScan emptyScan() { return {}; }

LabelledScan noLandmarks() {
  LabelledScan s;
  test::addPoints(s, test::makeFloor(-20, 20, -8, 8, -1.7, 0.5), test::kRoad);
  test::addPoints(s, test::makeWall(-20, 9, 20, 9, -1.7, 5, 0.4), test::kBuilding);
  test::addPoints(s, test::makePole(5, 3, -1.7, 3), test::kUnlabelled);
  return s;
}

LabelledScan noBackground() {
  LabelledScan s;
  for (int k = 0; k < 8; ++k)
    test::addPoints(s, test::makePole(-20 + 5.5 * k, (k % 2 ? 6.0 : -5.0) + 0.3 * k, -1.7, 3), test::kPole);
  test::addPoints(s, test::makeBoxSurface({3, 2, -1}, {2, 0.9, 0.7}, 10, 0.1), test::kCar);
  return s;
}

LabelledScan allOneClass() {
  LabelledScan s;
  // Every point a pole, everywhere (a scan labelled by a broken network).
  for (int k = 0; k < 6; ++k)
    test::addPoints(s, test::makeFloor(-30 + 10 * k, -25 + 10 * k, -5, 5, -1.7 + 0.3 * k, 0.5), test::kPole);
  return s;
}

LabelledScan allRoad() {
  LabelledScan s;
  test::addPoints(s, test::makeFloor(-30, 30, -30, 30, -1.7, 0.5), test::kRoad);
  return s;
}

LabelledScan singlePoint() {
  LabelledScan s;
  s.points.emplace_back(3.0f, 4.0f, -1.0f);
  s.labels.push_back(test::kPole);
  return s;
}

LabelledScan pointAtOrigin() {
  LabelledScan s;
  for (int k = 0; k < 20; ++k) {
    s.points.emplace_back(0.0f, 0.0f, 0.0f);
    s.labels.push_back(k % 2 ? test::kPole : test::kRoad);
  }
  return s;
}

TEST(SyntheticPipeline, EdgeCaseScans) {
  const Pipeline p;
  const Fingerprint street = p.fingerprint(test::viewFrom(test::makeStreetWorld(), Mat4d::Identity()));
  const std::pair<const char*, LabelledScan> cases[] = {
      {"empty", emptyScan()},
      {"no landmarks", noLandmarks()},
      {"no road/building", noBackground()},
      {"all one class", allOneClass()},
      {"all road", allRoad()},
      {"single point", singlePoint()},
      {"points at the origin", pointAtOrigin()},
  };
  for (const auto& [name, scan] : cases) {
    SCOPED_TRACE(name);
    Fingerprint fp;
    ASSERT_NO_THROW(fp = p.fingerprint(scan));
    EXPECT_EQ(static_cast<int>(fp.descriptor.size()), fp.layout.scanDim());
    for (float v : fp.descriptor) ASSERT_TRUE(std::isfinite(v));
    EXPECT_TRUE(fp.node_descriptors.allFinite());
    EXPECT_EQ(fp.num_points, scan.points.size());
    const Fingerprint& f = fp;
    const std::pair<const Fingerprint*, const Fingerprint*> combos[] = {{&f, &f}, {&f, &street}, {&street, &f}};
    for (const auto& [q, c] : combos) {
      LoopResult r;
      ASSERT_NO_THROW(r = p.match(*q, *c));
      expectSane(r);
      if (q == c && name == std::string("no landmarks")) {
        // Against itself: its wall's ends pin the pose along the wall, a loop from the background alone at the
        // identity.
        EXPECT_TRUE(r.is_loop) << r.reason;
        EXPECT_EQ(r.inliers, 0);
        EXPECT_LT((r.T - Mat4d::Identity()).cwiseAbs().maxCoeff(), 0.01) << r.T;
      } else {
        EXPECT_FALSE(r.is_loop) << r.score;
      }
    }
    // And through serialisation.
    EXPECT_NO_THROW(deserialize(serialize(fp)));
  }
}

TEST(SyntheticPipeline, InvalidInput) {
  const Pipeline p;
  LabelledScan s = noBackground();
  s.labels.pop_back();
  EXPECT_THROW(p.fingerprint(s), InputError);
  s = noBackground();
  s.points[10].x() = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(p.fingerprint(s), InputError);
  s = noBackground();
  s.points[3].z() = std::numeric_limits<float>::infinity();
  EXPECT_THROW(p.fingerprint(s), InputError);
}

TEST(SyntheticPipeline, InvalidConfigRejected) {
  Config c;
  c.verify.min_probability = 2.0;
  EXPECT_THROW(Pipeline{c}, InputError);
  Config model;
  model.verify.model = "/nonexistent/loop_model.txt";
  EXPECT_THROW(Pipeline{model}, InputError);
  Config roles;
  roles.labels.road.push_back(80);  // pole and road
  EXPECT_THROW(Pipeline{roles}, InputError);
}

TEST(SyntheticPipeline, DifferentGeometryRejected) {
  const LabelledScan scan = test::viewFrom(test::makeStreetWorld(), Mat4d::Identity());
  const Pipeline p;
  Config c;
  c.graph.d_max = 50;
  const Pipeline q(c);
  const Fingerprint a = p.fingerprint(scan), b = q.fingerprint(scan);
  EXPECT_THROW(p.verify(a, b), InputError);
  EXPECT_THROW(p.match(b, a), InputError);
}

TEST(SyntheticPipeline, CustomLabelSet) {
  // Two node classes with custom ids: the descriptors follow the class count.
  Config c;
  c.labels.node_classes = {{"post", {1}}, {"box", {2}}};
  c.labels.road = {3};
  c.labels.building = {4};
  c.labels.fence = {};
  c.labels.vegetation = {};
  const Pipeline p(c);
  LabelledScan s;
  for (int k = 0; k < 6; ++k) test::addPoints(s, test::makePole(-15 + 6.0 * k, k % 2 ? 5.0 : -5.0, -1.7, 3), 1);
  test::addPoints(s, test::makeBoxSurface({4, 1, -1}, {2, 0.9, 0.7}, 0, 0.1), 2);
  test::addPoints(s, test::makeFloor(-20, 20, -8, 8, -1.7, 0.5), 3);
  const Fingerprint fp = p.fingerprint(s);
  EXPECT_EQ(fp.layout.num_classes, 2);
  EXPECT_EQ(static_cast<int>(fp.descriptor.size()), 2 + 3 * 30 + 48);
  EXPECT_EQ(fp.nodes.size(), 7u);
  int boxes = 0;
  for (const auto& n : fp.nodes) boxes += n.cls == 1;
  EXPECT_EQ(boxes, 1);
}

}  // namespace
}  // namespace sglc
