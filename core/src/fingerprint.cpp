#include "sglc/fingerprint.hpp"

#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

namespace sglc {
namespace {

constexpr std::uint32_t kMagic = 0x50464753;    // "SGFP" little-endian
constexpr std::size_t kHeaderBytes = 16;        // magic, version, payload length, crc32
constexpr std::uint8_t kLabellerStructure = 1;  // flags byte (format 4 on), bit 0

class Writer {
 public:
  template <typename T>
  void put(T v) {
    static_assert(std::is_trivially_copyable_v<T>);
    const auto* b = reinterpret_cast<const std::uint8_t*>(&v);
    out_.insert(out_.end(), b, b + sizeof(T));  // the engine targets little-endian hosts only
  }
  void cm(float v) { put(static_cast<std::int16_t>(std::lround(v * 100.0f))); }
  std::vector<std::uint8_t>& bytes() { return out_; }

 private:
  std::vector<std::uint8_t> out_;
};

class Reader {
 public:
  Reader(const std::uint8_t* data, std::size_t size) : p_(data), end_(data + size) {}
  template <typename T>
  T get() {
    need(sizeof(T));
    T v;
    std::memcpy(&v, p_, sizeof(T));
    p_ += sizeof(T);
    return v;
  }
  float cm() { return static_cast<float>(get<std::int16_t>()) / 100.0f; }
  float f32() {
    const float v = get<float>();
    if (!std::isfinite(v)) throw InputError("fingerprint: non-finite value");
    return v;
  }
  void need(std::size_t bytes) const {
    if (static_cast<std::size_t>(end_ - p_) < bytes) throw InputError("fingerprint: truncated payload");
  }
  // Guards a count read from the blob before allocating for it.
  std::uint32_t count(std::size_t bytes_each) {
    const auto n = get<std::uint32_t>();
    need(static_cast<std::size_t>(n) * bytes_each);
    return n;
  }
  bool done() const { return p_ == end_; }

 private:
  const std::uint8_t* p_;
  const std::uint8_t* end_;
};

}  // namespace

void Fingerprint::finalize() {
  node_descriptors = nodeDescriptors(nodes, layout, d_max, d_i);
  view_memo.clear();
  plane_memo.clear();
}

std::shared_ptr<const PlaneIndex> planeIndexOf(const Fingerprint& fp, double radius) {
  std::uint64_t key = 0;
  static_assert(sizeof key == sizeof radius);
  std::memcpy(&key, &radius, sizeof key);
  if (auto kept = fp.plane_memo.find(key)) return kept;
  auto made = std::make_shared<const PlaneIndex>(fp.planes, radius);
  fp.plane_memo.keep(key, made);
  return made;
}

std::vector<std::uint8_t> serialize(const Fingerprint& fp) {
  Writer w;
  for (std::size_t i = 0; i < kHeaderBytes; ++i) w.put<std::uint8_t>(0);
  w.put<std::uint8_t>(static_cast<std::uint8_t>(fp.layout.num_classes));
  w.put<std::uint16_t>(static_cast<std::uint16_t>(fp.layout.bins));
  w.put<std::uint16_t>(static_cast<std::uint16_t>(fp.layout.k_eigen));
  w.put<std::uint16_t>(static_cast<std::uint16_t>(fp.layout.rings));
  w.put<std::uint16_t>(static_cast<std::uint16_t>(fp.layout.orders));
  w.put(fp.d_max);
  w.put(fp.d_i);
  w.put(fp.background_cell);
  w.put(fp.plane_voxel);
  w.put(fp.background_max_z);
  w.put<std::uint8_t>(fp.labeller_structure ? kLabellerStructure : 0);
  w.put(fp.num_points);
  w.put(static_cast<std::uint32_t>(fp.nodes.size()));
  for (std::size_t i = 0; i < fp.nodes.size(); ++i) {
    const Node& n = fp.nodes[i];
    for (int k = 0; k < 3; ++k) w.put(n.center[k]);
    for (int k = 0; k < 3; ++k) w.put(n.size[k]);
    w.put(n.cls);
    w.put(fp.instance_offsets[i + 1] - fp.instance_offsets[i]);
  }
  for (const auto& p : fp.instance_points)
    for (int k = 0; k < 3; ++k) w.cm(p[k]);
  w.put(static_cast<std::uint32_t>(fp.background.size()));
  for (const auto& c : fp.background) {
    w.put(c.ix);
    w.put(c.iy);
    w.put(c.cls);
  }
  w.put(static_cast<std::uint32_t>(fp.planes.size()));
  for (const auto& p : fp.planes) {
    for (int k = 0; k < 3; ++k) w.cm(p.centroid[k]);
    for (int k = 0; k < 3; ++k) w.put(static_cast<std::int16_t>(std::lround(p.normal[k] * 32767.0f)));
    w.put(p.cls);
  }
  w.put(static_cast<std::uint32_t>(fp.descriptor.size()));
  for (float v : fp.descriptor) w.put(v);

  auto& out = w.bytes();
  const auto payload = static_cast<std::uint32_t>(out.size() - kHeaderBytes);
  const auto crc = static_cast<std::uint32_t>(crc32(0L, out.data() + kHeaderBytes, payload));
  const std::uint32_t header[4] = {kMagic, kFingerprintVersion, payload, crc};
  std::memcpy(out.data(), header, sizeof(header));
  return std::move(out);
}

namespace {

// The header's format version, once magic, version, length and checksum are checked.
std::uint32_t checkedVersion(std::span<const std::uint8_t> bytes) {
  if (bytes.size() < kHeaderBytes)
    throw InputError("fingerprint: " + std::to_string(bytes.size()) + " bytes is shorter than its header");
  std::uint32_t header[4];
  std::memcpy(header, bytes.data(), sizeof(header));
  if (header[0] != kMagic) throw InputError("fingerprint: not a fingerprint (bad magic)");
  if (header[1] > kFingerprintVersion || header[1] == 0)
    throw InputError("fingerprint: format version " + std::to_string(header[1]) +
                     " is not supported (this build reads " + std::to_string(kFingerprintVersion) + ")");
  if (header[2] != bytes.size() - kHeaderBytes)
    throw InputError("fingerprint: payload is " + std::to_string(bytes.size() - kHeaderBytes) + " bytes, header says " +
                     std::to_string(header[2]));
  if (static_cast<std::uint32_t>(crc32(0L, bytes.data() + kHeaderBytes, header[2])) != header[3])
    throw InputError("fingerprint: checksum mismatch (corrupted data)");
  return header[1];
}

// The descriptor layout and geometry parameters of the header, checked: derived data (node descriptors, plane
// lookup) is rebuilt from them on load.
void readGeometry(Reader& r, std::uint32_t version, Fingerprint& fp) {
  fp.layout.num_classes = r.get<std::uint8_t>();
  fp.layout.bins = r.get<std::uint16_t>();
  fp.layout.k_eigen = r.get<std::uint16_t>();
  fp.layout.rings = r.get<std::uint16_t>();
  if (version >= 3) {
    fp.layout.orders = r.get<std::uint16_t>();
  } else {
    // Formats 1 and 2 held a ring key of 2 * rings values: the spectrum that replaces it keeps the length.
    fp.layout.orders = fp.layout.rings % 3 == 0 ? 2 : 0;
    fp.layout.rings /= fp.layout.orders + 1;
  }
  if (fp.layout.num_classes < 1 || fp.layout.num_classes > 16 || fp.layout.bins < 1 || fp.layout.k_eigen < 1 ||
      fp.layout.rings < 1 || fp.layout.orders > 64)
    throw InputError("fingerprint: invalid descriptor layout");
  fp.d_max = r.f32();
  fp.d_i = r.f32();
  fp.background_cell = r.f32();
  fp.plane_voxel = r.f32();
  if (version >= 3) {
    fp.background_max_z = r.get<float>();
    if (std::isnan(fp.background_max_z) || fp.background_max_z == -std::numeric_limits<float>::infinity())
      throw InputError("fingerprint: invalid background height band");
  }
  if (version >= 4) {
    const auto flags = r.get<std::uint8_t>();
    if (flags & ~kLabellerStructure) throw InputError("fingerprint: unknown flags");
    fp.labeller_structure = (flags & kLabellerStructure) != 0;
  }
  // The same ranges validateConfig enforces, and a layout that agrees with them.
  if (!(fp.d_max > 0 && fp.d_max < 1000 && fp.d_i > 0 && fp.d_max / fp.d_i <= 1000 && fp.background_cell >= 0.05f &&
        fp.plane_voxel > 0.05f && fp.layout.k_eigen <= 1000 && fp.layout.rings <= 1000))
    throw InputError("fingerprint: invalid geometry parameters");
  if (fp.layout.bins != static_cast<int>(std::ceil(static_cast<double>(fp.d_max) / fp.d_i - 1e-9)))
    throw InputError("fingerprint: descriptor bins do not match d_max / d_i");
}

}  // namespace

Fingerprint deserialize(std::span<const std::uint8_t> bytes) {
  const auto version = checkedVersion(bytes);
  Reader r(bytes.data() + kHeaderBytes, bytes.size() - kHeaderBytes);
  Fingerprint fp;
  readGeometry(r, version, fp);
  fp.num_points = r.get<std::uint32_t>();
  const auto n_nodes = r.count(29);
  fp.nodes.resize(n_nodes);
  fp.instance_offsets.assign(1, 0);
  std::uint64_t total_points = 0;
  for (auto& n : fp.nodes) {
    for (int k = 0; k < 3; ++k) n.center[k] = r.f32();
    for (int k = 0; k < 3; ++k) n.size[k] = r.f32();
    n.cls = r.get<std::uint8_t>();
    if (n.cls >= fp.layout.num_classes) throw InputError("fingerprint: node class out of range");
    const auto count = r.get<std::uint32_t>();
    total_points += count;
    if (count > (1u << 24) || total_points > (1u << 26)) throw InputError("fingerprint: implausible instance size");
    fp.instance_offsets.push_back(static_cast<std::uint32_t>(total_points));
  }
  r.need(static_cast<std::size_t>(fp.instance_offsets.back()) * 6);
  fp.instance_points.resize(fp.instance_offsets.back());
  for (auto& p : fp.instance_points)
    for (int k = 0; k < 3; ++k) p[k] = r.cm();
  fp.background.resize(r.count(5));
  for (auto& c : fp.background) {
    c.ix = r.get<std::int16_t>();
    c.iy = r.get<std::int16_t>();
    c.cls = r.get<std::uint8_t>();
    if (c.cls < 1 || c.cls > 4) throw InputError("fingerprint: background class out of range");
  }
  fp.planes.resize(r.count(13));
  for (auto& p : fp.planes) {
    for (int k = 0; k < 3; ++k) p.centroid[k] = r.cm();
    for (int k = 0; k < 3; ++k) p.normal[k] = static_cast<float>(r.get<std::int16_t>()) / 32767.0f;
    p.cls = r.get<std::uint8_t>();
    if (p.cls < 1 || p.cls > 4) throw InputError("fingerprint: plane class out of range");
  }
  const auto dim = r.count(4);
  if (static_cast<int>(dim) != fp.layout.scanDim())
    throw InputError("fingerprint: descriptor has " + std::to_string(dim) + " values, layout needs " +
                     std::to_string(fp.layout.scanDim()));
  fp.descriptor.resize(dim);
  for (auto& v : fp.descriptor) v = r.f32();
  if (!r.done()) throw InputError("fingerprint: trailing bytes after the payload");
  // Formats 1 and 2 had another descriptor (hard-binned edges in 1, a ring key of building and road points in
  // both): recompute it as this build does, from the stored nodes and background view, so that old and new
  // scans compare alike. The spectrum's other settings are the defaults.
  if (version < 3) {
    const DescriptorConfig defaults;
    fp.descriptor = scanDescriptor(
        fp.nodes, structureSpectrum(fp.background, fp.background_cell, fp.layout.rings, fp.layout.orders, defaults),
        fp.layout, fp.d_max, fp.d_i, defaults.background_weight);
  }
  fp.finalize();
  return fp;
}

std::uint32_t fingerprintFormat(std::span<const std::uint8_t> bytes) {
  if (bytes.size() < kHeaderBytes) return 0;
  std::uint32_t header[2];
  std::memcpy(header, bytes.data(), sizeof(header));
  return header[0] == kMagic ? header[1] : 0;
}

bool sameScan(const Fingerprint& a, const Fingerprint& b) {
  if (a.labeller_structure != b.labeller_structure) {
    Fingerprint x = b;
    x.labeller_structure = a.labeller_structure;
    return sameScan(a, x);
  }
  if (a.background_max_z != b.background_max_z) {
    // Another height band: compare the rest (nodes, instances, planes); its background view must differ.
    Fingerprint x = a, y = b;
    for (Fingerprint* f : {&x, &y}) {
      f->background.clear();
      f->descriptor.assign(f->descriptor.size(), 0.0f);
      f->background_max_z = 0.0f;
    }
    return sameScan(x, y);
  }
  const auto& da = a.descriptor;
  const auto& db = b.descriptor;
  if (da.size() != db.size()) return false;
  for (std::size_t k = 0; k < da.size(); ++k)
    if (!(std::abs(da[k] - db[k]) <= 1e-6f)) return false;
  // The rest compares as written: the descriptor is the payload's last field, the checksum covers it.
  const auto sa = serialize(a), sb = serialize(b);
  const auto tail = static_cast<std::ptrdiff_t>(sizeof(float) * da.size());
  return sa.size() == sb.size() && std::equal(sa.begin() + kHeaderBytes, sa.end() - tail, sb.begin() + kHeaderBytes);
}

}  // namespace sglc
