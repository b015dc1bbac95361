#include "sglc/view_context.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <numbers>
#include <string>
#include <utility>

#include "fast_math.hpp"
#include "sglc/labels.hpp"

namespace sglc {
namespace {

using Row = ViewContext::Row;
constexpr int kSectors = ViewContext::kSectors;
constexpr double kMinRangeM = 2.0;  // nearer cells have too coarse a bearing

void setBit(Row& r, int s) { (s < 64 ? r.lo : r.hi) |= std::uint64_t{1} << (s & 63); }
int count(const Row& r) { return std::popcount(r.lo) + std::popcount(r.hi); }
Row operator&(const Row& a, const Row& b) { return {a.lo & b.lo, a.hi & b.hi}; }
Row operator|(const Row& a, const Row& b) { return {a.lo | b.lo, a.hi | b.hi}; }

// Sector s moves to sector (s + shift) % 128.
Row rotated(const Row& r, int shift) {
  if (shift >= 64) return rotated({r.hi, r.lo}, shift - 64);
  if (shift == 0) return r;
  return {(r.lo << shift) | (r.hi >> (64 - shift)), (r.hi << shift) | (r.lo >> (64 - shift))};
}

}  // namespace

std::shared_ptr<const ViewContext> viewContextOf(const Fingerprint& fp, const ViewSearchConfig& config) {
  // The settings that shape the context (FNV-1a over their bytes).
  std::uint64_t key = 1469598103934665603ULL;
  const auto mix = [&key](const auto& value) {
    const auto* bytes = reinterpret_cast<const unsigned char*>(&value);
    for (std::size_t i = 0; i < sizeof value; ++i) key = (key ^ bytes[i]) * 1099511628211ULL;
  };
  mix(config.rings);
  mix(config.max_range_m);
  mix(fp.background_cell);
  mix(fp.labeller_structure);
  if (auto kept = fp.view_memo.find(key)) return kept;
  auto made = std::make_shared<const ViewContext>(
      viewContext(fp.background, fp.background_cell, config, fp.labeller_structure));
  fp.view_memo.keep(key, made);
  return made;
}

ViewContext viewContext(const std::vector<BevCell>& cells, double cell, const ViewSearchConfig& config, bool merged) {
  if (config.rings < 1 || !(config.max_range_m > kMinRangeM) || !(cell > 0))
    throw InputError("view context: rings must be >= 1, max_range_m above 2 m and the cell size positive");
  ViewContext v;
  v.merged = merged;
  const int rings = config.rings;
  v.building.resize(static_cast<std::size_t>(rings));
  v.vegetation.resize(static_cast<std::size_t>(rings));
  std::vector<Row> any(static_cast<std::size_t>(rings));
  const double inv_ring = rings / config.max_range_m, inv_sector = kSectors / (2.0 * std::numbers::pi);
  for (const auto& c : cells) {
    const double x = (c.ix + 0.5) * cell, y = (c.iy + 0.5) * cell, r = std::sqrt(x * x + y * y);
    if (!(r >= kMinRangeM && r < config.max_range_m) || c.cls == 0) continue;
    const auto ring = static_cast<std::size_t>(std::min(rings - 1, static_cast<int>(r * inv_ring)));
    const int sector =
        static_cast<int>((detail::fastAtan2(static_cast<float>(y), static_cast<float>(x)) + std::numbers::pi) *
                         inv_sector) %
        kSectors;
    setBit(any[ring], sector);
    const auto cls = static_cast<Background>(c.cls);
    if (cls == Background::kBuilding || cls == Background::kFence) setBit(v.building[ring], sector);
    if (cls == Background::kVegetation) setBit(v.vegetation[ring], sector);
  }
  // A sector is seen where two rings or more hold something: one stray cell does not open a direction.
  Row once, twice;
  for (const auto& a : any) {
    twice = twice | (once & a);
    once = once | a;
  }
  v.seen = twice;
  return v;
}

bool ViewContext::seesStructure() const {
  for (std::size_t i = 0; i < building.size(); ++i)
    if (count((building[i] | vegetation[i]) & seen)) return true;
  return false;
}

std::vector<bool> ViewContext::field() const {
  const Row inner = seen & rotated(seen, 1) & rotated(seen, kSectors - 1);
  std::vector<bool> out(kSectors);
  for (int s = 0; s < kSectors; ++s)
    out[static_cast<std::size_t>(s)] = (((s < 64 ? inner.lo : inner.hi) >> (s & 63)) & 1U) != 0;
  return out;
}

bool isNarrowView(const Fingerprint& fp, double min_view_deg) {
  return viewSpanDeg(fp.background, fp.background_cell) < min_view_deg;
}

ViewMatcher::ViewMatcher(const ViewContext& narrow) : rings_(narrow.rings()), merged_(narrow.merged) {
  const auto rings = static_cast<std::size_t>(rings_);
  building_.resize(kSectors * rings);
  vegetation_.resize(kSectors * rings);
  seen_.resize(kSectors);
  for (int shift = 0; shift < kSectors; ++shift) {
    const Row seen = rotated(narrow.seen, shift);
    seen_[static_cast<std::size_t>(shift)] = seen;
    for (std::size_t i = 0; i < rings; ++i) {
      building_[shift * rings + i] = rotated(narrow.building[i], shift) & seen;
      vegetation_[shift * rings + i] = rotated(narrow.vegetation[i], shift) & seen;
    }
  }
}

// Most of a comparison is population counts: where the CPU has the instruction (x86-64 from 2008 on; Debian's
// baseline does not assume it), a second copy of this function uses it, chosen once at load time (GCC's
// function multi-versioning, an ifunc of glibc). 13 us instead of 55 us per comparison (BM_ViewMatch). The copies
// neither throw nor allocate: GCC 12 gives callers of such a function no cleanup for an exception from it (a
// sanitizer build found a temporary's vectors leaked when match() threw from inside it).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define SGLC_POPCNT_CLONES __attribute__((target_clones("popcnt", "default")))
#else
#define SGLC_POPCNT_CLONES
#endif

namespace {

// The narrow view's rows turned by each shift ([shift * rings + ring], seen [shift]) against the other's rows
// and structure (building | vegetation): the best shift and its similarity.
SGLC_POPCNT_CLONES std::pair<int, double> bestShift(const Row* building, const Row* vegetation, const Row* seen,
                                                    const Row* other_building, const Row* other_vegetation,
                                                    const Row* other_structure, std::size_t rings,
                                                    bool merged) noexcept {
  int best_shift = 0;
  double best = 0.0;
  for (int shift = 0; shift < kSectors; ++shift) {
    // The narrow view turned by `shift` sectors, compared where it saw.
    const Row* b = building + shift * rings;
    const Row* v = vegetation + shift * rings;
    int same = 0, judged = 0;
    for (std::size_t i = 0; i < rings; ++i) {
      const Row mine = b[i] | v[i];
      same +=
          merged ? count(mine & other_structure[i]) : count((b[i] & other_building[i]) | (v[i] & other_vegetation[i]));
      judged += count(mine | (other_structure[i] & seen[shift]));
    }
    const double similarity = judged ? static_cast<double>(same) / static_cast<double>(judged) : 0.0;
    if (similarity > best) {
      best = similarity;
      best_shift = shift;
    }
  }
  return {best_shift, best};
}

}  // namespace

ViewMatch ViewMatcher::match(const ViewContext& other) const {
  if (other.rings() != rings_)
    throw InputError("view contexts with " + std::to_string(rings_) + " and " + std::to_string(other.rings()) +
                     " rings cannot be compared");
  const auto rings = static_cast<std::size_t>(rings_);
  std::vector<Row> structure(rings);
  for (std::size_t i = 0; i < rings; ++i) structure[i] = other.building[i] | other.vegetation[i];
  const auto [best_shift, similarity] =
      bestShift(building_.data(), vegetation_.data(), seen_.data(), other.building.data(), other.vegetation.data(),
                structure.data(), rings, merged_ || other.merged);
  ViewMatch best;
  best.similarity = similarity;
  // Narrow's sector s lies at other's s + shift: other's frame turns by -shift sectors into narrow's.
  best.heading = static_cast<double>((kSectors - best_shift) % kSectors) * 2.0 * std::numbers::pi / kSectors;
  return best;
}

ViewMatch matchViews(const ViewContext& narrow, const ViewContext& other) { return ViewMatcher(narrow).match(other); }

}  // namespace sglc
