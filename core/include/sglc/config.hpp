// Every parameter of the engine, in one struct. Defaults are the paper's (Table "parameter settings")
// where it gives one, otherwise the published code's, otherwise ours (marked "ours").
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "sglc/params.hpp"

namespace sglc {

// Semantic roles: which raw label ids are landmark classes (graph nodes) and which are background.
struct LabelConfig {
  struct NodeClass {
    std::string name;
    std::vector<std::uint32_t> ids;
  };
  // Graph node classes, in order. Descriptor sizes follow their count (3 classes -> D=120, D'=231).
  std::vector<NodeClass> node_classes{{"vehicle", {10, 18, 20}}, {"trunk", {71}}, {"pole", {80}}};
  std::vector<std::uint32_t> road{40};
  std::vector<std::uint32_t> building{50};
  std::vector<std::uint32_t> fence{51};
  std::vector<std::uint32_t> vegetation{70};
  // Ids that are never landmarks nor background, even if listed above (moving objects).
  std::vector<std::uint32_t> moving{252, 253, 254, 255, 256, 257, 258, 259};
  // The named set these lists came from ("semantickitti", "semantickitti-train", "nuscenes"), or "custom".
  std::string preset = "semantickitti";
};

// The label sets this build knows: SemanticKITTI raw ids (the default), SemanticKITTI's 19 training ids,
// nuScenes-lidarseg's 32 classes (no pole or trunk class: the labeller fills them in "auto" mode). Throws
// InputError naming the known presets for any other name.
LabelConfig labelPreset(const std::string& name);
const std::vector<std::string>& labelPresetNames();

struct ClusterConfig {
  // Range-adaptive ("curved") voxels: azimuth x range x elevation. Not tied to any sensor's beam layout.
  double azimuth_deg = 2.0;
  double range_m = 1.0;
  double elevation_deg = 2.0;
  int min_points = 10;        // clusters with fewer points are dropped
  double max_range_m = 80.0;  // node-class points beyond this are ignored
};

struct GraphConfig {
  double d_max = 60.0;  // edge if node centres are closer than this (m)
  int max_nodes = 200;  // ours: the largest instances are kept if a scan has more
  // Ours: a cluster whose length and height are both below this (m) is a fragment, not a landmark: pieces of a
  // mislabelled blob or of a passing car broken up at close range. Real trunks and poles are taller (the
  // shortest of 72 in five SemanticKITTI scans: 0.83 m).
  double min_extent_m = 0.5;
};

struct DescriptorConfig {
  double d_i = 2.0;  // distance bin width of node and edge histograms (m); bins = d_max / d_i
  int k_eigen = 30;  // eigenvectors of the adjacency matrix used in the node descriptor
  // Background part of the scan descriptor (ours): the stored BEV's structure cells (building and fence;
  // vegetation) between ring_min_m and ring_max_m fall in `rings` rings of `sectors` sectors; per part and ring,
  // the magnitudes of the occupancy's angular Fourier series, orders 0 to `orders` (rotation invariant). It is
  // weighted by background_weight against the graph part (node counts and edges): the background outlasts parked
  // cars and is seen alike by every LiDAR in the stored height band, while the number of landmarks a scan holds
  // changes with the sensor (docs/METHOD.md, section 4).
  int rings = 8;
  int orders = 2;
  double ring_min_m = 5.0;
  double ring_max_m = 50.0;
  int sectors = 360;
  double background_weight = 3.0;
};

struct MatchConfig {
  double d_b = 2.0;            // max difference of each box dimension (m)
  double min_cosine = 0.5;     // node descriptor similarity floor
  double d_l = 20.0;           // neighbourhood radius for local triangles (m)
  double triangle_tol = 0.25;  // side-length tolerance for "same triangle" (m; reference value)
  int t_m = 2;                 // triangles that must agree for a match to survive
  int prune_min_matches = 15;  // prune only when at least this many matches (reference behaviour)
  // Ours: when pruning keeps fewer matches than this, RANSAC gets the unpruned ones instead. Triangles need
  // two neighbours placed within triangle_tol in both scans; under label noise or a large change of heading
  // they can all fail for a true loop, while RANSAC and the verification still reject false ones.
  int prune_min_kept = 6;
  // Ours: consensus matching (sglc/consensus.hpp) for small graphs. When either scan has at most this many
  // nodes and the descriptor matches give no pose, every compatible node pair becomes a candidate and the
  // largest set one rigid motion aligns is kept. 0 switches it off.
  int consensus_max_nodes = 16;
  double consensus_min_cosine = 0.0;     // descriptor similarity floor of a candidate pair (0: no floor)
  int consensus_per_node = 8;            // candidates kept per node of the smaller graph (most similar first)
  int consensus_max_hypotheses = 20000;  // agreeing triples examined at most (flat ones count), seeded order
};

struct RansacConfig {
  double inlier_threshold = 1.0;       // node-centre residual (m)
  int max_iterations = 2000;           // hypotheses; all triples are tried when there are fewer
  std::uint64_t seed = 0x5eed5ca1ULL;  // fixed: results never change run to run
  double min_triangle_height = 0.5;    // samples flatter than this (m) are degenerate and skipped
  int min_inliers = 3;
};

// The loop decision (docs/METHOD.md, section 8): pose hypotheses from named sources (sglc/evidence.hpp), each
// refined by one guarded plane fit, judged by one model (sglc/loop_model.hpp); a pair is a loop when the model's
// probability reaches min_probability and its translation is within max_translation.
struct VerifyConfig {
  // The probability a loop needs: raise it for fewer false loops, lower it for more loops. On the fitting worlds
  // (tools/calibrate/fit.py over scripts/calibrate.sh's evidence, a pose true within 2 m and 5 deg) each query's
  // top-1 answer had a precision of 0.9926 at 0.5 and 0.9956 at 0.8, answering 98.4 % and 97.4 % of the queries
  // with a true hypothesis. 0.8 keeps a margin: at 0.5 the validation worlds got three false answers (p 0.51 to
  // 0.64) and wedges of real non-loop scans four (p 0.54 to 0.61), none at 0.8 (docs/RESULTS.md).
  double min_probability = 0.8;
  // A loop model file (tools/calibrate writes them); empty: the model built into the engine.
  std::string model;
  double max_translation = 10.0;  // reject loops whose translation exceeds this (m); <= 0 disables
  // The plane fit that refines every hypothesis may move it at most this far; a fit that moves it more is
  // dropped (the hypothesis is judged without plane evidence). <= 0: no plane fit.
  double fit_max_shift_m = 3.0;
  double fit_max_turn_deg = 15.0;
  // Pose hypotheses from the background alone (bird's-eye overlays at the walls' headings, or for a narrow
  // view at its view context's) are sought when the landmarks' hypothesis does not reach min_probability and
  // either scan has at most background_max_nodes landmarks (0: never), for the first background_candidates
  // candidates of a query (view_search.background_candidates for a narrow query): they cost milliseconds.
  int background_max_nodes = 24;
  int background_candidates = 3;
  // A scan that saw less of the horizon than this (viewSpanDeg) is a narrow view: agreement is judged over its
  // field, its candidates are ranked by view context, and its overlays are searched at the context's heading.
  double background_min_view_deg = 180.0;
};

struct FingerprintConfig {
  double instance_voxel_m = 0.25;  // downsampling of instance points kept for fine ICP
  double background_cell_m = 0.5;  // BEV cell of the stored labelled background cloud
  double background_max_range_m = 50.0;
  // Ours: structure points (building, fence, vegetation) higher than this above the sensor are left out of the
  // stored BEV, so that it holds the band every LiDAR sees: an HDL-64 looks at most 2 deg up, a VLP-16 15 deg
  // and an OS1 22.5 deg, so without the band tree crowns and upper storeys over the street turned road cells
  // into vegetation or building for one sensor and not for another.
  double background_max_z_m = 1.0;
  double plane_voxel_m = 1.0;  // background plane features
  int plane_min_points = 8;
  double plane_max_thickness_m = 0.08;  // sqrt of the smallest eigenvalue of the voxel's covariance
  double plane_max_range_m = 60.0;
};

struct FineConfig {
  bool enabled = true;
  int max_iterations = 30;
  double max_corr_start_m = 1.5;  // correspondence gate, shrinking to max_corr_end_m
  double max_corr_end_m = 0.5;
  double huber_m = 0.2;
  double converged_m = 1e-4;  // stop when the update moves less than this
  // Guard (ours): the fine stage only polishes the coarse pose. Its result is dropped when it rests on fewer
  // than min_correspondences point pairs or moves the pose by more than max_shift_m / max_turn_deg: then it
  // locked onto something else. The refine stage may still drop it (RefineConfig::max_rmse_m).
  int min_correspondences = 3;
  double max_shift_m = 2.0;
  double max_turn_deg = 10.0;
};

struct RefineConfig {
  bool enabled = true;
  int max_iterations = 15;
  double max_corr_m = 1.0;         // plane centroid association radius
  double min_normal_cosine = 0.9;  // normals must agree this well
  double cauchy_m = 0.1;           // robust kernel scale of plane residuals
  double instance_weight = 1.0;    // weight of instance point residuals kept as anchor
  // Directions whose plane information (Hessian eigenvalue, rotations scaled by a 10 m lever arm, in 1/m^2)
  // is below this are degenerate for the planes (a straight corridor); only there, and only among the horizontal
  // directions (yaw, x, y), the anchor acts: roll, pitch and height always stay with the planes.
  double min_information = 5.0;
  double converged_m = 1e-5;
  // Guard (ours): the planes may move the pose they start from by at most this much. Beyond it the refinement
  // is not trusted (the pose before it stays; see max_rmse_m for the fine stage's pose) and a loop with few node
  // inliers is not confirmed.
  double max_shift_m = 1.0;
  double max_turn_deg = 5.0;
  // Guard (ours): when the planes, anchored on the fine stage's point pairs, end with an RMSE above this, they
  // run again from the coarse pose without the pairs; that fit stands (the fine stage's pose is dropped: its
  // instance points locked onto something else) when it is within the shift / turn guard and this RMSE and
  // explains at least as many of the candidate's planes.
  double max_rmse_m = 0.1;
};

// Ours (not in the paper): the pose of a pair the caller knows to be a loop when the landmarks give none or
// verification rejects the one they give (Pipeline::refine with known_loop): a search over heading and shift
// overlaying the two labelled bird's-eye views, then the plane refinement from the best `keep` overlays; the
// result with the most evidence stands (plane fitness x background agreement x Cauchy weight of the plane RMSE).
struct BevSearchConfig {
  bool enabled = true;
  double cell_m = 1.0;          // coarse grid of the search
  double max_shift_m = 10.0;    // on each axis
  double yaw_step_deg = 2.0;    // coarse heading step (all headings are searched)
  double max_range_m = 40.0;    // candidate cells used
  int keep = 3;                 // distinct overlays refined
  int min_correspondences = 6;  // plane pairs a refined overlay needs to stand
};

// Ours: narrow views (a solid-state sensor's 70 deg; any scan that saw less than
// verify.background_min_view_deg of the horizon, viewSpanDeg). Their scan descriptor, a full turn's summary,
// ranks the true place near the middle of the map, and their walls alone overlay on many streets. The view
// context (sglc/view_context.hpp) compares where structure lies around the sensor only in the directions the
// narrow view saw, at every heading: a LoopFinder ranks a narrow query's candidates by it (among the
// max_scans nearest by descriptor that the scope allows), and a background-only loop of a narrow view searches
// the overlay only near the heading it gives. Simulated rosette queries against an HDL-64 map (docs/RESULTS.md,
// seeds 11 and 12): the true place first for 0.84-0.88 of them, within ten for 0.97-0.99. enabled false: narrow
// views get descriptor retrieval and no background-only loop. A query whose context holds nothing (no structure in
// view) keeps the descriptor's candidates.
struct ViewSearchConfig {
  bool enabled = true;
  // 30 rings to 45 m (1.5 m each): single rosette frames against an HDL-64 map with the true place first, 498 of
  // 568 on seed 11 and 476 on seed 12, against 367 and 348 with 20 rings to 30 m (120 sectors in both). Part of
  // the view context's definition: no configuration key sets it.
  int rings = 30;
  double max_range_m = 45.0;
  // The map's search returns at most 10,000 scans. Each one compared costs a fingerprint read (from the store's
  // cache when it holds it) and about 54 us of CPU; a map larger than this compares only its nearest by descriptor.
  int max_scans = 10000;
  // A narrow query's candidates that get background hypotheses (the context ranks the true place within the
  // first 10 for 0.98 of rosette queries).
  int background_candidates = 10;
  // The shifts kept at each heading step of a narrow view's overlay search (walls along a street overlay alike
  // all along it): part of the `view` source's definition: no configuration key sets it.
  int shifts_per_heading = 3;
};

// Ours: the built-in labeller for scans without labels (sglc/labeller.hpp). mode: "off" (labels required),
// "auto" (label unlabelled scans; in labelled ones fill the roles the label map has no ids for, e.g. poles and
// trunks for nuScenes-lidarseg), "always" (ignore given labels).
struct LabellerConfig {
  std::string mode = "auto";
  double max_range_m = 80.0;        // points farther (horizontally) are not labelled
  double ground_cell_m = 2.0;       // ground columns
  double ground_band_m = 0.3;       // points this close above a column's floor fit its ground plane
  double ground_tolerance_m = 0.2;  // ground = within this of the plane (curbs included)
  double ground_max_step_m = 0.25;  // a column this far above two neighbours' ground planes has none of its own
  double cell_m = 0.25;             // object columns
  double link_m = 0.25;             // columns this close belong to one object (raise for sparse clouds)
  double low_band_m = 2.0;          // objects are found in the band below this height (under canopies)
  double pole_max_width_m = 1.0;    // pole-like: footprint at most this long ...
  double pole_min_height_m = 1.2;   // ... and at least this tall
  double vehicle_min_length_m = 1.5, vehicle_max_length_m = 6.5, vehicle_max_width_m = 3.0;
  double vehicle_min_height_m = 0.8, vehicle_max_height_m = 2.6;
  double wall_min_length_m = 3.0, wall_max_width_m = 0.8, wall_min_height_m = 1.8;
};

struct Config {
  LabelConfig labels;
  LabellerConfig labeller;
  ClusterConfig cluster;
  GraphConfig graph;
  DescriptorConfig descriptor;
  MatchConfig match;
  RansacConfig ransac;
  VerifyConfig verify;
  FingerprintConfig fingerprint;
  FineConfig fine;
  RefineConfig refine;
  BevSearchConfig bev_search;
  ViewSearchConfig view_search;
};

// Every field with its key ("verify.t_g"), valid range and a line of documentation; files and command lines
// are read through it (sglc/config/engine_file.hpp), and docs/CONFIGURATION.md is generated from it.
const params::Table<Config>& engineParams();

// Throws InputError naming the first field out of its valid range or the first rule between fields broken.
void validateConfig(const Config& config);

}  // namespace sglc
