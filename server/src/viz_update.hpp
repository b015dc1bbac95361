// What the live view's hub (VizHub) hands its WebSocket server (VizServer): a map's messages, in Foxglove's
// schemas (posegraph/foxglove_scene.hpp), each shared by every viewer it is sent to.
#pragma once

#include <cstdint>
#include <memory>
#include <set>
#include <string>
#include <vector>

namespace sglc::server {

struct VizMessage {
  std::string topic;  // relative to the map ("trajectory/a", "loops", ...)
  std::string schema_name;
  std::shared_ptr<const std::string> payload;  // the JSON message
  std::uint64_t stamp_ns = 0;
};

struct VizUpdate {
  std::string map;
  // The map's whole set of graph topics: a graph topic (trajectory/, odometry/, loops, loop_list) of the map
  // not in it is gone. False: these topics only (events, keyframe), the others as they are.
  bool complete = false;
  bool deleted = false;  // the map is gone: every topic of it is
  std::vector<VizMessage> messages;
};

// What the viewers ask for, as the server tells the hub.
struct VizDemand {
  int viewers = 0;                      // connected: none, and the hub builds nothing
  std::set<std::string> keyframe_maps;  // maps whose keyframe topic some viewer subscribes to
};

}  // namespace sglc::server
