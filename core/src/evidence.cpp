#include "sglc/evidence.hpp"

namespace sglc {

const char* poseSourceName(PoseSource source) {
  switch (source) {
    case PoseSource::kLandmarks:
      return "landmarks";
    case PoseSource::kConsensus:
      return "consensus";
    case PoseSource::kWallHeadings:
      return "walls";
    case PoseSource::kViewHeadings:
      return "view";
    case PoseSource::kNone:
      break;
  }
  return "none";
}

}  // namespace sglc
