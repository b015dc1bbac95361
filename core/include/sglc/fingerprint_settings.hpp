// The settings that shape a fingerprint: the keys of engineParams() in the sections a scan's fingerprint is made
// with (labels, labeller, cluster, graph, descriptor, fingerprint), each with its formatted value, and a hash of
// them. A map records them when it is created (sglc/storage/map_store.hpp), so that a server made with other
// settings does not add differently made fingerprints to it or compare its scans with them. Verification's
// sections (verify, match, ransac, fine, refine, bev_search, view_search) only decide what a comparison
// concludes: they may differ between servers of one map.
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "sglc/config.hpp"

namespace sglc {

// One setting: its key ("labels.preset") and its value as params::format writes it ("semantickitti").
using Setting = std::pair<std::string, std::string>;

struct FingerprintSettings {
  std::vector<Setting> values;  // in engineParams() order
  std::string hash;             // settingsHash(values)
  bool empty() const { return values.empty(); }
  bool operator==(const FingerprintSettings&) const = default;
};

// Whether a key of engineParams() belongs to a section that shapes fingerprints.
bool shapesFingerprints(const std::string& key);

// The fingerprint-shaping settings of `config`: every such key of engineParams(), so a setting added to one of
// those sections is included without a change here.
FingerprintSettings fingerprintSettings(const Config& config);

// 16 lower-case hex digits of FNV-1a 64 over each key and value, each followed by a NUL byte (neither holds one:
// keys are identifiers, values formatted text), so ("a", "bc") and ("ab", "c") differ. Not a defence against a
// deliberate collision: the values themselves are compared before anything is refused.
std::string settingsHash(const std::vector<Setting>& values);

// Where a map's recorded settings and a server's differ.
struct SettingDifference {
  std::string key;
  std::string recorded;  // the map's value, or "(not recorded)"
  std::string current;   // the server's value
};

// The first of `current`'s keys (in its order) whose value `recorded` holds differently; nullopt when they agree.
// A key the record lacks agrees when `current` holds its default (the value of Config{}): a setting added by a
// newer build has the default that reproduces the older fingerprints, so maps recorded before it stay usable. A
// key only the record has (a setting this build no longer has) is not compared: no server could match it.
std::optional<SettingDifference> firstDifference(const FingerprintSettings& recorded,
                                                 const FingerprintSettings& current);

}  // namespace sglc
