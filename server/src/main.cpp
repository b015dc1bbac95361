// sglc-server: the SGLC loop-closure service over gRPC, on a persistent SQLite map database.
#include <dlfcn.h>
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <malloc.h>
#include <signal.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <iostream>
#include <map>

#include "call.hpp"
#include "compaction_timer.hpp"
#include "gauge_refresher.hpp"
#include "io_poller.hpp"
#include "metrics_http.hpp"
#include "server_metrics.hpp"
#include "service.hpp"
#include "settings.hpp"
#include "sglc/config/settings_file.hpp"
#include "sglc/elapsed.hpp"
#include "sglc/log/json_lines.hpp"
#include "sglc/log/log_line.hpp"
#include "sglc/version.hpp"
#include "viz_hub.hpp"
#include "viz_server.hpp"

namespace {

using sglc::server::Settings;

// What the command line asks for beyond the settings themselves.
struct Request {
  std::string config_path;
  std::vector<std::string> sets;
  bool dump = false, reference = false, sync_normal = false;
  std::map<std::string, std::string> flag_values;  // by key, for the server.* flags given
  std::map<std::string, CLI::Option*> flags;
};

// Every server.* key is also a flag: server.max_calls is --max-calls.
void addFlags(CLI::App& app, Request& r) {
  app.add_option("--config", r.config_path, "YAML file with sections server, storage, pose_graph, engine");
  app.add_option("--set", r.sets, "KEY=VALUE for any key of the file (repeatable; wins over the file)");
  app.add_flag("--dump-config", r.dump, "print the settings in effect as YAML and exit");
  app.add_flag("--config-reference", r.reference, "print every key with its default, range and meaning and exit");
  app.add_flag("--sync-normal", r.sync_normal, "same as --set storage.sync=normal");
  for (const auto& p : sglc::server::settingsTable().params()) {
    const auto& key = p.info.key;
    if (key.rfind("server.", 0) != 0) continue;
    std::string name = key.substr(7);
    std::replace(name.begin(), name.end(), '_', '-');
    const auto kind = p.info.kind == sglc::params::Kind::kText   ? "TEXT"
                      : p.info.kind == sglc::params::Kind::kReal ? "NUMBER"
                                                                 : "INT";
    r.flags[key] = app.add_option("--" + name, r.flag_values[key],
                                  p.info.doc + " [" + sglc::params::format(p.get(Settings{})) + "]")
                       ->type_name(kind);
  }
}

// The settings: defaults, then the file, then --set in order, then the flags.
Settings settingsFrom(const Request& r) {
  std::vector<std::pair<std::string, std::string>> overrides;
  for (const auto& set : r.sets) overrides.emplace_back("--set " + set, set);
  for (const auto& [key, option] : r.flags)
    if (*option) {
      const auto& value = r.flag_values.at(key);
      overrides.emplace_back(option->get_name() + " " + value, key + "=" + value);
    }
  if (r.sync_normal) overrides.emplace_back("--sync-normal", "storage.sync=normal");
  return sglc::server::settingsFrom(r.config_path, overrides);
}

void configure(grpc::ServerBuilder& builder, const Settings& s, grpc::ResourceQuota& quota,
               sglc::server::Metrics& metrics) {
  // A second server must not share the port (gRPC sets SO_REUSEPORT by default: clients would be split
  // between two processes with diverging indexes).
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  // Dead peers are found by keepalive pings, so their streams do not linger; clients may ping every 10 s.
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIME_MS, 60'000);
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 20'000);
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, 10'000);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MAX_PING_STRIKES, 5);
  const int max_bytes = static_cast<int>(s.max_message_mb * 1024 * 1024);
  builder.SetMaxReceiveMessageSize(max_bytes);
  builder.SetMaxSendMessageSize(max_bytes);
  // One gRPC thread per call in flight (the sync server); CPU work is bounded separately (ComputePool).
  // Streams are callback reactors and hold no thread while idle; unary calls hold one while they run.
  quota.SetMaxThreads(s.max_calls + 2);
  builder.SetResourceQuota(quota);
  std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> interceptors;
  interceptors.push_back(sglc::server::makeBadRequestInterceptorFactory());
  // After the one above, so that it counts the status the client gets.
  if (!s.metrics_listen.empty()) interceptors.push_back(sglc::server::makeMetricsInterceptorFactory(metrics));
  builder.experimental().SetInterceptorCreators(std::move(interceptors));
  builder.SetSyncServerOption(grpc::ServerBuilder::SyncServerOption::MAX_POLLERS, 2);
}

std::shared_ptr<grpc::ServerCredentials> credentials(const Settings& s) {
  if (s.tls_cert.empty()) return grpc::InsecureServerCredentials();
  grpc::SslServerCredentialsOptions ssl;
  ssl.pem_key_cert_pairs.push_back(
      {sglc::config::readTextFile(s.tls_key, "TLS key"), sglc::config::readTextFile(s.tls_cert, "TLS certificate")});
  return grpc::SslServerCredentials(ssl);
}

std::unique_ptr<sglc::storage::MapStore> openStore(const Settings& s, grpc::Server& server) {
  const auto t0 = sglc::Clock::now();
  std::unique_ptr<sglc::storage::MapStore> store;
  try {
    store = sglc::storage::MapStore::open(s.store);
  } catch (...) {
    server.Shutdown();
    server.Wait();
    throw;
  }
  const auto st = store->stats();
  spdlog::info("{}", sglc::logging::logLine({{"event", "serving"},
                                             {"db", sglc::storage::printableLocation(s.db)},
                                             {"maps", st.maps},
                                             {"scans", st.scans},
                                             {"load_ms", std::round(sglc::msSince(t0) * 10) / 10}}));
  return store;
}

// gRPC's own log lines (e.g. a failed TLS handshake) as JSON lines too.
void grpcLog(gpr_log_func_args* args) {
  const auto line = sglc::logging::logLine(
      {{"event", "grpc"}, {"file", args->file ? args->file : ""}, {"line", args->line}, {"msg", args->message}});
  if (args->severity == GPR_LOG_SEVERITY_ERROR)
    spdlog::error("{}", line);
  else if (args->severity == GPR_LOG_SEVERITY_INFO)
    spdlog::info("{}", line);
  else
    spdlog::debug("{}", line);
}

// The Prometheus endpoint, when asked for: the gauges are read on a thread of their own, when a scrape asks,
// and the HTTP server serves what they read. Destroyed in reverse: no scrape outlives the refresher.
struct MetricsEndpoint {
  std::unique_ptr<sglc::server::GaugeRefresher> refresher;
  std::unique_ptr<sglc::server::MetricsHttpServer> http;
};

MetricsEndpoint serveMetrics(const Settings& s, sglc::server::ServiceState& state) {
  if (s.metrics_listen.empty()) return {};
  sglc::server::declareServerGauges(state.metrics(), state);
  MetricsEndpoint endpoint;
  endpoint.refresher = std::make_unique<sglc::server::GaugeRefresher>(state.metrics());
  endpoint.http = std::make_unique<sglc::server::MetricsHttpServer>(
      s.metrics_listen, sglc::server::MetricsSource{[&state] { return state.metrics().render(); },
                                                    [r = endpoint.refresher.get()] { return r->request(); }});
  spdlog::info("{}", sglc::logging::logLine(
                         {{"event", "metrics"}, {"address", s.metrics_listen}, {"port", endpoint.http->port()}}));
  return endpoint;
}

// Serves until SIGTERM or SIGINT, then shuts down in order.
// The live view's hub over the map (none without --viz-listen), attached to the service.
std::unique_ptr<sglc::server::VizHub> startVizHub(const Settings& s, sglc::server::VizServer* viz,
                                                  sglc::storage::MapStore& store, sglc::server::GraphOptimiser& graph,
                                                  sglc::server::ServiceState& state) {
  if (!viz) return nullptr;
  sglc::server::VizHubOptions options;
  options.min_interval = std::chrono::milliseconds(static_cast<long>(s.viz_interval_s * 1000));
  auto hub = std::make_unique<sglc::server::VizHub>(store, graph, options,
                                                    [viz](sglc::server::VizUpdate u) { viz->publish(std::move(u)); });
  viz->onDemand([h = hub.get()](const sglc::server::VizDemand& d) { h->setDemand(d); });
  state.attachViz(hub.get());
  return hub;
}

int serve(const Settings& s, sigset_t& signals) {
  const auto state = std::make_unique<sglc::server::ServiceState>(
      sglc::Pipeline(s.engine), sglc::server::TokenTable::load(s.tokens), sglc::server::limitsOf(s));
  sglc::server::LoopClosureService loop_service(*state);
  sglc::server::MapAdminService admin_service(*state);
  sglc::server::PoseGraphService graph_service(*state);
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  int port = 0;
  builder.AddListeningPort(s.listen, credentials(s), &port);
  builder.RegisterService(&loop_service);
  builder.RegisterService(&admin_service);
  builder.RegisterService(&graph_service);
  grpc::ResourceQuota quota("sglc");
  configure(builder, s, quota, state->metrics());
  sglc::server::IoPoller io_poller(builder);    // see io_poller.hpp
  auto metrics_http = serveMetrics(s, *state);  // before the server starts: a bad address stops nothing
  std::unique_ptr<sglc::server::VizServer> viz;
  if (!s.viz_listen.empty()) {
    viz = std::make_unique<sglc::server::VizServer>(s.viz_listen, state->tokens(), &state->metrics());
    spdlog::info("{}", sglc::logging::logLine({{"event", "viz"}, {"address", s.viz_listen}, {"port", viz->port()}}));
  }
  std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
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
  auto store = openStore(s, *server);
  state->settingsGuard().recordMissing(*store);  // maps from before settings were recorded get this server's
  auto graph = std::make_unique<sglc::server::GraphOptimiser>(*store, s.graph);
  const auto solves = graph->subscribe([&metrics = state->metrics()](const std::string&, const auto& event) {
    sglc::server::observeSolve(metrics, event);
  });
  auto hub = startVizHub(s, viz.get(), *store, *graph, *state);
  state->attach(store.get(), graph.get());
  // Lifelong maps: retire what ended sessions added beyond their places' versions (docs/LIFELONG.md).
  auto compactor = sglc::server::startCompactionTimer(*store, s.lifelong, state->limits().odometry, *graph);
  health->SetServingStatus(true);

  int sig = 0;
  sigwait(&signals, &sig);
  spdlog::info("{}", sglc::logging::logLine({{"event", "shutdown"}, {"signal", sig}}));
  health->SetServingStatus(false);
  compactor.reset();  // a compaction in progress finishes first
  graph->stop();      // loops recorded from now on are optimised after the next start
  graph->unsubscribe(solves);
  // Watchers end; ingest streams end after the request they are working on; new streams are refused.
  state->streams().closeAll(grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down"));
  // Refuse new calls, let in-flight ones finish (up to the grace period), then close the database cleanly.
  server->Shutdown(std::chrono::system_clock::now() +
                   std::chrono::milliseconds(static_cast<long>(s.shutdown_grace_s * 1000)));
  server->Wait();
  io_poller.stop();
  state->attachViz(nullptr);
  if (viz) viz->onDemand(nullptr);
  hub.reset();
  metrics_http.http.reset();  // its gauges read the store: no scrape or refresh may outlive it
  metrics_http.refresher.reset();
  viz.reset();  // after the scrapes: a gauge reads it
  state->detach();
  graph.reset();
  store.reset();
  spdlog::info("{}", R"({"event":"stopped"})");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  // SIGTERM / SIGINT are blocked before any thread starts (every thread inherits the mask) and taken by
  // sigwait in serve(); a thread started earlier would take them with the default action and kill the process.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  // Buffers of 16 MB and more (scans of a million points and up) are mmapped, so each returns to the system
  // when freed instead of growing the heap (glibc's adaptive threshold would move them onto it after the first
  // free). Ordinary keyframes (~2 MB) stay on the heap: mmapping those too cost 3-5 ms per ingest in page faults.
  mallopt(M_MMAP_THRESHOLD, 16 << 20);
  // Freed memory stays with the process between calls instead of going back at every free that leaves 128 kB
  // at the top of an arena (glibc's default once the threshold above is set): each call's scan, message and
  // engine buffers then touched fresh pages again, a third of the server's CPU in page faults (sglc-bench, ingest
  // without a query: 12-17 -> 6-7 ms CPU per keyframe). After a burst, MemoryBudget::trim hands the memory back
  // once the server is idle.
  mallopt(M_TRIM_THRESHOLD, 256 << 20);
  // OpenBLAS (the BLAS under FAISS and Ceres' sparse solver) runs a thread per core that spins on sched_yield
  // after every call: that doubled the server's CPU per keyframe (68-77 ms against 35-39 ms with one BLAS
  // thread, sglc-bench round trip). The server spreads its own work over the cores (ComputePool), so BLAS
  // runs on the calling thread. Looked up at run time: another BLAS has no such call and needs none.
  using SetBlasThreads = void (*)(int);
  if (auto* set_threads = reinterpret_cast<SetBlasThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads")))
    set_threads(1);
  sglc::logging::useJsonLines();  // every log line one JSON object
  gpr_set_log_function(grpcLog);
  CLI::App app{"SGLC loop-closure service: gRPC (sglc.v1) on a persistent SQLite map database."};
  app.set_version_flag("--version", std::string("sglc-server ") + sglc::kVersion);
  Request request;
  addFlags(app, request);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "sglc-server: error: " << e.what() << " (see --help)" << std::endl;
    return 2;
  }
  try {
    if (request.reference) {
      std::cout << sglc::server::configReference();
      return 0;
    }
    const Settings settings = settingsFrom(request);
    if (request.dump) {
      auto shown = settings;  // a PostgreSQL URL's password is not printed
      shown.db = sglc::storage::printableLocation(settings.db);
      std::cout << sglc::config::dumpYaml(sglc::server::settingsTable(), shown);
      return 0;
    }
    spdlog::set_level(settings.log_level);
    return serve(sglc::server::resolved(settings), signals);
  } catch (const sglc::storage::StorageError& e) {
    // The operator starting the server is told what the database said too (clients never are).
    std::cerr << "sglc-server: error: " << e.what() << (e.detail().empty() ? "" : " (" + e.detail() + ")") << std::endl;
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "sglc-server: error: " << e.what() << std::endl;
    return 1;
  }
}
