// Helpers for storage tests: plausible random fingerprints (valid for serialize/deserialize) and temp dirs.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <functional>
#include <random>
#include <string>

#include "sglc/fingerprint.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::storage::testing {

inline float cm(float v) { return static_cast<float>(std::lround(v * 100.0f)) / 100.0f; }

// A random fingerprint with the default layout (scan descriptor of 231 values, unit norm).
inline Fingerprint randomFingerprint(std::uint64_t seed, int nodes = 12) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(-30.0f, 30.0f), s(0.2f, 4.0f);
  Fingerprint fp;
  fp.layout = DescriptorLayout{};
  fp.num_points = 120000;
  fp.instance_offsets.assign(1, 0);
  for (int i = 0; i < nodes; ++i) {
    Node n;
    n.center = Vec3f(u(rng), u(rng), u(rng) * 0.05f);
    n.size = Vec3f(s(rng), s(rng), s(rng));
    n.cls = static_cast<std::uint8_t>(rng() % 3);
    fp.nodes.push_back(n);
    for (int k = 0; k < 20; ++k)
      fp.instance_points.emplace_back(cm(n.center.x() + u(rng) * 0.02f), cm(n.center.y() + u(rng) * 0.02f),
                                      cm(n.center.z() + u(rng) * 0.02f));
    fp.instance_offsets.push_back(static_cast<std::uint32_t>(fp.instance_points.size()));
  }
  for (int i = 0; i < 300; ++i)
    fp.background.push_back({static_cast<std::int16_t>(rng() % 200 - 100), static_cast<std::int16_t>(rng() % 200 - 100),
                             static_cast<std::uint8_t>(1 + rng() % 4)});
  for (int i = 0; i < 100; ++i) {
    Plane p;
    p.centroid = Vec3f(cm(u(rng)), cm(u(rng)), cm(u(rng) * 0.1f));
    p.normal = Vec3f(0, 0, 32767.0f / 32767.0f);
    p.cls = 1;
    fp.planes.push_back(p);
  }
  fp.descriptor.resize(fp.layout.scanDim());
  std::normal_distribution<float> g;
  double norm = 0;
  for (auto& v : fp.descriptor) {
    v = std::abs(g(rng));
    norm += double(v) * v;
  }
  for (auto& v : fp.descriptor) v = static_cast<float>(v / std::sqrt(norm));
  fp.finalize();
  return fp;
}

// A fresh directory under the system temp dir, removed afterwards.
class TempDir {
 public:
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "sglc-storage-XXXXXX").string();
    path_ = mkdtemp(tmpl.data());
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::permissions(path_, std::filesystem::perms::owner_all, ec);
    std::filesystem::remove_all(path_, ec);
  }
  std::string path() const { return path_; }
  std::string file(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

// The code of the StorageError `f` throws (a test failure if it throws none).
inline StorageError::Code errorCode(const std::function<void()>& f) {
  try {
    f();
  } catch (const StorageError& e) {
    return e.code();
  }
  ADD_FAILURE() << "no StorageError thrown";
  return StorageError::Code::kIo;
}

inline StoreOptions options(const std::string& path) {
  StoreOptions o;
  o.path = path;
  o.sync = StoreOptions::Sync::kNormal;  // tests that need FULL say so
  return o;
}

}  // namespace sglc::storage::testing
