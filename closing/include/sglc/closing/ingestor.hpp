// The ingest use case: fingerprint a scan, optionally look for its loops in the map, store it (idempotently:
// the identical scan re-sent for a stored key answers as the first time did), and record its verified loops
// for the pose graph. Free of any transport; the caller sequences the two phases around its own resources
// (a compute slot for the engine work, none for the database write).
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "sglc/closing/loop_finder.hpp"
#include "sglc/closing/loop_query.hpp"
#include "sglc/closing/places.hpp"
#include "sglc/pipeline.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::closing {

struct ScanKey {
  std::string map, robot, session;
  std::int64_t seq = 0;
};

// One scan's request (the scan's points and labels travel beside it).
struct IngestInput {
  ScanKey key;
  std::optional<double> stamp;
  std::optional<Mat4d> odometry_pose;  // a rigid motion (the caller has checked it)
  bool store_raw = false;              // keep the raw cloud too
  bool query = false;                  // look for loops before storing
  QueryOptions query_options;
};

struct IngestTiming {
  double fingerprint_ms = 0, store_ms = 0;
  QueryTiming query;
};

struct Ingested {
  std::int64_t scan_id = 0;     // set by commit
  bool already_stored = false;  // the key held this identical scan already
  ScanReport report;            // where the labels came from, warnings
  std::vector<FoundLoop> loops;
  // Verified loops that could not be recorded for the pose graph, and why (the scan is stored regardless).
  std::vector<std::string> unrecorded_loops;
  // Lifelong maps: the scan's place, and whether the map keeps it as one of the place's versions (else it retires
  // with its session). Absent with the policy off, for a scan stored before, or when recording failed.
  std::optional<storage::PlaceRecord> place;
  IngestTiming timing;
};

// The result of the engine phase, to be committed.
struct PendingScan {
  IngestInput input;
  Fingerprint fingerprint;
  std::optional<std::int64_t> stored;  // the key's scan, when it is stored already
  Ingested outcome;
};

class Ingestor {
 public:
  // Told the map after verified loops were recorded for it.
  using LoopsRecorded = std::function<void(const std::string& map)>;

  // Both must outlive the ingestor. Verified loops are recorded (MapStore::addLoop) only when `loops_recorded`
  // is given (a server with a pose graph): every one, also of scans without an odometry pose, which the pose
  // graph leaves out but listings and exports show.
  // With `lifelong` enabled, each stored scan gets a place (places.hpp) from its verified loops.
  Ingestor(const Pipeline& pipeline, storage::MapStore& store, LoopsRecorded loops_recorded = {},
           LifelongOptions lifelong = {})
      : pipeline_(pipeline),
        store_(store),
        finder_(pipeline, store),
        loops_recorded_(std::move(loops_recorded)),
        lifelong_(lifelong) {}

  // Told where the scan's labels came from and what may keep it from closing loops, as soon as it is
  // fingerprinted (before the checks that may still fail the call).
  using ReportListener = std::function<void(const ScanReport&)>;

  // Engine work (InputError for a stamp that is not finite): the fingerprint, the retry check (StorageError
  // kAlreadyExists when the key holds a different scan) and, with input.query, the loops (excluding the stored copy of
  // a retried scan). The map must exist.
  PendingScan compute(const LabelledScan& scan, IngestInput input, const Execution& exec,
                      const ReportListener& on_report = {}) const;

  // Database work: stores the scan (unless it was stored already, or another call stored the identical scan
  // meanwhile: then its own copy leaves the loops), records its verified loops and, for a lifelong map, its place.
  Ingested commit(PendingScan pending, const LabelledScan& scan) const;

 private:
  void requireSameScan(std::int64_t id, const Fingerprint& fp, const IngestInput& input) const;
  void recordLoops(Ingested& out, const IngestInput& input) const;
  void recordPlace(Ingested& out, const IngestInput& input) const;

  const Pipeline& pipeline_;
  storage::MapStore& store_;
  const LoopFinder finder_;  // over the same engine and map
  LoopsRecorded loops_recorded_;
  LifelongOptions lifelong_;
};

}  // namespace sglc::closing
