// Refuses maps made with other fingerprint settings (map_settings_guard.hpp).
#include "map_settings_guard.hpp"

#include <spdlog/spdlog.h>

#include <optional>

#include "rpc_error.hpp"
#include "sglc/log/log_line.hpp"

namespace sglc::server {
namespace {

// Label lists can be long: a message shows the start of a value.
std::string shortened(const std::string& value) {
  constexpr std::size_t kMax = 120;
  return value.size() <= kMax ? value : value.substr(0, kMax) + "...";
}

void logRecorded(const std::string& map, const std::string& hash) {
  spdlog::info("{}", logging::logLine({{"event", "map_settings_recorded"}, {"map", map}, {"settings_hash", hash}}));
}

}  // namespace

std::string settingsMismatchMessage(const std::string& map, const SettingDifference& d) {
  return "map '" + map + "' was built with " + d.key + " = " + shortened(d.recorded) + "; this server has " +
         shortened(d.current) +
         ": its fingerprints would not compare with the map's. Run this server with the map's settings (those of "
         "the server that created it), or create a new map for these settings";
}

storage::MapInfo MapSettingsGuard::require(storage::MapStore& store, const std::string& map) const {
  const auto info = store.findMap(map);
  if (!info) throw RpcError(grpc::StatusCode::NOT_FOUND, "no map named '" + map + "'");
  std::optional<std::string> refusal;
  {
    std::lock_guard lock(mutex_);
    if (const auto it = verdicts_.find(info->id); it != verdicts_.end()) refusal = it->second;
  }
  if (!refusal) {
    refusal = verdict(store, map);  // outside the lock: calls for other maps need not wait for the database
    std::lock_guard lock(mutex_);
    verdicts_.emplace(info->id, *refusal);
  }
  if (!refusal->empty()) throw RpcError(grpc::StatusCode::FAILED_PRECONDITION, *refusal);
  return *info;
}

std::string MapSettingsGuard::verdict(storage::MapStore& store, const std::string& map) const {
  auto recorded = store.mapSettings(map);
  if (!recorded) {
    for (const auto& name : store.recordSettings(map)) logRecorded(name, ours_.hash);
    recorded = store.mapSettings(map);  // ours, or another replica's that recorded first
  }
  if (!recorded) return "";  // a store that records no settings: nothing to compare
  const auto d = firstDifference(*recorded, ours_);
  if (!d) return "";
  spdlog::warn("{}", logging::logLine({{"event", "map_settings_differ"},
                                       {"map", map},
                                       {"key", d->key},
                                       {"map_value", d->recorded},
                                       {"server_value", d->current},
                                       {"map_settings_hash", recorded->hash},
                                       {"server_settings_hash", ours_.hash}}));
  return settingsMismatchMessage(map, *d);
}

void MapSettingsGuard::recordMissing(storage::MapStore& store) const {
  try {
    for (const auto& name : store.recordSettings()) logRecorded(name, ours_.hash);
  } catch (const storage::StorageError& e) {
    // Not fatal: the first ingest or query of each such map records them (verdict).
    spdlog::warn("{}", logging::logLine({{"event", "map_settings_not_recorded"}, {"error", e.what()}}));
  }
}

}  // namespace sglc::server
