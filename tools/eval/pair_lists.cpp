#include "pair_lists.hpp"

#include <fstream>
#include <sstream>

#include "sim/ground_truth.hpp"

namespace sglc::eval {
namespace {

PairRow parseRow(const std::string& where, const std::vector<double>& v) {
  PairRow r;
  r.i = static_cast<int>(v[0]);
  r.j = static_cast<int>(v[1]);
  if (v[0] != r.i || v[1] != r.j || r.i < 0 || r.j < 0)
    throw InputError(where + ": frame numbers must be non-negative integers");
  if (v.size() == 3) {
    if (v[2] != 0 && v[2] != 1) throw InputError(where + ": label must be 0 or 1");
    r.label = static_cast<int>(v[2]);
  }
  if (v.size() == 14) {
    Mat4d T = Mat4d::Identity();
    for (int k = 0; k < 12; ++k) T(k / 4, k % 4) = v[2 + static_cast<std::size_t>(k)];
    r.T = T;
  }
  return r;
}

// The selected frames' poses, as the simulator's ground-truth functions take them.
std::vector<Mat4d> posesOf(const FrameSource& source) {
  std::vector<Mat4d> poses;
  for (int f : source.frames()) {
    if (!source.hasPose(f)) throw InputError("frame " + std::to_string(f) + " has no ground-truth pose");
    poses.push_back(source.pose(f));
  }
  return poses;
}

}  // namespace

std::vector<PairRow> readPairs(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path + ": cannot read the pair file");
  std::vector<PairRow> rows;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    std::vector<double> v;
    for (double x; ss >> x;) v.push_back(x);
    const std::string where = path + ":" + std::to_string(n);
    if (!ss.eof() || (v.size() != 2 && v.size() != 3 && v.size() != 14))
      throw InputError(where + ": expected 'i j', 'i j label' or 'i j' + 12 numbers");
    rows.push_back(parseRow(where, v));
  }
  if (rows.empty()) throw InputError(path + ": no pairs");
  return rows;
}

std::vector<PairRow> distancePairs(const FrameSource& source, const GroundTruthPairs& options) {
  const auto& frames = source.frames();
  sim::PairListConfig config;
  config.positive_m = options.positive_m;
  config.negative_m = options.negative_m;
  config.min_gap = options.min_gap;
  config.seed = options.seed;
  std::vector<PairRow> rows;
  for (const auto& p : sim::distancePairs(posesOf(source), frames, config))
    rows.push_back({frames[static_cast<std::size_t>(p.query)], frames[static_cast<std::size_t>(p.database)],
                    p.loop ? 1 : 0, std::nullopt});
  if (rows.empty()) throw InputError("the selected frames hold no loop or non-loop pair (check --frames)");
  return rows;
}

std::vector<PairRow> posePairs(const FrameSource& source, double max_m, int min_gap) {
  const auto& frames = source.frames();
  std::vector<PairRow> rows;
  for (const auto& p : sim::loopPoses(posesOf(source), frames, max_m, min_gap))
    rows.push_back({frames[static_cast<std::size_t>(p.first)], frames[static_cast<std::size_t>(p.second)], 1, p.T});
  if (rows.empty()) throw InputError("the selected frames hold no loop pair for the pose protocol (check --frames)");
  return rows;
}

}  // namespace sglc::eval
