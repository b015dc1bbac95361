#include "settings.hpp"

#include <algorithm>
#include <filesystem>
#include <thread>

#include "sglc/config/settings_file.hpp"
#include "sglc/fingerprint_settings.hpp"
#include "sglc/storage/store_params.hpp"

namespace sglc::server {
namespace {

using namespace params;

#define SGLC_KEY(name) \
  "server." #name, [](auto& s) -> auto& { return s.name; }

void addServer(Table<Settings>& t) {
  t.add(field<Settings>(SGLC_KEY(db), {},
                        "map database: a SQLite file (created with its directory if missing) or a postgresql:// URL"));
  t.add(field<Settings>(SGLC_KEY(listen), {}, "address to serve on (host:port)"));
  t.add(field<Settings>(SGLC_KEY(metrics_listen), {},
                        "serve Prometheus metrics over HTTP at host:port/metrics (empty: off; no TLS, no tokens: "
                        "keep it on loopback or a trusted network)"));
  t.add(field<Settings>(SGLC_KEY(viz_listen), {},
                        "serve the live view at host:port: the Foxglove WebSocket protocol, and a page for any "
                        "browser at / (empty: off; no TLS: keep it on loopback or put a TLS proxy in front; the "
                        "token file applies)"));
  t.add(field<Settings>(SGLC_KEY(viz_interval_s), closed(0.05, 60),
                        "seconds between two rebuilds of one map's live view (each reads the whole graph)"));
  t.add(field<Settings>(SGLC_KEY(threads), closed(0, 256), "compute threads (0: the machine's cores)"));
  t.add(field<Settings>(SGLC_KEY(max_calls), closed(1, 4096),
                        "unary calls served at once (open streams hold no thread); beyond: RESOURCE_EXHAUSTED"));
  t.add(field<Settings>(SGLC_KEY(max_message_mb), openClosed(0, 2047),
                        "largest message (MB); larger scans use the chunked ingest"));
  t.add(field<Settings>(SGLC_KEY(max_points), atLeast(1), "points per scan"));
  t.add(field<Settings>(SGLC_KEY(max_inflight_mb), closed(1, 1 << 20),
                        "scan memory in flight (MB, counted as 3 x wire bytes); calls beyond it wait"));
  t.add(field<Settings>(
      "server.max_streams_per_client", [](auto& s) -> auto& { return s.streams.max_per_client; }, atLeast(1),
      "open streams of each kind per client (bearer token, else IP address)"));
  t.add(field<Settings>(
      "server.max_streams", [](auto& s) -> auto& { return s.streams.max_total; }, atLeast(1),
      "open streams of each kind in total"));
  t.add(duration<Settings>(
      "server.stream_idle_timeout_s", [](auto& s) -> auto& { return s.streams.idle_timeout; }, 1000, closed(0.1, 86400),
      "close an ingest stream that sends nothing for this long (s)"));
  t.add(field<Settings>(SGLC_KEY(tokens), {},
                        "bearer token file: 'TOKEN map1,map2' or 'TOKEN *' per line ('#' comments; "
                        "%XX in a map name is the byte XX: %2C ',', %23 '#', %20 ' ', %25 '%')"));
  t.add(field<Settings>(SGLC_KEY(tls_cert), {}, "PEM certificate chain (TLS, with tls_key)"));
  t.add(field<Settings>(SGLC_KEY(tls_key), {}, "PEM private key"));
  t.add(field<Settings>(SGLC_KEY(backup_dir), {},
                        "where the Backup call writes (plain file names only; empty: backups/ beside a SQLite "
                        "database, var/backups for PostgreSQL)"));
  t.add(field<Settings>(SGLC_KEY(shutdown_grace_s), closed(0, 3600),
                        "on SIGTERM, calls in flight get this long to finish (s)"));
  t.add(choice<Settings>(SGLC_KEY(log_level),
                         std::vector<std::pair<std::string, spdlog::level::level_enum>>{{"debug", spdlog::level::debug},
                                                                                        {"info", spdlog::level::info},
                                                                                        {"warn", spdlog::level::warn},
                                                                                        {"error", spdlog::level::err}},
                         "least severe log lines written (debug adds gRPC's own; warn keeps only problems)"));
  t.rule({"server.tls_cert", "server.tls_key"}, "given together",
         [](const Settings& s) { return s.tls_cert.empty() == s.tls_key.empty(); });
}

#undef SGLC_KEY

Table<Settings> makeTable() {
  Table<Settings> t;
  addServer(t);
  storage::storeParams().nestInto(
      t, "storage", [](auto& s) -> auto& { return s.store; });
  posegraph::graphParams().nestInto(
      t, "pose_graph", [](auto& s) -> auto& { return s.graph; });
  closing::lifelongParams().nestInto(
      t, "map", [](auto& s) -> auto& { return s.lifelong; });
  engineParams().nestInto(
      t, "engine", [](auto& s) -> auto& { return s.engine; });
  return t;
}

}  // namespace

const params::Table<Settings>& settingsTable() {
  static const params::Table<Settings> table = makeTable();
  return table;
}

Settings settingsFrom(const std::string& config_path,
                      const std::vector<std::pair<std::string, std::string>>& overrides) {
  const auto& table = settingsTable();
  Settings s;
  if (!config_path.empty()) {
    try {
      config::applyYaml(table, config::readTextFile(config_path), s);
    } catch (const InputError& e) {
      throw InputError(config_path + ": " + e.what());
    }
  }
  for (const auto& [source, setting] : overrides) {
    try {
      config::applySetting(table, setting, s);
    } catch (const InputError& e) {
      throw InputError(source + ": " + e.what());
    }
  }
  table.validate(s);
  return s;
}

Settings resolved(Settings s) {
  if (s.threads == 0) s.threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  if (s.backup_dir.empty())
    s.backup_dir =
        storage::isPostgresUrl(s.db) ? "var/backups" : (std::filesystem::path(s.db).parent_path() / "backups").string();
  s.store.path = s.db;
  s.store.settings = fingerprintSettings(s.engine);  // recorded with the maps this server creates
  return s;
}

ServiceLimits limitsOf(const Settings& s) {
  return {s.max_points,
          s.backup_dir,
          s.threads,
          static_cast<std::size_t>(s.max_inflight_mb * 1024 * 1024),
          static_cast<std::int64_t>(s.max_message_mb * 1024 * 1024),
          s.streams,
          s.lifelong,
          {s.graph.odometry_sigma_m, s.graph.odometry_sigma_per_m, s.graph.odometry_sigma_deg,
           s.graph.odometry_sigma_deg_per_m}};
}

std::string configReference() {
  return "# sglc-server configuration\n\n"
         "Generated from the settings registry by `scripts/gen-config-doc.sh` (`sglc-server --config-reference`); "
         "a test fails when\nthis file and the code disagree. Every key can be set in the YAML file given to "
         "`--config` (its dots are the\nnesting: `engine: {verify: {min_probability: 0.9}}`), on the command line with "
         "`--set engine.verify.min_probability=0.9`, and the\n`server.*` keys also with their own flags (`--max-calls "
         "64`). "
         "Flags and `--set` win over the file.\n`sglc-server --dump-config` prints the values in effect; "
         "`sglc-pair --config` and `sglc-eval --config` read the\n`engine` keys without the `engine.` "
         "prefix. Unknown keys, values of the wrong kind and values out of range\nare refused with the key's "
         "name. Why the engine's defaults are what they are: `core/include/sglc/config.hpp`.\n\nA map records "
         "the values of the `engine` sections that shape fingerprints (`labels`, `labeller`, `cluster`,\n`graph`, "
         "`descriptor`, `fingerprint`) when it is created; a server with other values refuses to ingest into it "
         "or\nquery it (FAILED_PRECONDITION, `docs/STORAGE.md`). The other `engine` sections may differ between "
         "servers of one map.\n\n" +
         config::markdownOf(settingsTable(), Settings{});
}

}  // namespace sglc::server
