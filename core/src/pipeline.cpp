#include "sglc/pipeline.hpp"

#include <algorithm>
#include <cmath>
#include <tuple>

#include "fast_math.hpp"
#include "pose_guard.hpp"
#include "sglc/bev_search.hpp"
#include "sglc/labeller.hpp"
#include "sglc/view_context.hpp"
#include "sglc/voxel_map.hpp"

namespace sglc {
namespace {

// Voxel-averaged points of one instance, snapped to the stored 1 cm grid (order: first point per voxel).
void downsampleInstance(const Points& points, const Cluster& cluster, double voxel, Points& out) {
  const float inv = static_cast<float>(1.0 / voxel);
  VoxelMap map(cluster.points.size());
  std::vector<Vec3d> sums;
  std::vector<int> counts;
  for (auto i : cluster.points) {
    const Vec3f& p = points[i];
    bool inserted = false;
    const int idx = map.findOrInsert(
        packCell(detail::floorInt(p.x() * inv), detail::floorInt(p.y() * inv), detail::floorInt(p.z() * inv)),
        static_cast<int>(sums.size()), &inserted);
    if (inserted) {
      sums.push_back(Vec3d::Zero());
      counts.push_back(0);
    }
    sums[idx] += p.cast<double>();
    ++counts[idx];
  }
  for (std::size_t k = 0; k < sums.size(); ++k) {
    const Vec3d m = sums[k] / counts[k];
    out.emplace_back(detail::snapCm(static_cast<float>(m.x())), detail::snapCm(static_cast<float>(m.y())),
                     detail::snapCm(static_cast<float>(m.z())));
  }
}

constexpr float kMaxCoordinate = 320.0f;

}  // namespace

Pipeline::Pipeline(Config config)
    : config_(std::move(config)),
      labels_((validateConfig(config_), config_.labels)),
      model_(LoopModel::load(config_.verify.model)) {}

std::vector<std::uint32_t> Pipeline::ownLabels(const LabelledScan& input, ScanReport& rep) const {
  const auto& c = config_;
  const std::size_t n = input.points.size();
  std::vector<std::uint32_t> labels;
  const bool missing_roles = !labels_.hasVehicleIds() || !labels_.hasTrunkIds() || !labels_.hasPoleIds();
  if (n > 0 && (input.labels.empty() || c.labeller.mode == "always")) {
    if (c.labeller.mode == "off")
      throw InputError("scan has no labels and the built-in labeller is off (labeller.mode: off)");
    labels = labelScene(input.points, c.labeller);
    rep.label_source = ScanReport::LabelSource::kComputed;
  } else if (n > 0 && c.labeller.mode == "auto" && missing_roles) {
    labels = input.labels;
    const auto computed = labelScene(input.points, c.labeller);
    for (std::size_t i = 0; i < n; ++i) {
      const auto l = computed[i];
      const bool fill = (l == labeller_ids::kVehicle && !labels_.hasVehicleIds()) ||
                        (l == labeller_ids::kTrunk && !labels_.hasTrunkIds()) ||
                        (l == labeller_ids::kPole && !labels_.hasPoleIds());
      // Only points the given labels do not make landmarks of (a given vehicle stays a vehicle).
      if (fill && labels_.role(input.labels[i]) < 0) labels[i] = l;
    }
    rep.label_source = ScanReport::LabelSource::kCompleted;
  }
  return labels;
}

Fingerprint Pipeline::fingerprint(const LabelledScan& input, ScanReport* report) const {
  const auto& c = config_;
  const std::size_t n = input.points.size();
  if (!input.labels.empty() && input.labels.size() != n)
    throw InputError("scan has " + std::to_string(n) + " points but " + std::to_string(input.labels.size()) +
                     " labels");
  ScanReport local;
  ScanReport& rep = report ? *report : local;
  rep = {};
  const auto own = ownLabels(input, rep);
  const auto& labels = own.empty() ? input.labels : own;
  const auto& points = input.points;
  // One pass splits the scan by role into compact arrays, so every later stage streams over just its points.
  Points node_points, bg_points;
  std::vector<std::int8_t> node_class;
  std::vector<Background> background;
  node_points.reserve(n / 4);
  node_class.reserve(n / 4);
  bg_points.reserve(n);
  background.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3f& p = points[i];
    if (!p.allFinite()) throw InputError("point " + std::to_string(i) + " has a non-finite coordinate");
    // Fingerprints keep centimetres in 16 bits: points beyond +-320 m on any axis cannot be landmarks.
    if (p.cwiseAbs().maxCoeff() > kMaxCoordinate) continue;
    const int role = labels_.role(labels[i]);
    if (role >= 0) {
      node_points.push_back(p);
      node_class.push_back(static_cast<std::int8_t>(role));
    } else if (role <= -2) {
      bg_points.push_back(p);
      background.push_back(static_cast<Background>(-role - 1));
    }
  }

  Fingerprint fp;
  fp.layout = descriptorLayout(labels_.numNodeClasses(), c.graph, c.descriptor);
  fp.d_max = static_cast<float>(c.graph.d_max);
  fp.d_i = static_cast<float>(c.descriptor.d_i);
  fp.background_cell = static_cast<float>(c.fingerprint.background_cell_m);
  fp.plane_voxel = static_cast<float>(c.fingerprint.plane_voxel_m);
  fp.num_points = static_cast<std::uint32_t>(n);
  fp.labeller_structure = rep.label_source == ScanReport::LabelSource::kComputed;

  const auto clusters = clusterInstances(node_points, node_class, c.cluster);
  std::vector<int> kept;
  fp.nodes = buildNodes(node_points, clusters, c.graph, &kept);
  fp.instance_offsets.assign(1, 0);
  for (int k : kept) {
    downsampleInstance(node_points, clusters[k], c.fingerprint.instance_voxel_m, fp.instance_points);
    fp.instance_offsets.push_back(static_cast<std::uint32_t>(fp.instance_points.size()));
  }
  fp.background_max_z = static_cast<float>(c.fingerprint.background_max_z_m);
  fp.background = bevCells(bg_points, background, c.fingerprint.background_cell_m, c.fingerprint.background_max_range_m,
                           c.fingerprint.background_max_z_m);
  fp.planes = extractPlanes(bg_points, background, c.fingerprint);
  fp.descriptor = scanDescriptor(
      fp.nodes, structureSpectrum(fp.background, fp.background_cell, fp.layout.rings, fp.layout.orders, c.descriptor),
      fp.layout, fp.d_max, fp.d_i, c.descriptor.background_weight);
  fp.finalize();
  if (n > 0 && node_points.empty() && bg_points.empty())
    rep.warnings.push_back("no point carries a label the active label map (labels.preset: " + c.labels.preset +
                           ") uses: check the label set, or send the scan without labels");
  else if (fp.nodes.size() < 3)
    rep.warnings.push_back(
        "only " + std::to_string(fp.nodes.size()) +
        " landmarks (vehicle, trunk and pole instances): a loop can be verified only from the background, and only"
        " where background-only loops are on (verify.background_max_nodes) and, for a scan that saw less than"
        " verify.background_min_view_deg of the horizon, view_search is on");
  return fp;
}

void Pipeline::refine(const Fingerprint& query, const Fingerprint& candidate, LoopResult& r, bool known_loop) const {
  if (r.refined || !(r.is_loop || known_loop)) return;
  const auto& c = config_;
  const bool planes_kept = r.inliers >= 3 && refinePose(query, candidate, r);
  // A known loop whose pose the landmarks may have got wrong (no coarse pose, a pose verification rejected, or
  // one the plane stage would have moved beyond its guard): overlay the background views as well, refine the
  // best overlays on the planes, and keep the pose with the most evidence for it: the share of the candidate's
  // planes it explains, how tightly (the Cauchy weight of their RMS residual), and how well the background views
  // agree there. No one of them alone: along a street of repeated facades a pose a few metres off explains as
  // many planes, loosely, and where the structure repeats its bird's-eye view can agree as well.
  if (!known_loop || (r.is_loop && planes_kept) || !c.bev_search.enabled || !c.refine.enabled) return;
  const PairView view = pairView(query, candidate, c);
  auto evidence = [&](const Mat4d& T, double fitness, double rmse) {
    const double u = rmse / c.refine.cauchy_m;
    return fitness * nearAgreement(query, candidate, view, T) / (1.0 + u * u);
  };
  // Compared as (evidence, fitness, -rmse): ties (disjoint views agree 0) go to more planes, then the tighter
  // fit, then the earlier contender.
  std::tuple<double, double, double> best{-1.0, 0.0, 0.0};
  if (r.refined) best = {evidence(r.T, r.fitness, r.rmse), r.fitness, -r.rmse};
  for (const auto& h : searchBevPose(query.background, candidate.background, query.background_cell, c.bev_search)) {
    const auto ref =
        refinePlanes(query.planes, *planeIndexOf(query, c.refine.max_corr_m), candidate.planes, {}, h.T, c.refine);
    if (ref.iterations == 0 || ref.correspondences < c.bev_search.min_correspondences) continue;
    const std::tuple<double, double, double> e{evidence(ref.T, ref.fitness, ref.rmse), ref.fitness, -ref.rmse};
    if (!(e > best)) continue;
    best = e;
    r.T = ref.T;
    r.fitness = ref.fitness;
    r.rmse = ref.rmse;
    r.information = ref.information;
    r.refined = true;
  }
}

bool Pipeline::refinePose(const Fingerprint& query, const Fingerprint& candidate, LoopResult& r) const {
  const auto& c = config_;
  Mat4d T = r.T;
  std::vector<std::pair<Vec3f, Vec3f>> anchor;
  if (c.fine.enabled) {
    std::vector<std::pair<InstanceView, InstanceView>> instances;
    for (const auto& [i, j] : r.inlier_pairs) instances.emplace_back(query.instance(i), candidate.instance(j));
    auto icp = icpInstances(instances, T, c.fine);
    // Guard: the fine stage only polishes; a large jump means it locked onto something else.
    if (icp.correspondences >= c.fine.min_correspondences &&
        detail::movedWithin(r.T, icp.T, c.fine.max_shift_m, c.fine.max_turn_deg)) {
      T = icp.T;
      r.fitness = icp.fitness;
      r.rmse = icp.rmse;
      r.information = pointPairInformation(icp.pairs, T, icp.rmse);
      anchor = std::move(icp.pairs);
    }
  }
  bool kept = false;
  if (c.refine.enabled) {
    auto ref =
        refinePlanes(query.planes, *planeIndexOf(query, c.refine.max_corr_m), candidate.planes, anchor, T, c.refine);
    kept = ref.iterations > 0 && detail::movedWithin(T, ref.T, c.refine.max_shift_m, c.refine.max_turn_deg);
    // Guard: the fine stage led the planes to a loose fit (refine.max_rmse_m) where the planes alone, from the
    // pose before it, fit within that bar and explain at least as many planes: then the instance points locked
    // onto something else, and the fine stage's pose is dropped.
    if (kept && !anchor.empty() && ref.rmse > c.refine.max_rmse_m) {
      auto alone =
          refinePlanes(query.planes, *planeIndexOf(query, c.refine.max_corr_m), candidate.planes, {}, r.T, c.refine);
      if (alone.iterations > 0 && alone.rmse <= c.refine.max_rmse_m && alone.fitness >= ref.fitness &&
          detail::movedWithin(r.T, alone.T, c.refine.max_shift_m, c.refine.max_turn_deg))
        ref = std::move(alone);
    }
    if (kept) {
      T = ref.T;
      r.information = ref.information;
    } else if (ref.iterations > 0) {
      // Guard: the planes moved too far to trust; report how well they fit at the pose that stays.
      RefineConfig at = c.refine;
      at.max_iterations = 0;
      ref = refinePlanes(query.planes, *planeIndexOf(query, c.refine.max_corr_m), candidate.planes, {}, T, at);
    }
    r.fitness = ref.fitness;
    r.rmse = ref.rmse;
  }
  r.T = T;
  r.refined = true;
  return kept;
}

double ViewRanking::similarity(const Fingerprint& fp) const {
  if (!active_) return 0.0;
  return matcher_->match(*viewContextOf(fp, *config_)).similarity;
}

bool Pipeline::isNarrow(const Fingerprint& scan) const {
  return viewSpanDeg(scan.background, scan.background_cell) < config_.verify.background_min_view_deg;
}

ViewRanking Pipeline::viewRanking(const Fingerprint& query) const {
  ViewRanking r;
  r.query_ = &query;
  r.span_deg_ = viewSpanDeg(query.background, query.background_cell);
  if (r.span_deg_ >= config_.verify.background_min_view_deg) return r;  // a full view
  r.context_ = viewContextOf(query, config_.view_search);
  r.matcher_ = std::make_shared<const ViewMatcher>(*r.context_);
  r.config_ = &config_.view_search;
  r.active_ = config_.view_search.enabled && r.context_->seesStructure();
  return r;
}

std::size_t Pipeline::backgroundCandidates(const Fingerprint& query) const {
  const bool narrow = config_.view_search.enabled && isNarrow(query);
  return static_cast<std::size_t>(narrow ? config_.view_search.background_candidates
                                         : config_.verify.background_candidates);
}

LoopResult Pipeline::match(const Fingerprint& query, const Fingerprint& candidate) const {
  LoopResult r = verify(query, candidate);
  refine(query, candidate, r);
  return r;
}

}  // namespace sglc
