// De-skewing a scan the service receives: which motion moves its points to the stamp. The sender's twist when
// it gave one; for a stored scan of a robot's run without one, the constant velocity from the session's
// previous stored scan (both with a stamp and an odometry pose, at most kMaxSweepGap apart), as a
// constant-velocity front end would. Without either the scan is left as sent and the outcome says why.
#pragma once

#include <optional>
#include <string>

#include "sglc/closing/ingestor.hpp"
#include "sglc/deskew.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::closing {

// Beyond this gap (s) between two scans their mean velocity says too little about the sweep's.
inline constexpr double kMaxSweepGap = 5.0;

struct SweepOutcome {
  bool deskewed = false;
  std::optional<std::string> warning;  // why a scan with point times was not de-skewed
};

// Moves `scan`'s points by the sweep's times (a sweep without times leaves it alone). `input` is the ingest's
// request, looked up in `store` for the previous scan; pass neither for a scan that is not stored (a query).
// The sweep's times must be one per point (the wire codec checks them).
SweepOutcome undoSweep(const ScanSweep& sweep, LabelledScan& scan, const storage::MapStore* store = nullptr,
                       const IngestInput* input = nullptr);

}  // namespace sglc::closing
