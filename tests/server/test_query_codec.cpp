// The server's answer codec: every loop answer carries the loop model's probability, and with include_evidence
// its evidence record, field for field (rejected candidates too).
#include <gtest/gtest.h>

#include "evidence_codec.hpp"
#include "query_codec.hpp"

namespace sglc::server {
namespace {

closing::FoundLoop found(bool is_loop, double probability) {
  closing::FoundLoop f;
  f.scan_id = 42;
  f.robot = "r";
  f.session = "s";
  f.seq = 7;
  f.result.is_loop = is_loop;
  f.result.reason = is_loop ? "" : "loop probability below verify.min_probability; weakest evidence: pin";
  f.result.probability = probability;
  f.result.score = 0.25;
  auto& e = f.result.evidence;
  e.source = PoseSource::kWallHeadings;
  e.landmarks = 9;
  e.landmark_similarity = 0.5;
  e.field_deg = 270.0;
  e.agreement = 0.61;
  e.wide_agreement = 0.52;
  e.pin = 0.125;
  e.plane_overlap = 0.75;
  e.plane_rmse_m = 0.0625;
  e.constraint = 3.5;
  e.context_similarity = 0.875;
  e.translation_m = 4.25;
  return f;
}

TEST(QueryCodec, ProbabilityAlwaysEvidenceOnRequest) {
  google::protobuf::RepeatedPtrField<v1::Candidate> plain, full;
  toWire({found(true, 0.9375), found(false, 0.125)}, &plain, false);
  toWire({found(true, 0.9375), found(false, 0.125)}, &full, true);
  ASSERT_EQ(plain.size(), 2);
  ASSERT_EQ(full.size(), 2);
  EXPECT_TRUE(plain[0].has_probability());
  EXPECT_EQ(plain[0].probability(), 0.9375);
  EXPECT_EQ(plain[1].probability(), 0.125);
  EXPECT_FALSE(plain[0].has_evidence());
  EXPECT_FALSE(plain[1].verified());
  // The rejected one says why, with or without its evidence; a loop has no reason.
  EXPECT_EQ(plain[0].reason(), "");
  EXPECT_EQ(plain[1].reason(), "loop probability below verify.min_probability; weakest evidence: pin");
  for (const auto& c : full) {  // the rejected candidate carries its evidence as the loop does
    ASSERT_TRUE(c.has_evidence());
    const auto& e = c.evidence();
    EXPECT_EQ(e.source(), v1::EVIDENCE_SOURCE_WALLS);
    EXPECT_EQ(e.landmarks(), 9);
    EXPECT_EQ(e.landmark_similarity(), 0.5);
    EXPECT_EQ(e.field_deg(), 270.0);
    EXPECT_EQ(e.agreement(), 0.61);
    EXPECT_EQ(e.wide_agreement(), 0.52);
    EXPECT_EQ(e.pin(), 0.125);
    EXPECT_EQ(e.plane_overlap(), 0.75);
    EXPECT_EQ(e.plane_rmse_m(), 0.0625);
    EXPECT_EQ(e.constraint(), 3.5);
    EXPECT_EQ(e.context_similarity(), 0.875);
    EXPECT_EQ(e.translation_m(), 4.25);
  }
  // Through the bytes and back: the fields survive serialisation.
  v1::Candidate back;
  ASSERT_TRUE(back.ParseFromString(full[1].SerializeAsString()));
  EXPECT_EQ(back.probability(), 0.125);
  EXPECT_EQ(back.evidence().translation_m(), 4.25);
  EXPECT_EQ(back.evidence().source(), v1::EVIDENCE_SOURCE_WALLS);
}

TEST(QueryCodec, EverySourceHasItsOwnWireValue) {
  EXPECT_EQ(toWire(PoseSource::kNone), v1::EVIDENCE_SOURCE_NONE);
  EXPECT_EQ(toWire(PoseSource::kLandmarks), v1::EVIDENCE_SOURCE_LANDMARKS);
  EXPECT_EQ(toWire(PoseSource::kConsensus), v1::EVIDENCE_SOURCE_CONSENSUS);
  EXPECT_EQ(toWire(PoseSource::kWallHeadings), v1::EVIDENCE_SOURCE_WALLS);
  EXPECT_EQ(toWire(PoseSource::kViewHeadings), v1::EVIDENCE_SOURCE_VIEW);
}

TEST(QueryCodec, IncludeEvidenceIsAnOptionOfItsOwn) {
  v1::QueryOptions o;
  o.set_include_evidence(true);
  v1::QueryOptions back;
  ASSERT_TRUE(back.ParseFromString(o.SerializeAsString()));
  EXPECT_TRUE(back.include_evidence());
  EXPECT_FALSE(v1::QueryOptions().include_evidence());
}

}  // namespace
}  // namespace sglc::server
