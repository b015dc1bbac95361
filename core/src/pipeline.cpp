#include "sglc/pipeline.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "fast_math.hpp"
#include "sglc/bev_search.hpp"
#include "sglc/consensus.hpp"
#include "sglc/labeller.hpp"
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

bool sameGeometry(const Fingerprint& a, const Fingerprint& b) {
  return a.layout.num_classes == b.layout.num_classes && a.layout.bins == b.layout.bins &&
         a.layout.k_eigen == b.layout.k_eigen && a.layout.rings == b.layout.rings && a.d_max == b.d_max &&
         a.d_i == b.d_i && a.background_cell == b.background_cell && a.plane_voxel == b.plane_voxel;
}

double rotationAngleDeg(const Mat3d& R) {
  return std::acos(std::clamp((R.trace() - 1.0) / 2.0, -1.0, 1.0)) * 180.0 / std::numbers::pi;
}

// RANSAC over the matched node centres (not found with fewer than 3 matches).
RansacResult coarsePose(const Fingerprint& query, const Fingerprint& candidate, const std::vector<Match>& matches,
                        const RansacConfig& config) {
  if (matches.size() < 3) return {};
  std::vector<Vec3d> q, t;
  for (const auto& [i, j] : matches) {
    q.push_back(query.nodes[i].center.cast<double>());
    t.push_back(candidate.nodes[j].center.cast<double>());
  }
  return ransacRigid(q, t, config);
}

}  // namespace

Pipeline::Pipeline(Config config) : config_(std::move(config)), labels_((validateConfig(config_), config_.labels)) {}

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

  const auto clusters = clusterInstances(node_points, node_class, c.cluster);
  std::vector<int> kept;
  fp.nodes = buildNodes(node_points, clusters, c.graph, &kept);
  fp.instance_offsets.assign(1, 0);
  for (int k : kept) {
    downsampleInstance(node_points, clusters[k], c.fingerprint.instance_voxel_m, fp.instance_points);
    fp.instance_offsets.push_back(static_cast<std::uint32_t>(fp.instance_points.size()));
  }
  fp.background =
      bevCells(bg_points, background, c.fingerprint.background_cell_m, c.fingerprint.background_max_range_m);
  fp.planes = extractPlanes(bg_points, background, c.fingerprint);
  fp.descriptor = scanDescriptor(fp.nodes, ringKey(bg_points, background, c.descriptor), fp.layout, fp.d_max, fp.d_i);
  fp.finalize();
  if (n > 0 && node_points.empty() && bg_points.empty())
    rep.warnings.push_back("no point carries a label the active label map (labels.preset: " + c.labels.preset +
                           ") uses: check the label set, or send the scan without labels");
  else if (fp.nodes.size() < 3)
    rep.warnings.push_back("only " + std::to_string(fp.nodes.size()) +
                           " landmarks (vehicle, trunk and pole instances): loops cannot be verified from this scan");
  return fp;
}

LoopResult Pipeline::verify(const Fingerprint& query, const Fingerprint& candidate) const {
  if (!sameGeometry(query, candidate))
    throw InputError("fingerprints were built with different descriptor or voxel parameters");
  const auto& c = config_;
  LoopResult r;
  auto matches = matchNodes(query.nodes, query.node_descriptors, candidate.nodes, candidate.node_descriptors, c.match);
  if (auto pruned = pruneMatches(query.nodes, candidate.nodes, matches, c.match);
      static_cast<int>(pruned.size()) >= c.match.prune_min_kept)
    matches = std::move(pruned);
  auto ransac = coarsePose(query, candidate, matches, c.ransac);
  // Small graphs: descriptors too unstable to pair nodes; let geometry pair them. Pairs found by geometry
  // alone carry less evidence, so their graph similarity must reach the stricter consensus_t_g.
  double t_g = c.verify.t_g;
  if (!ransac.found && consensusApplies(c.match, query.nodes.size(), candidate.nodes.size())) {
    auto agreed = consensusMatches(query.nodes, query.node_descriptors, candidate.nodes, candidate.node_descriptors,
                                   c.match, c.ransac);
    if (auto second = coarsePose(query, candidate, agreed, c.ransac); second.found) {
      matches = std::move(agreed);
      ransac = std::move(second);
      t_g = std::max(t_g, c.match.consensus_t_g);
    }
  }
  r.matches = static_cast<int>(matches.size());
  if (!ransac.found) {
    r.reason = r.matches < 3 ? "fewer than 3 node matches" : "no pose agrees with enough node matches";
    return r;
  }
  r.T = ransac.T;
  r.inliers = static_cast<int>(ransac.inliers.size());
  r.graph_similarity = std::exp(-ransac.mean_residual);
  r.background_similarity = bevAgreement(query.background, candidate.background, query.background_cell, r.T,
                                         c.verify.bev_cell_m, c.verify.bev_radius_m);
  const double translation = r.T.topRightCorner<3, 1>().norm();
  r.score = r.graph_similarity * r.background_similarity * (1.0 - std::exp(-r.inliers / 3.0));
  // Nearer revisits rank first: they share more of the scene, so their pose is the more reliable.
  if (c.verify.score_distance_m > 0) r.score *= std::exp(-translation / c.verify.score_distance_m);
  if (r.graph_similarity < t_g)
    r.reason = t_g > c.verify.t_g ? "graph similarity below match.consensus_t_g (nodes paired by consensus)"
                                  : "graph similarity below t_g";
  else if (r.background_similarity < c.verify.t_b)
    r.reason = "background similarity below t_b";
  else if (c.verify.max_translation > 0 && translation > c.verify.max_translation)
    r.reason = "translation exceeds verify.max_translation";
  else
    r.is_loop = true;
  // Few node inliers are weak evidence (three or four landmarks align by chance between look-alike streets):
  // such a loop stands only if the background planes, aligned from the coarse pose, agree with it.
  if (r.is_loop && r.inliers < c.verify.confirm_below_inliers) {
    const auto planes = refinePlanes(query.planes, query.plane_index, candidate.planes, {}, r.T, c.refine);
    const Mat4d d = r.T.inverse() * planes.T;  // confirming means staying near the coarse pose
    if (planes.iterations == 0 || planes.fitness < c.verify.confirm_min_fitness ||
        planes.rmse > c.verify.confirm_max_rmse_m || planes.horizontal_constraint < c.verify.confirm_min_constraint ||
        d.topRightCorner<3, 1>().norm() > c.refine.max_shift_m ||
        rotationAngleDeg(d.topLeftCorner<3, 3>()) > c.refine.max_turn_deg) {
      r.is_loop = false;
      r.reason = "few node inliers and the background planes do not confirm the pose";
    }
  }
  // The inlier node pairs, for the fine stage.
  r.inlier_pairs.reserve(ransac.inliers.size());
  for (int k : ransac.inliers) r.inlier_pairs.push_back(matches[k]);
  return r;
}

void Pipeline::refine(const Fingerprint& query, const Fingerprint& candidate, LoopResult& r, bool known_loop) const {
  if (r.refined || !(r.is_loop || known_loop)) return;
  const auto& c = config_;
  const bool planes_kept = r.inliers >= 3 && refinePose(query, candidate, r);
  // A known loop whose pose the landmarks may have got wrong (no coarse pose, a pose verification rejected, or
  // one the plane stage would have moved beyond its guard): overlay the background views as well, refine the
  // best overlays on the planes, and keep whichever pose explains most of the candidate's planes.
  if (!known_loop || (r.is_loop && planes_kept) || !c.bev_search.enabled || !c.refine.enabled) return;
  for (const auto& h : searchBevPose(query.background, candidate.background, query.background_cell, c.bev_search)) {
    const auto ref = refinePlanes(query.planes, query.plane_index, candidate.planes, {}, h.T, c.refine);
    if (ref.iterations == 0 || ref.correspondences < c.bev_search.min_correspondences) continue;
    if (r.refined && (ref.fitness < r.fitness || (ref.fitness == r.fitness && ref.rmse >= r.rmse))) continue;
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
    const Mat4d d = r.T.inverse() * icp.T;
    if (icp.correspondences >= c.fine.min_correspondences && d.topRightCorner<3, 1>().norm() < c.fine.max_shift_m &&
        rotationAngleDeg(d.topLeftCorner<3, 3>()) < c.fine.max_turn_deg) {
      T = icp.T;
      r.fitness = icp.fitness;
      r.rmse = icp.rmse;
      r.information = pointPairInformation(icp.pairs, T, icp.rmse);
      anchor = std::move(icp.pairs);
    }
  }
  bool kept = false;
  if (c.refine.enabled) {
    auto ref = refinePlanes(query.planes, query.plane_index, candidate.planes, anchor, T, c.refine);
    const Mat4d d = T.inverse() * ref.T;
    kept = ref.iterations > 0 && d.topRightCorner<3, 1>().norm() < c.refine.max_shift_m &&
           rotationAngleDeg(d.topLeftCorner<3, 3>()) < c.refine.max_turn_deg;
    if (kept) {
      T = ref.T;
      r.information = ref.information;
    } else if (ref.iterations > 0) {
      // Guard: the planes moved too far to trust; report how well they fit at the pose that stays.
      RefineConfig at = c.refine;
      at.max_iterations = 0;
      ref = refinePlanes(query.planes, query.plane_index, candidate.planes, {}, T, at);
    }
    r.fitness = ref.fitness;
    r.rmse = ref.rmse;
  }
  r.T = T;
  r.refined = true;
  return kept;
}

LoopResult Pipeline::match(const Fingerprint& query, const Fingerprint& candidate) const {
  LoopResult r = verify(query, candidate);
  refine(query, candidate, r);
  return r;
}

}  // namespace sglc
