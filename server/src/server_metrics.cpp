#include "server_metrics.hpp"

#include <unistd.h>

#include <chrono>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <vector>

#include "service.hpp"
#include "sglc/v1/sglc.grpc.pb.h"
#include "sglc/version.hpp"
#include "sglc/wire/error.hpp"

namespace sglc::server {
namespace {

namespace gx = grpc::experimental;
using Clock = std::chrono::steady_clock;

// The methods this server serves, by full path ("/sglc.v1.LoopClosure/Ingest"), with their labels. A call to
// any other path (anyone can send one, before any token is checked) counts under method="unknown": label
// values come from this closed set, so such calls cannot grow the registry.
class MethodLabels {
 public:
  MethodLabels() {
    const auto* pool = google::protobuf::DescriptorPool::generated_pool();
    for (const char* service :
         {v1::LoopClosure::service_full_name(), v1::MapAdmin::service_full_name(), v1::PoseGraph::service_full_name()})
      if (const auto* s = pool->FindServiceByName(service))
        for (int i = 0; i < s->method_count(); ++i) add(service, s->method(i)->name());
    // gRPC's own services, which the server registers too (health checking, reflection).
    add("grpc.health.v1.Health", "Check");
    add("grpc.health.v1.Health", "Watch");
    add("grpc.reflection.v1alpha.ServerReflection", "ServerReflectionInfo");  // gRPC 1.51 registers no v1
  }
  const Labels& of(const char* path) const {
    static const Labels unknown = {{"service", "unknown"}, {"method", "unknown"}};
    const auto it = known_.find(path != nullptr ? path : "");
    return it == known_.end() ? unknown : it->second;
  }

 private:
  void add(const std::string& service, const std::string& method) {
    known_.emplace("/" + service + "/" + method, Labels{{"service", service}, {"method", method}});
  }
  std::map<std::string, Labels, std::less<>> known_;
};

class MetricsInterceptor final : public gx::Interceptor {
 public:
  MetricsInterceptor(Metrics& metrics, const Labels& labels) : metrics_(metrics), labels_(labels) {}
  void Intercept(gx::InterceptorBatchMethods* methods) override {
    if (methods->QueryInterceptionHookPoint(gx::InterceptionHookPoints::PRE_SEND_STATUS)) {
      auto labels = labels_;
      labels.emplace_back("code", wire::statusCodeName(methods->GetSendStatus().error_code()));
      metrics_.add(kRpcTotal, labels);
      metrics_.observe(kRpcSeconds, labels, std::chrono::duration<double>(Clock::now() - start_).count());
    }
    methods->Proceed();
  }

 private:
  Metrics& metrics_;
  const Labels& labels_;
  Clock::time_point start_ = Clock::now();
};

class MetricsInterceptorFactory final : public gx::ServerInterceptorFactoryInterface {
 public:
  explicit MetricsInterceptorFactory(Metrics& metrics) : metrics_(metrics) {}
  gx::Interceptor* CreateServerInterceptor(gx::ServerRpcInfo* info) override {
    return new MetricsInterceptor(metrics_, methods_.of(info->method()));
  }

 private:
  Metrics& metrics_;
  const MethodLabels methods_;
};

double residentBytes() {
  std::ifstream statm("/proc/self/statm");
  double pages_total = 0, pages_resident = 0;
  statm >> pages_total >> pages_resident;
  return pages_resident * static_cast<double>(sysconf(_SC_PAGESIZE));
}

// One look at the database per scrape, shared by the gauges below (its statistics scan the scans table).
struct StoreSnapshot {
  std::mutex mutex;
  bool valid = false;
  storage::Stats stats;
  std::vector<storage::MapInfo> maps;

  template <typename F>
  auto read(F&& f) {
    const std::lock_guard lock(mutex);
    if (!valid) throw std::runtime_error("the map database is not loaded");
    return f(*this);
  }
};

void declareStoreGauges(Metrics& m, const ServiceState& state) {
  using S = Metrics::Sample;
  auto snap = std::make_shared<StoreSnapshot>();
  m.beforeScrape([snap, &state] {
    const std::lock_guard lock(snap->mutex);
    snap->valid = false;
    snap->stats = state.store().stats();  // throws while loading: the gauges are left out
    snap->maps = state.store().listMaps();
    snap->valid = true;
  });
  auto one = [snap](auto value) {
    return [snap, value] { return snap->read([&](const StoreSnapshot& s) { return std::vector<S>{{{}, value(s)}}; }); };
  };
  auto perMap = [snap](auto value) {
    return [snap, value] {
      return snap->read([&](const StoreSnapshot& s) {
        std::vector<S> out;
        for (const auto& map : s.maps) out.push_back({{{"map", map.name}}, value(map)});
        return out;
      });
    };
  };
  m.gauge("sglc_map_database_up",
          "1 when the newest read of the map database succeeded, 0 when it failed or the database is loading", [snap] {
            const std::lock_guard lock(snap->mutex);
            return std::vector<S>{{{}, snap->valid ? 1.0 : 0.0}};
          });
  m.gauge("sglc_maps", "Maps in the database", one([](const StoreSnapshot& s) { return double(s.stats.maps); }));
  m.gauge("sglc_map_scans", "Scans stored per map", perMap([](const storage::MapInfo& x) { return double(x.scans); }));
  m.gauge("sglc_map_robots", "Robots per map", perMap([](const storage::MapInfo& x) { return double(x.robots); }));
  m.gauge("sglc_pose_graph_loops",
          "Loops in each map's pose graph as of its last solve: state accepted, or rejected (discounted by the "
          "robust loss as false)",
          [snap, &state] {
            return snap->read([&](const StoreSnapshot& s) {
              std::vector<S> out;
              const auto* graph = state.graph();
              if (!graph) return out;
              for (const auto& map : s.maps)
                if (const auto e = graph->latest(map.name); e && !e->failed) {
                  out.push_back({{{"map", map.name}, {"state", "accepted"}}, double(e->loops - e->rejected_loops)});
                  out.push_back({{{"map", map.name}, {"state", "rejected"}}, double(e->rejected_loops)});
                }
              return out;
            });
          });
  m.gauge("sglc_index_entries", "Descriptors in the in-memory search indexes (all maps)",
          one([](const StoreSnapshot& s) { return double(s.stats.index_entries); }));
  m.gauge("sglc_db_bytes", "Size of the map database file (bytes)",
          one([](const StoreSnapshot& s) { return double(s.stats.db_bytes); }));
  m.gauge("sglc_fingerprint_cache_bytes", "Fingerprints held in the memory cache (bytes)",
          one([](const StoreSnapshot& s) { return s.stats.cache_mb * 1024.0 * 1024.0; }));
  // Lifelong maps (docs/LIFELONG.md).
  m.gauge("sglc_places", "Places of lifelong maps (all maps)",
          one([](const StoreSnapshot& s) { return double(s.stats.places); }));
  m.gauge("sglc_place_versions", "Scans kept as versions of their places (all maps)",
          one([](const StoreSnapshot& s) { return double(s.stats.versions); }));
  m.gauge("sglc_retired_scans", "Scans retired by compaction since the maps were created (all maps)",
          one([](const StoreSnapshot& s) { return double(s.stats.retired_scans); }));
  m.gauge("sglc_retired_bytes", "Fingerprint bytes of the scans retired since the maps were created (all maps)",
          one([](const StoreSnapshot& s) { return double(s.stats.retired_bytes); }));
}

// A closed set of label values for the engine's refusal reasons (core/src/verification.cpp, landmarks).
const char* reasonName(std::string_view reason) {
  if (reason.rfind("loop probability below", 0) == 0) return "low_probability";
  if (reason.find("narrow view") != std::string_view::npos) return "narrow_view";
  if (reason.rfind("no pose hypothesis", 0) == 0) return "no_pose";
  if (reason.find("max_translation") != std::string_view::npos) return "translation";
  return "landmarks";
}

}  // namespace

std::unique_ptr<Metrics> newServerMetrics() {
  auto m = std::make_unique<Metrics>();
  m->counter(kRpcTotal, "RPCs finished, by service, method and status code");
  m->histogram(kRpcSeconds, "RPC duration by service, method and status code (streams: their whole life), seconds");
  m->histogram(kStageSeconds,
               "Time per engine stage of an ingest or query (fingerprint, store, search, verify, "
               "refine), seconds");
  m->counter(kScansIngested, "Scans stored (retries of stored scans not counted), by label source");
  m->counter(kLoopCandidates,
             "Loop candidates verified: result verified, or refused with the reason (low_probability, no_pose, "
             "narrow_view, landmarks, translation)");
  m->histogram(kSolveSeconds,
               "Pose-graph solve time by result (converged, bounded, failed) and scope (local, global), seconds");
  return m;
}

void declareServerGauges(Metrics& m, const ServiceState& state) {
  using S = Metrics::Sample;
  m.gauge("sglc_build_info", "Version of this server", [] { return std::vector<S>{{{{"version", kVersion}}, 1.0}}; });
  m.gauge("sglc_compute_busy", "Compute threads running engine work", [&state] {
    return std::vector<S>{{{}, static_cast<double>(state.compute().busy())}};
  });
  m.gauge("sglc_compute_queue_depth", "Calls waiting for a compute thread", [&state] {
    return std::vector<S>{{{}, static_cast<double>(state.compute().waiting())}};
  });
  m.gauge("sglc_inflight_bytes", "Scan memory reserved by calls in flight (3 x wire bytes), bytes", [&state] {
    return std::vector<S>{{{}, static_cast<double>(state.memory().inUse())}};
  });
  m.gauge("sglc_inflight_bytes_limit", "Limit of sglc_inflight_bytes (server.max_inflight_mb), bytes", [&state] {
    return std::vector<S>{{{}, static_cast<double>(state.memory().capacity())}};
  });
  m.gauge("process_resident_memory_bytes", "Resident memory of the server process, bytes", [] {
    return std::vector<S>{{{}, residentBytes()}};
  });
  declareStoreGauges(m, state);
}

std::unique_ptr<gx::ServerInterceptorFactoryInterface> makeMetricsInterceptorFactory(Metrics& metrics) {
  return std::make_unique<MetricsInterceptorFactory>(metrics);
}

void observeStages(Metrics& m, const v1::Timing& t) {
  const std::pair<const char*, double> stages[] = {{"fingerprint", t.fingerprint_ms()},
                                                   {"store", t.store_ms()},
                                                   {"search", t.search_ms()},
                                                   {"verify", t.verify_ms()},
                                                   {"refine", t.refine_ms()}};
  for (const auto& [stage, ms] : stages)
    if (ms > 0) m.observe(kStageSeconds, {{"stage", stage}}, ms / 1000);
}

void observeSolve(Metrics& m, const posegraph::GraphEvent& event) {
  if (event.deleted) return;  // a deletion, not a solve
  const char* result = event.failed ? "failed" : event.converged ? "converged" : "bounded";
  m.observe(kSolveSeconds, {{"result", result}, {"scope", event.global ? "global" : "local"}},
            event.optimise_ms / 1000);
}

}  // namespace sglc::server

namespace sglc::server {

void countScan(Metrics& m, v1::LabelSource source) {
  const char* name = source == v1::LABELS_COMPUTED    ? "computed"
                     : source == v1::LABELS_COMPLETED ? "completed"
                                                      : "provided";
  m.add(kScansIngested, {{"label_source", name}});
}

void countCandidates(Metrics& m, const closing::QueryTiming& decided) {
  if (decided.verified > 0) m.add(kLoopCandidates, {{"result", "verified"}, {"reason", ""}}, decided.verified);
  for (const char* reason : decided.refused)
    m.add(kLoopCandidates, {{"result", "refused"}, {"reason", reasonName(reason)}});
}

}  // namespace sglc::server
