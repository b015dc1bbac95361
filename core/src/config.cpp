#include "sglc/config.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <variant>

#include "sglc/types.hpp"

namespace sglc {
namespace {

using FieldRef = std::variant<double*, int*, bool*, std::uint64_t*, std::vector<std::uint32_t>*, std::string*>;

// Every scalar parameter, by "section.key". The YAML reader and the validator both use this table, so a
// new field only has to be added here to become configurable.
std::map<std::string, FieldRef> fields(Config& c) {
  return {
      {"labels.road", &c.labels.road},
      {"labels.building", &c.labels.building},
      {"labels.fence", &c.labels.fence},
      {"labels.vegetation", &c.labels.vegetation},
      {"labels.moving", &c.labels.moving},
      {"labels.preset", &c.labels.preset},
      {"labeller.mode", &c.labeller.mode},
      {"labeller.max_range_m", &c.labeller.max_range_m},
      {"labeller.ground_cell_m", &c.labeller.ground_cell_m},
      {"labeller.ground_band_m", &c.labeller.ground_band_m},
      {"labeller.ground_tolerance_m", &c.labeller.ground_tolerance_m},
      {"labeller.ground_max_step_m", &c.labeller.ground_max_step_m},
      {"labeller.cell_m", &c.labeller.cell_m},
      {"labeller.link_m", &c.labeller.link_m},
      {"labeller.low_band_m", &c.labeller.low_band_m},
      {"labeller.pole_max_width_m", &c.labeller.pole_max_width_m},
      {"labeller.pole_min_height_m", &c.labeller.pole_min_height_m},
      {"labeller.vehicle_min_length_m", &c.labeller.vehicle_min_length_m},
      {"labeller.vehicle_max_length_m", &c.labeller.vehicle_max_length_m},
      {"labeller.vehicle_max_width_m", &c.labeller.vehicle_max_width_m},
      {"labeller.vehicle_min_height_m", &c.labeller.vehicle_min_height_m},
      {"labeller.vehicle_max_height_m", &c.labeller.vehicle_max_height_m},
      {"labeller.wall_min_length_m", &c.labeller.wall_min_length_m},
      {"labeller.wall_max_width_m", &c.labeller.wall_max_width_m},
      {"labeller.wall_min_height_m", &c.labeller.wall_min_height_m},
      {"cluster.azimuth_deg", &c.cluster.azimuth_deg},
      {"cluster.range_m", &c.cluster.range_m},
      {"cluster.elevation_deg", &c.cluster.elevation_deg},
      {"cluster.min_points", &c.cluster.min_points},
      {"cluster.max_range_m", &c.cluster.max_range_m},
      {"graph.d_max", &c.graph.d_max},
      {"graph.max_nodes", &c.graph.max_nodes},
      {"graph.min_extent_m", &c.graph.min_extent_m},
      {"descriptor.d_i", &c.descriptor.d_i},
      {"descriptor.k_eigen", &c.descriptor.k_eigen},
      {"descriptor.rings", &c.descriptor.rings},
      {"descriptor.ring_min_m", &c.descriptor.ring_min_m},
      {"descriptor.ring_max_m", &c.descriptor.ring_max_m},
      {"descriptor.sectors", &c.descriptor.sectors},
      {"match.d_b", &c.match.d_b},
      {"match.min_cosine", &c.match.min_cosine},
      {"match.d_l", &c.match.d_l},
      {"match.triangle_tol", &c.match.triangle_tol},
      {"match.t_m", &c.match.t_m},
      {"match.prune_min_matches", &c.match.prune_min_matches},
      {"match.prune_min_kept", &c.match.prune_min_kept},
      {"ransac.inlier_threshold", &c.ransac.inlier_threshold},
      {"ransac.max_iterations", &c.ransac.max_iterations},
      {"ransac.seed", &c.ransac.seed},
      {"ransac.min_triangle_height", &c.ransac.min_triangle_height},
      {"ransac.min_inliers", &c.ransac.min_inliers},
      {"verify.t_g", &c.verify.t_g},
      {"verify.t_b", &c.verify.t_b},
      {"verify.max_translation", &c.verify.max_translation},
      {"verify.confirm_below_inliers", &c.verify.confirm_below_inliers},
      {"verify.confirm_min_fitness", &c.verify.confirm_min_fitness},
      {"verify.confirm_max_rmse_m", &c.verify.confirm_max_rmse_m},
      {"verify.confirm_min_constraint", &c.verify.confirm_min_constraint},
      {"verify.score_distance_m", &c.verify.score_distance_m},
      {"verify.bev_cell_m", &c.verify.bev_cell_m},
      {"verify.bev_radius_m", &c.verify.bev_radius_m},
      {"fingerprint.instance_voxel_m", &c.fingerprint.instance_voxel_m},
      {"fingerprint.background_cell_m", &c.fingerprint.background_cell_m},
      {"fingerprint.background_max_range_m", &c.fingerprint.background_max_range_m},
      {"fingerprint.plane_voxel_m", &c.fingerprint.plane_voxel_m},
      {"fingerprint.plane_min_points", &c.fingerprint.plane_min_points},
      {"fingerprint.plane_max_thickness_m", &c.fingerprint.plane_max_thickness_m},
      {"fingerprint.plane_max_range_m", &c.fingerprint.plane_max_range_m},
      {"fine.enabled", &c.fine.enabled},
      {"fine.max_iterations", &c.fine.max_iterations},
      {"fine.max_corr_start_m", &c.fine.max_corr_start_m},
      {"fine.max_corr_end_m", &c.fine.max_corr_end_m},
      {"fine.huber_m", &c.fine.huber_m},
      {"fine.converged_m", &c.fine.converged_m},
      {"refine.enabled", &c.refine.enabled},
      {"refine.max_iterations", &c.refine.max_iterations},
      {"refine.max_corr_m", &c.refine.max_corr_m},
      {"refine.min_normal_cosine", &c.refine.min_normal_cosine},
      {"refine.cauchy_m", &c.refine.cauchy_m},
      {"refine.instance_weight", &c.refine.instance_weight},
      {"refine.min_information", &c.refine.min_information},
      {"refine.converged_m", &c.refine.converged_m},
      {"bev_search.enabled", &c.bev_search.enabled},
      {"bev_search.cell_m", &c.bev_search.cell_m},
      {"bev_search.max_shift_m", &c.bev_search.max_shift_m},
      {"bev_search.yaw_step_deg", &c.bev_search.yaw_step_deg},
      {"bev_search.max_range_m", &c.bev_search.max_range_m},
      {"bev_search.keep", &c.bev_search.keep},
  };
}

bool sameLists(const LabelConfig& a, const LabelConfig& b) {
  if (a.node_classes.size() != b.node_classes.size()) return false;
  for (std::size_t i = 0; i < a.node_classes.size(); ++i)
    if (a.node_classes[i].name != b.node_classes[i].name || a.node_classes[i].ids != b.node_classes[i].ids)
      return false;
  return a.road == b.road && a.building == b.building && a.fence == b.fence && a.vegetation == b.vegetation &&
         a.moving == b.moving;
}

void require(bool ok, const std::string& field, const std::string& rule) {
  if (!ok) throw InputError("config: " + field + " must be " + rule);
}

}  // namespace

void validateConfig(const Config& config) {
  Config copy = config;
  for (const auto& [name, ref] : fields(copy)) {
    if (auto d = std::get_if<double*>(&ref)) require(std::isfinite(**d), name, "finite");
  }
  const auto& c = config;
  require(!c.labels.node_classes.empty() && c.labels.node_classes.size() <= 16, "labels.node_classes",
          "1 to 16 classes");
  require(c.cluster.azimuth_deg > 0 && c.cluster.azimuth_deg <= 90, "cluster.azimuth_deg", "in (0, 90]");
  require(c.cluster.range_m > 0, "cluster.range_m", "> 0");
  require(c.cluster.elevation_deg > 0 && c.cluster.elevation_deg <= 90, "cluster.elevation_deg", "in (0, 90]");
  require(c.cluster.min_points >= 1, "cluster.min_points", ">= 1");
  require(c.cluster.max_range_m > 0 && c.cluster.max_range_m < 1000, "cluster.max_range_m", "in (0, 1000)");
  require(c.graph.d_max > 0 && c.graph.d_max < 1000, "graph.d_max", "in (0, 1000)");
  require(c.graph.max_nodes >= 3 && c.graph.max_nodes <= 2000, "graph.max_nodes", "in [3, 2000]");
  require(c.graph.min_extent_m >= 0 && c.graph.min_extent_m <= 100, "graph.min_extent_m", "in [0, 100]");
  require(c.descriptor.d_i > 0 && c.graph.d_max / c.descriptor.d_i <= 1000, "descriptor.d_i",
          "> 0 with d_max / d_i <= 1000");
  require(c.descriptor.k_eigen >= 1 && c.descriptor.k_eigen <= 1000, "descriptor.k_eigen", "in [1, 1000]");
  require(c.descriptor.rings >= 1 && c.descriptor.rings <= 1000, "descriptor.rings", "in [1, 1000]");
  require(c.descriptor.ring_min_m >= 0 && c.descriptor.ring_max_m > c.descriptor.ring_min_m,
          "descriptor.ring_min_m/ring_max_m", "0 <= min < max");
  require(c.descriptor.sectors >= 1 && c.descriptor.sectors <= 3600, "descriptor.sectors", "in [1, 3600]");
  require(c.match.d_b >= 0, "match.d_b", ">= 0");
  require(c.match.min_cosine >= -1 && c.match.min_cosine <= 1, "match.min_cosine", "in [-1, 1]");
  require(c.match.d_l > 0, "match.d_l", "> 0");
  require(c.match.triangle_tol >= 0, "match.triangle_tol", ">= 0");
  require(c.match.t_m >= 0, "match.t_m", ">= 0");
  require(c.match.prune_min_matches >= 0, "match.prune_min_matches", ">= 0");
  require(c.match.prune_min_kept >= 0, "match.prune_min_kept", ">= 0");
  require(c.ransac.inlier_threshold > 0, "ransac.inlier_threshold", "> 0");
  require(c.ransac.max_iterations >= 1 && c.ransac.max_iterations <= 1000000, "ransac.max_iterations", "in [1, 1e6]");
  require(c.ransac.min_triangle_height >= 0, "ransac.min_triangle_height", ">= 0");
  require(c.ransac.min_inliers >= 3, "ransac.min_inliers", ">= 3");
  require(c.verify.t_g >= 0 && c.verify.t_g <= 1, "verify.t_g", "in [0, 1]");
  require(c.verify.t_b >= 0 && c.verify.t_b <= 1, "verify.t_b", "in [0, 1]");
  require(c.verify.confirm_below_inliers >= 0, "verify.confirm_below_inliers", ">= 0");
  require(c.verify.confirm_min_fitness >= 0 && c.verify.confirm_min_fitness <= 1, "verify.confirm_min_fitness",
          "in [0, 1]");
  require(c.verify.confirm_max_rmse_m > 0, "verify.confirm_max_rmse_m", "> 0");
  require(c.verify.confirm_min_constraint >= 0, "verify.confirm_min_constraint", ">= 0");
  require(c.verify.bev_cell_m > 0 && c.verify.bev_radius_m / c.verify.bev_cell_m <= 2000, "verify.bev_cell_m",
          "> 0 with bev_radius_m / bev_cell_m <= 2000");
  require(c.verify.bev_radius_m > 0, "verify.bev_radius_m", "> 0");
  const auto& f = c.fingerprint;
  require(f.instance_voxel_m >= 0.01, "fingerprint.instance_voxel_m", ">= 0.01");
  require(f.background_cell_m >= 0.05 && f.background_max_range_m / f.background_cell_m < 32000,
          "fingerprint.background_cell_m", ">= 0.05 with background_max_range_m / background_cell_m < 32000");
  require(f.background_max_range_m > 0 && f.background_max_range_m <= 320, "fingerprint.background_max_range_m",
          "in (0, 320]");
  require(f.plane_voxel_m > 0.05, "fingerprint.plane_voxel_m", "> 0.05");
  require(f.plane_min_points >= 3, "fingerprint.plane_min_points", ">= 3");
  require(f.plane_max_thickness_m > 0, "fingerprint.plane_max_thickness_m", "> 0");
  require(f.plane_max_range_m > 0 && f.plane_max_range_m <= 320, "fingerprint.plane_max_range_m", "in (0, 320]");
  require(c.cluster.max_range_m <= 320, "cluster.max_range_m", "<= 320 (fingerprints store centimetres in 16 bits)");
  require(c.fine.max_iterations >= 0, "fine.max_iterations", ">= 0");
  require(c.fine.max_corr_start_m > 0 && c.fine.max_corr_end_m > 0 && c.fine.max_corr_end_m <= c.fine.max_corr_start_m,
          "fine.max_corr_start_m/max_corr_end_m", "> 0 with end <= start");
  require(c.fine.huber_m > 0, "fine.huber_m", "> 0");
  require(c.refine.max_iterations >= 0, "refine.max_iterations", ">= 0");
  require(c.refine.max_corr_m > 0, "refine.max_corr_m", "> 0");
  require(c.refine.min_normal_cosine >= 0 && c.refine.min_normal_cosine <= 1, "refine.min_normal_cosine", "in [0, 1]");
  require(c.refine.cauchy_m > 0, "refine.cauchy_m", "> 0");
  require(c.refine.instance_weight >= 0, "refine.instance_weight", ">= 0");
  require(c.refine.min_information >= 0, "refine.min_information", ">= 0");
  const auto& l = c.labeller;
  require(l.mode == "off" || l.mode == "auto" || l.mode == "always", "labeller.mode", "off, auto or always");
  require(l.max_range_m > 0 && l.max_range_m <= 320, "labeller.max_range_m", "in (0, 320]");
  // The ground grid is (2 max_range_m / ground_cell_m)^2 columns, allocated per scan.
  require(l.ground_cell_m >= 0.5 && l.ground_cell_m <= 10 && l.max_range_m / l.ground_cell_m <= 200,
          "labeller.ground_cell_m", "in [0.5, 10] with max_range_m / ground_cell_m <= 200");
  require(l.cell_m >= 0.05 && l.cell_m <= 2, "labeller.cell_m", "in [0.05, 2]");
  require(l.link_m >= 0 && l.link_m <= 10 * l.cell_m, "labeller.link_m", "in [0, 10 x cell_m]");
  require(l.ground_band_m > 0 && l.ground_tolerance_m > 0 && l.low_band_m > l.ground_tolerance_m,
          "labeller.ground_band_m/ground_tolerance_m/low_band_m", "> 0 with low_band_m > ground_tolerance_m");
  require(l.vehicle_min_length_m <= l.vehicle_max_length_m && l.vehicle_min_height_m <= l.vehicle_max_height_m,
          "labeller.vehicle_*", "min <= max");
  for (const auto& [name, ref] : fields(copy))
    if (name.rfind("labeller.", 0) == 0)
      if (auto d = std::get_if<double*>(&ref)) require(**d >= 0, name, ">= 0");
  labelPreset(c.labels.preset == "custom" ? "semantickitti" : c.labels.preset);  // throws for unknown names
  const auto& b = c.bev_search;
  require(b.cell_m >= 0.25 && b.cell_m <= 5, "bev_search.cell_m", "in [0.25, 5]");
  require(b.max_shift_m >= 0 && b.max_shift_m <= 50, "bev_search.max_shift_m", "in [0, 50]");
  require(b.yaw_step_deg > 0.1 && b.yaw_step_deg <= 30, "bev_search.yaw_step_deg", "in (0.1, 30]");
  require(b.max_range_m > 0 && b.max_range_m <= 100, "bev_search.max_range_m", "in (0, 100]");
  require(b.keep >= 1 && b.keep <= 20, "bev_search.keep", "in [1, 20]");
}

LabelConfig labelPreset(const std::string& name) {
  LabelConfig c;  // SemanticKITTI raw ids
  c.preset = name;
  if (name == "semantickitti") return c;
  if (name == "semantickitti-train") {
    // SemanticKITTI's learning map (19 classes): 1 car, 4 truck, 5 other-vehicle, 9 road, 13 building,
    // 14 fence, 15 vegetation, 16 trunk, 18 pole; moving objects are merged into their static classes.
    c.node_classes = {{"vehicle", {1, 4, 5}}, {"trunk", {16}}, {"pole", {18}}};
    c.road = {9};
    c.building = {13};
    c.fence = {14};
    c.vegetation = {15};
    c.moving = {};
    return c;
  }
  if (name == "nuscenes") {
    // nuScenes-lidarseg (32 classes): vehicles 15-20, 22, 23 (bus, car, construction, emergency, trailer,
    // truck); 24 driveable surface; 28 static.manmade; 9 barrier; 30 vegetation. No pole or trunk class: they
    // are part of manmade and vegetation, and the labeller fills them in "auto" mode.
    c.node_classes = {{"vehicle", {15, 16, 17, 18, 19, 20, 22, 23}}, {"trunk", {}}, {"pole", {}}};
    c.road = {24};
    c.building = {28};
    c.fence = {9};
    c.vegetation = {30};
    c.moving = {};
    return c;
  }
  throw InputError("labels.preset: unknown preset '" + name +
                   "' (known: semantickitti, semantickitti-train, nuscenes)");
}

Config parseConfig(const std::string& yaml_text) {
  Config config;
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::Exception& e) {
    throw InputError(std::string("config: not valid YAML: ") + e.what());
  }
  if (root.IsNull()) return config;
  if (!root.IsMap()) throw InputError("config: the top level must be a mapping of sections");
  auto table = fields(config);
  // Keys must be plain scalars ("{}: ..." or "? [a]" would make yaml-cpp throw from the conversion).
  auto keyOf = [](const YAML::Node& key, const std::string& where) {
    if (!key.IsScalar()) throw InputError("config: " + where + " has a key that is not a plain name");
    return key.Scalar();
  };
  // A preset replaces the label lists; lists given beside it then edit the preset (and make it "custom").
  // "custom" (what dumpConfig writes for edited lists) names no preset: the lists beside it are the labels.
  if (const auto labels = root["labels"]; labels && labels.IsMap() && labels["preset"]) {
    try {
      if (const auto name = labels["preset"].as<std::string>(); name != "custom") config.labels = labelPreset(name);
    } catch (const YAML::Exception& e) {
      throw InputError(std::string("config: bad value for 'labels.preset': ") + e.what());
    }
  }
  for (const auto& section : root) {
    const auto section_name = keyOf(section.first, "the top level");
    if (!section.second.IsMap()) throw InputError("config: section '" + section_name + "' must be a mapping");
    for (const auto& item : section.second) {
      const auto key = section_name + "." + keyOf(item.first, "section '" + section_name + "'");
      try {
        if (key == "labels.preset") continue;  // applied above
        if (key == "labels.node_classes") {
          config.labels.node_classes.clear();
          for (const auto& cls : item.second)
            config.labels.node_classes.push_back(
                {cls["name"].as<std::string>(), cls["ids"].as<std::vector<std::uint32_t>>()});
          continue;
        }
        auto it = table.find(key);
        if (it == table.end()) throw InputError("config: unknown parameter '" + key + "'");
        std::visit([&](auto* field) { *field = item.second.as<std::remove_pointer_t<decltype(field)>>(); }, it->second);
      } catch (const YAML::Exception& e) {
        throw InputError("config: bad value for '" + key + "': " + e.what());
      }
    }
  }
  // The preset's name stays while the lists are the preset's; edited lists are "custom".
  if (!sameLists(config.labels, labelPreset(config.labels.preset == "custom" ? "semantickitti" : config.labels.preset)))
    config.labels.preset = "custom";
  validateConfig(config);
  return config;
}

std::string dumpConfig(const Config& config) {
  Config copy = config;
  YAML::Emitter out;
  out.SetDoublePrecision(17);  // exact round trip of every double
  out << YAML::BeginMap;
  std::string section;
  out << YAML::Key << "labels" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "node_classes" << YAML::Value << YAML::BeginSeq;
  for (const auto& cls : config.labels.node_classes)
    out << YAML::Flow << YAML::BeginMap << YAML::Key << "name" << YAML::Value << cls.name << YAML::Key << "ids"
        << YAML::Value << YAML::Flow << cls.ids << YAML::EndMap;
  out << YAML::EndSeq;
  section = "labels";
  auto table = fields(copy);
  std::vector<std::pair<std::string, FieldRef>> ordered;  // labels first, then sections alphabetically
  for (const auto& entry : table)
    if (entry.first.rfind("labels.", 0) == 0) ordered.push_back(entry);
  for (const auto& entry : table)
    if (entry.first.rfind("labels.", 0) != 0) ordered.push_back(entry);
  for (const auto& [name, ref] : ordered) {
    const auto dot = name.find('.');
    const auto sec = name.substr(0, dot);
    if (sec != section) {
      out << YAML::EndMap << YAML::Key << sec << YAML::Value << YAML::BeginMap;
      section = sec;
    }
    out << YAML::Key << name.substr(dot + 1) << YAML::Value;
    std::visit(
        [&](auto* field) {
          if constexpr (std::is_same_v<decltype(field), std::vector<std::uint32_t>*>)
            out << YAML::Flow << *field;
          else
            out << *field;
        },
        ref);
  }
  out << YAML::EndMap << YAML::EndMap;
  return std::string(out.c_str()) + "\n";
}

Config loadConfig(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path + ": cannot open config file");
  std::stringstream ss;
  ss << in.rdbuf();
  try {
    return parseConfig(ss.str());
  } catch (const InputError& e) {
    throw InputError(path + ": " + e.what());
  }
}

}  // namespace sglc
