// Background features: labelled BEV cells, their structure spectrum and agreement, plane features.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "sglc/background.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

using test::deg2rad;

// Angle of the centre of one-degree sector k (sectors start at -pi).
double sectorCentre(int k) { return -std::numbers::pi + deg2rad(k + 0.5); }

struct BgCloud {
  Points points;
  std::vector<Background> bg;
  void add(const Vec3f& p, Background b) {
    points.push_back(p);
    bg.push_back(b);
  }
  void add(const Points& pts, Background b) {
    for (const auto& p : pts) add(p, b);
  }
};

// Stored BEV cells of `cls` at the given polar positions (cell size 0.5 m).
std::vector<BevCell> cellsAt(const std::vector<std::pair<double, double>>& range_angle, Background cls) {
  std::vector<BevCell> out;
  for (const auto& [r, a] : range_angle)
    out.push_back({static_cast<std::int16_t>(std::floor(r * std::cos(a) / 0.5)),
                   static_cast<std::int16_t>(std::floor(r * std::sin(a) / 0.5)), static_cast<std::uint8_t>(cls)});
  return out;
}

TEST(StructureSpectrum, ZeroWithoutStructure) {
  const DescriptorConfig cfg;
  // Road only, and structure more than half a ring (2.81 m) outside [ring_min, ring_max).
  auto cells = cellsAt({{10, 0.1}, {20, 1.0}, {30, 2.0}}, Background::kRoad);
  for (const auto& c : cellsAt({{2.0, 0.3}, {53.2, 0.3}, {70.0, 1.3}}, Background::kBuilding)) cells.push_back(c);
  const auto s = structureSpectrum(cells, 0.5, 8, 2, cfg);
  ASSERT_EQ(s.size(), 48u);
  for (float v : s) EXPECT_EQ(v, 0.0f);
  EXPECT_EQ(structureSpectrum({}, 0.5, 8, 2, cfg), std::vector<float>(48, 0.0f));
  // Just outside the edges, the outer rings get a share that tapers: less than half, and less the farther out.
  double previous = 0.5;
  for (const double r : {50.5, 51.5, 52.5}) {
    const auto t = structureSpectrum(cellsAt({{r, 0.3}}, Background::kBuilding), 0.5, 8, 2, cfg);
    EXPECT_GT(t[7 * 3], 0.0f) << r;
    EXPECT_LT(t[7 * 3], previous) << r;
    previous = t[7 * 3];
    for (int k = 0; k < 7 * 3; ++k) EXPECT_EQ(t[k], 0.0f) << r;
  }
  const auto inner = structureSpectrum(cellsAt({{4.0, 0.3}}, Background::kBuilding), 0.5, 8, 2, cfg);
  EXPECT_GT(inner[0], 0.0f);
  EXPECT_LT(inner[0], 0.5f);
}

TEST(StructureSpectrum, HandChecked) {
  // 8 rings over [5, 50): 5.625 m each, ring k centred at 5 + (k + 0.5) * 5.625 m. Building and fence (part 0)
  // at two opposite sectors, 12 m out: between the centres of rings 0 (7.81 m) and 1 (13.44 m), so 0.256 of each
  // cell goes to ring 0 and 0.744 to ring 1. Per ring, order 0 adds both shares, order 1 cancels (e^0 + e^(i pi)
  // = 0), order 2 adds up again. One vegetation cell (part 1) on ring 3's centre: 1 at every order of ring 3.
  const DescriptorConfig cfg;  // 360 sectors
  auto cells = cellsAt({{12.0, sectorCentre(10)}}, Background::kBuilding);
  for (const auto& c : cellsAt({{12.0, sectorCentre(190)}}, Background::kFence)) cells.push_back(c);
  for (const auto& c : cellsAt({{24.6875, sectorCentre(100)}}, Background::kVegetation)) cells.push_back(c);
  const auto s = structureSpectrum(cells, 0.5, 8, 2, cfg);
  ASSERT_EQ(s.size(), 48u);
  std::vector<float> expected(48, 0.0f);
  const float w1 = static_cast<float>((12.0 - 5.0) / 5.625 - 0.5);  // 0.744
  for (const auto& [ring, share] : {std::pair{0, 1.0f - w1}, std::pair{1, w1}}) {
    expected[ring * 3 + 0] = 2.0f * share;
    expected[ring * 3 + 2] = 2.0f * share;
  }
  for (int k = 0; k < 3; ++k) expected[(8 + 3) * 3 + k] = 1.0f;
  // Cell centres sit on a 0.5 m grid, near but not on the positions above (a few centimetres of radius).
  for (int k = 0; k < 48; ++k) EXPECT_NEAR(s[k], expected[k], 0.03) << k;
}

// A wall a little nearer (the other lane) moves weight between neighbouring rings gradually.
TEST(StructureSpectrum, SmoothInRange) {
  const DescriptorConfig cfg;
  std::vector<float> previous;
  for (double r = 12.0; r <= 16.0 + 1e-9; r += 0.5) {
    std::vector<std::pair<double, double>> wall;
    for (int s = 0; s < 40; ++s) wall.emplace_back(r, sectorCentre(100 + s));
    const auto now = structureSpectrum(cellsAt(wall, Background::kBuilding), 0.5, 8, 2, cfg);
    if (!previous.empty()) {
      double step = 0, norm = 0;
      for (std::size_t k = 0; k < now.size(); ++k) {
        step += double(now[k] - previous[k]) * (now[k] - previous[k]);
        norm += double(now[k]) * now[k];
      }
      EXPECT_LT(std::sqrt(step / norm), 0.25) << r;  // at most a share of ~0.09 per 0.5 m moves
    }
    previous = now;
  }
}

TEST(StructureSpectrum, RotationInvariant) {
  // Structure at random places; turning the view changes only the phases of the angular Fourier series.
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> angle(-std::numbers::pi, std::numbers::pi), range(5.5, 49.5);
  std::vector<std::pair<double, double>> walls, trees;
  for (int k = 0; k < 300; ++k) (k % 3 ? walls : trees).emplace_back(range(rng), angle(rng));
  auto cells = [&](double turn) {
    auto turned = [&](const std::vector<std::pair<double, double>>& v) {
      std::vector<std::pair<double, double>> out;
      for (const auto& [r, a] : v) out.emplace_back(r, a + turn);
      return out;
    };
    auto out = cellsAt(turned(walls), Background::kBuilding);
    for (const auto& c : cellsAt(turned(trees), Background::kVegetation)) out.push_back(c);
    return out;
  };
  const DescriptorConfig cfg;
  const auto s = structureSpectrum(cells(0.0), 0.5, 8, 2, cfg);
  double norm = 0;
  for (float v : s) norm += double(v) * v;
  for (double deg : {7.0, 90.0, 180.0, 263.0}) {
    const auto t = structureSpectrum(cells(deg2rad(deg)), 0.5, 8, 2, cfg);
    double diff = 0;
    for (std::size_t k = 0; k < s.size(); ++k) diff += double(s[k] - t[k]) * (s[k] - t[k]);
    // Cells move on the 0.5 m grid when turned, so a few land in a neighbouring sector or ring.
    EXPECT_LT(std::sqrt(diff / norm), 0.1) << deg;
  }
  // Another place differs by far more.
  std::vector<std::pair<double, double>> other;
  for (int k = 0; k < 300; ++k) other.emplace_back(range(rng), angle(rng));
  const auto o = structureSpectrum(cellsAt(other, Background::kBuilding), 0.5, 8, 2, cfg);
  double diff = 0;
  for (std::size_t k = 0; k < s.size(); ++k) diff += double(s[k] - o[k]) * (s[k] - o[k]);
  EXPECT_GT(std::sqrt(diff / norm), 0.3);
}

TEST(BevCells, PriorityInSharedCell) {
  BgCloud c;
  // Cell (2, 2) of 0.5 m: road + fence -> fence.
  c.add(Vec3f(1.1f, 1.1f, -1.7f), Background::kRoad);
  c.add(Vec3f(1.2f, 1.3f, 0.5f), Background::kFence);
  // Cell (4, 2): building + vegetation + road -> building.
  c.add(Vec3f(2.1f, 1.2f, 0), Background::kVegetation);
  c.add(Vec3f(2.2f, 1.4f, 3), Background::kBuilding);
  c.add(Vec3f(2.3f, 1.1f, -1.7f), Background::kRoad);
  // Cell (-3, 2): vegetation + road -> vegetation.
  c.add(Vec3f(-1.4f, 1.2f, -1.7f), Background::kRoad);
  c.add(Vec3f(-1.3f, 1.3f, 1.0f), Background::kVegetation);
  // Cell (0, -1): road only.
  c.add(Vec3f(0.2f, -0.3f, -1.7f), Background::kRoad);
  // Ignored: no background class, and beyond range.
  c.add(Vec3f(3.1f, 3.1f, 0), Background::kNone);
  c.add(Vec3f(60.0f, 0.0f, 0), Background::kBuilding);
  const auto cells = bevCells(c.points, c.bg, 0.5, 50.0, 1e9);
  ASSERT_EQ(cells.size(), 4u);
  // Sorted by (iy, ix).
  auto expect = [&](int k, int ix, int iy, Background b) {
    EXPECT_EQ(cells[k].ix, ix) << k;
    EXPECT_EQ(cells[k].iy, iy) << k;
    EXPECT_EQ(cells[k].cls, static_cast<std::uint8_t>(b)) << k;
  };
  expect(0, 0, -1, Background::kRoad);
  expect(1, -3, 2, Background::kVegetation);
  expect(2, 2, 2, Background::kFence);
  expect(3, 4, 2, Background::kBuilding);
  // The order of points does not matter.
  BgCloud rev;
  for (std::size_t i = c.points.size(); i-- > 0;) rev.add(c.points[i], c.bg[i]);
  const auto cells2 = bevCells(rev.points, rev.bg, 0.5, 50.0, 1e9);
  ASSERT_EQ(cells2.size(), cells.size());
  for (std::size_t k = 0; k < cells.size(); ++k) {
    EXPECT_EQ(cells2[k].ix, cells[k].ix);
    EXPECT_EQ(cells2[k].iy, cells[k].iy);
    EXPECT_EQ(cells2[k].cls, cells[k].cls);
  }
}

TEST(BevCells, StructureAboveTheBandIsLeftOut) {
  BgCloud c;
  // A tree crown over the road (cell (2, 2)): above the band it leaves the road to the road. A wall whose foot
  // is in the band (cell (6, 2)) stays a wall. Road points are never left out, however high.
  c.add(Vec3f(1.1f, 1.1f, -1.7f), Background::kRoad);
  c.add(Vec3f(1.2f, 1.2f, 3.5f), Background::kVegetation);
  c.add(Vec3f(3.1f, 1.1f, 0.4f), Background::kBuilding);
  c.add(Vec3f(3.2f, 1.2f, 6.0f), Background::kBuilding);
  c.add(Vec3f(-2.2f, 1.2f, 2.0f), Background::kRoad);  // a ramp above the sensor: cell (-5, 2)
  const auto banded = bevCells(c.points, c.bg, 0.5, 50.0, 1.0);
  ASSERT_EQ(banded.size(), 3u);
  EXPECT_EQ(banded[0].ix, -5);
  EXPECT_EQ(banded[0].cls, static_cast<std::uint8_t>(Background::kRoad));
  EXPECT_EQ(banded[1].ix, 2);
  EXPECT_EQ(banded[1].cls, static_cast<std::uint8_t>(Background::kRoad));
  EXPECT_EQ(banded[2].ix, 6);
  EXPECT_EQ(banded[2].cls, static_cast<std::uint8_t>(Background::kBuilding));
  // Without the band the crown makes its cell vegetation.
  const auto all = bevCells(c.points, c.bg, 0.5, 50.0, 1e9);
  ASSERT_EQ(all.size(), 3u);
  EXPECT_EQ(all[1].cls, static_cast<std::uint8_t>(Background::kVegetation));
}

TEST(BevCells, MajorityOfStructureClassesWins) {
  BgCloud c;
  // Cell (2, 2): a facade with one point mislabelled fence -> building (the highest priority present would
  // be fence); road at its foot does not count while any structure is seen.
  for (int k = 0; k < 5; ++k) c.add(Vec3f(1.1f + 0.05f * k, 1.1f, 0.5f * k), Background::kBuilding);
  c.add(Vec3f(1.3f, 1.2f, 2.0f), Background::kFence);
  for (int k = 0; k < 9; ++k) c.add(Vec3f(1.05f + 0.04f * k, 1.4f, -1.7f), Background::kRoad);
  // Cell (-3, 2): vegetation 2, fence 2 -> a tie goes to the higher priority (fence).
  c.add(Vec3f(-1.4f, 1.2f, 1.0f), Background::kVegetation);
  c.add(Vec3f(-1.3f, 1.3f, 1.2f), Background::kVegetation);
  c.add(Vec3f(-1.2f, 1.3f, 0.4f), Background::kFence);
  c.add(Vec3f(-1.3f, 1.4f, 0.6f), Background::kFence);
  const auto cells = bevCells(c.points, c.bg, 0.5, 50.0, 1e9);
  ASSERT_EQ(cells.size(), 2u);
  EXPECT_EQ(cells[0].ix, -3);
  EXPECT_EQ(cells[0].cls, static_cast<std::uint8_t>(Background::kFence));
  EXPECT_EQ(cells[1].ix, 2);
  EXPECT_EQ(cells[1].cls, static_cast<std::uint8_t>(Background::kBuilding));
}

TEST(BevAgreement, GridCellsTakeTheMajorityOfTheirStoredCells) {
  // One 2 m grid cell holds four stored 0.5 m cells: building x3 + fence x1 in one cloud, building x4 in the
  // other -> the same class (building), full agreement. With road x3 + vegetation x1 the cell is vegetation.
  const std::vector<BevCell> a{{0, 0, 3}, {1, 0, 3}, {0, 1, 3}, {1, 1, 4}},
      b{{0, 0, 3}, {1, 0, 3}, {2, 1, 3}, {3, 3, 3}};
  EXPECT_DOUBLE_EQ(bevAgreement(a, b, 0.5, Mat4d::Identity(), 2.0, 10.0), 1.0);
  const std::vector<BevCell> road{{0, 0, 1}, {1, 0, 1}, {0, 1, 1}, {1, 1, 2}}, veg{{2, 2, 2}};
  EXPECT_DOUBLE_EQ(bevAgreement(road, veg, 0.5, Mat4d::Identity(), 2.0, 10.0), 1.0);
  EXPECT_DOUBLE_EQ(bevAgreement(a, veg, 0.5, Mat4d::Identity(), 2.0, 10.0), 0.0);
}

// With the structure classes merged (views labelled by the built-in labeller), building against vegetation
// agrees; structure against road, and structure where the other view saw nothing, are judged as before.
TEST(BevAgreement, MergedClassesCompareStructureAgainstRoadOnly) {
  constexpr auto kMerged = StructureClasses::kMerged;
  // Grid cells of 2 m: (0, 0) building in a, vegetation in b; (1, 0) fence in a, road in b.
  const std::vector<BevCell> a{{0, 0, 3}, {4, 0, 4}}, b{{0, 0, 2}, {4, 0, 1}};
  EXPECT_DOUBLE_EQ(bevAgreement(a, b, 0.5, Mat4d::Identity(), 2.0, 10.0), 0.0);
  EXPECT_DOUBLE_EQ(bevAgreement(a, b, 0.5, Mat4d::Identity(), 2.0, 10.0, kMerged), 0.5);
  const std::vector<BevCell> road{{0, 0, 1}, {4, 0, 1}};
  EXPECT_DOUBLE_EQ(bevAgreement(a, road, 0.5, Mat4d::Identity(), 2.0, 10.0, kMerged), 0.0);
  // Vegetation 20 m away from anything the other view holds: not judged, in either mode.
  const std::vector<BevCell> far{{0, 0, 2}, {40, 0, 2}}, near{{0, 0, 3}};
  EXPECT_DOUBLE_EQ(bevAgreement(far, near, 0.5, Mat4d::Identity(), 2.0, 30.0), 0.0);
  EXPECT_DOUBLE_EQ(bevAgreement(far, near, 0.5, Mat4d::Identity(), 2.0, 30.0, kMerged), 1.0);
}

// A field (a narrow view's sectors) limits the judged cells to the directions the query looked in: the
// candidate's fence behind the query, which the query never saw, does not count against it.
TEST(BevAgreement, FieldLimitsTheJudgedCellsToTheQuerysDirections) {
  // 2 m grid cells: ahead (+x) both hold building; behind (-x) the query holds road, the candidate fence.
  const std::vector<BevCell> query{{10, 0, 3}, {-10, 0, 1}}, candidate{{10, 0, 3}, {-10, 0, 4}};
  EXPECT_DOUBLE_EQ(bevAgreement(query, candidate, 0.5, Mat4d::Identity(), 2.0, 10.0), 0.5);
  // Four sectors from -pi: the second and third (-90 .. 90 deg) are ahead.
  const std::vector<bool> ahead{false, true, true, false}, behind{true, false, false, true};
  EXPECT_DOUBLE_EQ(
      bevAgreement(query, candidate, 0.5, Mat4d::Identity(), 2.0, 10.0, StructureClasses::kCompared, &ahead), 1.0);
  EXPECT_DOUBLE_EQ(
      bevAgreement(query, candidate, 0.5, Mat4d::Identity(), 2.0, 10.0, StructureClasses::kCompared, &behind), 0.0);
  const std::vector<bool> nowhere(4, false), all;
  EXPECT_DOUBLE_EQ(
      bevAgreement(query, candidate, 0.5, Mat4d::Identity(), 2.0, 10.0, StructureClasses::kCompared, &nowhere), 0.0);
  EXPECT_DOUBLE_EQ(bevAgreement(query, candidate, 0.5, Mat4d::Identity(), 2.0, 10.0, StructureClasses::kCompared, &all),
                   0.5);
}

// An asymmetric place: a road, facades along both sides with a cross wall each, a hedge of vegetation and a
// fence, as the BEV sees a street (structure in strips, not blocks: a block shifted by a few metres would still
// cover most of itself).
BgCloud street() {
  BgCloud c;
  c.add(test::makeFloor(-40, 40, -6, 6, -1.7, 0.25), Background::kRoad);
  c.add(test::makeFloor(-35, -5, 8, 9.5, 0.5, 0.25), Background::kBuilding);
  c.add(test::makeFloor(-36.5, -35, 8, 25, 0.5, 0.25), Background::kBuilding);
  c.add(test::makeFloor(5, 35, -9.5, -8, 0.5, 0.25), Background::kBuilding);
  c.add(test::makeFloor(15, 16.5, -25, -9.5, 0.5, 0.25), Background::kBuilding);
  c.add(test::makeFloor(5, 30, 10, 13, 0.0, 0.25), Background::kVegetation);
  c.add(test::makeFloor(-30, -8, -8, -7.5, 0.0, 0.25), Background::kFence);
  return c;
}

TEST(BevAgreement, RobustToScatteredLabelNoise) {
  // The street relabelled at random: 10 % of building points become fence or vegetation, 10 % of
  // vegetation becomes building. Agreement with the clean street stays high on the 2 m grid.
  const BgCloud clean = street();
  BgCloud noisy = clean;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (auto& b : noisy.bg) {
    const double x = u(rng);
    if (b == Background::kBuilding && x < 0.1)
      b = x < 0.05 ? Background::kFence : Background::kVegetation;
    else if (b == Background::kVegetation && x < 0.1)
      b = Background::kBuilding;
  }
  const auto q = bevCells(clean.points, clean.bg, 0.5, 50.0, 1e9);
  const auto c = bevCells(noisy.points, noisy.bg, 0.5, 50.0, 1e9);
  EXPECT_GT(bevAgreement(q, c, 0.5, Mat4d::Identity(), 2.0, 25.0), 0.95);
}

TEST(BevAgreement, SelfAndMoved) {
  const BgCloud c = street();
  const auto q = bevCells(c.points, c.bg, 0.5, 50.0, 1e9);
  ASSERT_FALSE(q.empty());
  EXPECT_DOUBLE_EQ(bevAgreement(q, q, 0.5, Mat4d::Identity(), 1.0, 50.0), 1.0);
  // The same place seen from a sensor at T (the candidate): candidate points = T^-1 * query points.
  const Mat4d T = test::makeT(12.0, 3.3, -1.7, 0.2);
  const auto cand = bevCells(test::transformPoints(T.inverse(), c.points), c.bg, 0.5, 50.0, 1e9);
  // On the default 2 m grid nearly every structure cell agrees; on a 1 m grid the strips' edges, re-binned after
  // the turn, disagree more often.
  EXPECT_GT(bevAgreement(q, cand, 0.5, T, 2.0, 25.0), 0.85);
  const double right = bevAgreement(q, cand, 0.5, T, 1.0, 50.0);
  EXPECT_GT(right, 0.7);
  EXPECT_LE(right, 1.0);
  // Wrong poses: shifted across the road, or rotated.
  const double shifted = bevAgreement(q, cand, 0.5, test::makeT(0, 0, 6.0, 0) * T, 1.0, 50.0);
  const double rotated = bevAgreement(q, cand, 0.5, test::makeT(20.0, 0, 0, 0) * T, 1.0, 50.0);
  const double identity = bevAgreement(q, cand, 0.5, Mat4d::Identity(), 1.0, 50.0);
  EXPECT_LT(shifted, right - 0.4);
  EXPECT_LT(rotated, right - 0.4);
  EXPECT_LT(identity, right - 0.4);
  for (double v : {shifted, rotated, identity}) EXPECT_GE(v, 0.0);
}

TEST(BevAgreement, EmptyCloudsGiveZero) {
  const BgCloud c = street();
  const auto q = bevCells(c.points, c.bg, 0.5, 50.0, 1e9);
  const double both = bevAgreement({}, {}, 0.5, Mat4d::Identity(), 1.0, 50.0);
  const double one = bevAgreement(q, {}, 0.5, Mat4d::Identity(), 1.0, 50.0);
  const double other = bevAgreement({}, q, 0.5, Mat4d::Identity(), 1.0, 50.0);
  for (double v : {both, one, other}) {
    EXPECT_FALSE(std::isnan(v));
    EXPECT_EQ(v, 0.0);
  }
  // Everything outside the grid: nothing to compare, 0 (not NaN).
  const double far = bevAgreement(q, q, 0.5, test::makeT(0, 500, 0, 0), 1.0, 50.0);
  EXPECT_FALSE(std::isnan(far));
  EXPECT_EQ(far, 0.0);
}

TEST(BevAgreement, StructureTheOtherViewHasNotSeenIsNotJudged) {
  // Grid 2 m. The query sees a wall at x = 20 m the candidate has no return near (hidden from it, or out of
  // its field of view); both see the wall at x = 4 m and the road before it.
  std::vector<BevCell> q{{8, 0, 3}, {40, 0, 3}, {2, 0, 1}, {4, 2, 1}}, c{{8, 0, 3}, {2, 0, 1}};
  EXPECT_DOUBLE_EQ(bevAgreement(q, c, 0.5, Mat4d::Identity(), 2.0, 30.0), 1.0);
  // Had the candidate seen road beside that wall, the missing wall would count against it.
  c.push_back({44, 0, 1});
  EXPECT_DOUBLE_EQ(bevAgreement(q, c, 0.5, Mat4d::Identity(), 2.0, 30.0), 0.5);
}

TEST(BevAgreement, RoadAgainstRoadIsNotJudged) {
  // Two streets agree on road anywhere: with no structure in either view there is nothing to judge.
  const std::vector<BevCell> a{{0, 0, 1}, {4, 0, 1}, {8, 0, 1}}, b{{0, 0, 1}, {4, 0, 1}};
  EXPECT_EQ(bevAgreement(a, b, 0.5, Mat4d::Identity(), 2.0, 10.0), 0.0);
  // A wall on the other's road is a disagreement.
  const std::vector<BevCell> wall{{0, 0, 3}, {4, 0, 1}};
  EXPECT_DOUBLE_EQ(bevAgreement(a, wall, 0.5, Mat4d::Identity(), 2.0, 10.0), 0.0);
}

TEST(BevAgreement, ClassMismatchCounts) {
  // Same cells, different classes: no agreement.
  std::vector<BevCell> a{{0, 0, 1}, {4, 4, 3}}, b{{0, 0, 2}, {4, 4, 3}};
  EXPECT_DOUBLE_EQ(bevAgreement(a, b, 0.5, Mat4d::Identity(), 0.5, 10.0), 0.5);
}

TEST(ViewSpan, CountsTheTenDegreeSectorsHoldingACell) {
  EXPECT_EQ(viewSpanDeg({}, 0.5, 0.0), 0.0);
  // Road all around at 10 m: the whole horizon.
  std::vector<std::pair<double, double>> ring;
  for (int k = 0; k < 36; ++k) ring.emplace_back(10.0, deg2rad(10.0 * k + 5.0));
  EXPECT_DOUBLE_EQ(viewSpanDeg(cellsAt(ring, Background::kRoad), 0.5, 4.0), 360.0);
  // A 70 deg wedge ahead (-35..35 deg, road and a wall) touches the 8 sectors from -40 to 40 deg.
  std::vector<std::pair<double, double>> wedge;
  for (double a = -35.0; a <= 35.0; a += 1.0)
    for (double r : {6.0, 15.0, 30.0}) wedge.emplace_back(r, deg2rad(a));
  EXPECT_DOUBLE_EQ(viewSpanDeg(cellsAt(wedge, Background::kBuilding), 0.5, 4.0), 80.0);
  // Behind the sensor, on either side of the +-180 deg seam: one sector each.
  EXPECT_DOUBLE_EQ(viewSpanDeg(cellsAt({{20.0, deg2rad(175.0)}, {20.0, deg2rad(-175.0)}}, Background::kRoad), 0.5, 4.0),
                   20.0);
  // Cells nearer than min_range are not counted: their bearing is too coarse.
  EXPECT_EQ(viewSpanDeg(cellsAt({{1.0, 0.0}, {1.0, 3.0}}, Background::kRoad), 0.5, 4.0), 0.0);
  EXPECT_DOUBLE_EQ(viewSpanDeg(cellsAt({{1.0, 0.0}, {1.0, 3.0}}, Background::kRoad), 0.5, 0.0), 20.0);
}

TEST(ExtractPlanes, FlatFloorFacesSensor) {
  BgCloud c;
  // Floor 1.7 m below the sensor, offset so no point sits on a voxel face.
  c.add(test::makeFloor(2.013, 9.913, -3.987, 3.913, -1.7, 0.1), Background::kRoad);
  const auto planes = extractPlanes(c.points, c.bg, FingerprintConfig{});
  ASSERT_GE(planes.size(), 40u);  // ~8 x 8 one-metre voxels
  for (const auto& p : planes) {
    EXPECT_NEAR(p.normal.x(), 0.0f, 1e-3f);
    EXPECT_NEAR(p.normal.y(), 0.0f, 1e-3f);
    EXPECT_NEAR(p.normal.z(), 1.0f, 1e-3f);  // up: towards the sensor above the floor
    EXPECT_NEAR(p.centroid.z(), -1.7f, 0.006f);
    EXPECT_EQ(p.cls, static_cast<std::uint8_t>(Background::kRoad));
    // Stored on the 1 cm grid.
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(p.centroid[k] * 100.0f, std::round(p.centroid[k] * 100.0f), 1e-3f);
  }
}

TEST(ExtractPlanes, WallsFaceSensor) {
  BgCloud c;
  c.add(test::makeWall(8.05, -4.03, 8.05, 4.03, -1.55, 2.45, 0.1), Background::kBuilding);  // in front
  c.add(test::makeWall(-6.05, -3.03, -6.05, 3.03, -1.55, 2.45, 0.1), Background::kFence);   // behind
  const auto planes = extractPlanes(c.points, c.bg, FingerprintConfig{});
  ASSERT_GE(planes.size(), 20u);
  int front = 0, back = 0;
  for (const auto& p : planes) {
    if (p.centroid.x() > 0) {
      ++front;
      EXPECT_NEAR(p.normal.x(), -1.0f, 1e-3f);
      EXPECT_EQ(p.cls, static_cast<std::uint8_t>(Background::kBuilding));
    } else {
      ++back;
      EXPECT_NEAR(p.normal.x(), 1.0f, 1e-3f);
      EXPECT_EQ(p.cls, static_cast<std::uint8_t>(Background::kFence));
    }
    EXPECT_LT(p.centroid.dot(p.normal), 0.0f);
  }
  EXPECT_GT(front, 0);
  EXPECT_GT(back, 0);
}

TEST(ExtractPlanes, NoisyBlobVegetationAndSparseGiveNothing) {
  BgCloud c;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int i = 0; i < 2000; ++i)
    c.add(Vec3f(5.0f + 3 * u(rng), 2.0f + 3 * u(rng), -1.0f + 3 * u(rng)), Background::kBuilding);
  // A flat floor, but vegetation (no planes from vegetation).
  c.add(test::makeFloor(-9.987, -3.013, -2.987, 2.987, -1.7, 0.1), Background::kVegetation);
  // A flat floor with too few points per voxel (spacing 0.5 m -> 4 points per 1 m voxel < 8).
  c.add(test::makeFloor(10.013, 19.513, 0.013, 9.513, -1.7, 0.5), Background::kRoad);
  EXPECT_TRUE(extractPlanes(c.points, c.bg, FingerprintConfig{}).empty());
  EXPECT_TRUE(extractPlanes({}, {}, FingerprintConfig{}).empty());
}

TEST(ExtractPlanes, RangeLimit) {
  BgCloud c;
  c.add(test::makeFloor(70.013, 75.913, 0.013, 3.913, -1.7, 0.1), Background::kRoad);  // beyond 60 m
  EXPECT_TRUE(extractPlanes(c.points, c.bg, FingerprintConfig{}).empty());
  FingerprintConfig cfg;
  cfg.plane_max_range_m = 100;
  EXPECT_FALSE(extractPlanes(c.points, c.bg, cfg).empty());
}

// The header promises planes "sorted by voxel": the output must not depend on the order of the input points.
TEST(ExtractPlanes, OrderIndependentOfPointOrder) {
  BgCloud c;
  c.add(test::makeFloor(-9.987, 9.913, -5.987, 5.913, -1.7, 0.1), Background::kRoad);
  c.add(test::makeWall(12.05, -6.03, 12.05, 6.03, -1.55, 2.45, 0.1), Background::kBuilding);
  const auto a = extractPlanes(c.points, c.bg, FingerprintConfig{});
  ASSERT_FALSE(a.empty());
  BgCloud rev;
  std::vector<std::size_t> order(c.points.size());
  std::iota(order.begin(), order.end(), 0);
  std::mt19937 rng(8);
  std::shuffle(order.begin(), order.end(), rng);
  for (auto i : order) rev.add(c.points[i], c.bg[i]);
  const auto b = extractPlanes(rev.points, rev.bg, FingerprintConfig{});
  ASSERT_EQ(a.size(), b.size());
  int differing = 0;
  for (std::size_t k = 0; k < a.size(); ++k)
    differing += (a[k].centroid - b[k].centroid).norm() > 0.011f || (a[k].normal - b[k].normal).norm() > 1e-3f;
  EXPECT_EQ(differing, 0) << "planes come out in a different order when the input points are shuffled";
}

}  // namespace
}  // namespace sglc
