// The loop model (sglc/loop_model.hpp) and the evidence record it reads (sglc/evidence.hpp).
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <sstream>
#include <string>

#include "sglc/evidence.hpp"
#include "sglc/loop_model.hpp"
#include "sglc/pipeline.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

// A valid model text with every feature at `w` (signed as each feature demands) and the given extra lines.
std::string modelText(double w = 1.0, const std::string& extra = "") {
  std::ostringstream text;
  text << "# test\nsglc-loop-model 1\nversion t-1\nbias -3\n";
  for (const auto& f : modelFeatures()) text << f.name << " " << (f.sign < 0 ? -w : w) << "\n";
  return text.str() + extra;
}

std::string errorOf(const std::string& text) {
  try {
    LoopModel::parse(text, "m.txt");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(LoopModel, BuiltInModelParsesAndHasAVersion) {
  const LoopModel m = LoopModel::builtIn();
  EXPECT_FALSE(m.version().empty());
  EXPECT_EQ(m.curves().size(), modelFeatures().size());
  EXPECT_EQ(featureValues(Evidence{}).size(), modelFeatures().size());
}

TEST(LoopModel, ParsesAndComputesTheLogistic) {
  const LoopModel m = LoopModel::parse(modelText(0.5), "m.txt");
  EXPECT_EQ(m.version(), "t-1");
  EXPECT_EQ(m.bias(), -3.0);
  Evidence e;
  e.source = PoseSource::kLandmarks;
  e.landmarks = 6;
  e.agreement = 0.7;
  e.translation_m = 4.0;
  double z = -3.0;
  const auto x = featureValues(e);
  for (std::size_t k = 0; k < x.size(); ++k) z += m.curves()[k].slope * x[k];
  EXPECT_NEAR(m.probability(e), 1.0 / (1.0 + std::exp(-z)), 1e-15);
  // No hypothesis: no probability; evidence that is not a number gives none either, never NaN.
  EXPECT_EQ(m.probability(Evidence{}), 0.0);
  e.translation_m = std::nan("");
  EXPECT_EQ(m.probability(e), 0.0);
}

// The weights' signs make p monotone: more of what speaks for a loop never lowers it, a longer translation never
// raises it.
TEST(LoopModel, MoreEvidenceNeverLowersTheProbability) {
  const LoopModel m = LoopModel::builtIn();
  Evidence base;
  base.source = PoseSource::kLandmarks;
  base.landmarks = 3;
  base.landmark_similarity = 0.5;
  base.agreement = 0.4;
  base.wide_agreement = 0.4;
  base.plane_overlap = 0.4;
  base.plane_rmse_m = 0.05;
  base.constraint = 2.0;
  base.translation_m = 5.0;
  const double p = m.probability(base);
  auto more = [&](auto edit) {
    Evidence e = base;
    edit(e);
    return m.probability(e);
  };
  EXPECT_GE(more([](Evidence& e) { e.landmarks = 10; }), p);
  EXPECT_GE(more([](Evidence& e) { e.agreement = 0.8; }), p);
  EXPECT_GE(more([](Evidence& e) { e.wide_agreement = 0.8; }), p);
  EXPECT_GE(more([](Evidence& e) { e.plane_overlap = 0.9; }), p);
  EXPECT_GE(more([](Evidence& e) { e.plane_rmse_m = 0.01; }), p);
  EXPECT_GE(more([](Evidence& e) { e.constraint = 20.0; }), p);
  EXPECT_GE(more([](Evidence& e) { e.pin = 0.1; }), p);
  EXPECT_LE(more([](Evidence& e) { e.translation_m = 9.0; }), p);
}

TEST(LoopModel, BadFilesAreRefusedWithTheLineAndTheReason) {
  EXPECT_NE(errorOf("").find("empty"), std::string::npos);
  EXPECT_NE(errorOf("sglc-loop-model 3\n").find("line 1: not an sglc loop model"), std::string::npos);
  EXPECT_NE(errorOf(modelText(1.0, "wings 3\n")).find("unknown feature 'wings'"), std::string::npos);
  EXPECT_NE(errorOf(modelText(1.0, "agreement 3\n")).find("feature agreement given twice"), std::string::npos);
  EXPECT_NE(errorOf(modelText(1.0, "bias 1\n")).find("bias given twice"), std::string::npos);
  std::string text = modelText();
  text.replace(text.find("agreement 1"), 11, "agreement -1");
  EXPECT_NE(errorOf(text).find("weight of agreement must be >= 0"), std::string::npos) << errorOf(text);
  text = modelText();
  text.replace(text.find("translation -1"), 14, "translation 1");
  EXPECT_NE(errorOf(text).find("weight of translation must be <= 0"), std::string::npos);
  text = modelText();
  text.replace(text.find("pin 1"), 5, "pin nan");
  EXPECT_NE(errorOf(text).find("not a number within +-1e6"), std::string::npos);
  text = modelText();
  text.replace(text.find("pin 1"), 5, "pin 1x");
  EXPECT_NE(errorOf(text).find("not a number within +-1e6"), std::string::npos);
  text = modelText();
  text.replace(text.find("pin 1"), 5, "pin 2e6");
  EXPECT_NE(errorOf(text).find("not a number within +-1e6"), std::string::npos);
  text = modelText();
  text.erase(text.find("pin 1\n"), 6);
  EXPECT_NE(errorOf(text).find("feature pin has no weight"), std::string::npos);
  text = modelText();
  text.erase(text.find("version t-1\n"), 12);
  EXPECT_NE(errorOf(text).find("no 'version' line"), std::string::npos);
  EXPECT_NE(errorOf(modelText(1.0, "pin\n")).find("expected 'NAME VALUE'"), std::string::npos);
  EXPECT_NE(errorOf(modelText(1.0, "bias 1 2\n")).find("expected 'bias VALUE'"), std::string::npos);
}

// A curve: linear between its knots, constant beyond them; its direction must follow the feature's sign.
TEST(LoopModel, PiecewiseLinearCurves) {
  std::string text = modelText();
  text.replace(text.find("agreement 1\n"), 12, "agreement 0.2:0 0.4:1 0.6:4\n");
  const LoopModel m = LoopModel::parse(text, "m.txt");
  std::size_t k = 0;
  while (std::string_view(modelFeatures()[k].name) != "agreement") ++k;
  const auto& c = m.curves()[k];
  EXPECT_EQ(c(0.0), 0.0);
  EXPECT_EQ(c(0.2), 0.0);
  EXPECT_NEAR(c(0.3), 0.5, 1e-12);
  EXPECT_NEAR(c(0.5), 2.5, 1e-12);
  EXPECT_EQ(c(0.6), 4.0);
  EXPECT_EQ(c(7.0), 4.0);
  EXPECT_EQ(c(std::nan("")), 0.0);  // never read past the knots
  // The model adds the curve's term: agreement 0.5 instead of 0.2 raises the log-odds by 2.5.
  Evidence e;
  e.source = PoseSource::kWallHeadings;
  e.agreement = 0.2;
  const double p0 = m.probability(e);
  e.agreement = 0.5;
  const double p1 = m.probability(e);
  EXPECT_NEAR(std::log(p1 / (1 - p1)) - std::log(p0 / (1 - p0)), 2.5, 1e-9);

  auto with = [&](const std::string& curve) {
    std::string t = modelText();
    t.replace(t.find("agreement 1\n"), 12, "agreement " + curve + "\n");
    return errorOf(t);
  };
  EXPECT_NE(with("0.2:0 0.4:1 0.3:2").find("increasing X"), std::string::npos);
  EXPECT_NE(with("0.2:0 0.2:1").find("increasing X"), std::string::npos);
  EXPECT_NE(with("0.2:0 0.4:2 0.6:1").find("must be non-decreasing"), std::string::npos) << with("0.2:0 0.4:2 0.6:1");
  EXPECT_NE(with("0.2:0").find("at least 2 knots"), std::string::npos);
  EXPECT_NE(with("0.2:0 0.4").find("not X:T"), std::string::npos);
  EXPECT_NE(with("0.2:0 0.4:inf").find("not X:T"), std::string::npos);
  EXPECT_NE(with("0.2:0 1e300:1").find("within +-1e6"), std::string::npos);
  std::string t = modelText();
  t.replace(t.find("translation -1\n"), 15, "translation 0:0 1:1\n");
  EXPECT_NE(errorOf(t).find("curve of translation must be non-increasing"), std::string::npos) << errorOf(t);
}

TEST(LoopModel, LoadsAFileAndTheEngineUsesIt) {
  test::TempDir dir;
  {
    std::ofstream out(dir.file("m.txt"));
    out << modelText(0.0);  // every weight 0: p = 1 / (1 + e^3) for every hypothesis
  }
  EXPECT_EQ(LoopModel::load("").version(), LoopModel::builtIn().version());
  EXPECT_EQ(LoopModel::load(dir.file("m.txt")).version(), "t-1");
  EXPECT_THROW(LoopModel::load(dir.file("absent.txt")), InputError);
  // Not a regular file, or too large: refused without reading it whole.
  EXPECT_THROW(LoopModel::load(dir.path().string()), InputError);
  EXPECT_THROW(LoopModel::load("/dev/zero"), InputError);
  {
    std::ofstream out(dir.file("big.txt"));
    out << modelText(0.0) << std::string(70000, '#') << "\n";
  }
  try {
    LoopModel::load(dir.file("big.txt"));
    ADD_FAILURE() << "a 70 KB model file was read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("larger than 64 KiB"), std::string::npos) << e.what();
  }
  Config c;
  c.verify.model = dir.file("m.txt");
  const Pipeline p(c);
  EXPECT_EQ(p.model().version(), "t-1");
  const LabelledScan world = test::makeStreetWorld();
  const Fingerprint a = p.fingerprint(test::viewFrom(world, Mat4d::Identity()));
  const Fingerprint b = p.fingerprint(test::viewFrom(world, test::makeT(1.0, 2.0, 0.5, 0.0)));
  const LoopResult r = p.verify(a, b);
  EXPECT_NEAR(r.probability, 1.0 / (1.0 + std::exp(3.0)), 1e-12);
  EXPECT_FALSE(r.is_loop);  // 0.047 is below the default bar
}

// The evidence at the true pose against the same pose 3 m off: the landmarks, the background and its planes all
// say less off the place.
TEST(Evidence, IsStrongerAtTheTruePose) {
  const Pipeline p;
  const LabelledScan world = test::makeStreetWorld();
  const Mat4d T = test::makeT(1.0, 2.0, 0.5, 0.0);
  const Fingerprint a = p.fingerprint(test::viewFrom(world, Mat4d::Identity()));
  const Fingerprint b = p.fingerprint(test::viewFrom(world, T));
  const PairView view = pairView(a, b, p.config());
  EXPECT_FALSE(view.narrow);
  EXPECT_GE(view.field_deg, 300.0);
  const auto planes =
      refinePlanes(a.planes, *planeIndexOf(a, p.config().refine.max_corr_m), b.planes, {}, T, p.config().refine);
  const Evidence at = measureEvidence(a, b, view, PoseSource::kLandmarks, planes.T, &planes, p.config());
  Mat4d off = T;
  off(1, 3) += 3.0;
  const Evidence away = measureEvidence(a, b, view, PoseSource::kLandmarks, off, nullptr, p.config());
  EXPECT_GT(at.landmarks, away.landmarks);
  EXPECT_GT(at.agreement, away.agreement);
  EXPECT_GT(at.wide_agreement, away.wide_agreement);
  EXPECT_GT(at.plane_overlap, 0.5);
  EXPECT_EQ(away.plane_overlap, 0.0);  // no plane fit: no plane evidence
  EXPECT_NEAR(at.translation_m, (T.topRightCorner<3, 1>().norm()), 0.05);
  EXPECT_STREQ(poseSourceName(at.source), "landmarks");
}

// Band-plane overlap is a share in [0, 1]: only planes in the band (centroid at most max_z above the sensor)
// count on either side, so a candidate's band planes matched to query planes above the band explain nothing.
TEST(Evidence, BandOverlapCountsTheBandOnBothSides) {
  Fingerprint query, candidate;
  auto wall = [](float x, float y, float z) {
    Plane p;
    p.centroid = Vec3f(x, y, z);
    p.normal = Vec3f::UnitX();
    return p;
  };
  // The query: one band plane at y = 0 and three above the band; the candidate: four band planes at the places
  // of all four (its sensor stood 3 m lower).
  query.planes = {wall(5, 0, 0), wall(5, 4, 3.5), wall(5, 8, 3.5), wall(5, 12, 3.5)};
  candidate.planes = {wall(5, 0, 0), wall(5, 4, 0.5), wall(5, 8, 0.5), wall(5, 12, 0.5)};
  RefineConfig rc;
  rc.max_corr_m = 4.0;
  Mat4d up = Mat4d::Identity();
  up(2, 3) = 3.0;                                                     // the candidate's planes at the query's heights
  EXPECT_DOUBLE_EQ(bandOverlap(query, candidate, up, 1.0, rc), 1.0);  // the one band plane of the query, explained
  // Without the lift only the plane at y = 0 meets a query band plane; the others reach planes above the band.
  EXPECT_DOUBLE_EQ(bandOverlap(query, candidate, Mat4d::Identity(), 1.0, rc), 1.0);
  query.planes[0].centroid.y() = 30;  // the query's band plane elsewhere: nothing in the band is explained
  query.plane_memo.clear();           // its planes changed: the lookup is built again
  EXPECT_DOUBLE_EQ(bandOverlap(query, candidate, Mat4d::Identity(), 1.0, rc), 0.0);
  EXPECT_DOUBLE_EQ(bandOverlap(query, candidate, up, 1.0, rc), 0.0);
}

}  // namespace
}  // namespace sglc
