// The evidence record (docs/METHOD.md, section 8): every measure at a pose, one definition each.
#include "sglc/evidence.hpp"

#include <algorithm>
#include <cmath>

#include "sglc/background.hpp"

namespace sglc {
namespace {

// The near background (the street around the sensor) and the wide one (out to the view context's range).
constexpr double kNearCellM = 2.0, kNearRadiusM = 25.0;
constexpr double kWideCellM = 1.0, kWideRadiusM = 45.0;
// How far along the planes' weakest direction the pin looks (m): the bird's-eye view of a corridor pins its
// pose when the agreement is lower at each of these shifts.
constexpr double kPinShifts[] = {-4.0, -2.0, 2.0, 4.0};

StructureClasses classesOf(const Fingerprint& query, const Fingerprint& candidate) {
  // Building against vegetation is evidence only where neither scan's classes came from the built-in labeller.
  return query.labeller_structure || candidate.labeller_structure ? StructureClasses::kMerged
                                                                  : StructureClasses::kCompared;
}

// The smallest drop of the near agreement when the pose moves along `shift` (unit, horizontal, turning `turn`
// radians per metre about the query's origin).
double pinAlong(const Fingerprint& query, const Fingerprint& candidate, const PairView& view, const Mat4d& T,
                const Vec2d& shift, double turn, double here) {
  double smallest = 1.0;
  for (const double s : kPinShifts) {
    Mat4d M = Mat4d::Identity();
    M.topLeftCorner<3, 3>() = Eigen::AngleAxisd(s * turn, Vec3d::UnitZ()).toRotationMatrix();
    M.topRightCorner<2, 1>() = s * shift;
    smallest = std::min(smallest, here - nearAgreement(query, candidate, view, Mat4d(M * T)));
  }
  return smallest;
}

}  // namespace

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

PairView pairView(const Fingerprint& query, const Fingerprint& candidate, const Config& config,
                  const QueryView& given) {
  const QueryView known = given.of == &query ? given : QueryView{};
  PairView v;
  const double q = known.span_deg >= 0 ? known.span_deg : viewSpanDeg(query.background, query.background_cell);
  const double c = viewSpanDeg(candidate.background, candidate.background_cell);
  v.query_saw_less = q <= c;
  v.field_deg = std::min(q, c);
  v.narrow = v.field_deg < config.verify.background_min_view_deg;
  v.both_narrow = std::max(q, c) < config.verify.background_min_view_deg;
  if (!v.narrow) return v;
  std::shared_ptr<const ViewContext> own;
  const ViewContext* query_context = known.context;
  if (!query_context) {
    own = viewContextOf(query, config.view_search);
    query_context = own.get();
  }
  const auto other = viewContextOf(candidate, config.view_search);
  if (v.query_saw_less) {
    v.context = known.matcher ? known.matcher->match(*other) : matchViews(*query_context, *other);
    v.field = query_context->field();
  } else {
    v.context = matchViews(*other, *query_context);
    v.field = other->field();
  }
  return v;
}

double fieldAgreement(const Fingerprint& query, const Fingerprint& candidate, const PairView& view, const Mat4d& T_q_c,
                      double cell, double radius) {
  const auto classes = classesOf(query, candidate);
  const auto* field = view.field.empty() ? nullptr : &view.field;
  if (view.query_saw_less)
    return bevAgreement(query.background, candidate.background, query.background_cell, T_q_c, cell, radius, classes,
                        field);
  return bevAgreement(candidate.background, query.background, candidate.background_cell, T_q_c.inverse(), cell, radius,
                      classes, field);
}

double nearAgreement(const Fingerprint& query, const Fingerprint& candidate, const PairView& view, const Mat4d& T_q_c) {
  return fieldAgreement(query, candidate, view, T_q_c, kNearCellM, kNearRadiusM);
}

double bandOverlap(const Fingerprint& query, const Fingerprint& candidate, const Mat4d& T, double max_z,
                   const RefineConfig& config) {
  std::size_t in_query = 0, in_candidate = 0, explained = 0;
  for (const auto& p : query.planes) in_query += p.centroid.z() <= max_z;
  std::vector<bool> reached(query.planes.size(), false);
  const Eigen::Matrix3f R = T.topLeftCorner<3, 3>().cast<float>();
  const Vec3f t = T.topRightCorner<3, 1>().cast<float>();
  const auto index = planeIndexOf(query, config.max_corr_m);
  for (const auto& p : candidate.planes) {
    if (p.centroid.z() > max_z) continue;
    ++in_candidate;
    const int q =
        index->nearest(query.planes, R * p.centroid + t, R * p.normal, config.max_corr_m, config.min_normal_cosine);
    // Only the band's planes count on either side: the share stays within [0, 1].
    if (q < 0 || query.planes[static_cast<std::size_t>(q)].centroid.z() > max_z) continue;
    ++explained;
    reached[static_cast<std::size_t>(q)] = true;
  }
  const auto distinct = static_cast<std::size_t>(std::count(reached.begin(), reached.end(), true));
  const std::size_t fewer = std::min(in_query, in_candidate);
  return fewer ? static_cast<double>(std::min(explained, distinct)) / static_cast<double>(fewer) : 0.0;
}

int landmarksAt(const Fingerprint& query, const Fingerprint& candidate, const Mat4d& T_q_c, double gate,
                double* mean_distance) {
  const Eigen::Matrix3f R = T_q_c.topLeftCorner<3, 3>().cast<float>();
  const Vec3f t = T_q_c.topRightCorner<3, 1>().cast<float>();
  std::vector<Vec3f> moved;
  moved.reserve(candidate.nodes.size());
  for (const auto& c : candidate.nodes) moved.push_back(R * c.center + t);
  // One to one: each query node takes the nearest free candidate node of its class within the gate, so one
  // pole cannot vouch twice.
  const float gate_sq = static_cast<float>(gate * gate);
  std::vector<bool> used(moved.size(), false);
  int n = 0;
  double sum = 0.0;
  for (const auto& q : query.nodes) {
    int best = -1;
    float best_sq = gate_sq;
    for (std::size_t j = 0; j < moved.size(); ++j) {
      const float d = (moved[j] - q.center).head<2>().squaredNorm();
      if (!used[j] && candidate.nodes[j].cls == q.cls && d <= best_sq) {
        best = static_cast<int>(j);
        best_sq = d;
      }
    }
    if (best < 0) continue;
    used[static_cast<std::size_t>(best)] = true;
    sum += std::sqrt(static_cast<double>(best_sq));
    ++n;
  }
  if (mean_distance) *mean_distance = n ? sum / n : 0.0;
  return n;
}

Evidence measureEvidence(const Fingerprint& query, const Fingerprint& candidate, const PairView& view,
                         PoseSource source, const Mat4d& T, const RefineResult* planes, const Config& config) {
  Evidence e;
  e.source = source;
  e.narrow = view.narrow;
  e.field_deg = view.field_deg;
  e.translation_m = T.topRightCorner<3, 1>().norm();
  double mean = 0.0;
  e.landmarks = landmarksAt(query, candidate, T, config.ransac.inlier_threshold, &mean);
  e.landmark_similarity = e.landmarks ? std::exp(-mean) : 0.0;
  e.agreement = nearAgreement(query, candidate, view, T);
  e.wide_agreement = fieldAgreement(query, candidate, view, T, kWideCellM, kWideRadiusM);
  e.context_similarity = view.narrow ? view.context.similarity : 0.0;
  if (!planes || planes->iterations == 0) return e;
  e.plane_overlap = bandOverlap(query, candidate, T, config.fingerprint.background_max_z_m, config.refine);
  e.plane_rmse_m = planes->rmse;
  e.constraint = planes->horizontal_constraint;
  // Along the planes' weakest direction, or, when that is mostly a turn, along both ground axes.
  if (!planes->weak_shift.isZero())
    e.pin = pinAlong(query, candidate, view, T, planes->weak_shift, planes->weak_turn, e.agreement);
  else
    e.pin = std::min(pinAlong(query, candidate, view, T, Vec2d::UnitX(), 0.0, e.agreement),
                     pinAlong(query, candidate, view, T, Vec2d::UnitY(), 0.0, e.agreement));
  return e;
}

}  // namespace sglc
