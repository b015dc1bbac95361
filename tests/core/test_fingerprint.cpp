// Fingerprint serialisation: exact round trip, rejection of bad blobs, size of a real scan.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>

#include "older_formats.hpp"
#include "sglc/fingerprint.hpp"
#include "sglc/io.hpp"
#include "sglc/pipeline.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

// Plain CRC-32 (IEEE, reflected, as zlib's crc32), written here so the tests can build blobs with a valid
// checksum independently of the library.
std::uint32_t crc32Ieee(const std::uint8_t* data, std::size_t n) {
  static const auto table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
      t[i] = c;
    }
    return t;
  }();
  std::uint32_t c = 0xFFFFFFFFu;
  for (std::size_t i = 0; i < n; ++i) c = table[(c ^ data[i]) & 0xFFu] ^ (c >> 8);
  return ~c;
}

void fixChecksum(std::vector<std::uint8_t>& blob) {
  const std::uint32_t crc = crc32Ieee(blob.data() + 16, blob.size() - 16);
  std::memcpy(blob.data() + 12, &crc, 4);
}

std::uint32_t headerWord(const std::vector<std::uint8_t>& blob, int k) {
  std::uint32_t v;
  std::memcpy(&v, blob.data() + 4 * k, 4);
  return v;
}

void setHeaderWord(std::vector<std::uint8_t>& blob, int k, std::uint32_t v) { std::memcpy(blob.data() + 4 * k, &v, 4); }

void expectSameFingerprint(const Fingerprint& a, const Fingerprint& b) {
  EXPECT_EQ(a.layout.num_classes, b.layout.num_classes);
  EXPECT_EQ(a.layout.bins, b.layout.bins);
  EXPECT_EQ(a.layout.k_eigen, b.layout.k_eigen);
  EXPECT_EQ(a.layout.rings, b.layout.rings);
  EXPECT_EQ(a.d_max, b.d_max);
  EXPECT_EQ(a.d_i, b.d_i);
  EXPECT_EQ(a.background_cell, b.background_cell);
  EXPECT_EQ(a.plane_voxel, b.plane_voxel);
  EXPECT_EQ(a.num_points, b.num_points);
  ASSERT_EQ(a.nodes.size(), b.nodes.size());
  for (std::size_t i = 0; i < a.nodes.size(); ++i) {
    EXPECT_EQ(a.nodes[i].center, b.nodes[i].center) << "node " << i;
    EXPECT_EQ(a.nodes[i].size, b.nodes[i].size) << "node " << i;
    EXPECT_EQ(a.nodes[i].cls, b.nodes[i].cls) << "node " << i;
  }
  EXPECT_EQ(a.instance_offsets, b.instance_offsets);
  ASSERT_EQ(a.instance_points.size(), b.instance_points.size());
  std::size_t bad_points = 0;
  for (std::size_t i = 0; i < a.instance_points.size(); ++i) bad_points += a.instance_points[i] != b.instance_points[i];
  EXPECT_EQ(bad_points, 0u);
  ASSERT_EQ(a.background.size(), b.background.size());
  std::size_t bad_cells = 0;
  for (std::size_t i = 0; i < a.background.size(); ++i)
    bad_cells += a.background[i].ix != b.background[i].ix || a.background[i].iy != b.background[i].iy ||
                 a.background[i].cls != b.background[i].cls;
  EXPECT_EQ(bad_cells, 0u);
  ASSERT_EQ(a.planes.size(), b.planes.size());
  std::size_t bad_planes = 0;
  for (std::size_t i = 0; i < a.planes.size(); ++i)
    bad_planes += a.planes[i].centroid != b.planes[i].centroid || a.planes[i].normal != b.planes[i].normal ||
                  a.planes[i].cls != b.planes[i].cls;
  EXPECT_EQ(bad_planes, 0u);
  EXPECT_EQ(a.descriptor, b.descriptor);
  ASSERT_EQ(a.node_descriptors.rows(), b.node_descriptors.rows());
  ASSERT_EQ(a.node_descriptors.cols(), b.node_descriptors.cols());
  EXPECT_TRUE((a.node_descriptors.array() == b.node_descriptors.array()).all());
  // The plane lookups agree.
  const auto ia = planeIndexOf(a, 1.0), ib = planeIndexOf(b, 1.0);
  for (std::size_t i = 0; i < a.planes.size(); ++i)
    EXPECT_EQ(ia->nearest(a.planes, a.planes[i].centroid, a.planes[i].normal, 1.0, 0.9),
              ib->nearest(b.planes, b.planes[i].centroid, b.planes[i].normal, 1.0, 0.9));
}

void expectExactRoundTrip(const Fingerprint& fp) {
  const auto bytes = serialize(fp);
  const Fingerprint back = deserialize(bytes);
  expectSameFingerprint(fp, back);
  const auto again = serialize(back);
  EXPECT_EQ(again, bytes);
}

// The synthetic street seen from a pose whose -x axis (the azimuth wrap-around, see
// Clustering.AzimuthWrapAroundStaysOneCluster) crosses no object, so every object is exactly one node.
Fingerprint syntheticFingerprint() {
  const Pipeline p;
  return p.fingerprint(test::viewFrom(test::makeStreetWorld(), test::makeT(-8.0, 2.0, 0.5, 0.1)));
}

TEST(Fingerprint, SyntheticContentsSane) {
  const Fingerprint fp = syntheticFingerprint();
  // 14 poles/trunks and 5 cars in the synthetic street.
  EXPECT_EQ(fp.nodes.size(), 19u);
  EXPECT_EQ(fp.instance_offsets.size(), fp.nodes.size() + 1);
  EXPECT_EQ(fp.instance_offsets.back(), fp.instance_points.size());
  EXPECT_FALSE(fp.background.empty());
  EXPECT_FALSE(fp.planes.empty());
  EXPECT_EQ(static_cast<int>(fp.descriptor.size()), fp.layout.scanDim());
  EXPECT_EQ(fp.node_descriptors.rows(), static_cast<Eigen::Index>(fp.nodes.size()));
  EXPECT_EQ(fp.node_descriptors.cols(), fp.layout.nodeDim());
  // Instance points and plane centroids are stored on a 1 cm grid.
  for (const auto& p : fp.instance_points)
    for (int k = 0; k < 3; ++k) ASSERT_NEAR(p[k] * 100.0f, std::round(p[k] * 100.0f), 1e-3f);
  for (int i = 0; i < static_cast<int>(fp.nodes.size()); ++i) EXPECT_GT(fp.instance(i).size, 0) << i;
}

TEST(Fingerprint, SyntheticRoundTripExact) { expectExactRoundTrip(syntheticFingerprint()); }

TEST(Fingerprint, EmptyScanRoundTrip) {
  const Pipeline p;
  const Fingerprint fp = p.fingerprint(LabelledScan{});
  EXPECT_TRUE(fp.nodes.empty());
  expectExactRoundTrip(fp);
}

TEST(Fingerprint, RealScanRoundTripAndSize) {
  SGLC_REQUIRE_REAL_DATA();
  const std::string dir = test::scansDir() + "/sequences/00";
  const Pipeline p;
  const Fingerprint fp = p.fingerprint(readScan(dir + "/velodyne/000052.bin", dir + "/labels/000052.label"));
  EXPECT_GE(fp.nodes.size(), 10u);
  EXPECT_FALSE(fp.planes.empty());
  expectExactRoundTrip(fp);
  const auto bytes = serialize(fp);
  RecordProperty("fingerprint_bytes_00_000052", static_cast<int>(bytes.size()));
  std::printf("fingerprint of 00/000052: %zu bytes (%zu nodes, %zu instance points, %zu BEV cells, %zu planes)\n",
              bytes.size(), fp.nodes.size(), fp.instance_points.size(), fp.background.size(), fp.planes.size());
  EXPECT_LE(bytes.size(), 64u * 1024u);
}

// Instance points are stored as int16 centimetres. cluster.max_range_m (<= 320) bounds their horizontal range,
// but nothing bounds their height: a landmark 330 m above the sensor (a scan in a frame with an altitude offset,
// or bad points) must still round-trip exactly (or be left out of the fingerprint), not wrap around to -325 m.
TEST(Fingerprint, RoundTripExactForPointsHighAboveSensor) {
  LabelledScan s;
  test::addPoints(s, test::makePole(5, 0, 330, 331), test::kPole);
  test::addPoints(s, test::makePole(8, 3, -1.7, 3), test::kPole);
  const Pipeline p;
  const Fingerprint fp = p.fingerprint(s);
  const Fingerprint back = deserialize(serialize(fp));
  ASSERT_EQ(back.instance_points.size(), fp.instance_points.size());
  std::size_t wrong = 0;
  float first_original = 0, first_loaded = 0;
  for (std::size_t i = 0; i < fp.instance_points.size(); ++i)
    if (fp.instance_points[i] != back.instance_points[i] && wrong++ == 0) {
      first_original = fp.instance_points[i].z();
      first_loaded = back.instance_points[i].z();
    }
  EXPECT_EQ(wrong, 0u) << "e.g. z = " << first_original << " m comes back as " << first_loaded << " m";
}

class FingerprintBlob : public ::testing::Test {
 protected:
  // A small scene (a few kB of blob), so that the many single-byte mutations below stay fast under sanitizers.
  static Fingerprint smallFingerprint() {
    LabelledScan s;
    for (int k = 0; k < 4; ++k)
      test::addPoints(s, test::makePole(6.0 + 4.5 * k, k % 2 ? 4.0 : -3.5, -1.7, 2.0), test::kPole);
    test::addPoints(s, test::makeBoxSurface({9, 1, -1}, {2, 0.9, 0.7}, 15, 0.2), test::kCar);
    test::addPoints(s, test::makeFloor(2.013, 12.013, -3.987, 4.013, -1.7, 0.3), test::kRoad);
    test::addPoints(s, test::makeWall(2.05, 6.03, 12.05, 6.03, -1.55, 2.45, 0.3), test::kBuilding);
    return Pipeline().fingerprint(s);
  }
  static void SetUpTestSuite() {
    fp_ = new Fingerprint(smallFingerprint());
    blob_ = new std::vector<std::uint8_t>(serialize(*fp_));
  }
  static void TearDownTestSuite() {
    delete blob_;
    delete fp_;
    blob_ = nullptr;
    fp_ = nullptr;
  }
  static Fingerprint* fp_;
  static std::vector<std::uint8_t>* blob_;
};
Fingerprint* FingerprintBlob::fp_ = nullptr;
std::vector<std::uint8_t>* FingerprintBlob::blob_ = nullptr;

TEST_F(FingerprintBlob, HeaderLayout) {
  const auto& b = *blob_;
  ASSERT_GE(b.size(), 16u);
  ASSERT_EQ(fp_->nodes.size(), 5u);  // 4 poles and a car
  ASSERT_FALSE(fp_->planes.empty());
  ASSERT_FALSE(fp_->background.empty());
  RecordProperty("small_blob_bytes", static_cast<int>(b.size()));
  EXPECT_EQ(std::string(b.begin(), b.begin() + 4), "SGFP");
  EXPECT_EQ(headerWord(b, 1), kFingerprintVersion);
  EXPECT_EQ(headerWord(b, 2), b.size() - 16);
  EXPECT_EQ(headerWord(b, 3), crc32Ieee(b.data() + 16, b.size() - 16));
}

// A hostile height band (NaN, or minus infinity: no point could be kept) with a valid checksum is refused by
// name; plus infinity (every height) is what older formats mean and loads.
TEST_F(FingerprintBlob, BadHeightBandRejected) {
  constexpr std::size_t kMaxZ = 16 + 5 + 2 + 2 + 16;  // after rings, orders and the four geometry floats
  for (const float band : {std::numeric_limits<float>::quiet_NaN(), -std::numeric_limits<float>::infinity(),
                           std::numeric_limits<float>::infinity()}) {
    auto b = *blob_;
    std::memcpy(b.data() + kMaxZ, &band, 4);
    const auto crc = static_cast<std::uint32_t>(crc32(0L, b.data() + 16, static_cast<std::uint32_t>(b.size() - 16)));
    std::memcpy(b.data() + 12, &crc, 4);
    if (std::isinf(band) && band > 0) {
      EXPECT_EQ(deserialize(b).background_max_z, band);
      continue;
    }
    try {
      deserialize(b);
      ADD_FAILURE() << "loaded a band of " << band;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("height band"), std::string::npos) << e.what();
    }
  }
  // The offset above is the band's: the stored value sits there.
  float stored = 0;
  std::memcpy(&stored, blob_->data() + kMaxZ, 4);
  EXPECT_EQ(stored, fp_->background_max_z);
}

// Format 4's flags byte: bit 0 (the structure classes are the labeller's) survives the round trip, other bits are
// refused by name; a format-3 blob (no flags byte) reads with the bit clear, and an ingest retry of the same
// scan across the upgrade is still the same scan.
TEST_F(FingerprintBlob, LabellerFlagRoundTripsAndUnknownFlagsAreRefused) {
  constexpr std::size_t kFlags = 16 + 5 + 2 + 2 + 16 + 4;  // after the height band
  EXPECT_EQ((*blob_)[kFlags], 0);
  ASSERT_FALSE(fp_->labeller_structure);
  Fingerprint flagged = *fp_;
  flagged.labeller_structure = true;
  const auto b = serialize(flagged);
  EXPECT_EQ(b[kFlags], 1);
  EXPECT_TRUE(deserialize(b).labeller_structure);
  EXPECT_TRUE(sameScan(flagged, *fp_));
  for (const std::uint8_t bits : {std::uint8_t{2}, std::uint8_t{0x81}}) {
    auto t = b;
    t[kFlags] = bits;
    fixChecksum(t);
    try {
      deserialize(t);
      ADD_FAILURE() << "flags " << int(bits) << " accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("unknown flags"), std::string::npos) << e.what();
    }
  }
  const auto three = test::olderFormatBlob(flagged, 3);
  EXPECT_EQ(three.size(), b.size() - 1);
  EXPECT_EQ(headerWord(three, 1), 3u);
  const Fingerprint loaded = deserialize(three);
  EXPECT_FALSE(loaded.labeller_structure);
  EXPECT_EQ(loaded.descriptor, flagged.descriptor);  // format 3's descriptor is the current one: kept as stored
  EXPECT_TRUE(sameScan(loaded, flagged));
}

TEST_F(FingerprintBlob, TruncatedRejected) {
  const auto& b = *blob_;
  for (std::size_t len : {std::size_t{0}, std::size_t{3}, std::size_t{15}, std::size_t{16}, std::size_t{17},
                          b.size() / 2, b.size() - 1}) {
    std::vector<std::uint8_t> t(b.begin(), b.begin() + static_cast<std::ptrdiff_t>(len));
    EXPECT_THROW(deserialize(t), InputError) << "length " << len;
  }
  // Truncated but with the header's length and checksum made consistent: the payload parser must notice.
  for (std::size_t cut : {std::size_t{1}, std::size_t{4}, std::size_t{100}}) {
    std::vector<std::uint8_t> t(b.begin(), b.end() - static_cast<std::ptrdiff_t>(cut));
    setHeaderWord(t, 2, static_cast<std::uint32_t>(t.size() - 16));
    fixChecksum(t);
    EXPECT_THROW(deserialize(t), InputError) << "cut " << cut;
  }
  // Trailing garbage.
  std::vector<std::uint8_t> longer = b;
  longer.push_back(0);
  EXPECT_THROW(deserialize(longer), InputError);
  setHeaderWord(longer, 2, static_cast<std::uint32_t>(longer.size() - 16));
  fixChecksum(longer);
  EXPECT_THROW(deserialize(longer), InputError);
}

TEST_F(FingerprintBlob, FlippedByteFailsChecksum) {
  const auto& b = *blob_;
  for (std::size_t pos : {std::size_t{16}, std::size_t{40}, b.size() / 2, b.size() - 1}) {
    std::vector<std::uint8_t> t = b;
    t[pos] ^= 0x10;
    try {
      deserialize(t);
      ADD_FAILURE() << "flipped byte " << pos << " accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("checksum"), std::string::npos) << e.what();
    }
  }
}

TEST_F(FingerprintBlob, BadMagicAndVersions) {
  std::vector<std::uint8_t> t = *blob_;
  t[0] = 'X';
  EXPECT_THROW(deserialize(t), InputError);
  for (std::uint32_t v : {0u, kFingerprintVersion + 1, 0xFFFFFFFFu}) {
    t = *blob_;
    setHeaderWord(t, 1, v);  // the checksum covers the payload only, so this is the only change
    try {
      deserialize(t);
      ADD_FAILURE() << "version " << v << " accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("version"), std::string::npos) << e.what();
    }
  }
  t = *blob_;
  setHeaderWord(t, 1, kFingerprintVersion);
  EXPECT_NO_THROW(deserialize(t));
}

// Blobs of formats 1 and 2 (another scan descriptor: hard-binned edges in 1, a ring key of building and road
// points in both, and no height band) load with the descriptor recomputed from their nodes and background view;
// everything else is as stored, and they serialise in the current format.
TEST_F(FingerprintBlob, OlderFormatBlobsGetTheCurrentDescriptor) {
  const auto dim = fp_->descriptor.size();
  const std::vector<float> old(dim, 0.05f);  // whatever the old definition gave
  for (const std::uint32_t version : {1u, 2u}) {
    SCOPED_TRACE("format " + std::to_string(version));
    auto t = test::olderFormatBlob(*fp_, version, old);
    const Fingerprint loaded = deserialize(t);
    // The fixture's fingerprint comes from the default configuration, whose spectrum the recomputation uses.
    ASSERT_EQ(loaded.descriptor.size(), dim);
    for (std::size_t k = 0; k < dim; ++k) EXPECT_NEAR(loaded.descriptor[k], fp_->descriptor[k], 1e-6) << k;
    EXPECT_EQ(loaded.layout.rings, fp_->layout.rings);  // 24 ring-key rings become 8 rings of orders 0-2
    EXPECT_EQ(loaded.layout.orders, fp_->layout.orders);
    EXPECT_EQ(loaded.background_max_z, std::numeric_limits<float>::infinity());  // every height was kept
    EXPECT_EQ(loaded.nodes.size(), fp_->nodes.size());
    EXPECT_EQ(loaded.background.size(), fp_->background.size());
    EXPECT_EQ(headerWord(serialize(loaded), 1), kFingerprintVersion);
    EXPECT_EQ(deserialize(serialize(loaded)).background_max_z, std::numeric_limits<float>::infinity());
    EXPECT_TRUE(sameScan(loaded, *fp_));  // so an identical ingest retry across the upgrade still answers OK
  }
  // A ring key whose length does not divide by 3 becomes rings of order 0 only, keeping the length.
  Fingerprint odd = *fp_;
  odd.layout.rings = 5;
  odd.layout.orders = 0;
  odd.descriptor.assign(static_cast<std::size_t>(odd.layout.scanDim()), 0.1f);
  const Fingerprint loaded = deserialize(test::olderFormatBlob(odd, 2));
  EXPECT_EQ(loaded.layout.rings, 5);
  EXPECT_EQ(loaded.layout.orders, 0);
  EXPECT_EQ(static_cast<int>(loaded.descriptor.size()), odd.layout.scanDim());
}

// The same scan fingerprinted with another height band (stored by a build before format 3, sent again): its
// background view differs, everything else must match.
TEST_F(FingerprintBlob, SameScanAcrossTheHeightBandComparesTheRest) {
  Fingerprint before = *fp_;
  before.background_max_z = std::numeric_limits<float>::infinity();
  before.background.push_back({-90, -90, 3});  // a crown the band now leaves out
  before.descriptor[5] += 0.2f;
  EXPECT_TRUE(sameScan(before, *fp_));
  Fingerprint same_band = before;
  same_band.background_max_z = fp_->background_max_z;
  EXPECT_FALSE(sameScan(same_band, *fp_));  // with the same band, the views must agree
  Fingerprint moved = before;
  moved.nodes[0].center.x() += 0.01f;
  EXPECT_FALSE(sameScan(moved, *fp_));
}

TEST_F(FingerprintBlob, SameScanToleratesOnlyDescriptorRounding) {
  const Fingerprint& fp = *fp_;
  EXPECT_TRUE(sameScan(fp, fp));
  Fingerprint nudged = fp;
  nudged.descriptor[3] = std::nextafter(nudged.descriptor[3], 2.0f);
  EXPECT_TRUE(sameScan(fp, nudged));
  Fingerprint other = fp;
  other.descriptor[3] += 0.01f;
  EXPECT_FALSE(sameScan(fp, other));
  Fingerprint moved = fp;
  moved.nodes[0].center.x() += 0.01f;
  EXPECT_FALSE(sameScan(fp, moved));
  Fingerprint counted = fp;
  counted.num_points += 1;
  EXPECT_FALSE(sameScan(fp, counted));
  Fingerprint shorter = fp;
  shorter.planes.pop_back();
  EXPECT_FALSE(sameScan(fp, shorter));
}

// Single-byte changes of the payload (with a recomputed checksum) either load or throw InputError; nothing else
// (no crash, no other exception type). Every byte of the fixed fields, the node records and the section counts
// is mutated (see below), and a sample of the bulk arrays. The four geometry floats (d_max, d_i, background_cell,
// plane_voxel) are left to FingerprintDeathTest.GeometryInconsistentWithLayoutRejected, which fails on its own.
TEST_F(FingerprintBlob, SingleByteMutationsAreHandled) {
  const auto& b = *blob_;
  const Fingerprint& fp = *fp_;
  const std::size_t geometry_begin = 16 + 9, geometry_end = geometry_begin + 16;
  const std::size_t nodes_end = geometry_end + 13 + 29 * fp.nodes.size();  // band, flags, points, node count
  const std::size_t bg_count = nodes_end + 6 * fp.instance_points.size();
  const std::size_t plane_count = bg_count + 4 + 5 * fp.background.size();
  const std::size_t desc_count = plane_count + 4 + 13 * fp.planes.size();
  ASSERT_EQ(desc_count + 4 + 4 * fp.descriptor.size(), b.size());
  // All header fields, the first three node records (the others have the same layout) and the last one, the
  // section counts; every 7th byte elsewhere.
  const std::size_t first_nodes_end = geometry_end + 13 + 29 * std::min<std::size_t>(3, fp.nodes.size());
  std::vector<std::size_t> positions;
  for (std::size_t pos = 16; pos < b.size(); ++pos) {
    const bool fixed = pos < first_nodes_end || (pos >= nodes_end - 29 && pos < nodes_end) ||
                       (pos >= bg_count && pos < bg_count + 4) || (pos >= plane_count && pos < plane_count + 4) ||
                       (pos >= desc_count && pos < desc_count + 4);
    if (pos >= geometry_begin && pos < geometry_end) continue;
    if (fixed || pos % 7 == 0) positions.push_back(pos);
  }
  int loaded = 0, rejected = 0;
  for (std::size_t pos : positions) {
    for (std::uint8_t v : {std::uint8_t{0x00}, std::uint8_t{0xFF}, std::uint8_t(b[pos] ^ 0x01)}) {
      if (v == b[pos]) continue;
      std::vector<std::uint8_t> t = b;
      t[pos] = v;
      fixChecksum(t);
      try {
        const Fingerprint f = deserialize(t);
        ++loaded;
        EXPECT_EQ(f.instance_offsets.back(), f.instance_points.size()) << "byte " << pos;
        EXPECT_EQ(static_cast<int>(f.descriptor.size()), f.layout.scanDim()) << "byte " << pos;
      } catch (const InputError&) {
        ++rejected;
      } catch (const std::exception& e) {
        ADD_FAILURE() << "byte " << pos << " = " << int(v) << ": " << e.what();
      }
    }
  }
  EXPECT_GT(loaded, 0);
  EXPECT_GT(rejected, 0);
}

// The instance point count of each node is limited to 2^24, but their sum is accumulated in 32 bits: 256 nodes
// of 2^24 points sum to 2^32 == 0, and a blob claiming 4 billion instance points but holding none would load,
// leaving every Fingerprint::instance() view pointing past the end of instance_points.
TEST(FingerprintOverflow, InstanceCountSumOverflowRejected) {
  Fingerprint fp;
  fp.layout = descriptorLayout(3, GraphConfig{}, DescriptorConfig{});
  fp.descriptor.assign(static_cast<std::size_t>(fp.layout.scanDim()), 0.0f);
  fp.instance_offsets.assign(1, 0);
  for (int i = 0; i < 256; ++i) {
    Node n;
    n.center = Vec3f(100.0f * static_cast<float>(i), 0.0f, 0.0f);  // far apart: cheap adjacency
    fp.nodes.push_back(n);
    fp.instance_offsets.push_back(fp.instance_offsets.back() + (1u << 24));  // wraps to 0 at the end
  }
  // No instance points at all: serialize writes the per-node counts (2^24 each) and zero points, with a valid
  // checksum.
  const auto blob = serialize(fp);
  try {
    const Fingerprint back = deserialize(blob);
    ADD_FAILURE() << "BUG: blob with 256 x 2^24 instance points (sum wraps to " << back.instance_offsets.back()
                  << ") and no point data was accepted; instance(0) claims " << back.instance(0).size
                  << " points while instance_points holds " << back.instance_points.size();
  } catch (const InputError&) {
  }
}

// A blob whose d_i does not match its own layout (bins = 30 but d_max / d_i = 6e31) must be rejected.
// Otherwise finalize() -> nodeDescriptors() computes static_cast<int>(d / d_i) beyond INT_MAX (undefined;
// INT_MIN on x86) and writes to a negative column of the descriptor matrix. Run in a child process so that a
// crash fails this test only.
TEST(FingerprintDeathTest, GeometryInconsistentWithLayoutRejected) {
  Fingerprint fp;
  fp.layout = descriptorLayout(3, GraphConfig{}, DescriptorConfig{});
  fp.descriptor.assign(static_cast<std::size_t>(fp.layout.scanDim()), 0.0f);
  fp.instance_offsets.assign(1, 0);
  for (int i = 0; i < 3; ++i) {
    Node n;
    n.center = Vec3f(5.0f * static_cast<float>(i), 0.0f, 0.0f);
    n.cls = static_cast<std::uint8_t>(i);
    fp.nodes.push_back(n);
    fp.instance_offsets.push_back(0);
  }
  fp.d_i = 1e-30f;
  const auto blob = serialize(fp);
  EXPECT_EXIT(
      {
        try {
          (void)deserialize(blob);
        } catch (const InputError&) {
          std::exit(0);
        }
        std::exit(1);
      },
      ::testing::ExitedWithCode(0), "")
      << "deserialize must throw InputError for d_i = 1e-30 with a 30-bin layout (exit 1: accepted; "
         "signal: crashed)";
}

}  // namespace
}  // namespace sglc
