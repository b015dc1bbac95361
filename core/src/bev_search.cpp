#include "sglc/bev_search.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <tuple>

#include "class_votes.hpp"
#include "fast_math.hpp"

namespace sglc {
namespace {

constexpr int kClasses = 3;  // vegetation, building, fence (Background values 2..4)

int structureIndex(std::uint8_t cls) {
  return cls >= static_cast<std::uint8_t>(Background::kVegetation) &&
                 cls <= static_cast<std::uint8_t>(Background::kFence)
             ? cls - static_cast<int>(Background::kVegetation)
             : -1;
}

Background classOf(int structure_index) {
  return static_cast<Background>(structure_index + static_cast<int>(Background::kVegetation));
}

struct Point2 {
  double x, y;
  int k;  // structure index
};

// Per structure class, a square grid of scores around the query: 2 where the query has that class, 1 where a
// neighbouring cell has it. Cells are (ix, iy) = floor((x + half) / cell).
struct ScoreGrid {
  double cell = 1.0, half = 0.0;
  int n = 0;
  std::vector<std::uint8_t> score;  // kClasses grids of n * n, row-major (iy, ix)

  ScoreGrid(const std::vector<Point2>& points, double cell_m, double half_m)
      : cell(cell_m),
        half(half_m),
        n(static_cast<int>(std::ceil(2.0 * half_m / cell_m))),
        score(static_cast<std::size_t>(kClasses) * n * n, 0) {
    // Each cell's class by the stored BEV's own rule (majority, ties to the higher priority).
    std::vector<detail::ClassVotes> votes(static_cast<std::size_t>(n) * n);
    for (const auto& p : points) {
      const int ix = cellOf(p.x), iy = cellOf(p.y);
      if (ix >= 0 && iy >= 0 && ix < n && iy < n) votes[static_cast<std::size_t>(iy) * n + ix].add(classOf(p.k));
    }
    for (int iy = 0; iy < n; ++iy)
      for (int ix = 0; ix < n; ++ix) {
        const int k = structureIndex(votes[static_cast<std::size_t>(iy) * n + ix].winner());
        if (k < 0) continue;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int x = ix + dx, y = iy + dy;
            if (x < 0 || y < 0 || x >= n || y >= n) continue;
            auto& s = at(k, x, y);
            s = std::max<std::uint8_t>(s, dx == 0 && dy == 0 ? 2 : 1);
          }
      }
  }
  int cellOf(double v) const { return detail::floorInt(static_cast<float>((v + half) / cell)); }
  std::size_t index(int k, int ix, int iy) const {
    return (static_cast<std::size_t>(k) * n + static_cast<std::size_t>(iy)) * n + static_cast<std::size_t>(ix);
  }
  std::uint8_t& at(int k, int ix, int iy) { return score[index(k, ix, iy)]; }
  std::uint8_t get(int k, double x, double y) const {
    const int ix = cellOf(x), iy = cellOf(y);
    return ix < 0 || iy < 0 || ix >= n || iy >= n ? 0 : score[index(k, ix, iy)];
  }
};

std::vector<Point2> structurePoints(const std::vector<BevCell>& cells, double stored_cell, double max_range) {
  std::vector<Point2> out;
  for (const auto& c : cells) {
    const int k = structureIndex(c.cls);
    if (k < 0) continue;
    const double x = (c.ix + 0.5) * stored_cell, y = (c.iy + 0.5) * stored_cell;
    if (x * x + y * y <= max_range * max_range) out.push_back({x, y, k});
  }
  return out;
}

// One representative point per (coarse cell, class): the coarse search costs per point.
std::vector<Point2> thin(const std::vector<Point2>& points, double cell) {
  std::vector<Point2> out;
  std::vector<std::pair<std::tuple<int, int, int>, std::size_t>> keyed;
  for (std::size_t i = 0; i < points.size(); ++i)
    keyed.push_back({{detail::floorInt(static_cast<float>(points[i].x / cell)),
                      detail::floorInt(static_cast<float>(points[i].y / cell)), points[i].k},
                     i});
  std::stable_sort(keyed.begin(), keyed.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  for (std::size_t i = 0; i < keyed.size(); ++i)
    if (i == 0 || keyed[i].first != keyed[i - 1].first) out.push_back(points[keyed[i].second]);
  return out;
}

Mat4d planar(double yaw, double tx, double ty) {
  Mat4d T = Mat4d::Identity();
  T(0, 0) = std::cos(yaw);
  T(0, 1) = -std::sin(yaw);
  T(1, 0) = std::sin(yaw);
  T(1, 1) = std::cos(yaw);
  T(0, 3) = tx;
  T(1, 3) = ty;
  return T;
}

struct Hypothesis {
  double score, yaw, tx, ty;
};

// Whether coarse heading step s (of `steps`) lies within one step of a wanted heading (every step when none is).
bool wanted(int s, int steps, const std::vector<double>& headings) {
  if (headings.empty()) return true;
  const double step = 2.0 * std::numbers::pi / steps;
  return std::any_of(headings.begin(), headings.end(), [&](double h) {
    return std::abs(std::remainder(s * step - h, 2.0 * std::numbers::pi)) <= step * 1.001;
  });
}

// The best `count` cells of a w x w score grid (cleared as it goes), each more than two cells from the ones
// before: a corridor scores alike along itself. Calls take(score, x, y), best first; the first maximum wins ties.
template <class Take>
void bestShifts(std::vector<std::uint32_t>& acc, int w, int count, const Take& take) {
  for (int k = 0; k < count; ++k) {
    const auto best = std::max_element(acc.begin(), acc.end()) - acc.begin();
    const auto score = acc[static_cast<std::size_t>(best)];
    if (k > 0 && score == 0) return;
    const int bx = static_cast<int>(best % w), by = static_cast<int>(best / w);
    take(score, bx, by);
    for (int y = std::max(0, by - 2); y <= std::min(w - 1, by + 2); ++y)
      for (int x = std::max(0, bx - 2); x <= std::min(w - 1, bx + 2); ++x) acc[static_cast<std::size_t>(y) * w + x] = 0;
  }
}

}  // namespace

std::vector<double> wallHeadings(const std::vector<Plane>& query, const std::vector<Plane>& candidate, int peaks) {
  constexpr int kBins = 180;
  constexpr float kMaxNormalZ = 0.3f;  // |n_z| of a wall's normal at most (about 17 deg from horizontal)
  auto histogram = [](const std::vector<Plane>& planes) {
    std::array<double, kBins> h{};
    for (const auto& p : planes) {
      if (std::abs(p.normal.z()) > kMaxNormalZ) continue;
      const double deg = std::atan2(p.normal.y(), p.normal.x()) * 180.0 / std::numbers::pi;
      const int b = static_cast<int>(std::floor(std::fmod(deg + 360.0, 180.0))) % kBins;
      h[b] += 1.0;  // spread over the neighbours: normals of one wall scatter by a degree or two
      h[(b + 1) % kBins] += 0.5;
      h[(b + kBins - 1) % kBins] += 0.5;
    }
    return h;
  };
  const auto hq = histogram(query), hc = histogram(candidate);
  std::array<double, kBins> corr{};
  for (int s = 0; s < kBins; ++s)
    for (int i = 0; i < kBins; ++i) corr[s] += hq[(i + s) % kBins] * hc[i];
  std::vector<std::pair<double, int>> maxima;  // (correlation, shift in degrees)
  for (int s = 0; s < kBins; ++s)
    if (corr[s] > 0 && corr[s] >= corr[(s + 1) % kBins] && corr[s] > corr[(s + kBins - 1) % kBins])
      maxima.emplace_back(corr[s], s);
  std::stable_sort(maxima.begin(), maxima.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<double> out;
  for (int k = 0; k < peaks && k < static_cast<int>(maxima.size()); ++k)
    for (double turn : {0.0, 180.0}) out.push_back((maxima[k].second + turn) * std::numbers::pi / 180.0);
  return out;
}

std::vector<BevPose> searchBevPose(const std::vector<BevCell>& query, const std::vector<BevCell>& candidate,
                                   double stored_cell, const BevSearchConfig& config,
                                   const std::vector<double>& headings, bool fine, int shifts_per_heading) {
  const double cell = config.cell_m;
  const double range = config.max_range_m;
  const double half = range + config.max_shift_m + 2.0 * cell;
  const auto q = structurePoints(query, stored_cell, half);
  const auto c_all = structurePoints(candidate, stored_cell, range);
  if (q.empty() || c_all.empty() || config.keep <= 0) return {};
  const auto c = thin(c_all, cell);

  // Coarse: every heading step; for each, every whole-cell shift, accumulated row by row.
  const ScoreGrid coarse(q, cell, half);
  const int S = static_cast<int>(std::floor(config.max_shift_m / cell));
  const int w = 2 * S + 1;
  const int steps = std::max(1, static_cast<int>(std::lround(360.0 / config.yaw_step_deg)));
  std::vector<Hypothesis> per_yaw;
  std::vector<std::uint32_t> acc(static_cast<std::size_t>(w) * w);
  for (int s = 0; s < steps; ++s) {
    if (!wanted(s, steps, headings)) continue;
    const double yaw = 2.0 * std::numbers::pi * s / steps;
    const double cy = std::cos(yaw), sy = std::sin(yaw);
    std::fill(acc.begin(), acc.end(), 0u);
    for (const auto& p : c) {
      const double x = cy * p.x - sy * p.y, y = sy * p.x + cy * p.y;
      const int bx = coarse.cellOf(x) - S, by = coarse.cellOf(y) - S;
      if (bx < 0 || by < 0 || bx + w > coarse.n || by + w > coarse.n) continue;
      for (int dy = 0; dy < w; ++dy) {
        const std::uint8_t* row = &coarse.score[coarse.index(p.k, bx, by + dy)];
        std::uint32_t* out = acc.data() + static_cast<std::size_t>(dy) * w;
        for (int dx = 0; dx < w; ++dx) out[dx] += row[dx];
      }
    }
    bestShifts(acc, w, shifts_per_heading, [&](std::uint32_t score, int bx, int by) {
      per_yaw.push_back({static_cast<double>(score), yaw, (bx - S) * cell, (by - S) * cell});
    });
  }
  std::stable_sort(per_yaw.begin(), per_yaw.end(), [](const auto& a, const auto& b) { return a.score > b.score; });
  std::vector<Hypothesis> picked;
  const double min_yaw_gap = 3.0 * config.yaw_step_deg * std::numbers::pi / 180.0;
  for (const auto& h : per_yaw) {
    if (static_cast<int>(picked.size()) == config.keep) break;
    const bool distinct = std::all_of(picked.begin(), picked.end(), [&](const Hypothesis& o) {
      const double dyaw = std::abs(std::remainder(h.yaw - o.yaw, 2.0 * std::numbers::pi));
      return dyaw > min_yaw_gap || std::hypot(h.tx - o.tx, h.ty - o.ty) > 2.0 * cell;
    });
    if (distinct) picked.push_back(h);
  }

  std::vector<BevPose> out;
  if (!fine) {
    for (const auto& h : picked)
      out.push_back({planar(h.yaw, h.tx, h.ty), h.score / (2.0 * static_cast<double>(c.size()))});
    return out;
  }
  // Fine: around each, a quarter of the heading step and a quarter of the cell, on a grid of the stored cell.
  const ScoreGrid fine_grid(q, stored_cell, half);
  const double yaw_step = config.yaw_step_deg * std::numbers::pi / 180.0 / 4.0, shift_step = cell / 4.0;
  for (const auto& h : picked) {
    Hypothesis best{-1.0, h.yaw, h.tx, h.ty};
    for (int a = -4; a <= 4; ++a) {
      const double yaw = h.yaw + a * yaw_step;
      const double cy = std::cos(yaw), sy = std::sin(yaw);
      for (int iy = -4; iy <= 4; ++iy)
        for (int ix = -4; ix <= 4; ++ix) {
          const double tx = h.tx + ix * shift_step, ty = h.ty + iy * shift_step;
          std::uint32_t sum = 0;
          for (const auto& p : c_all) sum += fine_grid.get(p.k, cy * p.x - sy * p.y + tx, sy * p.x + cy * p.y + ty);
          if (sum > best.score) best = {static_cast<double>(sum), yaw, tx, ty};
        }
    }
    out.push_back({planar(best.yaw, best.tx, best.ty), best.score / (2.0 * static_cast<double>(c_all.size()))});
  }
  std::stable_sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.score > b.score; });
  return out;
}

}  // namespace sglc
