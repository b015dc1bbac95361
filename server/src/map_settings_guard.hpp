// The one check that a map's fingerprints and this server's are made alike: a map records the fingerprint-shaping
// settings it was created with (sglc/fingerprint_settings.hpp, MapStore::mapSettings), and a server whose
// settings differ neither adds its fingerprints to the map nor compares them with the map's (Ingest and its
// streams, Query). Each replica checks for itself, since it may start after another created the map. The
// verdict is cached per map id: a map's settings never change once recorded, and a map deleted and created again
// has a new id, so the hot path reads the database once per map and process.
#pragma once

#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <utility>

#include "sglc/fingerprint_settings.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::server {

class MapSettingsGuard {
 public:
  explicit MapSettingsGuard(FingerprintSettings ours) : ours_(std::move(ours)) {}

  // The map, when this server may ingest into it and query it: RpcError NOT_FOUND for an unknown map,
  // FAILED_PRECONDITION naming the first setting that differs, with the map's value and this server's. A map
  // with no settings recorded (created by an older build) gets this server's first (MapStore::recordSettings),
  // with a log line.
  storage::MapInfo require(storage::MapStore& store, const std::string& map) const;

  // Records this server's settings (the store's, StoreOptions::settings) with every map that has none (run once
  // the database is open), one log line per map. A database error is logged, not thrown: require() records them
  // for each such map on its first use instead.
  void recordMissing(storage::MapStore& store) const;

  const FingerprintSettings& ours() const { return ours_; }

 private:
  // "" when the map's recorded settings are this server's, else the refusal's message.
  std::string verdict(storage::MapStore& store, const std::string& map) const;

  const FingerprintSettings ours_;
  mutable std::mutex mutex_;
  mutable std::map<std::int64_t, std::string> verdicts_;  // map id -> verdict
};

// The FAILED_PRECONDITION message for `map` whose recorded settings differ from this server's at `d`.
std::string settingsMismatchMessage(const std::string& map, const SettingDifference& d);

}  // namespace sglc::server
