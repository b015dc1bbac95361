// The SGLC pipeline: scan -> fingerprint; (query, candidate) -> coarse pose and loop decision -> fine
// (instance ICP) -> refine (background point-to-plane). Thread-safe: every method is const and the
// object holds no mutable state, so one Pipeline serves many threads.
#pragma once

#include "sglc/config.hpp"
#include "sglc/evidence.hpp"
#include "sglc/fingerprint.hpp"
#include "sglc/labels.hpp"
#include "sglc/loop_model.hpp"

#include <memory>
#include <string>
#include <vector>

namespace sglc {

struct LoopResult {
  bool is_loop = false;
  // The loop model's probability that the pair is a true loop at pose T (sglc/loop_model.hpp): a loop when it
  // reaches verify.min_probability. 0 when no pose hypothesis was found.
  double probability = 0.0;
  Evidence evidence;  // what the probability was computed from
  // Every hypothesis judged for this pair (the chosen one among them), at its pose after the plane fit.
  struct Judged {
    Mat4d T = Mat4d::Identity();
    Evidence evidence;
    double probability = 0.0;
  };
  std::vector<Judged> considered;
  // In [0, 1]; ranks candidates: the probability (one scale for every source).
  double score = 0.0;
  int matches = 0;                     // node matches after pruning
  int inliers = 0;                     // RANSAC inliers
  double graph_similarity = 0.0;       // S_graph = exp(-mean inlier residual)
  double background_similarity = 0.0;  // BEV agreement at the coarse pose
  // Maps candidate points into the query frame: p_query = T * p_candidate.
  Mat4d T = Mat4d::Identity();
  bool refined = false;
  // After refinement: share of the candidate's plane features with a consistent query plane, and their
  // point-to-plane RMSE (m). With the plane stage disabled: the instance ICP's share of matched points and RMSE.
  double fitness = 0.0;
  double rmse = 0.0;
  // After refinement: Fisher information of T (6x6, translation then rotation, metres and radians) for a
  // right perturbation T_true = T exp(xi) in the candidate's frame; directions the registration leaves free
  // (a straight corridor) get little. Zero when neither stage ran or was kept.
  Mat6d information = Mat6d::Zero();
  const char* reason = "";          // why it is not a loop (empty for loops)
  std::vector<Match> inlier_pairs;  // node matches consistent with the coarse T (query node, candidate node)
};

// Where a scan's labels came from, and what may keep it from closing loops (for the caller to show).
struct ScanReport {
  enum class LabelSource { kProvided, kComputed, kCompleted };
  LabelSource label_source = LabelSource::kProvided;  // computed: by the labeller; completed: roles filled in
  std::vector<std::string> warnings;
};

class ViewMatcher;

// A narrow query's ranking of stored scans by view context (docs/METHOD.md, section 6), built once per query:
// its context is computed and turned once, then compared with each stored scan's.
class ViewRanking {
 public:
  // Whether the ranking applies: the query is a narrow view, view_search is on, and its context sees structure
  // (without, every similarity would be 0 and the descriptor's order stands).
  bool active() const { return active_; }
  // The view-context similarity of a stored scan to the query, in [0, 1]; 0 when not active.
  double similarity(const Fingerprint& stored) const;
  // The query's own view, for every candidate's verification: its span, and its context when it is narrow.
  QueryView queryView() const { return {query_, span_deg_, context_.get(), matcher_.get()}; }

 private:
  friend class Pipeline;
  bool active_ = false;
  const Fingerprint* query_ = nullptr;  // the scan it was made for
  double span_deg_ = -1.0;
  std::shared_ptr<const ViewContext> context_;  // narrow queries only
  std::shared_ptr<const ViewMatcher> matcher_;  // the context turned to every heading
  const ViewSearchConfig* config_ = nullptr;
};

class Pipeline {
 public:
  explicit Pipeline(Config config = {});

  const Config& config() const { return config_; }
  const LoopModel& model() const { return model_; }

  // Throws InputError on an invalid scan. A scan without labels (empty `labels`) is labelled by the built-in
  // labeller unless config.labeller.mode is "off"; in "auto" mode a labelled scan whose label set lacks a
  // landmark role (no ids for trunk, pole or vehicle) gets those from the labeller; "always" ignores given
  // labels. `report` (optional) says which happened and warns about scans that cannot close loops.
  Fingerprint fingerprint(const LabelledScan& scan, ScanReport* report = nullptr) const;
  // Pose hypotheses and the loop decision. When the landmarks give no loop, `background` allows hypotheses from
  // the background alone (config.verify.background_*: scans with few nodes only). `query_view`, the query's
  // viewRanking, spares recomputing its view for every candidate (the same answer without it).
  LoopResult verify(const Fingerprint& query, const Fingerprint& candidate, bool background = true,
                    const ViewRanking* query_view = nullptr) const;
  // Fine and refine stages on a verified result (no-op for non-loops). With known_loop (the caller already
  // knows the pair is a loop: relocalization at a chosen place, the loop-pose protocol), on any result: from
  // its coarse pose and, when there is none, verification rejected it or the plane stage would leave its
  // guard, also from a search over the two background views (config.bev_search), keeping the pose with the
  // most evidence (plane fitness x background agreement x the Cauchy weight of the plane RMSE). `refined` says
  // whether a pose was found; is_loop and reason keep verification's decision.
  void refine(const Fingerprint& query, const Fingerprint& candidate, LoopResult& result,
              bool known_loop = false) const;
  // Whether a scan is a narrow view (less than verify.background_min_view_deg of the horizon).
  bool isNarrow(const Fingerprint& scan) const;
  // The query's ranking by view context (inactive for full views or with view_search off), and its view.
  ViewRanking viewRanking(const Fingerprint& query) const;
  // How many of a query's first candidates may get background hypotheses (verify.background_candidates, or
  // view_search.background_candidates for a narrow query).
  std::size_t backgroundCandidates(const Fingerprint& query) const;
  // verify + refine.
  LoopResult match(const Fingerprint& query, const Fingerprint& candidate) const;

 private:
  // The hypothesis from T0 refined by the guarded plane fit, its evidence and probability, into r (T, evidence,
  // probability, background_similarity, and the plane fit's fitness, rmse and information when it stood).
  void judge(const Fingerprint& query, const Fingerprint& candidate, const PairView& view, PoseSource source,
             const Mat4d& T0, LoopResult& r) const;
  // The fine and refine stages from the coarse pose; true when the plane stage's pose was kept.
  bool refinePose(const Fingerprint& query, const Fingerprint& candidate, LoopResult& r) const;
  // The labels the scan is fingerprinted with when they are not the given ones: computed by the labeller, or
  // the given ones completed by it (roles the label set has no ids for). Empty: use the given labels.
  std::vector<std::uint32_t> ownLabels(const LabelledScan& input, ScanReport& rep) const;

  Config config_;
  LabelMap labels_;
  LoopModel model_;
};

}  // namespace sglc
