// The fingerprint-shaping settings of a configuration, their hash, and where two sets of them differ.
#include "sglc/fingerprint_settings.hpp"

#include <array>
#include <cstdint>
#include <map>

namespace sglc {
namespace {

// The sections of Config a fingerprint is made with (Pipeline::fingerprint: labels or the labeller, clustering,
// graph nodes and edges, descriptors, background cells and planes).
constexpr std::array<const char*, 6> kShapingSections = {"labels", "labeller",   "cluster",
                                                         "graph",  "descriptor", "fingerprint"};

std::string hex64(std::uint64_t v) {
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string out(16, '0');
  for (int i = 15; i >= 0; --i, v >>= 4) out[static_cast<std::size_t>(i)] = kDigits[v & 0xF];
  return out;
}

}  // namespace

bool shapesFingerprints(const std::string& key) {
  const auto dot = key.find('.');
  if (dot == std::string::npos) return false;
  const auto section = key.substr(0, dot);
  for (const char* s : kShapingSections)
    if (section == s) return true;
  return false;
}

std::string settingsHash(const std::vector<Setting>& values) {
  constexpr std::uint64_t kOffset = 14695981039346656037ULL, kPrime = 1099511628211ULL;
  std::uint64_t h = kOffset;
  const auto add = [&h](const std::string& text) {
    for (const unsigned char c : text) h = (h ^ c) * kPrime;
    h = (h ^ 0U) * kPrime;  // the terminator
  };
  for (const auto& [key, value] : values) {
    add(key);
    add(value);
  }
  return hex64(h);
}

FingerprintSettings fingerprintSettings(const Config& config) {
  FingerprintSettings out;
  for (const auto& p : engineParams().params())
    if (shapesFingerprints(p.info.key)) out.values.emplace_back(p.info.key, params::format(p.get(config)));
  out.hash = settingsHash(out.values);
  return out;
}

std::optional<SettingDifference> firstDifference(const FingerprintSettings& recorded,
                                                 const FingerprintSettings& current) {
  if (recorded.values == current.values) return std::nullopt;
  const std::map<std::string, std::string> theirs(recorded.values.begin(), recorded.values.end());
  std::map<std::string, std::string> defaults;  // built only when the record lacks a key
  for (const auto& [key, value] : current.values) {
    const auto it = theirs.find(key);
    if (it != theirs.end()) {
      if (it->second != value) return SettingDifference{key, it->second, value};
      continue;
    }
    if (defaults.empty())
      for (auto& kv : fingerprintSettings(Config{}).values) defaults.insert(std::move(kv));
    if (defaults[key] != value) return SettingDifference{key, "(not recorded)", value};
  }
  return std::nullopt;
}

}  // namespace sglc
