// The query use case: candidates from the map (descriptor search or a given list), verification, ranking and
// refinement. Free of any transport: the gRPC service and the in-process evaluation call the same code.
#pragma once

#include <memory>
#include <utility>
#include <vector>

#include "sglc/closing/loop_query.hpp"
#include "sglc/pipeline.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::closing {

// The L2 distance between two descriptors of the same length, computed in double and returned as float (the
// map's search sums in float: its figure agrees to float rounding).
float descriptorDistance(const std::vector<float>& a, const std::vector<float>& b);

// What happens to verified candidates (the part of QueryOptions the ranking needs, without limits).
struct Ranking {
  std::size_t top_k = 5;
  bool include_rejected = false;
  std::optional<double> min_score;
  bool refine = true;
  bool known_loops = false;
};

class LoopFinder {
 public:
  // Both must outlive the finder. Thread-safe: any number of queries at once.
  LoopFinder(const Pipeline& pipeline, const storage::MapStore& store) : pipeline_(pipeline), store_(store) {}

  // A stored scan as the query: its fingerprint and its origin (so it excludes itself and its recent
  // neighbours). The fingerprint is the query's own copy, not the store's cached one. StorageError kNotFound
  // when `map` has no such scan.
  std::pair<std::shared_ptr<const Fingerprint>, QueryOrigin> storedQuery(const std::string& map,
                                                                         std::int64_t scan_id) const;

  // Checks the options (InputError saying which is wrong; StorageError kNotFound for a listed scan the map
  // does not have), finds the candidates, verifies each, orders them (accepted first, then by score, then by
  // scan id), keeps the top_k and refines those. Each answer carries its scan's robot, session and seq.
  std::vector<FoundLoop> find(const Fingerprint& query, const QueryOrigin& origin, const QueryOptions& options,
                              const Execution& exec, QueryTiming* timing) const;

  // The steps after the search: verifies `hits` (in parallel when exec allows; a scan deleted meanwhile is
  // skipped), orders, trims and refines as `ranking` says. Answers carry no robot, session or seq. `view`, the
  // query's Pipeline::viewRanking when the caller has it, is not computed again.
  std::vector<FoundLoop> verify(const Fingerprint& query, const std::vector<storage::SearchHit>& hits,
                                const Ranking& ranking, const Execution& exec, QueryTiming* timing,
                                const ViewRanking* view = nullptr) const;

  // Listed scans as candidates, with their descriptor distances: InputError for more than `max` or a repeated
  // id or another descriptor layout, StorageError kNotFound for a scan `map` does not have.
  std::vector<storage::SearchHit> listed(const Fingerprint& query, const std::string& map,
                                         const std::vector<std::int64_t>& ids, std::size_t max = 200) const;

 private:
  // The search's candidates, or the listed scans. A narrow view (less than verify.background_min_view_deg of
  // the horizon, viewSpanDeg) with view_search on gets viewRanked's instead of the descriptor's.
  std::vector<storage::SearchHit> candidates(const Fingerprint& query, const QueryOrigin& origin,
                                             const QueryOptions& options, std::uint32_t k, const Execution& exec,
                                             const ViewRanking& view) const;
  // The request's k scans whose view context is most like the query's (sglc/view_context.hpp), ties by
  // descriptor distance then scan id, from the view_search.max_scans (at least k) nearest by descriptor that the
  // request's filters allow. Each hit keeps its descriptor distance. A query whose context sees no structure gets
  // the descriptor search's k (the same order, without reading the scans).
  std::vector<storage::SearchHit> viewRanked(const ViewRanking& view, storage::SearchRequest request,
                                             const Execution& exec) const;

  const Pipeline& pipeline_;
  const storage::MapStore& store_;
};

}  // namespace sglc::closing
