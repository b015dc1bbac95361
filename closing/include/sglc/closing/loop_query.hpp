// What a loop query asks and what it answers, in plain types: the use case's side of QueryOptions and
// Candidate (sglc.v1), shared by the gRPC service, the evaluation and any other caller.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "sglc/pipeline.hpp"

namespace sglc::closing {

// Which stored scans a query may match. kUnknown stands for a value the caller's wire format does not know;
// it is refused where the scope is checked (after the numeric options), as "unknown scope".
enum class Scope { kWholeMap, kSameRobot, kOtherRobots, kSessions, kUnknown };

struct SessionRef {
  std::string robot, session;
};

// The caller's options, as the wire gives them (0 means "the default" where the comment says so).
struct QueryOptions {
  std::uint32_t top_k = 0;          // loops answered, at most 100 (0: 5)
  std::uint32_t candidates = 0;     // descriptor neighbours verified, at most 200 (0: max(top_k, 10))
  std::int64_t exclude_recent = 0;  // skip the querying robot's scans within this many seq of the query's
  double exclude_seconds = 0;       // ... or within this many seconds of its stamp
  bool refine = true;               // refine the loops answered (poses, fitness, information)
  bool known_loops = false;         // every candidate is a loop: refine rejected ones too (needs refine)
  bool include_rejected = false;    // answer candidates verification rejects too (after the accepted ones)
  std::optional<double> min_score;  // drop accepted loops scoring below this
  Scope scope = Scope::kWholeMap;
  // With kSessions, the sessions searched: "robot/session" (split at the first '/') and as pairs.
  std::vector<std::string> sessions;
  std::vector<SessionRef> session_refs;
  std::vector<std::int64_t> verify_scan_ids;  // verify exactly these scans instead of searching (at most 200)
};

// Who asks: their own recent scans are excluded as the options say, and a stored query scan never matches
// itself.
struct QueryOrigin {
  std::string map, robot, session;
  std::int64_t seq = 0;
  std::optional<double> stamp;
  std::int64_t self_scan = 0;  // the query's own stored scan (0: none)
};

// One answered candidate: the engine's verdict and pose, and who the stored scan belongs to.
struct FoundLoop {
  std::int64_t scan_id = 0;
  std::string robot, session;  // empty when the scan was deleted meanwhile
  std::int64_t seq = 0;
  float descriptor_distance = 0;
  LoopResult result;  // is_loop, score, inliers, T (candidate -> query), and after refinement fitness, rmse,
                      // information
};

// Milliseconds spent per stage, and what verification decided about the candidates it checked.
struct QueryTiming {
  double search_ms = 0, verify_ms = 0, refine_ms = 0;
  int verified = 0;
  std::vector<const char*> refused;  // the engine's reason for each refused candidate (static strings)
};

// How the caller runs independent items and abandons work: parallel_for(n, fn) runs fn(i) for every i in
// [0, n), in any order and at once (empty: one after another); check_alive() throws to stop the work (a
// cancelled call, a passed deadline) and is called before each item.
struct Execution {
  std::function<void(std::size_t, const std::function<void(std::size_t)>&)> parallel_for;
  std::function<void()> check_alive;

  void forEach(std::size_t n, const std::function<void(std::size_t)>& fn) const;
  void checkAlive() const {
    if (check_alive) check_alive();
  }
};

}  // namespace sglc::closing
