// Pipeline::verify: pose hypotheses from their sources, each refined by one guarded plane fit, the evidence at
// each, and one decision: the loop model's probability (docs/METHOD.md, section 8).
#include <algorithm>
#include <cmath>
#include <string>

#include "pose_guard.hpp"
#include "pose_sources.hpp"
#include "sglc/pipeline.hpp"

namespace sglc {
namespace {

bool sameGeometry(const Fingerprint& a, const Fingerprint& b) {
  return a.layout.num_classes == b.layout.num_classes && a.layout.bins == b.layout.bins &&
         a.layout.k_eigen == b.layout.k_eigen && a.layout.rings == b.layout.rings &&
         a.layout.orders == b.layout.orders && a.d_max == b.d_max && a.d_i == b.d_i &&
         a.background_cell == b.background_cell && a.plane_voxel == b.plane_voxel;
}

// Hypotheses whose background disagrees this much at the starting pose get no plane fit: it costs most of a
// verification, and the overlays and landmark poses of other places mostly start there.
constexpr double kFitMinAgreement = 0.25;

// The rejection reason naming the evidence that fell shortest: of the features that raise p, the one whose
// term would gain most at its best value.
const char* shortfall(const LoopModel& model, const Evidence& e) {
  static const std::vector<std::string> reasons = [] {
    std::vector<std::string> r;
    for (const auto& f : modelFeatures())
      r.push_back(std::string("loop probability below verify.min_probability; weakest evidence: ") + f.name);
    return r;
  }();
  const auto x = featureValues(e);
  const auto& features = modelFeatures();
  std::size_t worst = 0;
  double gap = -1.0;
  for (std::size_t k = 0; k < x.size(); ++k) {
    if (features[k].sign <= 0) continue;
    const double best = std::string_view(features[k].name) == "constraint" ? std::log1p(100.0)
                        : std::string_view(features[k].name) == "pin"      ? 0.2
                                                                           : 1.0;
    const double g = model.curves()[k](best) - model.curves()[k](x[k]);
    if (g > gap) {
      gap = g;
      worst = k;
    }
  }
  return reasons[worst].c_str();
}

}  // namespace

void Pipeline::judge(const Fingerprint& query, const Fingerprint& candidate, const PairView& view, PoseSource source,
                     const Mat4d& T0, LoopResult& r) const {
  const auto& c = config_;
  r.T = T0;
  RefineResult planes;
  bool fitted = false;
  if (c.verify.fit_max_shift_m > 0 && c.refine.enabled &&
      nearAgreement(query, candidate, view, T0) >= kFitMinAgreement) {
    planes = refinePlanes(query.planes, *planeIndexOf(query, c.refine.max_corr_m), candidate.planes, {}, T0, c.refine);
    fitted =
        planes.iterations > 0 && detail::movedWithin(T0, planes.T, c.verify.fit_max_shift_m, c.verify.fit_max_turn_deg);
    if (fitted) r.T = planes.T;
  }
  r.evidence = measureEvidence(query, candidate, view, source, r.T, fitted ? &planes : nullptr, c);
  r.probability = model_.probability(r.evidence);
  r.background_similarity = r.evidence.agreement;
  if (fitted) {
    r.fitness = planes.fitness;
    r.rmse = planes.rmse;
    r.information = planes.information;
  }
}

LoopResult Pipeline::verify(const Fingerprint& query, const Fingerprint& candidate, bool background,
                            const ViewRanking* query_view) const {
  if (!sameGeometry(query, candidate))
    throw InputError("fingerprints were built with different descriptor or voxel parameters");
  const auto& c = config_;
  const auto& v = c.verify;
  const PairView view = pairView(query, candidate, c, query_view ? query_view->queryView() : QueryView{});
  LoopResult r;
  std::vector<LoopResult::Judged> considered;
  auto landmarks = detail::landmarkPose(query, candidate, c);
  r.matches = landmarks.matches;
  r.reason = landmarks.failure;
  if (landmarks.source != PoseSource::kNone) {
    r.inliers = landmarks.inliers;
    r.graph_similarity = landmarks.graph_similarity;
    r.inlier_pairs = std::move(landmarks.inlier_pairs);
    judge(query, candidate, view, landmarks.source, landmarks.T, r);
    considered.push_back({r.T, r.evidence, r.probability});
    r.fitness = r.rmse = 0.0;  // the fine and refine stages report their own fit
    r.information = Mat6d::Zero();
  }
  // The background's hypotheses, where the landmarks' falls short and few landmarks are in view.
  const bool few_nodes =
      v.background_max_nodes > 0 &&
      static_cast<int>(std::min(query.nodes.size(), candidate.nodes.size())) <= v.background_max_nodes;
  const bool wanted =
      background && few_nodes && r.probability < v.min_probability && c.bev_search.enabled && c.refine.enabled;
  if (wanted && view.narrow && !c.view_search.enabled && landmarks.source == PoseSource::kNone)
    r.reason = "no landmark pose, and a narrow view gets no background hypotheses without view_search";
  if (wanted && view.both_narrow && landmarks.source == PoseSource::kNone)
    r.reason = "no landmark pose, and two narrow views get no background hypotheses";
  if (wanted && (!view.narrow || c.view_search.enabled) && !view.both_narrow)
    for (const auto& T0 : detail::overlayPoses(query, candidate, view, c)) {
      LoopResult h;
      judge(query, candidate, view, view.narrow ? PoseSource::kViewHeadings : PoseSource::kWallHeadings, T0, h);
      considered.push_back({h.T, h.evidence, h.probability});
      if (h.probability <= r.probability) continue;
      h.matches = r.matches;
      // The pose is the planes' own: refined already (the fine stage has no matched instances to work on).
      h.refined = h.evidence.plane_overlap > 0;
      r = std::move(h);
    }
  const double translation = r.T.topRightCorner<3, 1>().norm();
  r.score = r.probability;
  if (r.evidence.source == PoseSource::kNone) {
    if (!*r.reason) r.reason = "no pose hypothesis: no landmark pose and no background overlay";
  } else if (r.probability < v.min_probability) {
    r.reason = shortfall(model_, r.evidence);
  } else if (v.max_translation > 0 && translation > v.max_translation) {
    r.reason = "translation exceeds verify.max_translation";
  } else {
    r.is_loop = true;
    r.reason = "";
  }
  if (!r.is_loop) r.refined = false;
  r.considered = std::move(considered);
  return r;
}

}  // namespace sglc
