// Everything sglc-server can be told: its own settings and the engine's, the map store's and the pose graph's,
// in one registry with four sections (engine, storage, server, pose_graph). A YAML file, `--set KEY=VALUE` and
// the server flags all assign through it; `--dump-config` and docs/CONFIGURATION.md are written from it.
#pragma once

#include <spdlog/common.h>

#include <string>
#include <utility>
#include <vector>

#include "service.hpp"
#include "sglc/config.hpp"
#include "sglc/params.hpp"
#include "sglc/posegraph/graph_optimiser.hpp"
#include "sglc/storage/map_store.hpp"
#include "stream_registry.hpp"

namespace sglc::server {

struct Settings {
  std::string db = "var/sglc.db";
  std::string listen = "127.0.0.1:50051";
  std::string metrics_listen;   // host:port of the Prometheus endpoint; empty: none
  std::string viz_listen;       // host:port of the live view (Foxglove WebSocket and page); empty: none
  double viz_interval_s = 0.5;  // a map's live view is rebuilt at most this often
  int threads = 0;              // compute threads; 0 = the machine's cores
  int max_calls = 256;          // calls in flight (open streams included); beyond it gRPC answers RESOURCE_EXHAUSTED
  double max_message_mb = 64;
  std::uint64_t max_points = kMaxScanPoints;  // the scan file readers' cap too
  std::string tls_cert, tls_key, tokens;
  std::string backup_dir;  // empty: "backups" beside the database
  double shutdown_grace_s = 10;
  spdlog::level::level_enum log_level = spdlog::level::info;  // lines below it are not written
  double max_inflight_mb = 1024;                              // scan memory in flight (wire bytes x 3)
  StreamLimits streams;
  Config engine;
  storage::StoreOptions store;
  GraphOptimiserOptions graph;
  closing::LifelongOptions lifelong;  // map.*
};

const params::Table<Settings>& settingsTable();

// The defaults, then the YAML file (if a path is given), then each override "KEY=VALUE" in order, then the
// whole is validated. Errors name the file or the override's source (the first of each pair, e.g. "--set x=1").
Settings settingsFrom(const std::string& config_path,
                      const std::vector<std::pair<std::string, std::string>>& overrides);

// The values the service runs with: threads 0 becomes the machine's cores, an empty backup_dir "backups"
// beside the database, and the store opens `db`.
Settings resolved(Settings s);
ServiceLimits limitsOf(const Settings& s);

// The reference of every key, as docs/CONFIGURATION.md holds it.
std::string configReference();

}  // namespace sglc::server
