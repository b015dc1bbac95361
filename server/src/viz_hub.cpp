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
    // From none to some viewers: every map is shown afresh (listed on the hub's thread: this is the server's).
    if (viewers_ == 0 && demand.viewers > 0) list_maps_ = true;
    viewers_ = demand.viewers;
    watched_ = demand.viewers > 0;
    keyframe_maps_ = demand.viewers > 0 ? demand.keyframe_maps : std::set<std::string>{};
    std::erase_if(keyframes_, [this](const auto& k) { return !keyframe_maps_.count(k.first); });
  }
  wake_.notify_all();
}

void VizHub::scanStored(const std::string& map, std::int64_t scan_id, const Points& points) {
  if (!watched_.load(std::memory_order_relaxed)) return;
  bool copy = false;
  {
    std::lock_guard lock(mutex_);
    dirty_.insert(map);
    copy = keyframe_maps_.count(map) > 0;
  }
  if (copy) {
    Keyframe keyframe{scan_id, points};  // copied without the lock
    std::lock_guard lock(mutex_);
    if (keyframe_maps_.count(map)) keyframes_[map] = std::move(keyframe);
  }
  wake_.notify_all();
}

// On the solver's thread: must not block. The event goes out at once (it is small); the map is rebuilt.
void VizHub::graphEvent(const std::string& map, const posegraph::GraphEvent& event) {
  // A deletion always goes out (the server forgets the map's topics even when nobody watches).
  if (!event.deleted && !watched_.load(std::memory_order_relaxed)) return;
  VizUpdate update;
  update.map = map;
  update.deleted = event.deleted;
  if (!event.deleted)
    update.messages.push_back(message("events", "sglc.MapEvent", posegraph::foxgloveMapEvent(event), nowNs()));
  {
    // Published under the lock, as rebuilds are: a rebuild that read the map before its deletion is dropped
    // (generation) or went out before it, never after.
    std::lock_guard lock(mutex_);
    if (event.deleted) {
      ++generation_[map];
      dirty_.erase(map);
      keyframes_.erase(map);
    } else {
      dirty_.insert(map);
    }
    sink_(std::move(update));  // posts: never blocks
  }
  wake_.notify_all();
}

void VizHub::run() {
  std::unique_lock lock(mutex_);
  for (;;) {
    if (stopping_) return;
    if (list_maps_ && viewers_ > 0) {
      list_maps_ = false;
      lock.unlock();
      std::vector<std::string> names;
      try {
        for (const auto& m : store_.listMaps()) names.push_back(m.name);
      } catch (const std::exception& e) {
        spdlog::warn("{}", logging::logLine({{"event", "viz_error"}, {"error", e.what()}}));
      }
      lock.lock();
      dirty_.insert(names.begin(), names.end());
      continue;
    }
    // The next map due: changed, and last rebuilt at least min_interval ago; of those, the one rebuilt longest
    // ago (never: first), so that every changed map gets its turn.
    const auto now = Clock::now();
    std::optional<std::string> due;
    auto due_built = Clock::time_point::max();
    auto next = Clock::time_point::max();
    if (viewers_ > 0)
      for (const auto& map : dirty_) {
        const auto built = built_.find(map);
        const auto last = built == built_.end() ? Clock::time_point::min() : built->second;
        const auto at = built == built_.end() ? now : last + options_.min_interval;
        if (at > now) {
          next = std::min(next, at);
        } else if (!due || last < due_built) {
          due = map;
          due_built = last;
        }
      }
    if (!due) {
      if (next == Clock::time_point::max())
        wake_.wait(lock);
      else
        wake_.wait_until(lock, next);
      continue;
    }
    dirty_.erase(*due);
    built_[*due] = now;
    const auto generation = generation_[*due];
    std::optional<Keyframe> keyframe;
    if (const auto k = keyframes_.find(*due); k != keyframes_.end()) {
      keyframe = std::move(k->second);
      keyframes_.erase(k);
    }
    lock.unlock();
    std::optional<VizUpdate> update;
    try {
      update = rebuild(*due, keyframe);
    } catch (const std::exception& e) {
      spdlog::warn("{}", logging::logLine({{"event", "viz_error"}, {"map", *due}, {"error", e.what()}}));
    }
    lock.lock();
    // Deleted while it was read: the deletion went out already, and this picture of it must not follow.
    if (update && generation_[*due] == generation) sink_(std::move(*update));
  }
}

VizUpdate VizHub::rebuild(const std::string& map, const std::optional<Keyframe>& keyframe) {
  VizUpdate update;
  update.map = map;
  if (!store_.findMap(map)) {
    update.deleted = true;
    return update;
  }
  const auto graph = posegraph::exportGraph(store_, map, graph_.options());
  const auto stamp_ns = posegraph::newestStampNs(graph);
  update.complete = true;
  for (auto& t : posegraph::foxgloveScene(graph, stamp_ns))
    update.messages.push_back(message(std::move(t.topic), std::move(t.schema_name), std::move(t.message), stamp_ns));
  update.messages.push_back(
      message("map_stats", "sglc.MapStats", posegraph::foxgloveMapStats(store_.stats(map)), stamp_ns));
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
  return update;
}

}  // namespace sglc::server
