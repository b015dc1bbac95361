// The engine's settings: every field of Config with its key, valid range and a line of documentation. The
// defaults are the struct's own initialisers (config.hpp); the rationale of the values marked "ours" is there.
#include "sglc/config.hpp"

namespace sglc {
namespace {

using namespace params;

// "verify.min_probability" and an accessor of config.verify.min_probability, from one spelling of the path.
#define SGLC_KEY(path) \
#path, [](auto& c) -> auto& { return c.path; }

void addLabels(Table<Config>& t) {
  // The preset comes first: assigning it replaces the lists, which the keys after it then edit.
  auto names = labelPresetNames();
  names.push_back("custom");
  t.add({Info{"labels.preset",
              Kind::kText,
              {},
              names,
              "named label set the id lists come from; custom: the lists below are the labels"},
         [](const Config& c) { return Value(c.labels.preset); },
         [](Config& c, const Value& v) {
           const auto& name = std::get<std::string>(v);
           if (name != "custom") c.labels = labelPreset(name);
           c.labels.preset = name;
         }});
  t.add(
      {Info{"labels.node_classes", Kind::kNamedIds, {}, {}, "landmark classes (graph nodes), in order, with their ids"},
       [](const Config& c) {
         std::vector<NamedIds> out;
         for (const auto& n : c.labels.node_classes) out.push_back({n.name, n.ids});
         return Value(out);
       },
       [](Config& c, const Value& v) {
         c.labels.node_classes.clear();
         for (const auto& n : std::get<std::vector<NamedIds>>(v)) c.labels.node_classes.push_back({n.name, n.ids});
       }});
  t.add(field<Config>(SGLC_KEY(labels.road), {}, "ids of road (background)"));
  t.add(field<Config>(SGLC_KEY(labels.building), {}, "ids of buildings (background)"));
  t.add(field<Config>(SGLC_KEY(labels.fence), {}, "ids of fences (background)"));
  t.add(field<Config>(SGLC_KEY(labels.vegetation), {}, "ids of vegetation (background)"));
  t.add(field<Config>(SGLC_KEY(labels.moving), {}, "ids never used as landmarks or background (moving objects)"));
  t.rule({"labels.node_classes"}, "1 to 16 classes",
         [](const Config& c) { return !c.labels.node_classes.empty() && c.labels.node_classes.size() <= 16; });
  // Lists edited after a preset are no longer that preset.
  t.onAssigned([](Config& c) {
    if (c.labels.preset == "custom") return;
    const auto preset = labelPreset(c.labels.preset);
    const auto& a = c.labels;
    const auto& b = preset;
    bool same = a.node_classes.size() == b.node_classes.size() && a.road == b.road && a.building == b.building &&
                a.fence == b.fence && a.vegetation == b.vegetation && a.moving == b.moving;
    for (std::size_t i = 0; same && i < a.node_classes.size(); ++i)
      same = a.node_classes[i].name == b.node_classes[i].name && a.node_classes[i].ids == b.node_classes[i].ids;
    if (!same) c.labels.preset = "custom";
  });
}

void addLabeller(Table<Config>& t) {
  t.add(field<Config>(SGLC_KEY(labeller.mode), {},
                      "built-in labeller: off (labels required), auto (label unlabelled scans, fill missing roles), "
                      "always (ignore given labels)",
                      {"off", "auto", "always"}));
  t.add(field<Config>(SGLC_KEY(labeller.max_range_m), openClosed(0, 320),
                      "points farther (horizontally) stay unlabelled"));
  t.add(field<Config>(SGLC_KEY(labeller.ground_cell_m), closed(0.5, 10), "ground column size (m)"));
  t.add(field<Config>(SGLC_KEY(labeller.ground_band_m), above(0),
                      "points this close above a column's floor fit its ground plane (m)"));
  t.add(field<Config>(SGLC_KEY(labeller.ground_tolerance_m), above(0),
                      "ground: within this of the plane, curbs included (m)"));
  t.add(field<Config>(SGLC_KEY(labeller.ground_max_step_m), atLeast(0),
                      "a column this far above two neighbours' ground has none of its own (m)"));
  t.add(field<Config>(SGLC_KEY(labeller.cell_m), closed(0.05, 2), "object column size (m)"));
  t.add(field<Config>(SGLC_KEY(labeller.link_m), atLeast(0),
                      "columns this close form one object; raise for sparse clouds (m)"));
  t.add(field<Config>(SGLC_KEY(labeller.low_band_m), atLeast(0),
                      "objects are found below this height, under canopies (m)"));
  t.add(field<Config>(SGLC_KEY(labeller.pole_max_width_m), atLeast(0), "pole-like: footprint at most this long (m)"));
  t.add(field<Config>(SGLC_KEY(labeller.pole_min_height_m), atLeast(0), "pole-like: at least this tall (m)"));
  t.add(
      field<Config>(SGLC_KEY(labeller.vehicle_min_length_m), atLeast(0), "vehicle footprint length, lower bound (m)"));
  t.add(
      field<Config>(SGLC_KEY(labeller.vehicle_max_length_m), atLeast(0), "vehicle footprint length, upper bound (m)"));
  t.add(field<Config>(SGLC_KEY(labeller.vehicle_max_width_m), atLeast(0), "vehicle footprint width, upper bound (m)"));
  t.add(field<Config>(SGLC_KEY(labeller.vehicle_min_height_m), atLeast(0), "vehicle height, lower bound (m)"));
  t.add(field<Config>(SGLC_KEY(labeller.vehicle_max_height_m), atLeast(0), "vehicle height, upper bound (m)"));
  t.add(field<Config>(SGLC_KEY(labeller.wall_min_length_m), atLeast(0), "wall: at least this long (m)"));
  t.add(field<Config>(SGLC_KEY(labeller.wall_max_width_m), atLeast(0), "wall: at most this thick (m)"));
  t.add(field<Config>(SGLC_KEY(labeller.wall_min_height_m), atLeast(0), "wall: at least this tall (m)"));
  // The ground grid is (2 max_range_m / ground_cell_m)^2 columns, allocated per scan.
  t.rule({"labeller.max_range_m", "labeller.ground_cell_m"}, "at most 200 cells apart",
         [](const Config& c) { return c.labeller.max_range_m / c.labeller.ground_cell_m <= 200; });
  t.rule({"labeller.link_m"}, "at most 10 x labeller.cell_m",
         [](const Config& c) { return c.labeller.link_m <= 10 * c.labeller.cell_m; });
  t.rule({"labeller.low_band_m"}, "> labeller.ground_tolerance_m",
         [](const Config& c) { return c.labeller.low_band_m > c.labeller.ground_tolerance_m; });
  t.rule({"labeller.vehicle_min_length_m", "labeller.vehicle_max_length_m"}, "min <= max",
         [](const Config& c) { return c.labeller.vehicle_min_length_m <= c.labeller.vehicle_max_length_m; });
  t.rule({"labeller.vehicle_min_height_m", "labeller.vehicle_max_height_m"}, "min <= max",
         [](const Config& c) { return c.labeller.vehicle_min_height_m <= c.labeller.vehicle_max_height_m; });
}

void addGraph(Table<Config>& t) {
  t.add(field<Config>(SGLC_KEY(cluster.azimuth_deg), openClosed(0, 90), "cluster voxel: azimuth step (deg)"));
  t.add(field<Config>(SGLC_KEY(cluster.range_m), above(0), "cluster voxel: range step (m)"));
  t.add(field<Config>(SGLC_KEY(cluster.elevation_deg), openClosed(0, 90), "cluster voxel: elevation step (deg)"));
  t.add(field<Config>(SGLC_KEY(cluster.min_points), atLeast(1), "clusters with fewer points are dropped"));
  t.add(field<Config>(SGLC_KEY(cluster.max_range_m), openClosed(0, 320),
                      "landmark points beyond this are ignored (m; fingerprints store centimetres in 16 bits)"));
  t.add(field<Config>(SGLC_KEY(graph.d_max), open(0, 1000), "edge between nodes closer than this (m)"));
  t.add(field<Config>(SGLC_KEY(graph.max_nodes), closed(3, 2000), "the largest instances are kept beyond this many"));
  t.add(field<Config>(SGLC_KEY(graph.min_extent_m), closed(0, 100),
                      "clusters shorter and lower than this are fragments, not landmarks (m)"));
  t.add(field<Config>(SGLC_KEY(descriptor.d_i), above(0), "histogram bin width (m); bins = d_max / d_i"));
  t.add(field<Config>(SGLC_KEY(descriptor.k_eigen), closed(1, 1000), "adjacency eigenvectors in the node descriptor"));
  t.add(field<Config>(SGLC_KEY(descriptor.rings), closed(1, 1000), "rings of the background spectrum"));
  t.add(field<Config>(SGLC_KEY(descriptor.orders), closed(0, 64), "highest angular order of the background spectrum"));
  t.add(field<Config>(SGLC_KEY(descriptor.ring_min_m), atLeast(0), "background spectrum inner radius (m)"));
  t.add(field<Config>(SGLC_KEY(descriptor.ring_max_m), finite(), "background spectrum outer radius (m)"));
  t.add(field<Config>(SGLC_KEY(descriptor.sectors), closed(1, 3600), "sectors of the background spectrum"));
  t.add(field<Config>(SGLC_KEY(descriptor.background_weight), closed(0, 1000),
                      "weight of the background spectrum against the graph part"));
  t.rule({"graph.d_max", "descriptor.d_i"}, "at most 1000 bins apart",
         [](const Config& c) { return c.graph.d_max / c.descriptor.d_i <= 1000; });
  t.rule({"descriptor.ring_min_m", "descriptor.ring_max_m"}, "min < max",
         [](const Config& c) { return c.descriptor.ring_max_m > c.descriptor.ring_min_m; });
  t.rule({"descriptor.orders", "descriptor.sectors"}, "orders below half the sectors",
         [](const Config& c) { return 2 * c.descriptor.orders < c.descriptor.sectors; });
  t.rule({"descriptor.rings", "descriptor.orders"}, "at most 65535 values",
         [](const Config& c) { return 2L * c.descriptor.rings * (c.descriptor.orders + 1) <= 65535; });
}

void addMatching(Table<Config>& t) {
  t.add(field<Config>(SGLC_KEY(match.d_b), atLeast(0), "largest difference of each box dimension (m)"));
  t.add(field<Config>(SGLC_KEY(match.min_cosine), closed(-1, 1), "node descriptor similarity floor"));
  t.add(field<Config>(SGLC_KEY(match.d_l), above(0), "neighbourhood radius of local triangles (m)"));
  t.add(field<Config>(SGLC_KEY(match.triangle_tol), atLeast(0), "side-length tolerance of \"same triangle\" (m)"));
  t.add(field<Config>(SGLC_KEY(match.t_m), atLeast(0), "triangles that must agree for a match to survive"));
  t.add(field<Config>(SGLC_KEY(match.prune_min_matches), atLeast(0), "prune only with at least this many matches"));
  t.add(
      field<Config>(SGLC_KEY(match.prune_min_kept), atLeast(0), "fewer kept than this: RANSAC gets the unpruned ones"));
  t.add(field<Config>(SGLC_KEY(match.consensus_max_nodes), closed(0, 64),
                      "a scan with at most this many nodes may be matched by geometric consensus (0: never)"));
  t.add(field<Config>(SGLC_KEY(match.consensus_min_cosine), closed(0, 1),
                      "descriptor floor of a consensus candidate (0: every compatible pair)"));
  t.add(field<Config>(SGLC_KEY(match.consensus_per_node), closed(1, 32),
                      "consensus candidates per node of the smaller graph"));
  t.add(field<Config>(SGLC_KEY(match.consensus_max_hypotheses), closed(1, 1e7),
                      "agreeing consensus triples examined at most (flat ones count)"));
  t.add(field<Config>(SGLC_KEY(ransac.inlier_threshold), above(0), "node-centre residual of an inlier (m)"));
  t.add(field<Config>(SGLC_KEY(ransac.max_iterations), closed(1, 1e6), "hypotheses (all triples when fewer)"));
  t.add(field<Config>(SGLC_KEY(ransac.seed), {}, "random seed: results never change run to run"));
  t.add(field<Config>(SGLC_KEY(ransac.min_triangle_height), atLeast(0), "flatter samples are degenerate, skipped (m)"));
  t.add(field<Config>(SGLC_KEY(ransac.min_inliers), atLeast(3), "inliers a pose needs"));
}

void addVerification(Table<Config>& t) {
  t.add(field<Config>(SGLC_KEY(verify.min_probability), closed(0, 1),
                      "a pair is a loop when the loop model's probability reaches this"));
  t.add(field<Config>(SGLC_KEY(verify.model), {}, "loop model file (tools/calibrate); empty: the built-in model"));
  t.add(field<Config>(SGLC_KEY(verify.max_translation), finite(),
                      "reject loops whose translation exceeds this (m); <= 0 disables"));
  t.add(field<Config>(SGLC_KEY(verify.fit_max_shift_m), finite(),
                      "the plane fit of a pose hypothesis may move it at most this far (m); <= 0: no fit"));
  t.add(field<Config>(SGLC_KEY(verify.fit_max_turn_deg), closed(0, 180),
                      "the plane fit of a pose hypothesis may turn it at most this much (deg)"));
  t.add(field<Config>(SGLC_KEY(verify.background_max_nodes), closed(0, 2000),
                      "background hypotheses for scans with at most this many landmarks (0: never)"));
  t.add(field<Config>(SGLC_KEY(verify.background_candidates), closed(0, 200),
                      "a query's first candidates that may get background hypotheses"));
  t.add(field<Config>(SGLC_KEY(verify.background_min_view_deg), closed(0, 360),
                      "a scan that saw less of the horizon is a narrow view (deg)"));
}

void addFingerprint(Table<Config>& t) {
  t.add(field<Config>(SGLC_KEY(fingerprint.instance_voxel_m), atLeast(0.01),
                      "instance points kept for fine ICP: voxel (m)"));
  t.add(field<Config>(SGLC_KEY(fingerprint.background_cell_m), atLeast(0.05),
                      "stored labelled background: BEV cell (m)"));
  t.add(
      field<Config>(SGLC_KEY(fingerprint.background_max_range_m), openClosed(0, 320), "stored background: range (m)"));
  t.add(field<Config>(SGLC_KEY(fingerprint.background_max_z_m), closed(-100, 1000),
                      "stored background: highest structure point above the sensor (m)"));
  t.add(field<Config>(SGLC_KEY(fingerprint.plane_voxel_m), above(0.05), "background plane features: voxel (m)"));
  t.add(field<Config>(SGLC_KEY(fingerprint.plane_min_points), atLeast(3), "points a plane voxel needs"));
  t.add(field<Config>(SGLC_KEY(fingerprint.plane_max_thickness_m), above(0),
                      "plane: largest sqrt of the smallest eigenvalue (m)"));
  t.add(field<Config>(SGLC_KEY(fingerprint.plane_max_range_m), openClosed(0, 320), "plane features: range (m)"));
  t.rule(
      {"fingerprint.background_max_range_m", "fingerprint.background_cell_m"}, "fewer than 32000 cells apart",
      [](const Config& c) { return c.fingerprint.background_max_range_m / c.fingerprint.background_cell_m < 32000; });
}

void addRefinement(Table<Config>& t) {
  t.add(field<Config>(SGLC_KEY(fine.enabled), {}, "fine stage: ICP on the matched instances' points"));
  t.add(field<Config>(SGLC_KEY(fine.max_iterations), atLeast(0), "fine stage: iterations"));
  t.add(field<Config>(SGLC_KEY(fine.max_corr_start_m), above(0), "fine stage: first correspondence gate (m)"));
  t.add(field<Config>(SGLC_KEY(fine.max_corr_end_m), above(0), "fine stage: last correspondence gate (m)"));
  t.add(field<Config>(SGLC_KEY(fine.huber_m), above(0), "fine stage: Huber kernel scale (m)"));
  t.add(field<Config>(SGLC_KEY(fine.converged_m), finite(), "fine stage: stop when an update moves less (m)"));
  t.add(field<Config>(SGLC_KEY(fine.min_correspondences), atLeast(3), "fine stage: point pairs its result needs"));
  t.add(field<Config>(SGLC_KEY(fine.max_shift_m), above(0), "fine stage: a larger move of the pose is refused (m)"));
  t.add(field<Config>(SGLC_KEY(fine.max_turn_deg), openClosed(0, 180), "fine stage: a larger turn is refused (deg)"));
  t.rule({"fine.max_corr_end_m", "fine.max_corr_start_m"}, "end <= start",
         [](const Config& c) { return c.fine.max_corr_end_m <= c.fine.max_corr_start_m; });
  t.add(field<Config>(SGLC_KEY(refine.enabled), {}, "refine stage: background planes (point-to-plane)"));
  t.add(field<Config>(SGLC_KEY(refine.max_iterations), atLeast(0), "refine stage: iterations"));
  t.add(field<Config>(SGLC_KEY(refine.max_corr_m), above(0), "refine stage: plane centroid association radius (m)"));
  t.add(field<Config>(SGLC_KEY(refine.min_normal_cosine), closed(0, 1), "refine stage: normals agree at least this"));
  t.add(field<Config>(SGLC_KEY(refine.cauchy_m), above(0), "refine stage: Cauchy kernel scale (m)"));
  t.add(field<Config>(SGLC_KEY(refine.instance_weight), atLeast(0), "refine stage: weight of the instance anchor"));
  t.add(field<Config>(
      SGLC_KEY(refine.min_information), atLeast(0),
      "horizontal directions (yaw, x, y) the planes constrain less than this (1/m^2) are held by the anchor"));
  t.add(field<Config>(SGLC_KEY(refine.converged_m), finite(), "refine stage: stop when an update moves less (m)"));
  t.add(field<Config>(SGLC_KEY(refine.max_shift_m), above(0),
                      "planes moving the pose farther are not trusted, nor do they confirm a loop (m)"));
  t.add(field<Config>(SGLC_KEY(refine.max_turn_deg), openClosed(0, 180),
                      "planes turning the pose more are not trusted, nor do they confirm a loop (deg)"));
  t.add(field<Config>(SGLC_KEY(refine.max_rmse_m), above(0),
                      "a plane fit anchored on the fine stage looser than this is tried without it (m)"));
  t.add(
      field<Config>(SGLC_KEY(bev_search.enabled), {}, "known loops: search a pose by overlaying the bird's-eye views"));
  t.add(field<Config>(SGLC_KEY(bev_search.cell_m), closed(0.25, 5), "BEV search: grid cell (m)"));
  t.add(field<Config>(SGLC_KEY(bev_search.max_shift_m), closed(0, 50), "BEV search: shift on each axis (m)"));
  t.add(field<Config>(SGLC_KEY(bev_search.yaw_step_deg), openClosed(0.1, 30), "BEV search: heading step (deg)"));
  t.add(field<Config>(SGLC_KEY(bev_search.max_range_m), openClosed(0, 100), "BEV search: cells used (m)"));
  t.add(field<Config>(SGLC_KEY(bev_search.keep), closed(1, 20), "BEV search: distinct overlays refined"));
  t.add(
      field<Config>(SGLC_KEY(bev_search.min_correspondences), atLeast(3), "BEV search: plane pairs an overlay needs"));
  t.add(field<Config>(SGLC_KEY(view_search.enabled), {},
                      "narrow views: candidates ranked by the view context, overlays at its heading"));
  t.add(field<Config>(SGLC_KEY(view_search.max_range_m), closed(10, 100),
                      "view context and view agreement: structure used (m)"));
  t.add(field<Config>(SGLC_KEY(view_search.max_scans), closed(1, 10000),
                      "view context: scans a narrow query is compared with (nearest by descriptor)"));
  t.add(field<Config>(SGLC_KEY(view_search.background_candidates), closed(0, 200),
                      "a narrow query's first candidates that may get background hypotheses"));
}

#undef SGLC_KEY

Table<Config> makeTable() {
  Table<Config> t;
  addLabels(t);
  addLabeller(t);
  addGraph(t);
  addMatching(t);
  addVerification(t);
  addFingerprint(t);
  addRefinement(t);
  return t;
}

}  // namespace

const params::Table<Config>& engineParams() {
  static const params::Table<Config> table = makeTable();
  return table;
}

void validateConfig(const Config& config) { engineParams().validate(config); }

}  // namespace sglc
