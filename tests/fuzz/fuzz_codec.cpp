// Fuzzing the server side of the wire codec (proto/include/sglc/wire): decodeScan, decodeSweep,
// decodeRigidTransform and checkName see every request's bytes and throw WireError, which becomes the call's status;
// decodeInformation reads a candidate's 36 values. A rejection must be a WireError with code INVALID_ARGUMENT or
// RESOURCE_EXHAUSTED and a message. An accepted scan has as many labels as points (at least one, at most max_points),
// finite coordinates and the bytes it came from; an accepted sweep has no times or one finite time within 1 s per
// point, and a twist only with times, of 3 + 3 finite values; an accepted transform is 16 finite values that decode
// again to (nearly) the same.
#include "fuzz_util.hpp"
#include "fuzz_wire.hpp"
#include "sglc/wire/geometry_codec.hpp"
#include "sglc/wire/scan_codec.hpp"
#include "sglc/wire/sweep_codec.hpp"

namespace sglc {
namespace {

using fuzz::Outcome;
using fuzz::Rng;
using wire::WireError;

enum Kind : std::uint8_t { kScan, kTransform, kName, kInformation, kSweep, kKinds };
const char* const kKindNames[] = {"decodeScan", "decodeRigidTransform", "checkName", "decodeInformation",
                                  "decodeSweep"};

struct CodecCase {
  Kind kind = kScan;
  fuzz::WireScan scan;
  std::uint64_t max_points = 0;
  v1::Transform transform;
  std::string text;  // decodeTransform's `what`, checkName's name
  v1::Candidate candidate;
  std::string times;  // Scan.point_times, for max_points points
  v1::Twist twist;
};

std::string bytesOf(const CodecCase& c) {
  std::string out(1, static_cast<char>(c.kind));
  switch (c.kind) {
    case kScan:
      out.append(reinterpret_cast<const char*>(&c.max_points), 8);
      return out + fuzz::wireScanBytes(c.scan);
    case kTransform:
      return out + c.transform.SerializeAsString();
    case kName:
      return out + c.text;
    case kSweep:
      out.append(reinterpret_cast<const char*>(&c.max_points), 8);
      out += c.twist.SerializeAsString();
      return out.append(1, '\0') + c.times;
    default:
      return out + c.candidate.SerializeAsString();
  }
}

std::string describe(const CodecCase& c) {
  std::string out = std::string(kKindNames[c.kind]) + " on ";
  switch (c.kind) {
    case kScan:
      return out + "max_points " + std::to_string(c.max_points) + ", points " + fuzz::hexPreview(c.scan.points) +
             ", labels " + fuzz::hexPreview(c.scan.labels);
    case kTransform:
      return out + fuzz::describeTransform(c.transform);
    case kName:
      return out + fuzz::textPreview(c.text);
    case kSweep:
      return out + std::to_string(c.max_points) + " points, times " + fuzz::hexPreview(c.times) + ", twist of " +
             std::to_string(c.twist.linear_size()) + " + " + std::to_string(c.twist.angular_size()) + " values";
    default:
      return out + std::to_string(c.candidate.information_size()) + " information values";
  }
}

void checkRejection(const WireError& e, fuzz::Verdict& v) {
  if (e.code() != grpc::StatusCode::INVALID_ARGUMENT && e.code() != grpc::StatusCode::RESOURCE_EXHAUSTED)
    v.fail("WireError with status code " + std::to_string(static_cast<int>(e.code())) + ": " + e.what());
  if (!*e.what()) v.fail("WireError with an empty message");
}

TEST(Fuzz, ServerCodec) {
  const fuzz::Mutator mutator;
  const fuzz::Mutator name_mutator({"/", "..", "\x7f", "\t", "\n", " ", "\xc3\xa9", "\xff", std::string("\0", 1)});
  constexpr std::uint64_t kSeeds = kKinds;
  auto make = [&](Rng& rng, std::uint64_t i) -> CodecCase {
    CodecCase c;
    c.kind = static_cast<Kind>(i < kSeeds ? i : fuzz::below(rng, kKinds));
    if (i < kSeeds) {  // one valid case of each kind first
      const float pts[6] = {1, 2, 3, -4.5f, 0.25f, 1e-3f};
      const std::uint32_t labels[2] = {40, 10};
      c.scan = {std::string(reinterpret_cast<const char*>(pts), sizeof(pts)),
                std::string(reinterpret_cast<const char*>(labels), sizeof(labels))};
      c.max_points = 100;
      const Mat4d T = fuzz::randomRigid(rng);
      for (int k = 0; k < 16; ++k) c.transform.add_m(T(k / 4, k % 4));
      c.text = "robot-1";
      for (int k = 0; k < 36; ++k) c.candidate.add_information(k % 7 == 0 ? 1.0 : 0.0);
      if (c.kind == kSweep) {
        c.max_points = 2;
        c.times = wire::packPointTimes({0.01f, -0.02f});
        wire::packTwist(Twist{Eigen::Vector3d(3, 0, 0), Eigen::Vector3d(0, 0, 0.5)}, &c.twist);
      }
      return c;
    }
    switch (c.kind) {
      case kScan: {
        c.scan = fuzz::randomWireScan(rng, mutator);
        const std::uint64_t n = c.scan.points.size() / 12;
        const std::uint64_t choices[] = {0, 1, n, n ? n - 1 : 0, n + 1, 1000000, ~0ULL, fuzz::below(rng, 400)};
        c.max_points = choices[fuzz::below(rng, std::size(choices))];
        break;
      }
      case kTransform:
        c.transform = fuzz::randomTransform(rng);
        c.text = "odometry_pose";
        if (fuzz::chance(rng, 10)) {  // any printable `what` (a NUL would end what() early)
          c.text.resize(fuzz::below(rng, 40));
          for (auto& ch : c.text) ch = static_cast<char>(0x20 + fuzz::below(rng, 95));
        }
        break;
      case kName: {
        static const std::vector<std::string> names = {"m", "robot-1", "session 2024-01-01", std::string(256, 'x'),
                                                       "caf\xc3\xa9"};
        c.text = names[fuzz::below(rng, names.size())];
        if (fuzz::chance(rng, 10))
          c.text = mutator.random(rng, 300);
        else
          name_mutator.mutate(rng, c.text, names, 400);
        break;
      }
      case kSweep: {
        const std::size_t n = fuzz::below(rng, 40);
        std::vector<float> times(n);
        for (auto& t : times)
          t = fuzz::chance(rng, 10) ? static_cast<float>(fuzz::interestingReal(rng))
                                    : std::uniform_real_distribution<float>(-1.2f, 1.2f)(rng);
        c.times = wire::packPointTimes(times);
        if (fuzz::chance(rng, 5)) mutator.mutate(rng, c.times, {c.times}, 400);
        const std::uint64_t choices[] = {n, n, n + 1, n ? n - 1 : 0, 0};
        c.max_points = choices[fuzz::below(rng, std::size(choices))];
        if (fuzz::chance(rng, 2)) {
          const auto values = [&](google::protobuf::RepeatedField<double>* f) {
            const int count = fuzz::chance(rng, 4) ? static_cast<int>(fuzz::below(rng, 6)) : 3;
            for (int k = 0; k < count; ++k)
              f->Add(fuzz::chance(rng, 10) ? fuzz::interestingReal(rng)
                                           : std::uniform_real_distribution<double>(-10, 10)(rng));
          };
          values(c.twist.mutable_linear());
          values(c.twist.mutable_angular());
        }
        break;
      }
      default: {
        const int n = fuzz::chance(rng, 50) ? 36 : static_cast<int>(fuzz::below(rng, 80));
        for (int k = 0; k < n; ++k)
          c.candidate.add_information(fuzz::chance(rng, 10) ? fuzz::interestingReal(rng)
                                                            : std::uniform_real_distribution<double>(-1e3, 1e3)(rng));
        break;
      }
    }
    return c;
  };
  auto check = [&](const CodecCase& c, fuzz::Verdict& v) -> Outcome {
    try {
      switch (c.kind) {
        case kScan: {
          const LabelledScan s = wire::decodeScan(c.scan.points, c.scan.labels, c.max_points);
          // No labels at all is allowed (the server's labeller labels the scan); otherwise one per point.
          if ((!s.labels.empty() && s.points.size() != s.labels.size()) || s.points.empty() ||
              (s.labels.empty() && !c.scan.labels.empty()))
            v.fail("accepted scan has " + std::to_string(s.points.size()) + " points and " +
                   std::to_string(s.labels.size()) + " labels");
          if (s.points.size() > c.max_points) v.fail("accepted scan exceeds max_points");
          for (std::size_t k = 0; k < s.points.size(); ++k)
            if (!s.points[k].allFinite()) {
              v.fail("accepted scan has a non-finite point " + std::to_string(k));
              break;
            }
          if (s.points.size() * 12 != c.scan.points.size() ||
              std::memcmp(s.points.data(), c.scan.points.data(), c.scan.points.size()) != 0 ||
              s.labels.size() * 4 != c.scan.labels.size() ||
              (!c.scan.labels.empty() && std::memcmp(s.labels.data(), c.scan.labels.data(), c.scan.labels.size()) != 0))
            v.fail("decoded scan differs from its bytes");
          break;
        }
        case kTransform: {
          const Mat4d T = wire::decodeRigidTransform(c.transform, c.text);
          if (c.transform.m_size() != 16)
            v.fail("decodeTransform accepted " + std::to_string(c.transform.m_size()) + " values");
          if (!T.allFinite()) v.fail("decodeTransform returned non-finite values");
          for (int k = 0; k < c.transform.m_size(); ++k)
            if (!std::isfinite(c.transform.m(k))) {
              v.fail("decodeTransform accepted a non-finite value");
              break;
            }
          // What the server decoded (and may store or send back) decodes again to (nearly) the same matrix.
          v1::Transform again;
          wire::toTransform(T, &again);
          try {
            const Mat4d T2 = wire::decodeRigidTransform(again, c.text);
            if (!((T2 - T).array().abs() <= 1e-9 * (1.0 + T.array().abs())).all())
              v.fail("decoding the decoded transform again changes it");
          } catch (const WireError& e) {
            v.fail(std::string("the decoded transform is rejected when decoded again: ") + e.what());
          }
          break;
        }
        case kName: {
          wire::checkName("robot", c.text);
          if (c.text.empty() || c.text.size() > 256)
            v.fail("checkName accepted a name of " + std::to_string(c.text.size()) + " bytes");
          for (unsigned char ch : c.text)
            if (ch < 0x20 || ch == 0x7f) {
              v.fail("checkName accepted a control character");
              break;
            }
          break;
        }
        case kSweep: {
          const auto sweep = wire::decodeSweep(c.times, c.twist, c.max_points);
          const auto& t = sweep.point_times;
          if (!t.empty() && t.size() != c.max_points)
            v.fail("accepted " + std::to_string(t.size()) + " times for " + std::to_string(c.max_points) + " points");
          if (t.size() * 4 != c.times.size() || (!t.empty() && std::memcmp(t.data(), c.times.data(), c.times.size())))
            v.fail("decoded times differ from their bytes");
          for (std::size_t k = 0; k < t.size(); ++k)
            if (!std::isfinite(t[k]) || std::abs(t[k]) > 1.0f) {
              v.fail("accepted time " + std::to_string(k) + " of " + std::to_string(t[k]) + " s");
              break;
            }
          const bool has_values = c.twist.linear_size() + c.twist.angular_size() > 0;
          if (sweep.twist.has_value() != has_values) v.fail("a twist was decoded from nothing or lost");
          if (sweep.twist && (t.empty() || !sweep.twist->linear.allFinite() || !sweep.twist->angular.allFinite() ||
                              c.twist.linear_size() != 3 || c.twist.angular_size() != 3))
            v.fail("accepted a twist without times, not finite, or not of 3 + 3 values");
          if (sweep.twist && !twistError(*sweep.twist).empty()) v.fail("accepted a twist beyond the limits");
          break;
        }
        default: {
          const auto I = wire::decodeInformation(c.candidate);
          if (I.has_value() != (c.candidate.information_size() == 36))
            v.fail("decodeInformation: value present iff 36 values is violated");
          if (I) {
            for (int k = 0; k < 36; ++k)
              if (!((*I)(k / 6, k % 6) == c.candidate.information(k) ||
                    (std::isnan((*I)(k / 6, k % 6)) && std::isnan(c.candidate.information(k))))) {
                v.fail("decodeInformation changes value " + std::to_string(k));
                break;
              }
            return Outcome::kAccepted;
          }
          return Outcome::kRejected;
        }
      }
    } catch (const WireError& e) {
      checkRejection(e, v);
      return Outcome::kRejected;
    }
    return Outcome::kAccepted;
  };
  const auto r = fuzz::runFuzz<CodecCase>("ServerCodec", 1000000, kSeeds, make, check, bytesOf, describe);
  if (!fuzz::onlyIteration()) {
    EXPECT_GE(r.accepted, kSeeds) << "the valid seeds must decode";
    EXPECT_GT(r.rejected, 0u);
  }
}

}  // namespace
}  // namespace sglc
