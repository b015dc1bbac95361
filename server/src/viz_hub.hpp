// The live view's model: what each map looks like in Foxglove's schemas, rebuilt off the request path. It
// follows the pose graph's events (WatchMap's) and the keyframes ingest offers; while viewers are connected, a
// thread of its own rebuilds each changed map at most once per `min_interval` (the whole graph, as the export
// reads it: foxglove_scene.hpp) and hands the messages to the sink. Ingest only marks a map changed or hands
// over a keyframe's points (copied only while a viewer subscribes to keyframes): it never waits for a viewer.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>

#include "sglc/posegraph/graph_optimiser.hpp"
#include "sglc/storage/map_store.hpp"
#include "sglc/types.hpp"
#include "viz_update.hpp"

namespace sglc::server {

struct VizHubOptions {
  std::chrono::milliseconds min_interval{500};  // between two rebuilds of one map
  double keyframe_voxel_m = 0.4;                // the keyframe's points: one per voxel
  std::size_t keyframe_max_points = 30000;
};

class VizHub {
 public:
  using Sink = std::function<void(VizUpdate)>;

  // Subscribes to `graph`'s events; store and graph must outlive the hub.
  VizHub(const storage::MapStore& store, posegraph::GraphOptimiser& graph, VizHubOptions options, Sink sink);
  ~VizHub();  // stops its thread; the sink is not called after it returns
  VizHub(const VizHub&) = delete;
  VizHub& operator=(const VizHub&) = delete;

  // From the server: who is watching. From no viewers to some, every map is rebuilt.
  void setDemand(const VizDemand& demand);
  // Ingest stored a scan of `map`: the map is rebuilt. `points` (the scan's, in its own frame) are copied only
  // while a viewer subscribes to the map's keyframe topic: then the map's keyframe topic shows the newest scan at its
  // pose (a scan without an odometry pose has none and is not shown). Returns at once when no viewer is connected.
  void scanStored(const std::string& map, std::int64_t scan_id, const Points& points);

 private:
  struct Keyframe {
    std::int64_t scan_id = 0;
    Points points;
  };
  void run();
  // Builds the map's update (without the lock); returns it to be published if the map was not deleted meanwhile.
  VizUpdate rebuild(const std::string& map, const std::optional<Keyframe>& keyframe);
  void graphEvent(const std::string& map, const posegraph::GraphEvent& event);

  const storage::MapStore& store_;
  posegraph::GraphOptimiser& graph_;
  const VizHubOptions options_;
  const Sink sink_;
  std::atomic<bool> watched_{false};  // viewers are connected

  std::mutex mutex_;
  std::condition_variable wake_;
  bool stopping_ = false;
  int viewers_ = 0;
  std::set<std::string> keyframe_maps_;              // maps whose keyframes a viewer subscribes to
  bool list_maps_ = false;                           // list the maps (viewers came): done on the hub's thread
  std::set<std::string> dirty_;                      // maps to rebuild
  std::map<std::string, std::uint64_t> generation_;  // per map, bumped by its deletion
  std::map<std::string, Keyframe> keyframes_;        // the newest offered, per map
  std::map<std::string, std::chrono::steady_clock::time_point> built_;  // last rebuild per map
  std::uint64_t subscription_ = 0;
  std::thread thread_;
};

}  // namespace sglc::server
