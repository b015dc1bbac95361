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
  EXPECT_EQ(m.weights().size(), modelFeatures().size());
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
  for (std::size_t k = 0; k < x.size(); ++k) z += m.weights()[k] * x[k];
  EXPECT_NEAR(m.probability(e), 1.0 / (1.0 + std::exp(-z)), 1e-15);
  // No hypothesis: no probability.
  EXPECT_EQ(m.probability(Evidence{}), 0.0);
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
  EXPECT_NE(errorOf("sglc-loop-model 2\n").find("line 1: not an sglc loop model"), std::string::npos);
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
  EXPECT_NE(errorOf(text).find("not a finite number"), std::string::npos);
  text = modelText();
  text.replace(text.find("pin 1"), 5, "pin 1x");
  EXPECT_NE(errorOf(text).find("not a finite number"), std::string::npos);
  text = modelText();
  text.erase(text.find("pin 1\n"), 6);
  EXPECT_NE(errorOf(text).find("feature pin has no weight"), std::string::npos);
  text = modelText();
  text.erase(text.find("version t-1\n"), 12);
  EXPECT_NE(errorOf(text).find("no 'version' line"), std::string::npos);
  EXPECT_NE(errorOf(modelText(1.0, "pin 1 2\n")).find("expected 'NAME VALUE'"), std::string::npos);
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
  const auto planes = refinePlanes(a.planes, a.plane_index, b.planes, {}, T, p.config().refine);
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

}  // namespace
}  // namespace sglc
