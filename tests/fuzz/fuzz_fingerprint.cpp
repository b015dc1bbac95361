// Fuzzing sglc::deserialize (fingerprint blobs, e.g. read back from the map store): it accepts a blob or throws
// InputError. The header's CRC-32 (zlib crc32 over the payload, header word 3) rejects almost every mutated blob
// before the payload parser runs, so most cases mutate the payload and then fix the header's length and
// checksum, which reaches the parser; some are well-formed blobs with unusual contents (semanticMutant). An
// accepted blob must re-serialise to the very same bytes and be internally consistent.
#include <zlib.h>

#include <cstring>
#include <span>

#include "fuzz_util.hpp"
#include "sglc/fingerprint.hpp"
#include "sglc/pipeline.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

using fuzz::Outcome;
using fuzz::Rng;

constexpr std::size_t kHeaderBytes = 16;  // magic, version, payload length, crc32 (little-endian uint32 each)

std::string toString(const std::vector<std::uint8_t>& v) { return std::string(v.begin(), v.end()); }

// Sets the header's payload length and checksum to match the payload.
void fixHeader(std::string& blob) {
  if (blob.size() < kHeaderBytes) return;
  const auto payload = static_cast<std::uint32_t>(blob.size() - kHeaderBytes);
  const auto crc = static_cast<std::uint32_t>(
      crc32(0L, reinterpret_cast<const Bytef*>(blob.data() + kHeaderBytes), static_cast<uInt>(payload)));
  std::memcpy(blob.data() + 8, &payload, 4);
  std::memcpy(blob.data() + 12, &crc, 4);
}

// Fingerprints of synthetic scans: an empty scan, a small scene (4 poles, a car, road, a wall), the synthetic
// street from two poses. Their payloads cover every section with non-zero counts.
std::vector<Fingerprint> seedFingerprints() {
  const Pipeline p;
  std::vector<Fingerprint> out;
  out.push_back(p.fingerprint(LabelledScan{}));
  LabelledScan s;
  for (int k = 0; k < 4; ++k)
    test::addPoints(s, test::makePole(6.0 + 4.5 * k, k % 2 ? 4.0 : -3.5, -1.7, 2.0), test::kPole);
  test::addPoints(s, test::makeBoxSurface({9, 1, -1}, {2, 0.9, 0.7}, 15, 0.2), test::kCar);
  test::addPoints(s, test::makeFloor(2.013, 12.013, -3.987, 4.013, -1.7, 0.3), test::kRoad);
  test::addPoints(s, test::makeWall(2.05, 6.03, 12.05, 6.03, -1.55, 2.45, 0.3), test::kBuilding);
  out.push_back(p.fingerprint(s));
  const LabelledScan world = test::makeStreetWorld();
  out.push_back(p.fingerprint(test::viewFrom(world, test::makeT(-8.0, 2.0, 0.5, 0.1), 30.0)));
  out.push_back(p.fingerprint(test::viewFrom(world, test::makeT(170.0, -6.0, -1.0, 0.0))));
  return out;
}

float finiteInteresting(Rng& rng) {
  for (;;) {
    const auto v = static_cast<float>(fuzz::interestingReal(rng));
    if (std::isfinite(v)) return v;
  }
}

// A well-formed blob with unusual contents: a seed fingerprint with its layout, geometry, nodes or descriptor
// changed and serialised as the format wants it (consistent counts, a layout that matches d_max / d_i). Such
// blobs pass the format checks, so they exercise what deserialize accepts and finalize() builds from it.
std::string semanticMutant(Rng& rng, const std::vector<Fingerprint>& seeds) {
  Fingerprint fp = seeds[fuzz::below(rng, seeds.size())];
  const int n = 1 + static_cast<int>(fuzz::below(rng, 3));
  for (int k = 0; k < n; ++k) {
    switch (fuzz::below(rng, 8)) {
      case 0:
        fp.layout.num_classes = 1 + static_cast<int>(fuzz::below(rng, 16));
        for (auto& node : fp.nodes) node.cls = static_cast<std::uint8_t>(node.cls % fp.layout.num_classes);
        break;
      case 1:
        fp.layout.k_eigen = 1 + static_cast<int>(fuzz::below(rng, fuzz::chance(rng, 50) ? 40 : 1000));
        break;
      case 2:
        fp.layout.rings = 1 + static_cast<int>(fuzz::below(rng, fuzz::chance(rng, 50) ? 40 : 1000));
        break;
      case 3: {  // geometry, with the bins it implies
        const float d_max =
            fuzz::chance(rng, 50) ? std::uniform_real_distribution<float>(1e-3f, 999.0f)(rng) : finiteInteresting(rng);
        const float bins_wanted = std::uniform_real_distribution<float>(0.5f, 1000.0f)(rng);
        fp.d_max = d_max;
        fp.d_i = fuzz::chance(rng, 90) ? d_max / bins_wanted : finiteInteresting(rng);
        const double bins = std::ceil(static_cast<double>(fp.d_max) / fp.d_i - 1e-9);
        fp.layout.bins = std::isfinite(bins) ? static_cast<int>(std::clamp(bins, 0.0, 2000.0)) : 0;  // > 1000: rejected
        break;
      }
      case 4:
        if (!fp.nodes.empty()) {
          Node& node = fp.nodes[fuzz::below(rng, fp.nodes.size())];
          (fuzz::chance(rng, 70) ? node.center : node.size)[static_cast<int>(fuzz::below(rng, 3))] =
              finiteInteresting(rng);
        }
        break;
      case 5:
        (fuzz::chance(rng, 50) ? fp.plane_voxel : fp.background_cell) =
            fuzz::chance(rng, 50) ? std::uniform_real_distribution<float>(0.0f, 2.0f)(rng) : finiteInteresting(rng);
        break;
      case 6: {  // more nodes (without instance points), possibly all at one place
        const std::size_t extra = 1 + fuzz::below(rng, 100);
        for (std::size_t j = 0; j < extra; ++j) {
          Node node;
          if (!fp.nodes.empty() && fuzz::chance(rng, 50))
            node = fp.nodes[fuzz::below(rng, fp.nodes.size())];
          else
            node.center = Vec3f(finiteInteresting(rng), 0.0f, 0.0f);
          node.cls = static_cast<std::uint8_t>(fuzz::below(rng, static_cast<std::uint64_t>(fp.layout.num_classes)));
          fp.nodes.push_back(node);
          fp.instance_offsets.push_back(fp.instance_offsets.back());
        }
        break;
      }
      default:
        if (!fp.descriptor.empty()) fp.descriptor[fuzz::below(rng, fp.descriptor.size())] = finiteInteresting(rng);
        break;
    }
  }
  fp.descriptor.resize(static_cast<std::size_t>(fp.layout.scanDim()), 0.25f);
  std::string blob = toString(serialize(fp));
  if (fuzz::chance(rng, 25)) {  // labelled format 1: deserialize recomputes the descriptor
    const std::uint32_t one = 1;
    std::memcpy(blob.data() + 4, &one, 4);  // the checksum covers the payload only
  }
  return blob;
}

std::uint32_t formatOf(const std::string& blob) {
  std::uint32_t version = 0;
  if (blob.size() >= 8) std::memcpy(&version, blob.data() + 4, 4);
  return version;
}

// Properties of an accepted blob.
void checkAccepted(const std::string& blob, const Fingerprint& fp, fuzz::Verdict& v) {
  const std::string again = toString(serialize(fp));
  if (formatOf(blob) == 1) {  // upgraded on load: written in the current format, stable from then on
    const auto bytes = std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(again.data()), again.size());
    if (formatOf(again) != kFingerprintVersion || toString(serialize(deserialize(bytes))) != again)
      v.fail("an upgraded format-1 blob does not re-serialise stably in the current format");
  } else if (again != blob) {
    v.fail("accepted blob does not re-serialise to the same bytes");
  }
  if (fp.instance_offsets.size() != fp.nodes.size() + 1)
    v.fail("instance_offsets has the wrong length");
  else {
    if (fp.instance_offsets.front() != 0 || fp.instance_offsets.back() != fp.instance_points.size())
      v.fail("instance_offsets do not span instance_points");
    for (std::size_t i = 0; i + 1 < fp.instance_offsets.size(); ++i)
      if (fp.instance_offsets[i] > fp.instance_offsets[i + 1]) {
        v.fail("instance_offsets decrease at node " + std::to_string(i));
        break;
      }
  }
  if (static_cast<int>(fp.descriptor.size()) != fp.layout.scanDim()) v.fail("descriptor size != layout.scanDim()");
  for (float x : fp.descriptor)
    if (!std::isfinite(x)) {
      v.fail("non-finite descriptor value");
      break;
    }
  for (const auto& n : fp.nodes)
    if (!n.center.allFinite() || !n.size.allFinite() || n.cls >= fp.layout.num_classes) {
      v.fail("node with a non-finite box or a class outside the layout");
      break;
    }
  for (const auto& c : fp.background)
    if (c.cls < 1 || c.cls > 4) {
      v.fail("background cell class out of range");
      break;
    }
  for (const auto& p : fp.planes)
    if (!p.centroid.allFinite() || !p.normal.allFinite() || p.cls < 1 || p.cls > 4) {
      v.fail("plane with a non-finite value or a class out of range");
      break;
    }
  if (fp.node_descriptors.rows() != static_cast<Eigen::Index>(fp.nodes.size()) ||
      fp.node_descriptors.cols() != fp.layout.nodeDim())
    v.fail("node_descriptors has the wrong shape");
  else if (!fp.node_descriptors.allFinite())
    v.fail("node_descriptors has non-finite values");
  // The derived plane lookup finds only existing planes.
  const auto index = planeIndexOf(fp, 1.0);
  for (std::size_t i = 0; i < fp.planes.size() && i < 64; ++i) {
    const int k = index->nearest(fp.planes, fp.planes[i].centroid, fp.planes[i].normal, 1.0, 0.0);
    if (k < 0 || k >= static_cast<int>(fp.planes.size())) {
      v.fail("the plane lookup does not find plane " + std::to_string(i) + " at its own centroid");
      break;
    }
  }
}

TEST(Fuzz, FingerprintDeserialize) {
  const std::vector<Fingerprint> seeds = seedFingerprints();
  std::vector<std::string> corpus;
  for (const auto& fp : seeds) corpus.push_back(toString(serialize(fp)));
  std::vector<std::string> payloads;  // for splicing payloads only
  std::size_t largest = 0;
  for (const auto& b : corpus) {
    payloads.push_back(b.substr(kHeaderBytes));
    largest = std::max(largest, b.size());
  }
  const std::size_t max_size = largest + 4096;
  const fuzz::Mutator mutator;
  auto make = [&](Rng& rng, std::uint64_t i) -> std::string {
    if (i < corpus.size()) return corpus[i];  // the seeds themselves first
    const int mode = static_cast<int>(rng() % 100);
    if (mode >= 85) return semanticMutant(rng, seeds);
    if (mode < 10) {  // random bytes, half of them behind a valid header
      std::string blob = mutator.random(rng, 4096);
      if (fuzz::chance(rng, 50)) {
        blob = corpus[0].substr(0, kHeaderBytes) + blob;
        fixHeader(blob);
      }
      return blob;
    }
    const std::string& seed = corpus[fuzz::below(rng, corpus.size())];
    if (mode < 40) {  // the whole blob, header included, checksum left as it is
      std::string blob = seed;
      mutator.mutate(rng, blob, corpus, max_size);
      return blob;
    }
    // The payload, then a header with matching length and checksum: the parser itself is exercised.
    std::string payload = seed.substr(kHeaderBytes);
    mutator.mutate(rng, payload, payloads, max_size);
    std::string blob = seed.substr(0, kHeaderBytes) + payload;
    fixHeader(blob);
    return blob;
  };
  std::uint64_t accepted_mutants = 0;
  auto check = [&](const std::string& blob, fuzz::Verdict& v) -> Outcome {
    Fingerprint fp;
    try {
      fp = deserialize(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(blob.data()), blob.size()));
    } catch (const InputError& e) {
      if (!*e.what()) v.fail("InputError with an empty message");
      return Outcome::kRejected;
    }
    checkAccepted(blob, fp, v);
    accepted_mutants += std::find(corpus.begin(), corpus.end(), blob) == corpus.end();
    return Outcome::kAccepted;
  };
  const auto r = fuzz::runFuzzBytes("FingerprintDeserialize", 40000, corpus.size(), make, check);
  RecordProperty("fuzz_accepted_mutants", std::to_string(accepted_mutants));
  if (!fuzz::onlyIteration()) {
    EXPECT_GE(r.accepted, corpus.size()) << "the unmutated seeds must load";
    EXPECT_GT(r.rejected, 0u);
  }
}

}  // namespace
}  // namespace sglc
