// The view context: a narrow view matched against a full turn of the same place, at the right heading.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <random>

#include "sglc/view_context.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

using test::deg2rad;
using test::rad2deg;

constexpr double kCell = 0.5;

struct WorldCell {
  double x, y;
  Background cls;
};

// A random place: road everywhere within 45 m, building fronts along two sides of a street with gaps, and
// tree crowns scattered, all in the world frame.
std::vector<WorldCell> makePlace(std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<WorldCell> w;
  for (double x = -45; x <= 45; x += kCell)
    for (double y = -45; y <= 45; y += kCell)
      if (std::hypot(x, y) < 45) w.push_back({x, y, Background::kRoad});
  for (const double side : {-1.0, 1.0})
    for (double x = -45; x < 45;) {
      const double length = 4 + 16 * u(rng), depth = 6 + 8 * u(rng);
      for (double s = 0; s < length; s += kCell)
        w.push_back({x + s, side * depth, u(rng) < 0.5 ? Background::kBuilding : Background::kFence});
      x += length + 2 + 8 * u(rng);
    }
  for (int k = 0; k < 40; ++k) {
    const double cx = -40 + 80 * u(rng), cy = -40 + 80 * u(rng), r = 1 + 2 * u(rng);
    for (double dx = -r; dx <= r; dx += kCell)
      for (double dy = -r; dy <= r; dy += kCell)
        if (std::hypot(dx, dy) <= r) w.push_back({cx + dx, cy + dy, Background::kVegetation});
  }
  return w;
}

// The place as BEV cells seen from a sensor at the world's origin whose x axis points at `heading` (rad),
// keeping only cells within `half_fov` of it (pi: all). Later cells of a grid cell win, as structure does.
std::vector<BevCell> viewOf(const std::vector<WorldCell>& world, double heading, double half_fov = std::numbers::pi) {
  std::map<std::pair<int, int>, std::uint8_t> grid;
  const double c = std::cos(heading), s = std::sin(heading);
  for (const auto& w : world) {
    const double x = c * w.x + s * w.y, y = -s * w.x + c * w.y;  // into the sensor frame
    if (std::abs(std::atan2(y, x)) > half_fov) continue;
    auto& cls = grid[{static_cast<int>(std::floor(x / kCell)), static_cast<int>(std::floor(y / kCell))}];
    cls = std::max(cls, static_cast<std::uint8_t>(w.cls));
  }
  std::vector<BevCell> out;
  for (const auto& [ij, cls] : grid)
    out.push_back({static_cast<std::int16_t>(ij.first), static_cast<std::int16_t>(ij.second), cls});
  return out;
}

// Difference of two angles (rad), in degrees within [-180, 180).
double turnDeg(double a, double b) { return rad2deg(std::remainder(a - b, 2 * std::numbers::pi)); }

TEST(ViewContext, NarrowViewFindsItsPlaceAndHeadingInAFullTurn) {
  const ViewSearchConfig cfg;
  const auto place = makePlace(1);
  const auto full = viewContext(viewOf(place, 0.0), kCell, cfg);
  const double half_fov = deg2rad(35.0);
  for (const double heading_deg : {0.0, 37.0, 150.0, -100.0}) {
    const double heading = deg2rad(heading_deg);
    const auto narrow = viewContext(viewOf(place, heading, half_fov), kCell, cfg);
    const ViewMatch m = matchViews(narrow, full);
    EXPECT_GT(m.similarity, 0.6) << heading_deg;  // sector edges fall elsewhere once turned
    // T_narrow_full turns the full view's frame by -heading into the narrow one's.
    EXPECT_LE(std::abs(turnDeg(m.heading, -heading)), 3.0) << heading_deg << " got " << rad2deg(m.heading);
  }
}

TEST(ViewContext, OtherPlacesScoreLower) {
  const ViewSearchConfig cfg;
  const auto place = makePlace(1);
  const auto narrow = viewContext(viewOf(place, deg2rad(60.0), deg2rad(35.0)), kCell, cfg);
  const double same = matchViews(narrow, viewContext(viewOf(place, 0.0), kCell, cfg)).similarity;
  for (std::uint32_t seed = 2; seed < 8; ++seed) {
    const double other = matchViews(narrow, viewContext(viewOf(makePlace(seed), 0.0), kCell, cfg)).similarity;
    EXPECT_LT(other, same - 0.2) << "seed " << seed;
  }
}

TEST(ViewContext, OnlyTheNarrowViewsSectorsAreJudged) {
  // A full turn holds structure all round; a narrow view of it sees a wedge. Structure outside the wedge is not
  // counted against the pair, so the match is as good as the wedge's own.
  const ViewSearchConfig cfg;
  const auto place = makePlace(3);
  const auto narrow = viewContext(viewOf(place, 0.0, deg2rad(35.0)), kCell, cfg);
  EXPECT_GT(matchViews(narrow, viewContext(viewOf(place, 0.0), kCell, cfg)).similarity, 0.9);
  // The other way round (the full turn as the narrow side), most of it is not in the wedge.
  EXPECT_LT(matchViews(viewContext(viewOf(place, 0.0), kCell, cfg), narrow).similarity, 0.5);
  const int seen = std::popcount(narrow.seen.lo) + std::popcount(narrow.seen.hi);
  EXPECT_GE(seen, 22);  // 70 deg of 128 sectors of 2.8 deg: about 25
  EXPECT_LE(seen, 28);
}

// A narrow view's field is the sectors it saw, one sector in from each edge, counted as bevAgreement counts its
// sectors: a wedge turned 60 deg left has its field there, and bevAgreement judges structure there only.
TEST(ViewContext, FieldIsTheViewOneSectorInside) {
  const ViewSearchConfig cfg;
  const auto place = makePlace(5);
  const auto cells = viewOf(place, 0.0, deg2rad(35.0));
  // The sensor's frame is turned by -60 deg: the wedge it saw lies 60 deg to its left.
  std::vector<BevCell> left;
  const double c = std::cos(deg2rad(60.0)), s = std::sin(deg2rad(60.0));
  for (const auto& b : cells) {
    const double x = (b.ix + 0.5) * kCell, y = (b.iy + 0.5) * kCell;
    left.push_back({static_cast<std::int16_t>(std::floor((c * x - s * y) / kCell)),
                    static_cast<std::int16_t>(std::floor((s * x + c * y) / kCell)), b.cls});
  }
  const auto context = viewContext(left, kCell, cfg);
  const auto field = context.field();
  ASSERT_EQ(field.size(), static_cast<std::size_t>(ViewContext::kSectors));
  const int seen = std::popcount(context.seen.lo) + std::popcount(context.seen.hi);
  const auto in_field = static_cast<int>(std::count(field.begin(), field.end(), true));
  EXPECT_EQ(in_field, seen - 2);  // one contiguous wedge: its edge sectors drop out
  auto sector = [](double deg) { return static_cast<std::size_t>((deg + 180.0) / 360.0 * ViewContext::kSectors); };
  EXPECT_TRUE(field[sector(60.0)]);
  EXPECT_TRUE(field[sector(40.0)]);
  EXPECT_FALSE(field[sector(0.0)]);
  EXPECT_FALSE(field[sector(-120.0)]);
  // bevAgreement with that field judges the wedge: the view against itself agrees fully; with the opposite field
  // nothing is judged (0).
  EXPECT_DOUBLE_EQ(bevAgreement(left, left, kCell, Mat4d::Identity(), 1.0, 45.0, StructureClasses::kCompared, &field),
                   1.0);
  std::vector<bool> opposite(field.size());
  for (std::size_t k = 0; k < field.size(); ++k) opposite[k] = field[(k + field.size() / 2) % field.size()];
  EXPECT_DOUBLE_EQ(
      bevAgreement(left, left, kCell, Mat4d::Identity(), 1.0, 45.0, StructureClasses::kCompared, &opposite), 0.0);
}

TEST(ViewContext, MergedClassesCompareStructureOnly) {
  ViewSearchConfig cfg;
  std::vector<BevCell> building, vegetation;
  for (int r = 10; r < 30; ++r)
    for (int a = 0; a < 30; ++a) {
      const double x = r * std::cos(deg2rad(a)), y = r * std::sin(deg2rad(a));
      const auto ix = static_cast<std::int16_t>(std::floor(x / kCell)),
                 iy = static_cast<std::int16_t>(std::floor(y / kCell));
      building.push_back({ix, iy, static_cast<std::uint8_t>(Background::kBuilding)});
      vegetation.push_back({ix, iy, static_cast<std::uint8_t>(Background::kVegetation)});
    }
  EXPECT_EQ(matchViews(viewContext(building, kCell, cfg), viewContext(vegetation, kCell, cfg)).similarity, 0.0);
  EXPECT_DOUBLE_EQ(matchViews(viewContext(building, kCell, cfg, true), viewContext(vegetation, kCell, cfg)).similarity,
                   1.0);
  EXPECT_DOUBLE_EQ(matchViews(viewContext(building, kCell, cfg), viewContext(vegetation, kCell, cfg, true)).similarity,
                   1.0);
}

TEST(ViewContext, EmptyAndMismatchedContexts) {
  ViewSearchConfig cfg;
  const auto empty = viewContext({}, kCell, cfg);
  EXPECT_EQ(empty.rings(), cfg.rings);
  EXPECT_EQ(matchViews(empty, empty).similarity, 0.0);
  const auto full = viewContext(viewOf(makePlace(1), 0.0), kCell, cfg);
  EXPECT_EQ(matchViews(empty, full).similarity, 0.0);  // nothing seen, nothing judged
  // Cells beyond max_range_m, nearer than 2 m or of no class are left out.
  const std::vector<BevCell> outside = {{200, 0, 3}, {0, 0, 3}, {40, 0, 0}};
  const auto none = viewContext(outside, kCell, cfg);
  for (int i = 0; i < none.rings(); ++i) {
    EXPECT_EQ(none.building[i].lo | none.building[i].hi, 0u);
    EXPECT_EQ(none.vegetation[i].lo | none.vegetation[i].hi, 0u);
  }
  cfg.rings = 12;
  EXPECT_THROW(matchViews(viewContext({}, kCell, cfg), full), InputError);
  // Settings no configuration file can give (validateConfig refuses them) are refused here too.
  cfg.rings = 0;
  EXPECT_THROW(viewContext({}, kCell, cfg), InputError);
  cfg.rings = 65;  // a sector's rings must fit one word
  EXPECT_THROW(viewContext({}, kCell, cfg), InputError);
  ViewContext wide;
  wide.building.resize(65);
  wide.vegetation.resize(65);
  EXPECT_THROW(ViewMatcher{wide}, InputError);
  // Building and vegetation rings must pair up.
  auto uneven = full;
  uneven.vegetation.push_back({});
  EXPECT_THROW(ViewMatcher{uneven}, InputError);
  EXPECT_THROW(matchViews(full, uneven), InputError);
  cfg.rings = 30;
  EXPECT_THROW(viewContext({}, std::numeric_limits<double>::quiet_NaN(), cfg), InputError);
  cfg.max_range_m = 1.0;
  EXPECT_THROW(viewContext({}, kCell, cfg), InputError);
}

// The similarity and heading from the definition, bit by bit: at each shift, over every ring and every sector
// the narrow view saw, cells where both hold structure of one class group over cells where either holds any.
ViewMatch bruteMatch(const ViewContext& narrow, const ViewContext& other) {
  const auto bit = [](const ViewContext::Row& r, int s) { return ((s < 64 ? r.lo : r.hi) >> (s & 63) & 1U) != 0; };
  const bool merged = narrow.merged || other.merged;
  ViewMatch best;
  int best_shift = 0;
  for (int shift = 0; shift < ViewContext::kSectors; ++shift) {
    int same = 0, judged = 0;
    for (int i = 0; i < narrow.rings(); ++i)
      for (int u = 0; u < ViewContext::kSectors; ++u) {
        if (!bit(narrow.seen, u)) continue;
        const int t = (u + shift) % ViewContext::kSectors;
        const bool nb = bit(narrow.building[i], u), nv = bit(narrow.vegetation[i], u);
        const bool ob = bit(other.building[i], t), ov = bit(other.vegetation[i], t);
        same += merged ? ((nb || nv) && (ob || ov)) : ((nb && ob) || (nv && ov));
        judged += nb || nv || ob || ov;
      }
    const double similarity = judged ? static_cast<double>(same) / judged : 0.0;
    if (similarity > best.similarity) {
      best.similarity = similarity;
      best_shift = shift;
    }
  }
  best.heading =
      (ViewContext::kSectors - best_shift) % ViewContext::kSectors * 2.0 * std::numbers::pi / ViewContext::kSectors;
  return best;
}

// Random contexts of every kind (rings 1 to 64, views of any width, merged or not): the matcher agrees with the
// definition exactly.
TEST(ViewContext, MatchAgreesWithTheDefinition) {
  std::mt19937_64 rng(5);
  const auto randomRow = [&](double density) {
    ViewContext::Row r;
    for (int s = 0; s < ViewContext::kSectors; ++s)
      if (std::uniform_real_distribution<double>(0, 1)(rng) < density)
        (s < 64 ? r.lo : r.hi) |= std::uint64_t{1} << (s & 63);
    return r;
  };
  for (int trial = 0; trial < 300; ++trial) {
    const int rings = 1 + static_cast<int>(rng() % 64);
    const auto make = [&](double view, double density) {
      ViewContext v;
      v.merged = rng() % 4 == 0;
      v.seen = randomRow(view);
      for (int i = 0; i < rings; ++i) {
        v.building.push_back(randomRow(density));
        v.vegetation.push_back(randomRow(density));
      }
      return v;
    };
    const double view = trial % 3 == 0 ? 1.0 : 0.05 + 0.5 * (trial % 7) / 7.0;
    const auto narrow = make(view, 0.3), other = make(1.0, 0.1 + 0.1 * (trial % 5));
    const auto got = matchViews(narrow, other), want = bruteMatch(narrow, other);
    ASSERT_EQ(got.similarity, want.similarity) << trial;
    ASSERT_EQ(got.heading, want.heading) << trial;
  }
}

// Equal similarities at several shifts give the first of them: a structure pattern repeated every 90 deg
// matches itself at four headings, and the answer is always the unturned one.
TEST(ViewContext, TiesGoToTheFirstShift) {
  const ViewSearchConfig cfg;
  std::vector<BevCell> cross;
  for (int arm = 0; arm < 4; ++arm)
    for (double r = 5; r < 40; r += kCell) {
      const double a = arm * std::numbers::pi / 2 + 0.3;
      cross.push_back({static_cast<std::int16_t>(std::floor(r * std::cos(a) / kCell)),
                       static_cast<std::int16_t>(std::floor(r * std::sin(a) / kCell)),
                       static_cast<std::uint8_t>(Background::kBuilding)});
    }
  const auto c = viewContext(cross, kCell, cfg);
  const ViewMatch m = matchViews(c, c);
  EXPECT_DOUBLE_EQ(m.similarity, 1.0);
  EXPECT_EQ(m.heading, 0.0);
}

// Hostile cells (the ends of the int16 grid, class values no labeller writes) are left out or only open a
// sector: nothing is written out of bounds and nothing counts as structure.
TEST(ViewContext, OddCellsAreHarmless) {
  const ViewSearchConfig cfg;
  std::vector<BevCell> odd;
  for (const std::int16_t i : {std::int16_t{-32768}, std::int16_t{32767}, std::int16_t{0}, std::int16_t{40}})
    for (const std::int16_t j : {std::int16_t{-32768}, std::int16_t{32767}, std::int16_t{0}, std::int16_t{-40}})
      for (const std::uint8_t cls : {1, 5, 200, 255}) odd.push_back({i, j, cls});
  const auto v = viewContext(odd, kCell, cfg);
  EXPECT_FALSE(v.seesStructure());
  for (int i = 0; i < v.rings(); ++i) {
    EXPECT_EQ(v.building[i].lo | v.building[i].hi, 0u);
    EXPECT_EQ(v.vegetation[i].lo | v.vegetation[i].hi, 0u);
  }
  EXPECT_EQ(matchViews(v, viewContext(viewOf(makePlace(1), 0.0), kCell, cfg)).similarity, 0.0);
  EXPECT_TRUE(viewContext(viewOf(makePlace(1), 0.0, 0.6), kCell, cfg).seesStructure());
}

}  // namespace
}  // namespace sglc

namespace sglc {
namespace {

bool sameContext(const ViewContext& a, const ViewContext& b) {
  const auto rowsEqual = [](const std::vector<ViewContext::Row>& x, const std::vector<ViewContext::Row>& y) {
    return std::equal(x.begin(), x.end(), y.begin(), y.end(),
                      [](const auto& p, const auto& q) { return p.lo == q.lo && p.hi == q.hi; });
  };
  return rowsEqual(a.building, b.building) && rowsEqual(a.vegetation, b.vegetation) && a.seen.lo == b.seen.lo &&
         a.seen.hi == b.seen.hi && a.merged == b.merged;
}

TEST(ViewContext, KeptWithTheFingerprintForItsSettingsOnly) {
  Fingerprint fp;
  fp.background_cell = static_cast<float>(kCell);
  fp.background = viewOf(makePlace(3), 0.4);
  const ViewSearchConfig cfg;
  const auto first = viewContextOf(fp, cfg);
  EXPECT_TRUE(sameContext(*first, viewContext(fp.background, fp.background_cell, cfg)));
  EXPECT_EQ(viewContextOf(fp, cfg).get(), first.get());  // kept: not computed again
  ViewSearchConfig other = cfg;
  other.rings = 20;
  const auto fewer = viewContextOf(fp, other);  // other settings: computed for them, never the kept one
  EXPECT_EQ(fewer->rings(), 20);
  EXPECT_EQ(viewContextOf(fp, cfg)->rings(), cfg.rings);
  // A copy starts empty (it may be changed), and finalize() forgets what the stored data gave.
  Fingerprint copy = fp;
  copy.background = viewOf(makePlace(4), 0.0);
  EXPECT_TRUE(sameContext(*viewContextOf(copy, cfg), viewContext(copy.background, copy.background_cell, cfg)));
  fp.labeller_structure = true;  // part of the key: merged classes
  EXPECT_TRUE(viewContextOf(fp, cfg)->merged);
  fp.background = copy.background;
  fp.finalize();
  EXPECT_TRUE(sameContext(*viewContextOf(fp, cfg), viewContext(fp.background, fp.background_cell, cfg, true)));
}

}  // namespace
}  // namespace sglc
