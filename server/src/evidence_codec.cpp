// The evidence record -> its message, field by field; the source as an enum of the wire's own, so that a new
// engine source is a deliberate change of the contract rather than a renumbering.
#include "evidence_codec.hpp"

namespace sglc::server {

v1::EvidenceSource toWire(PoseSource source) {
  switch (source) {
    case PoseSource::kLandmarks:
      return v1::EVIDENCE_SOURCE_LANDMARKS;
    case PoseSource::kConsensus:
      return v1::EVIDENCE_SOURCE_CONSENSUS;
    case PoseSource::kWallHeadings:
      return v1::EVIDENCE_SOURCE_WALLS;
    case PoseSource::kViewHeadings:
      return v1::EVIDENCE_SOURCE_VIEW;
    case PoseSource::kNone:
      break;
  }
  return v1::EVIDENCE_SOURCE_NONE;
}

void toWire(const Evidence& e, v1::Evidence* out) {
  out->set_source(toWire(e.source));
  out->set_landmarks(e.landmarks);
  out->set_landmark_similarity(e.landmark_similarity);
  out->set_field_deg(e.field_deg);
  out->set_agreement(e.agreement);
  out->set_wide_agreement(e.wide_agreement);
  out->set_pin(e.pin);
  out->set_plane_overlap(e.plane_overlap);
  out->set_plane_rmse_m(e.plane_rmse_m);
  out->set_constraint(e.constraint);
  out->set_context_similarity(e.context_similarity);
  out->set_translation_m(e.translation_m);
}

}  // namespace sglc::server
