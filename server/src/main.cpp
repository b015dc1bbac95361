// sglc-server: the SGLC loop-closure service over gRPC, on a persistent SQLite map database.
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <malloc.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <yaml-cpp/yaml.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <thread>

#include "call.hpp"
#include "io_poller.hpp"
#include "service.hpp"
#include "sglc/config/engine_file.hpp"
#include "sglc/log/log_line.hpp"

namespace {

namespace fs = std::filesystem;

std::string readFile(const std::string& path, const char* what) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(std::string(what) + " " + path + ": cannot read");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

struct Settings {
  std::string db = "var/sglc.db";
  std::string listen = "127.0.0.1:50051";
  std::string config;
  int threads = 0;      // compute threads; 0 = the machine's cores
  int max_calls = 256;  // calls in flight (open streams included); beyond it gRPC answers RESOURCE_EXHAUSTED
  double max_message_mb = 64;
  std::size_t max_points = 2'000'000;
  std::string tls_cert, tls_key, tokens, backup_dir;
  double shutdown_grace_s = 10;
  double max_inflight_mb = 1024;  // scan memory in flight (wire bytes x 3)
  sglc::server::StreamLimits streams;
  sglc::Config engine;
  sglc::storage::StoreOptions store;
  sglc::server::GraphOptimiserOptions graph;
};

void setGraphOption(sglc::server::GraphOptimiserOptions& g, const std::string& key, double v) {
  const std::map<std::string, double*> fields{
      {"pose_graph.odometry_sigma_m", &g.odometry_sigma_m},
      {"pose_graph.odometry_sigma_per_m", &g.odometry_sigma_per_m},
      {"pose_graph.odometry_sigma_deg", &g.odometry_sigma_deg},
      {"pose_graph.odometry_sigma_deg_per_m", &g.odometry_sigma_deg_per_m},
      {"pose_graph.loop_sigma_m", &g.loop_sigma_m},
      {"pose_graph.loop_sigma_deg", &g.loop_sigma_deg},
      {"pose_graph.loss_scale", &g.loss_scale},
      {"pose_graph.max_seconds", &g.max_seconds},
  };
  if (key == "pose_graph.debounce_ms") {
    if (!(v >= 0 && v <= 60000)) throw std::runtime_error(key + " must be in [0, 60000]");
    g.debounce = std::chrono::milliseconds(static_cast<long>(v));
    return;
  }
  const auto it = fields.find(key);
  if (it == fields.end()) throw std::runtime_error("unknown parameter '" + key + "'");
  if (!std::isfinite(v) || v < 0) throw std::runtime_error(key + " must be a finite number >= 0");
  *it->second = v;
}

// Checks that need every pose_graph key read first.
void validateGraphOptions(const sglc::server::GraphOptimiserOptions& g) {
  if (g.odometry_sigma_m + g.odometry_sigma_per_m <= 0)
    throw std::runtime_error("pose_graph.odometry_sigma_m and odometry_sigma_per_m must not both be zero");
  if (g.odometry_sigma_deg + g.odometry_sigma_deg_per_m <= 0)
    throw std::runtime_error("pose_graph.odometry_sigma_deg and odometry_sigma_deg_per_m must not both be zero");
  for (const auto& [name, v] : {std::pair{"loop_sigma_m", g.loop_sigma_m},
                                {"loop_sigma_deg", g.loop_sigma_deg},
                                {"loss_scale", g.loss_scale},
                                {"max_seconds", g.max_seconds}})
    if (v <= 0) throw std::runtime_error(std::string("pose_graph.") + name + " must be > 0");
}

// The config file has four sections: engine (the same keys as `sglc-pair --config`), storage, server and
// pose_graph. Command-line flags override it.
void applyConfigFile(Settings& s, const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::Load(readFile(path, "config"));
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(path + ": not valid YAML: " + e.what());
  }
  for (const auto& section : root) {
    const auto name = section.first.as<std::string>();
    const auto& node = section.second;
    if (name == "engine") {
      YAML::Emitter out;
      out << node;
      s.engine = sglc::parseConfig(out.c_str());
      continue;
    }
    if (name != "storage" && name != "server" && name != "pose_graph")
      throw std::runtime_error(path + ": unknown section '" + name + "'");
    for (const auto& item : node) {
      const auto key = name + "." + item.first.as<std::string>();
      const auto& v = item.second;
      try {
        if (key == "storage.sync") {
          const auto m = v.as<std::string>();
          if (m == "full")
            s.store.sync = sglc::storage::StoreOptions::Sync::kFull;
          else if (m == "normal")
            s.store.sync = sglc::storage::StoreOptions::Sync::kNormal;
          else if (m == "off")
            s.store.sync = sglc::storage::StoreOptions::Sync::kOff;
          else
            throw std::runtime_error("storage.sync must be full, normal or off");
        } else if (key == "storage.cache_mb")
          s.store.cache_mb = v.as<double>();
        else if (key == "storage.busy_timeout_ms")
          s.store.busy_timeout_ms = v.as<int>();
        else if (key == "storage.snapshot_index")
          s.store.snapshot_index = v.as<bool>();
        else if (key == "storage.max_db_mb")
          s.store.max_db_mb = v.as<double>();
        else if (key == "storage.index") {
          const auto t = v.as<std::string>();
          if (t == "exact")
            s.store.index.type = sglc::storage::IndexOptions::Type::kExact;
          else if (t == "ivf")
            s.store.index.type = sglc::storage::IndexOptions::Type::kIvf;
          else
            throw std::runtime_error("storage.index must be exact or ivf");
        } else if (key == "storage.ivf_nlist")
          s.store.index.ivf_nlist = v.as<int>();
        else if (key == "storage.ivf_nprobe")
          s.store.index.ivf_nprobe = v.as<int>();
        else if (key == "storage.ivf_min_scans")
          s.store.index.ivf_min_scans = v.as<int>();
        else if (key == "server.db")
          s.db = v.as<std::string>();
        else if (key == "server.listen")
          s.listen = v.as<std::string>();
        else if (key == "server.threads")
          s.threads = v.as<int>();
        else if (key == "server.max_calls")
          s.max_calls = v.as<int>();
        else if (key == "server.max_message_mb")
          s.max_message_mb = v.as<double>();
        else if (key == "server.max_points")
          s.max_points = v.as<std::size_t>();
        else if (key == "server.tls_cert")
          s.tls_cert = v.as<std::string>();
        else if (key == "server.tls_key")
          s.tls_key = v.as<std::string>();
        else if (key == "server.tokens")
          s.tokens = v.as<std::string>();
        else if (key == "server.backup_dir")
          s.backup_dir = v.as<std::string>();
        else if (key == "server.shutdown_grace_s")
          s.shutdown_grace_s = v.as<double>();
        else if (key == "server.max_inflight_mb")
          s.max_inflight_mb = v.as<double>();
        else if (key == "server.max_streams_per_client")
          s.streams.max_per_client = v.as<int>();
        else if (key == "server.max_streams")
          s.streams.max_total = v.as<int>();
        else if (key == "server.stream_idle_timeout_s")
          s.streams.idle_timeout = std::chrono::milliseconds(static_cast<long>(v.as<double>() * 1000));
        else if (key.rfind("pose_graph.", 0) == 0)
          setGraphOption(s.graph, key, v.as<double>());
        else
          throw std::runtime_error("unknown parameter '" + key + "'");
      } catch (const YAML::Exception& e) {
        throw std::runtime_error(path + ": bad value for '" + key + "': " + e.what());
      } catch (const std::runtime_error& e) {
        throw std::runtime_error(path + ": " + e.what());
      }
    }
  }
  try {
    validateGraphOptions(s.graph);
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
}

}  // namespace

int main(int argc, char** argv) {
  // SIGTERM / SIGINT are blocked before any thread starts (every thread inherits the mask) and taken by
  // sigwait below; a thread started earlier would take them with the default action and kill the process.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  // Buffers of 16 MB and more (scans of a million points and up) are mmapped, so each returns to the system
  // when freed instead of growing the heap (glibc's adaptive threshold would move them onto it after the first
  // free). Ordinary keyframes (~2 MB) stay on the heap: mmapping those too cost 3-5 ms per ingest in page faults.
  mallopt(M_MMAP_THRESHOLD, 16 << 20);
  CLI::App app{"SGLC loop-closure service: gRPC (sglc.v1) on a persistent SQLite map database."};
  Settings s;
  std::string config_path;
  app.add_option("--config", config_path, "YAML file with sections engine, storage, server");
  auto* db_opt = app.add_option("--db", s.db, "map database (SQLite file; created if missing)");
  auto* listen_opt = app.add_option("--listen", s.listen, "address to serve on");
  auto* threads_opt = app.add_option("--threads", s.threads, "compute threads (0: the machine's cores)");
  auto* calls_opt =
      app.add_option("--max-calls", s.max_calls, "unary calls served at once (open streams hold no thread)");
  auto* tokens_opt =
      app.add_option("--tokens", s.tokens, "bearer token file ('TOKEN map1,map2' or 'TOKEN *' per line)");
  auto* cert_opt = app.add_option("--tls-cert", s.tls_cert, "PEM certificate chain (enables TLS with --tls-key)");
  auto* key_opt = app.add_option("--tls-key", s.tls_key, "PEM private key");
  auto* msg_opt = app.add_option("--max-message-mb", s.max_message_mb, "largest accepted message (MB)");
  double idle_timeout_s = 120;
  auto* inflight_opt = app.add_option("--max-inflight-mb", s.max_inflight_mb,
                                      "scan memory in flight (MB, counted as 3 x wire bytes); calls beyond wait")
                           ->capture_default_str();
  auto* per_client_opt = app.add_option("--max-streams-per-client", s.streams.max_per_client,
                                        "open streams of each kind per client (bearer token, else IP address)")
                             ->capture_default_str();
  auto* streams_opt =
      app.add_option("--max-streams", s.streams.max_total, "open streams of each kind in total")->capture_default_str();
  auto* idle_opt = app.add_option("--stream-idle-timeout-s", idle_timeout_s,
                                  "close an ingest stream that sends nothing for this long")
                       ->capture_default_str();
  bool sync_normal = false;
  app.add_flag("--sync-normal", sync_normal, "SQLite synchronous=NORMAL (survives process crashes, not power loss)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "sglc-server: error: " << e.what() << " (see --help)" << std::endl;
    return 2;
  }

  std::unique_ptr<grpc::Server> server;
  std::unique_ptr<sglc::server::ServiceState> state;
  try {
    // Flags win over the file: remember them, load the file, re-apply.
    const Settings flags = s;
    if (!config_path.empty()) applyConfigFile(s, config_path);
    if (*db_opt) s.db = flags.db;
    if (*listen_opt) s.listen = flags.listen;
    if (*threads_opt) s.threads = flags.threads;
    if (*calls_opt) s.max_calls = flags.max_calls;
    if (*tokens_opt) s.tokens = flags.tokens;
    if (*cert_opt) s.tls_cert = flags.tls_cert;
    if (*key_opt) s.tls_key = flags.tls_key;
    if (*msg_opt) s.max_message_mb = flags.max_message_mb;
    if (*inflight_opt) s.max_inflight_mb = flags.max_inflight_mb;
    if (*per_client_opt) s.streams.max_per_client = flags.streams.max_per_client;
    if (*streams_opt) s.streams.max_total = flags.streams.max_total;
    if (*idle_opt) s.streams.idle_timeout = std::chrono::milliseconds(static_cast<long>(idle_timeout_s * 1000));
    if (sync_normal) s.store.sync = sglc::storage::StoreOptions::Sync::kNormal;
    if (!(s.max_inflight_mb >= 1 && s.max_inflight_mb <= 1 << 20))
      throw std::runtime_error("--max-inflight-mb must be in [1, 1048576]");
    if (s.streams.max_per_client < 1 || s.streams.max_total < 1)
      throw std::runtime_error("--max-streams-per-client and --max-streams must be >= 1");
    if (s.streams.idle_timeout.count() < 100) throw std::runtime_error("--stream-idle-timeout-s must be >= 0.1");
    if (s.threads < 0 || s.threads > 256) throw std::runtime_error("--threads must be 0..256");
    if (s.threads == 0) s.threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    if (s.max_calls < 1 || s.max_calls > 4096) throw std::runtime_error("--max-calls must be 1..4096");
    if (!(s.max_message_mb > 0 && s.max_message_mb <= 2047))
      throw std::runtime_error("--max-message-mb must be in (0, 2047]");
    if (s.tls_cert.empty() != s.tls_key.empty()) throw std::runtime_error("--tls-cert and --tls-key go together");
    s.store.path = s.db;
    if (s.backup_dir.empty()) s.backup_dir = (fs::path(s.db).parent_path() / "backups").string();

    sglc::server::ServiceLimits limits{s.max_points,
                                       s.backup_dir,
                                       s.threads,
                                       static_cast<std::size_t>(s.max_inflight_mb * 1024 * 1024),
                                       static_cast<std::int64_t>(s.max_message_mb * 1024 * 1024),
                                       s.streams};
    state = std::make_unique<sglc::server::ServiceState>(sglc::Pipeline(s.engine),
                                                         sglc::server::TokenTable::load(s.tokens), limits);
    sglc::server::LoopClosureService loop_service(*state);
    sglc::server::MapAdminService admin_service(*state);

    grpc::EnableDefaultHealthCheckService(true);
    grpc::reflection::InitProtoReflectionServerBuilderPlugin();
    grpc::ServerBuilder builder;
    std::shared_ptr<grpc::ServerCredentials> creds = grpc::InsecureServerCredentials();
    if (!s.tls_cert.empty()) {
      grpc::SslServerCredentialsOptions ssl;
      ssl.pem_key_cert_pairs.push_back({readFile(s.tls_key, "TLS key"), readFile(s.tls_cert, "TLS certificate")});
      creds = grpc::SslServerCredentials(ssl);
    }
    int port = 0;
    builder.AddListeningPort(s.listen, creds, &port);
    // A second server must not share the port (gRPC sets SO_REUSEPORT by default: clients would be split
    // between two processes with diverging indexes).
    builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
    // Dead peers are found by keepalive pings, so their streams do not linger; clients may ping every 10 s.
    builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIME_MS, 60'000);
    builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 20'000);
    builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
    builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, 10'000);
    builder.AddChannelArgument(GRPC_ARG_HTTP2_MAX_PING_STRIKES, 5);
    builder.RegisterService(&loop_service);
    builder.RegisterService(&admin_service);
    sglc::server::PoseGraphService graph_service(*state);
    builder.RegisterService(&graph_service);
    const int max_bytes = static_cast<int>(s.max_message_mb * 1024 * 1024);
    builder.SetMaxReceiveMessageSize(max_bytes);
    builder.SetMaxSendMessageSize(max_bytes);
    grpc::ResourceQuota quota("sglc");
    // One gRPC thread per call in flight (the sync server); CPU work is bounded separately (ComputePool).
    // Streams are callback reactors and hold no thread while idle; unary calls hold one while they run.
    quota.SetMaxThreads(s.max_calls + 2);
    builder.SetResourceQuota(quota);
    std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> interceptors;
    interceptors.push_back(sglc::server::makeBadRequestInterceptorFactory());
    builder.experimental().SetInterceptorCreators(std::move(interceptors));
    builder.SetSyncServerOption(grpc::ServerBuilder::SyncServerOption::MAX_POLLERS, 2);

    sglc::server::IoPoller io_poller(builder);  // see io_poller.hpp
    server = builder.BuildAndStart();
    if (!server || port == 0) {
      if (server) server->Shutdown();  // before its completion queues go
      throw std::runtime_error("cannot listen on " + s.listen +
                               ": the address is in use (another sglc-server?) or not valid for this machine");
    }
    io_poller.start();
    auto* health = server->GetHealthCheckService();
    health->SetServingStatus(false);  // NOT_SERVING until the map database is loaded
    spdlog::info("{}", sglc::logging::logLine({{"event", "listening"},
                                               {"address", s.listen},
                                               {"port", port},
                                               {"tls", !s.tls_cert.empty()},
                                               {"auth", state->tokens().enabled()}}));

    const auto t0 = std::chrono::steady_clock::now();
    std::unique_ptr<sglc::storage::MapStore> store;
    try {
      store = sglc::storage::MapStore::open(s.store);
    } catch (...) {
      server->Shutdown();
      server->Wait();
      server.reset();
      throw;
    }
    const auto st = store->stats();
    auto graph = std::make_unique<sglc::server::GraphOptimiser>(*store, s.graph);
    state->attach(store.get(), graph.get());
    health->SetServingStatus(true);
    spdlog::info(
        "{}", sglc::logging::logLine(
                  {{"event", "serving"},
                   {"db", s.db},
                   {"maps", st.maps},
                   {"scans", st.scans},
                   {"load_ms",
                    std::round(
                        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count() * 10) /
                        10}}));

    int sig = 0;
    sigwait(&signals, &sig);
    spdlog::info("{}", sglc::logging::logLine({{"event", "shutdown"}, {"signal", sig}}));
    health->SetServingStatus(false);
    graph->stop();  // loops recorded from now on are optimised after the next start
    // Watchers end; ingest streams end after the request they are working on; new streams are refused.
    state->streams().closeAll(grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down"));
    // Refuse new calls, let in-flight ones finish (up to the grace period), then close the database cleanly.
    server->Shutdown(std::chrono::system_clock::now() +
                     std::chrono::milliseconds(static_cast<long>(s.shutdown_grace_s * 1000)));
    server->Wait();
    io_poller.stop();
    state->detach();
    graph.reset();
    store.reset();
    spdlog::info("{}", R"({"event":"stopped"})");
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "sglc-server: error: " << e.what() << std::endl;
    return 1;
  }
}
