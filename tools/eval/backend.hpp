// Where an evaluation runs the method: the engine and map database in this process, or a running sglc-server
// over gRPC. Both take the same steps (store, search with exclusions, verify, order, refine the top ones), so
// they give the same numbers; the server back-end measures the service itself.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "sglc/config.hpp"
#include "sglc/descriptors.hpp"
#include "sglc/pipeline.hpp"
#include "sglc/types.hpp"

namespace sglc::eval {

struct Candidate {
  int frame = -1;
  double score = 0;
  bool verified = false;
  bool refined = false;
  int inliers = 0;
  Mat4d T = Mat4d::Identity();  // maps the candidate's points into the query's frame
  float descriptor_distance = 0;
  double probability = 0;  // the loop model's (the server back-end: from the answer when it carries one)
  // The in-process back-end: every hypothesis verification judged, at its pose before refinement.
  std::vector<LoopResult::Judged> considered;
};

// Per-frame stage times (ms); zero for stages a call did not run.
struct StageTimes {
  double fingerprint = 0, search = 0, verify = 0, refine = 0, store = 0, total = 0;
};

// Which candidates get a refined pose.
enum class Refine {
  none,
  verified,     // those verification accepts
  known_loops,  // every candidate with a pose to start from, accepted or not (the pairs are known loops)
};

struct LoopQuery {
  int exclude_recent = 100;  // skip stored frames whose number is within this many of the query's
  int candidates = 10;       // descriptor neighbours verified (all of them are returned, verified first)
  bool refine = true;        // refine the verified ones
};

class Backend {
 public:
  virtual ~Backend() = default;
  virtual std::string name() const = 0;
  // Stores a frame.
  virtual void add(int frame, const LabelledScan& scan, StageTimes* times) = 0;
  // Looks for loops of the frame among the frames stored so far, then stores it. Candidates come ordered as
  // the service orders them: verified first, then by score (descending), then by storage order.
  virtual std::vector<Candidate> queryThenAdd(int frame, const LabelledScan& scan, const LoopQuery& query,
                                              StageTimes* times) = 0;
  // Looks for the places of a scan that is not stored (relocalization: no exclusions), refining verified ones.
  virtual std::vector<Candidate> query(const LabelledScan& scan, const LoopQuery& query, StageTimes* times) = 0;
  // Verifies stored frame `query` against each stored frame of `candidates`, refining as asked; returns one
  // Candidate per requested frame, in the service's order.
  virtual std::vector<Candidate> verify(int query, const std::vector<int>& candidates, Refine refine,
                                        StageTimes* times) = 0;
};

// The engine with a map database in `scratch_dir` (created; synchronous=OFF).
std::unique_ptr<Backend> inProcessBackend(const Config& config, const std::string& scratch_dir);
// A map on a running server, created now and deleted when the backend is destroyed unless keep_map.
std::unique_ptr<Backend> serverBackend(const std::string& address, const std::string& token, const std::string& map,
                                       bool keep_map = false);

}  // namespace sglc::eval
