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
constexpr int kMaxRings = 64;       // a sector's rings are the bits of one word when views are compared

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

// The rings of each sector as the bits of one word (ring i is bit i): a row per ring turned into a word per sector.
void sectorWords(const std::vector<Row>& rows, std::uint64_t* out) {
  std::fill(out, out + kSectors, std::uint64_t{0});
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const std::uint64_t ring = std::uint64_t{1} << i;
    for (std::uint64_t w = rows[i].lo; w != 0; w &= w - 1) out[std::countr_zero(w)] |= ring;
    for (std::uint64_t w = rows[i].hi; w != 0; w &= w - 1) out[64 + std::countr_zero(w)] |= ring;
  }
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
  if (config.rings < 1 || config.rings > kMaxRings || !(config.max_range_m > kMinRangeM) || !(cell > 0))
    throw InputError("view context: rings must be in [1, 64], max_range_m above 2 m and the cell size positive");
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
  if (rings_ < 1 || rings_ > kMaxRings || narrow.vegetation.size() != narrow.building.size())
    throw InputError("view context with " + std::to_string(rings_) + " building and " +
                     std::to_string(narrow.vegetation.size()) + " vegetation rings: a view is compared with 1 to 64");
  std::uint64_t building[kSectors], vegetation[kSectors];
  sectorWords(narrow.building, building);
  sectorWords(narrow.vegetation, vegetation);
  for (int s = 0; s < kSectors; ++s) {
    if ((((s < 64 ? narrow.seen.lo : narrow.seen.hi) >> (s & 63)) & 1U) == 0) continue;
    seen_.push_back(s);
    building_.push_back(building[s]);
    vegetation_.push_back(vegetation[s]);
  }
}

// Most of a comparison is population counts: where the CPU has the instruction (x86-64 from 2008 on; Debian's
// baseline does not assume it), a second copy of this function uses it, chosen once at load time (GCC's
// function multi-versioning, an ifunc of glibc). The copies neither throw nor allocate: GCC 12 gives callers of
// such a function no cleanup for an exception from it (a sanitizer build found a temporary's vectors leaked when
// match() threw from inside it).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define SGLC_POPCNT_CLONES __attribute__((target_clones("popcnt", "default")))
#else
#define SGLC_POPCNT_CLONES
#endif

namespace {

// The narrow view turned by each shift against the other's sector words (building, vegetation, and both; each
// given twice over, 256 words, so that sector u + shift needs no wrap): the best shift and its similarity. Only
// the sectors the narrow view saw count: its sector u lies on the other's sector u + shift. Counted per seen
// sector over all shifts at once, so the inner loop runs over consecutive words.
SGLC_POPCNT_CLONES std::pair<int, double> bestShift(const int* seen, const std::uint64_t* building,
                                                    const std::uint64_t* vegetation, std::size_t n_seen,
                                                    const std::uint64_t* other_building,
                                                    const std::uint64_t* other_vegetation,
                                                    const std::uint64_t* other_structure, bool merged) noexcept {
  int same[kSectors] = {}, judged[kSectors] = {};
  for (std::size_t k = 0; k < n_seen; ++k) {
    const std::uint64_t b = building[k], v = vegetation[k], mine = b | v;
    const std::uint64_t* ob = other_building + seen[k];
    const std::uint64_t* ov = other_vegetation + seen[k];
    const std::uint64_t* os = other_structure + seen[k];
    if (merged)
      for (int shift = 0; shift < kSectors; ++shift) same[shift] += std::popcount(mine & os[shift]);
    else
      for (int shift = 0; shift < kSectors; ++shift) same[shift] += std::popcount((b & ob[shift]) | (v & ov[shift]));
    for (int shift = 0; shift < kSectors; ++shift) judged[shift] += std::popcount(mine | os[shift]);
  }
  int best_shift = 0;
  double best = 0.0;
  for (int shift = 0; shift < kSectors; ++shift) {
    const double similarity =
        judged[shift] ? static_cast<double>(same[shift]) / static_cast<double>(judged[shift]) : 0.0;
    if (similarity > best) {
      best = similarity;
      best_shift = shift;
    }
  }
  return {best_shift, best};
}

}  // namespace

ViewMatch ViewMatcher::match(const ViewContext& other) const {
  if (other.rings() != rings_ || other.vegetation.size() != other.building.size())
    throw InputError("view contexts with " + std::to_string(rings_) + " and " + std::to_string(other.rings()) +
                     " rings (" + std::to_string(other.vegetation.size()) + " of vegetation) cannot be compared");
  std::uint64_t building[2 * kSectors], vegetation[2 * kSectors], structure[2 * kSectors];
  sectorWords(other.building, building);
  sectorWords(other.vegetation, vegetation);
  for (int s = 0; s < kSectors; ++s) {
    structure[s] = structure[s + kSectors] = building[s] | vegetation[s];
    building[s + kSectors] = building[s];
    vegetation[s + kSectors] = vegetation[s];
  }
  const auto [best_shift, similarity] = bestShift(seen_.data(), building_.data(), vegetation_.data(), seen_.size(),
                                                  building, vegetation, structure, merged_ || other.merged);
  ViewMatch best;
  best.similarity = similarity;
  // Narrow's sector s lies at other's s + shift: other's frame turns by -shift sectors into narrow's.
  best.heading = static_cast<double>((kSectors - best_shift) % kSectors) * 2.0 * std::numbers::pi / kSectors;
  return best;
}

ViewMatch matchViews(const ViewContext& narrow, const ViewContext& other) { return ViewMatcher(narrow).match(other); }

}  // namespace sglc
