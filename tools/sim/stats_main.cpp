// sglc-sim-stats: statistics of labelled scans (real or simulated) as one JSON object, for the realism check
// in tools/sim/README.md (see realism.py).
//
//   sglc-sim-stats NAME=BIN:LABEL [NAME=BIN:LABEL ...]
//   sglc-sim-stats --version
//
// Per scan: points, points per class, range histogram, median and 90th percentile, intensity, the engine's
// clustered landmarks (nodes per class and their sizes), graph edges, plane features, background cells,
// scan-descriptor occupancy. Across scans: the L2 distance of every pair of scan descriptors (the engine's
// retrieval distance).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <string_view>

#include "sglc/io.hpp"
#include "sglc/pipeline.hpp"
#include "sglc/version.hpp"

namespace {

using nlohmann::ordered_json;

// Edges of the range histogram in m; the last bin is open-ended.
const std::vector<double> kRangeEdges = {0, 5, 10, 20, 30, 40, 50, 60, 80, 1e9};

// One NAME=BIN:LABEL argument, read.
struct NamedScan {
  std::string name;
  sglc::LabelledScan scan;
  std::vector<float> intensity;
};

NamedScan readArgument(const std::string& arg) {
  const auto eq = arg.find('='), colon = arg.rfind(':');
  if (eq == std::string::npos || colon == std::string::npos || colon < eq)
    throw sglc::InputError("argument '" + arg + "' is not NAME=BIN:LABEL");
  NamedScan s;
  s.name = arg.substr(0, eq);
  s.scan.points = sglc::readKittiBin(arg.substr(eq + 1, colon - eq - 1), &s.intensity);
  s.scan.labels = sglc::readLabels(arg.substr(colon + 1));
  if (s.scan.labels.size() != s.scan.points.size())
    throw sglc::InputError(s.name + ": label count differs from points");
  return s;
}

// Points per class, mean intensity per class, the range histogram and range mean / median / max.
void addPointStats(ordered_json& s, const NamedScan& in) {
  const auto& scan = in.scan;
  std::map<std::uint32_t, std::size_t> per_class;
  std::map<std::uint32_t, double> intensity_sum;
  std::vector<std::size_t> hist(kRangeEdges.size() - 1, 0);
  double range_sum = 0;
  std::vector<double> ranges;
  ranges.reserve(scan.points.size());
  for (std::size_t i = 0; i < scan.points.size(); ++i) {
    const std::uint32_t cls = scan.labels[i] & 0xFFFFu;
    ++per_class[cls];
    intensity_sum[cls] += in.intensity[i];
    const double r = scan.points[i].norm();
    ranges.push_back(r);
    range_sum += r;
    for (std::size_t k = 0; k + 1 < kRangeEdges.size(); ++k)
      if (r >= kRangeEdges[k] && r < kRangeEdges[k + 1]) ++hist[k];
  }
  std::sort(ranges.begin(), ranges.end());
  ordered_json classes, mean_intensity;
  for (const auto& [cls, n] : per_class) {
    classes[std::to_string(cls)] = n;
    mean_intensity[std::to_string(cls)] = intensity_sum[cls] / n;
  }
  s["classes"] = classes;
  s["intensity_mean_per_class"] = mean_intensity;
  s["range_hist"] = hist;
  s["range_mean_m"] = ranges.empty() ? 0.0 : range_sum / ranges.size();
  s["range_median_m"] = ranges.empty() ? 0.0 : ranges[ranges.size() / 2];
  s["range_p90_m"] = ranges.empty() ? 0.0 : ranges[ranges.size() * 9 / 10];
  s["range_max_m"] = ranges.empty() ? 0.0 : ranges.back();
}

// Landmarks per node class and their mean size, graph edges, planes and background cells.
void addLandmarkStats(ordered_json& s, const sglc::Fingerprint& fp, const sglc::Config& cfg) {
  ordered_json nodes, sizes;
  for (std::size_t c = 0; c < cfg.labels.node_classes.size(); ++c) {
    int n = 0;
    sglc::Vec3f size_sum = sglc::Vec3f::Zero();
    for (const auto& node : fp.nodes)
      if (node.cls == c) {
        ++n;
        size_sum += node.size;
      }
    nodes[cfg.labels.node_classes[c].name] = n;
    if (n > 0) {
      const sglc::Vec3f m = size_sum / static_cast<float>(n);
      sizes[cfg.labels.node_classes[c].name] = {m.x(), m.y(), m.z()};
    }
  }
  s["nodes"] = nodes;
  s["node_mean_size_lwh"] = sizes;
  int graph_edges = 0;
  const float d2 = static_cast<float>(cfg.graph.d_max * cfg.graph.d_max);
  for (std::size_t i = 0; i < fp.nodes.size(); ++i)
    for (std::size_t j = i + 1; j < fp.nodes.size(); ++j)
      graph_edges += (fp.nodes[i].center - fp.nodes[j].center).squaredNorm() < d2;
  s["graph_edges"] = graph_edges;
  s["planes"] = fp.planes.size();
  s["background_cells"] = fp.background.size();
}

// Occupancy and norm of the scan descriptor's foreground and background parts.
void addDescriptorStats(ordered_json& s, const sglc::Fingerprint& fp) {
  const int fg = fp.layout.num_classes + fp.layout.edgeTypes() * fp.layout.bins;
  int fg_nonzero = 0, bg_nonzero = 0;
  double fg_norm2 = 0, bg_norm2 = 0;
  for (int k = 0; k < static_cast<int>(fp.descriptor.size()); ++k) {
    const double v = fp.descriptor[k];
    if (k < fg) {
      fg_nonzero += v != 0;
      fg_norm2 += v * v;
    } else {
      bg_nonzero += v != 0;
      bg_norm2 += v * v;
    }
  }
  s["descriptor"] = {
      {"foreground_nonzero", fg_nonzero},       {"foreground_dims", fg},
      {"background_nonzero", bg_nonzero},       {"background_dims", static_cast<int>(fp.descriptor.size()) - fg},
      {"foreground_norm", std::sqrt(fg_norm2)}, {"background_norm", std::sqrt(bg_norm2)}};
}

ordered_json scanStats(const NamedScan& in, const sglc::Fingerprint& fp, const sglc::Config& cfg) {
  ordered_json s;
  s["name"] = in.name;
  s["points"] = in.scan.points.size();
  addPointStats(s, in);
  addLandmarkStats(s, fp, cfg);
  addDescriptorStats(s, fp);
  return s;
}

// The L2 distance of every pair of scan descriptors, keyed "A vs B".
ordered_json descriptorDistances(const std::vector<std::string>& names,
                                 const std::vector<std::vector<float>>& descriptors) {
  ordered_json dist;
  for (std::size_t i = 0; i < descriptors.size(); ++i)
    for (std::size_t j = i + 1; j < descriptors.size(); ++j) {
      double d = 0;
      for (std::size_t k = 0; k < descriptors[i].size(); ++k)
        d += (descriptors[i][k] - descriptors[j][k]) * (descriptors[i][k] - descriptors[j][k]);
      dist[names[i] + " vs " + names[j]] = std::sqrt(d);
    }
  return dist;
}

// The statistics of the scans named in `args` (each read and fingerprinted in turn).
ordered_json statistics(const std::vector<std::string>& args) {
  const sglc::Pipeline pipeline;
  ordered_json out;
  out["range_edges_m"] = std::vector<double>(kRangeEdges.begin(), kRangeEdges.end() - 1);
  std::vector<std::vector<float>> descriptors;
  std::vector<std::string> names;
  for (const auto& arg : args) {
    const NamedScan in = readArgument(arg);
    const sglc::Fingerprint fp = pipeline.fingerprint(in.scan);
    out["scans"].push_back(scanStats(in, fp, pipeline.config()));
    descriptors.push_back(fp.descriptor);
    names.push_back(in.name);
  }
  out["descriptor_distance"] = descriptorDistances(names, descriptors);
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  if (std::any_of(argv + 1, argv + argc, [](const char* a) { return std::string_view(a) == "--version"; })) {
    std::cout << "sglc-sim-stats " << sglc::kVersion << std::endl;
    return 0;
  }
  if (argc < 2 || std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h") {
    std::cerr << "usage: sglc-sim-stats NAME=BIN:LABEL [NAME=BIN:LABEL ...]\n";
    return argc < 2 ? 2 : 0;
  }
  try {
    std::cout << statistics(std::vector<std::string>(argv + 1, argv + argc)).dump(2) << std::endl;
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "sglc-sim-stats: error: " << e.what() << std::endl;
    return 1;
  }
}
