#include "viz_hub.hpp"

#include <spdlog/spdlog.h>

#include "sglc/log/log_line.hpp"
#include "sglc/posegraph/foxglove_scene.hpp"
#include "sglc/posegraph/graph_export.hpp"

namespace sglc::server {

namespace {

using Clock = std::chrono::steady_clock;

VizMessage message(std::string topic, std::string schema, std::string json, std::uint64_t stamp_ns) {
  return {std::move(topic), std::move(schema), std::make_shared<const std::string>(std::move(json)), stamp_ns};
}

std::uint64_t nowNs() {
  return static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count());
}

}  // namespace

VizHub::VizHub(const storage::MapStore& store, posegraph::GraphOptimiser& graph, VizHubOptions options, Sink sink)
    : store_(store), graph_(graph), options_(options), sink_(std::move(sink)) {
  subscription_ =
      graph_.subscribe([this](const std::string& map, const posegraph::GraphEvent& e) { graphEvent(map, e); });
  thread_ = std::thread([this] { run(); });
}

VizHub::~VizHub() {
  graph_.unsubscribe(subscription_);
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void VizHub::setDemand(const VizDemand& demand) {
  {
    std::lock_guard lock(mutex_);
    if (viewers_ == 0 && demand.viewers > 0) {
      built_.clear();
      try {
        for (const auto& m : store_.listMaps()) dirty_.insert(m.name);
      } catch (const std::exception& e) {
        spdlog::warn("{}", logging::logLine({{"event", "viz_error"}, {"error", e.what()}}));
      }
    }
    viewers_ = demand.viewers;
    watched_ = demand.viewers > 0;
    wants_keyframes_ = demand.viewers > 0 && demand.keyframes;
    if (!wants_keyframes_) keyframes_.clear();
  }
  wake_.notify_all();
}

void VizHub::scanStored(const std::string& map, std::int64_t scan_id, const Points& points) {
  if (!watched_.load(std::memory_order_relaxed)) return;
  std::optional<Keyframe> keyframe;
  if (wants_keyframes_.load(std::memory_order_relaxed)) keyframe = Keyframe{scan_id, points};  // copied unlocked
  {
    std::lock_guard lock(mutex_);
    dirty_.insert(map);
    if (keyframe) keyframes_[map] = std::move(*keyframe);
  }
  wake_.notify_all();
}

// On the solver's thread: must not block. The event goes out at once (it is small); the map is rebuilt.
void VizHub::graphEvent(const std::string& map, const posegraph::GraphEvent& event) {
  // A deletion always goes out (the server forgets the map's topics even when nobody watches).
  if (!event.deleted && !watched_.load(std::memory_order_relaxed)) return;
  {
    std::lock_guard lock(mutex_);
    if (event.deleted) {
      dirty_.erase(map);
      keyframes_.erase(map);
      built_.erase(map);
    } else {
      dirty_.insert(map);
    }
  }
  wake_.notify_all();
  VizUpdate update;
  update.map = map;
  update.deleted = event.deleted;
  if (!event.deleted)
    update.messages.push_back(message("events", "sglc.MapEvent", posegraph::foxgloveMapEvent(event), nowNs()));
  sink_(std::move(update));
}

void VizHub::run() {
  std::unique_lock lock(mutex_);
  for (;;) {
    // The next map due: changed, and last rebuilt at least min_interval ago.
    const auto now = Clock::now();
    std::optional<std::string> due;
    auto next = Clock::time_point::max();
    if (viewers_ > 0)
      for (const auto& map : dirty_) {
        const auto built = built_.find(map);
        const auto at = built == built_.end() ? now : built->second + options_.min_interval;
        if (at <= now) {
          due = map;
          break;
        }
        next = std::min(next, at);
      }
    if (stopping_) return;
    if (!due) {
      if (next == Clock::time_point::max())
        wake_.wait(lock);
      else
        wake_.wait_until(lock, next);
      continue;
    }
    dirty_.erase(*due);
    built_[*due] = now;
    std::optional<Keyframe> keyframe;
    if (const auto k = keyframes_.find(*due); k != keyframes_.end()) {
      keyframe = std::move(k->second);
      keyframes_.erase(k);
    }
    lock.unlock();
    try {
      rebuild(*due, keyframe);
    } catch (const std::exception& e) {
      spdlog::warn("{}", logging::logLine({{"event", "viz_error"}, {"map", *due}, {"error", e.what()}}));
    }
    lock.lock();
  }
}

void VizHub::rebuild(const std::string& map, const std::optional<Keyframe>& keyframe) {
  VizUpdate update;
  update.map = map;
  if (!store_.findMap(map)) {
    update.deleted = true;
    sink_(std::move(update));
    return;
  }
  const auto graph = posegraph::exportGraph(store_, map, graph_.options());
  const auto stamp_ns = posegraph::newestStampNs(graph);
  update.complete = true;
  for (auto& t : posegraph::foxgloveScene(graph, stamp_ns))
    update.messages.push_back(message(std::move(t.topic), std::move(t.schema_name), std::move(t.message), stamp_ns));
  if (keyframe)
    for (const auto& n : graph.nodes)
      if (n.scan_id == keyframe->scan_id) {
        update.messages.push_back(
            message("keyframe", "foxglove.PointCloud",
                    posegraph::foxglovePointCloud(keyframe->points, n.pose, stamp_ns, options_.keyframe_voxel_m,
                                                  options_.keyframe_max_points),
                    stamp_ns));
        break;
      }
  sink_(std::move(update));
}

}  // namespace sglc::server
