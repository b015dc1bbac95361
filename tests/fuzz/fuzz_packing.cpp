// Fuzzing the client's unpacking of wire messages (sglc/client/packing.hpp): unpackPoints, unpackLabels,
// unpackScan and toMatrix take bytes and messages from the server. Every failure must be an InputError; what is
// accepted must pack back to the same bytes (points, labels) or hold 16 finite values (transforms).
#include "sglc/client/packing.hpp"

#include "fuzz_util.hpp"
#include "fuzz_wire.hpp"

namespace sglc {
namespace {

using fuzz::Outcome;
using fuzz::Rng;

enum Kind : std::uint8_t { kPoints, kLabels, kScan, kTransform, kTransformBytes, kKinds };
const char* const kKindNames[] = {"unpackPoints", "unpackLabels", "unpackScan", "toMatrix", "toMatrix(parsed)"};

struct PackCase {
  Kind kind = kPoints;
  fuzz::WireScan scan;  // kPoints (points only), kLabels (labels only), kScan
  v1::Transform transform;
};

std::string bytesOf(const PackCase& c) {
  return std::string(1, static_cast<char>(c.kind)) +
         (c.kind >= kTransform ? c.transform.SerializeAsString() : fuzz::wireScanBytes(c.scan));
}

std::string describe(const PackCase& c) {
  std::string out = std::string(kKindNames[c.kind]) + " on ";
  if (c.kind >= kTransform) return out + fuzz::describeTransform(c.transform);
  if (c.kind != kLabels) out += "points " + fuzz::hexPreview(c.scan.points) + " ";
  if (c.kind != kPoints) out += "labels " + fuzz::hexPreview(c.scan.labels);
  return out;
}

TEST(Fuzz, ClientPacking) {
  const fuzz::Mutator mutator;
  // Serialized valid transforms, for the byte-level mutations of kTransformBytes.
  std::vector<std::string> transform_corpus;
  {
    Rng rng(1);
    for (int k = 0; k < 8; ++k)
      transform_corpus.push_back(client::toTransform(fuzz::randomRigid(rng)).SerializeAsString());
  }
  constexpr std::uint64_t kSeeds = kKinds;  // one unmutated valid case of each kind first
  auto make = [&](Rng& rng, std::uint64_t i) -> PackCase {
    PackCase c;
    c.kind = static_cast<Kind>(i < kSeeds ? i : fuzz::below(rng, kKinds));
    if (i < kSeeds) {
      const LabelledScan s{{Vec3f(1, 2, 3), Vec3f(-4.5f, 0.25f, 1e-3f)}, {40, 10 | (7u << 16)}};
      c.scan = {client::packPoints(s.points), client::packLabels(s.labels)};
      c.transform = client::toTransform(fuzz::randomRigid(rng));
      return c;
    }
    switch (c.kind) {
      case kTransform:
        c.transform = fuzz::randomTransform(rng);
        break;
      case kTransformBytes: {
        std::string bytes = transform_corpus[fuzz::below(rng, transform_corpus.size())];
        mutator.mutate(rng, bytes, transform_corpus, 1024);
        if (!c.transform.ParseFromString(bytes)) c.transform = fuzz::randomTransform(rng);
        break;
      }
      default:
        c.scan = fuzz::randomWireScan(rng, mutator);
        break;
    }
    return c;
  };
  auto check = [&](const PackCase& c, fuzz::Verdict& v) -> Outcome {
    try {
      switch (c.kind) {
        case kPoints: {
          const Points pts = client::unpackPoints(c.scan.points);
          if (pts.size() * client::kPointBytes != c.scan.points.size()) v.fail("point count does not match the bytes");
          if (client::packPoints(pts) != c.scan.points) v.fail("packPoints(unpackPoints(b)) != b");
          break;
        }
        case kLabels: {
          const auto labels = client::unpackLabels(c.scan.labels);
          if (labels.size() * client::kLabelBytes != c.scan.labels.size())
            v.fail("label count does not match the bytes");
          if (client::packLabels(labels) != c.scan.labels) v.fail("packLabels(unpackLabels(b)) != b");
          break;
        }
        case kScan: {
          v1::Scan msg;
          msg.set_points(c.scan.points);
          msg.set_labels(c.scan.labels);
          const LabelledScan s = client::unpackScan(msg);
          // No labels at all is an unlabelled scan; otherwise one label per point.
          if (!s.labels.empty() && s.points.size() != s.labels.size())
            v.fail("unpackScan: point and label counts differ");
          if (s.labels.empty() && !msg.labels().empty()) v.fail("unpackScan: labels lost");
          if (client::packedSize(s) != client::packedSize(msg)) v.fail("unpackScan: packed sizes differ");
          const v1::Scan again = client::packScan(s);
          if (again.points() != msg.points() || again.labels() != msg.labels()) v.fail("packScan(unpackScan(m)) != m");
          break;
        }
        default: {
          const Mat4d T = client::toMatrix(c.transform);
          if (c.transform.m_size() != 16)
            v.fail("toMatrix accepted " + std::to_string(c.transform.m_size()) + " values");
          if (!T.allFinite()) v.fail("toMatrix returned non-finite values");
          for (int k = 0; k < c.transform.m_size(); ++k)
            if (!std::isfinite(c.transform.m(k))) {
              v.fail("toMatrix accepted a non-finite value");
              break;
            }
          break;
        }
      }
    } catch (const InputError& e) {
      if (!*e.what()) v.fail("InputError with an empty message");
      return Outcome::kRejected;
    }
    return Outcome::kAccepted;
  };
  const auto r = fuzz::runFuzz<PackCase>("ClientPacking", 1000000, kSeeds, make, check, bytesOf, describe);
  if (!fuzz::onlyIteration()) {
    EXPECT_GE(r.accepted, kSeeds) << "the valid seeds must unpack";
    EXPECT_GT(r.rejected, 0u);
  }
}

}  // namespace
}  // namespace sglc
