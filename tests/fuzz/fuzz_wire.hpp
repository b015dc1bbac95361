// Generators of wire-level inputs shared by the packing and codec fuzz tests: packed scans and Transform
// messages (rigid motions, perturbed ones, wrong sizes, non-finite values, random doubles).
#pragma once

#include <Eigen/Geometry>

#include "fuzz_util.hpp"
#include "sglc/types.hpp"
#include "sglc/v1/sglc.pb.h"

namespace sglc::fuzz {

inline Mat4d randomRigid(Rng& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::Quaterniond q(u(rng), u(rng), u(rng), u(rng));
  if (q.norm() < 1e-6) q = Eigen::Quaterniond::Identity();
  q.normalize();
  Mat4d T = Mat4d::Identity();
  T.topLeftCorner<3, 3>() = q.toRotationMatrix();
  const double scale = std::pow(10.0, static_cast<double>(below(rng, 9)) - 1.0);  // 0.1 m .. 1e7 m
  T.topRightCorner<3, 1>() = Vec3d(u(rng), u(rng), u(rng)) * scale;
  return T;
}

// Seeds: rigid motions. Then 0..3 mutations of the values: a value replaced (interesting or random bits), a
// small or large perturbation, values added or removed, the float precision of a pose written as float32.
inline v1::Transform randomTransform(Rng& rng) {
  v1::Transform t;
  const Mat4d T = randomRigid(rng);
  for (int k = 0; k < 16; ++k) t.add_m(T(k / 4, k % 4));
  if (chance(rng, 10)) return t;
  const int n = static_cast<int>(below(rng, 4));
  for (int j = 0; j < n; ++j) {
    const int size = t.m_size();
    switch (below(rng, 8)) {
      case 0:
        if (size) t.set_m(static_cast<int>(below(rng, size)), interestingReal(rng));
        break;
      case 1:
        if (size) {
          const std::uint64_t bits = rng();
          double d;
          std::memcpy(&d, &bits, 8);
          t.set_m(static_cast<int>(below(rng, size)), d);
        }
        break;
      case 2:
        if (size) {
          const int k = static_cast<int>(below(rng, size));
          t.set_m(k, t.m(k) + std::ldexp(1.0, -static_cast<int>(below(rng, 40))) * (chance(rng, 50) ? 1 : -1));
        }
        break;
      case 3:
        for (int k = 0; k < size; ++k) t.set_m(k, static_cast<float>(t.m(k)));
        break;
      case 4:
        t.add_m(interestingReal(rng));
        break;
      case 5:
        if (size) t.mutable_m()->RemoveLast();
        break;
      case 6:
        t.mutable_m()->Truncate(static_cast<int>(below(rng, static_cast<std::uint64_t>(size) + 1)));
        break;
      default:
        if (size) {  // a scaled or sheared rotation block
          const double f = 1.0 + (chance(rng, 50) ? 1e-4 : 0.1) * (chance(rng, 50) ? 1 : -1);
          const int k = static_cast<int>(below(rng, std::min(size, 12)));
          t.set_m(k, t.m(k) * f + (k % 4 == 3 ? 0.0 : 1e-3));
        }
        break;
    }
  }
  return t;
}

// Packed points and labels: valid ones (with or without non-finite coordinates), then byte-level mutations.
struct WireScan {
  std::string points;
  std::string labels;
};

inline WireScan randomWireScan(Rng& rng, const Mutator& mutator) {
  WireScan s;
  const std::size_t n = chance(rng, 10) ? 0 : 1 + below(rng, chance(rng, 80) ? 16 : 300);
  std::uniform_real_distribution<float> u(-80.0f, 80.0f);
  for (std::size_t i = 0; i < n; ++i) {
    float p[3] = {u(rng), u(rng), u(rng)};
    if (chance(rng, 2)) p[below(rng, 3)] = static_cast<float>(interestingReal(rng));
    s.points.append(reinterpret_cast<const char*>(p), 12);
    const std::uint32_t label =
        chance(rng, 80) ? static_cast<std::uint32_t>(below(rng, 260)) : static_cast<std::uint32_t>(rng());
    s.labels.append(reinterpret_cast<const char*>(&label), 4);
  }
  const std::vector<std::string> none;
  if (chance(rng, 50)) mutator.mutate(rng, s.points, none, 8192);
  if (chance(rng, 30)) mutator.mutate(rng, s.labels, none, 8192);
  if (chance(rng, 5)) s.points = mutator.random(rng, 4096);
  if (chance(rng, 5)) s.labels = mutator.random(rng, 4096);
  return s;
}

inline std::string wireScanBytes(const WireScan& s) {
  const auto n = static_cast<std::uint64_t>(s.points.size());
  return std::string(reinterpret_cast<const char*>(&n), 8) + s.points + s.labels;
}

inline std::string describeTransform(const v1::Transform& t) {
  std::string out = std::to_string(t.m_size()) + " values:";
  char buf[40];
  for (int k = 0; k < t.m_size(); ++k) {
    std::snprintf(buf, sizeof(buf), " %.17g", t.m(k));
    out += buf;
  }
  return out;
}

}  // namespace sglc::fuzz
