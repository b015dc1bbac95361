// The engine configuration: defaults, YAML parsing through the registry, validation, dump and reload.
#include <gtest/gtest.h>

#include <fstream>
#include <iomanip>
#include <sstream>
#include <string>

#include "sglc/config/engine_file.hpp"
#include "sglc/types.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

std::string errorOf(const std::string& yaml) {
  try {
    parseConfig(yaml);
  } catch (const InputError& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected InputError for\n" << yaml << "\ngot: " << e.what();
    return {};
  }
  ADD_FAILURE() << "expected InputError for\n" << yaml;
  return {};
}

TEST(Config, DefaultsArePaperValues) {
  const Config c;
  // SGLC paper, parameter settings.
  EXPECT_EQ(c.graph.d_max, 60.0);
  EXPECT_EQ(c.descriptor.d_i, 2.0);
  EXPECT_EQ(c.descriptor.k_eigen, 30);
  EXPECT_EQ(c.match.d_b, 2.0);
  EXPECT_EQ(c.match.d_l, 20.0);
  EXPECT_EQ(c.match.t_m, 2);
  EXPECT_EQ(c.verify.max_translation, 10.0);
  // Node classes: vehicle, trunk, pole.
  ASSERT_EQ(c.labels.node_classes.size(), 3u);
  EXPECT_EQ(c.labels.node_classes[0].name, "vehicle");
  EXPECT_EQ(c.labels.node_classes[1].name, "trunk");
  EXPECT_EQ(c.labels.node_classes[2].name, "pole");
  EXPECT_NO_THROW(validateConfig(c));
}

TEST(Config, EmptyYamlGivesDefaults) {
  const Config c = parseConfig("");
  const Config d;
  EXPECT_EQ(c.graph.d_max, d.graph.d_max);
  EXPECT_EQ(c.match.t_m, d.match.t_m);
  EXPECT_EQ(c.labels.node_classes.size(), d.labels.node_classes.size());
}

TEST(Config, OverridesKeepTheRest) {
  const Config c = parseConfig(
      "graph:\n"
      "  d_max: 50\n"
      "match:\n"
      "  t_m: 3\n"
      "  d_b: 1.5\n"
      "fine:\n"
      "  enabled: false\n"
      "ransac:\n"
      "  seed: 12345\n"
      "labels:\n"
      "  road: [40, 44]\n");
  const Config d;
  EXPECT_EQ(c.graph.d_max, 50.0);
  EXPECT_EQ(c.match.t_m, 3);
  EXPECT_EQ(c.match.d_b, 1.5);
  EXPECT_FALSE(c.fine.enabled);
  EXPECT_EQ(c.ransac.seed, 12345u);
  EXPECT_EQ(c.labels.road, (std::vector<std::uint32_t>{40, 44}));
  // Untouched keys, including siblings of overridden ones, keep their defaults.
  EXPECT_EQ(c.graph.max_nodes, d.graph.max_nodes);
  EXPECT_EQ(c.match.d_l, d.match.d_l);
  EXPECT_EQ(c.match.min_cosine, d.match.min_cosine);
  EXPECT_EQ(c.descriptor.d_i, d.descriptor.d_i);
  EXPECT_EQ(c.descriptor.k_eigen, d.descriptor.k_eigen);
  EXPECT_EQ(c.verify.min_probability, d.verify.min_probability);
  EXPECT_EQ(c.verify.fit_max_shift_m, d.verify.fit_max_shift_m);
  EXPECT_TRUE(c.refine.enabled);
  EXPECT_EQ(c.labels.building, d.labels.building);
  EXPECT_EQ(c.labels.node_classes.size(), d.labels.node_classes.size());
}

TEST(Config, UnknownKeyNamed) {
  std::string msg = errorOf("graph:\n  d_maxx: 50\n");
  EXPECT_NE(msg.find("graph.d_maxx"), std::string::npos) << msg;
  msg = errorOf("grpah:\n  d_max: 50\n");  // a misspelt section is named, with the known ones
  EXPECT_NE(msg.find("unknown section 'grpah'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("graph, descriptor"), std::string::npos) << msg;
}

TEST(Config, InvalidValueNamesField) {
  struct Case {
    const char* yaml;
    const char* field;
  };
  const Case cases[] = {
      {"graph: {d_max: -1}", "graph.d_max"},
      {"graph: {d_max: 0}", "graph.d_max"},
      {"verify: {min_probability: 2}", "verify.min_probability"},
      {"verify: {fit_max_turn_deg: -0.1}", "verify.fit_max_turn_deg"},
      {"descriptor: {k_eigen: 0}", "descriptor.k_eigen"},
      {"descriptor: {d_i: 0}", "descriptor.d_i"},
      {"match: {d_b: -0.5}", "match.d_b"},
      {"cluster: {min_points: 0}", "cluster.min_points"},
      {"ransac: {min_inliers: 2}", "ransac.min_inliers"},
      {"graph: {d_max: .nan}", "graph.d_max"},
      {"fingerprint: {plane_min_points: 2}", "fingerprint.plane_min_points"},
      {"bev_search: {cell_m: 0}", "bev_search.cell_m"},
      {"bev_search: {keep: 0}", "bev_search.keep"},
      {"bev_search: {max_range_m: 500}", "bev_search.max_range_m"},
      {"bev_search: {yaw_step_deg: 0}", "bev_search.yaw_step_deg"},
  };
  for (const auto& c : cases) {
    const std::string msg = errorOf(c.yaml);
    EXPECT_NE(msg.find(c.field), std::string::npos) << c.yaml << " -> " << msg;
  }
}

TEST(Config, WrongTypeNamesField) {
  std::string msg = errorOf("graph: {max_nodes: many}");
  EXPECT_NE(msg.find("graph.max_nodes"), std::string::npos) << msg;
  msg = errorOf("fine: {enabled: maybe}");
  EXPECT_NE(msg.find("fine.enabled"), std::string::npos) << msg;
  msg = errorOf("labels: {road: forty}");
  EXPECT_NE(msg.find("labels.road"), std::string::npos) << msg;
}

TEST(Config, BadYaml) {
  EXPECT_THROW(parseConfig("graph: {d_max: 50"), InputError);
  EXPECT_THROW(parseConfig("graph:\n  d_max: [1, 2\n"), InputError);
  EXPECT_THROW(parseConfig("- just\n- a list\n"), InputError);  // top level must be a mapping
  EXPECT_THROW(parseConfig("graph: 5\n"), InputError);          // section must be a mapping
}

TEST(Config, CustomNodeClasses) {
  const Config c = parseConfig(
      "labels:\n"
      "  node_classes:\n"
      "    - {name: car, ids: [10]}\n"
      "    - {name: pole, ids: [80, 81]}\n");
  ASSERT_EQ(c.labels.node_classes.size(), 2u);
  EXPECT_EQ(c.labels.node_classes[0].name, "car");
  EXPECT_EQ(c.labels.node_classes[0].ids, (std::vector<std::uint32_t>{10}));
  EXPECT_EQ(c.labels.node_classes[1].name, "pole");
  EXPECT_EQ(c.labels.node_classes[1].ids, (std::vector<std::uint32_t>{80, 81}));
  // Other label lists untouched.
  EXPECT_EQ(c.labels.road, Config{}.labels.road);
}

TEST(Config, NodeClassesValidated) {
  std::string msg = errorOf("labels:\n  node_classes: []\n");
  EXPECT_NE(msg.find("labels.node_classes"), std::string::npos) << msg;
  EXPECT_THROW(parseConfig("labels:\n  node_classes:\n    - {ids: [10]}\n"), InputError);  // no name
}

TEST(Config, ValidateConfigDirect) {
  Config c;
  c.match.t_m = -1;
  EXPECT_THROW(validateConfig(c), InputError);
  c = Config{};
  c.fine.max_corr_end_m = 2.0;  // end > start
  EXPECT_THROW(validateConfig(c), InputError);
  c = Config{};
  c.labels.node_classes.clear();
  EXPECT_THROW(validateConfig(c), InputError);
}

// Every field, as text, for comparing two configs (the struct has no operator==). Doubles printed with 17
// significant digits, so two configs compare equal only if every double is bit-identical.
std::string fingerprintOf(const Config& c) {
  std::ostringstream o;
  o.precision(17);
  for (const auto& n : c.labels.node_classes) {
    o << n.name << ":";
    for (auto id : n.ids) o << id << ",";
    o << ";";
  }
  auto ids = [&](const std::vector<std::uint32_t>& v) {
    for (auto id : v) o << id << ",";
    o << ";";
  };
  ids(c.labels.road);
  ids(c.labels.building);
  ids(c.labels.fence);
  ids(c.labels.vegetation);
  ids(c.labels.moving);
  o << c.cluster.azimuth_deg << " " << c.cluster.range_m << " " << c.cluster.elevation_deg << " "
    << c.cluster.min_points << " " << c.cluster.max_range_m << "|" << c.graph.d_max << " " << c.graph.max_nodes << "|"
    << c.descriptor.d_i << " " << c.descriptor.k_eigen << " " << c.descriptor.rings << " " << c.descriptor.ring_min_m
    << " " << c.descriptor.ring_max_m << " " << c.descriptor.sectors << "|" << c.match.d_b << " " << c.match.min_cosine
    << " " << c.match.d_l << " " << c.match.triangle_tol << " " << c.match.t_m << " " << c.match.prune_min_matches
    << "|" << c.ransac.inlier_threshold << " " << c.ransac.max_iterations << " " << c.ransac.seed << " "
    << c.ransac.min_triangle_height << " " << c.ransac.min_inliers << "|" << c.verify.min_probability << " "
    << c.verify.model << " " << c.verify.max_translation << " " << c.verify.fit_max_shift_m << " "
    << c.verify.fit_max_turn_deg << "|" << c.fingerprint.instance_voxel_m << " " << c.fingerprint.background_cell_m
    << " " << c.fingerprint.background_max_range_m << " " << c.fingerprint.plane_voxel_m << " "
    << c.fingerprint.plane_min_points << " " << c.fingerprint.plane_max_thickness_m << " "
    << c.fingerprint.plane_max_range_m << "|" << c.fine.enabled << " " << c.fine.max_iterations << " "
    << c.fine.max_corr_start_m << " " << c.fine.max_corr_end_m << " " << c.fine.huber_m << " " << c.fine.converged_m
    << "|" << c.refine.enabled << " " << c.refine.max_iterations << " " << c.refine.max_corr_m << " "
    << c.refine.min_normal_cosine << " " << c.refine.cauchy_m << " " << c.refine.instance_weight << " "
    << c.refine.converged_m;
  return o.str();
}

TEST(Config, DumpParsesBackToDefaults) {
  const Config d;
  const Config back = parseConfig(dumpConfig(d));
  EXPECT_EQ(fingerprintOf(back), fingerprintOf(d));
}

TEST(Config, DumpParsesBackEveryField) {
  Config c;
  c.labels.node_classes = {{"car: parked", {10, 18}}, {"pole", {80}}};  // a name that needs quoting
  c.labels.fence = {};
  c.labels.vegetation = {70, 72};
  c.cluster.min_points = 7;
  c.graph.d_max = 45.5;
  c.descriptor.rings = 12;
  c.match.triangle_tol = 0.3;
  c.ransac.seed = 0xFFFFFFFFFFFFFFFFull;
  c.verify.min_probability = 0.45;
  c.verify.model = "models/loop model.txt";
  c.fingerprint.plane_max_thickness_m = 0.05;
  c.fine.enabled = false;
  c.refine.converged_m = 1e-7;
  const Config back = parseConfig(dumpConfig(c));
  EXPECT_EQ(fingerprintOf(back), fingerprintOf(c));
  EXPECT_EQ(back.labels.node_classes[0].name, "car: parked");
  EXPECT_TRUE(back.labels.fence.empty());
}

// "YAML that parseConfig reads back to the same values": values that need all 17 significant digits of a double.
TEST(Config, DumpRoundTripIsExactForAnyDouble) {
  Config c;
  c.match.d_b = 1.0 / 3.0;
  c.verify.min_probability = 2.0 / 3.0;
  c.cluster.range_m = 0.1 + 0.2;  // 0.30000000000000004
  const std::string yaml = dumpConfig(c);
  const Config back = parseConfig(yaml);
  auto show = [](double v) {
    std::ostringstream o;
    o << std::setprecision(17) << v;
    return o.str();
  };
  EXPECT_EQ(show(back.match.d_b), show(c.match.d_b));
  EXPECT_EQ(show(back.verify.min_probability), show(c.verify.min_probability));
  EXPECT_EQ(show(back.cluster.range_m), show(c.cluster.range_m));
  EXPECT_EQ(back.match.d_b, c.match.d_b);
  EXPECT_EQ(back.verify.min_probability, c.verify.min_probability);
  EXPECT_EQ(back.cluster.range_m, c.cluster.range_m);
}

TEST(Config, LoadConfigFile) {
  test::TempDir dir;
  {
    std::ofstream out(dir.file("c.yaml"));
    out << "graph:\n  d_max: 40\nverify:\n  min_probability: 0.3\n";
  }
  const Config c = loadConfig(dir.file("c.yaml"));
  EXPECT_EQ(c.graph.d_max, 40.0);
  EXPECT_EQ(c.verify.min_probability, 0.3);
  EXPECT_EQ(c.verify.max_translation, 10.0);
  {
    std::ofstream out(dir.file("bad.yaml"));
    out << "graph:\n  typo: 1\n";
  }
  try {
    loadConfig(dir.file("bad.yaml"));
    ADD_FAILURE() << "expected InputError";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("bad.yaml"), std::string::npos) << msg;
    EXPECT_NE(msg.find("graph.typo"), std::string::npos) << msg;
  }
}

TEST(Config, LoadMissingFile) {
  test::TempDir dir;
  try {
    loadConfig(dir.file("missing.yaml"));
    ADD_FAILURE() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("missing.yaml"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace sglc
