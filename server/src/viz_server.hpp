// The live view (sglc-server --viz-listen): the Foxglove WebSocket protocol (subprotocol foxglove.websocket.v1)
// on Boost.Beast, and on the same port (GET /) a page that draws the maps in any browser. Viewers authenticate
// as gRPC callers do: with the token file on, `Authorization: Bearer TOKEN` or `?token=TOKEN` (browsers cannot
// set headers on a WebSocket), and each is advertised the topics of the maps its token grants.
//
// Topics per map ("/sglc/<map>/...", names percent-encoded: foxglove_scene.hpp): each robot's trajectory and
// odometry, loops, loop_list, the newest keyframe's points (built only while someone subscribes) and the pose
// graph's events. Every message is a whole picture (a trajectory, all loops), so a viewer that cannot keep up
// skips to the newest: each viewer holds at most one message per subscription plus kMaxControl protocol
// messages, and one that falls behind on those, or stops answering pings for Limits::idle_timeout, is dropped.
// Publishing never waits for a viewer. Connections are served on one thread of asynchronous I/O.
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <string>

#include "auth.hpp"
#include "metrics.hpp"
#include "viz_update.hpp"

namespace sglc::server {

struct VizServerLimits {
  int max_viewers = 64;  // connections (viewers and page loads); a newcomer beyond takes a waiting one's slot
  int max_per_peer = 16;
  std::chrono::milliseconds request_timeout{5000};  // to send the HTTP request head
  std::chrono::milliseconds idle_timeout{20000};    // no answer to a ping for this long: dropped
  std::size_t max_control = 1024;                   // protocol messages queued for one viewer
  std::size_t max_message_bytes = 1 << 16;          // a viewer's message
};

class VizServer {
 public:
  using Limits = VizServerLimits;

  // Binds host:port (port 0: any free port) and serves. `metrics` (may be null) gets its counters and gauge
  // (sglc_viz_connections_total, sglc_viz_messages_total, sglc_viz_viewers; the gauge reads this object: scrapes
  // must end before it goes). Throws std::runtime_error naming the address when it cannot listen.
  VizServer(const std::string& address, const TokenTable& tokens, Metrics* metrics, Limits limits = {});
  ~VizServer();  // stops serving; connections still open are closed
  VizServer(const VizServer&) = delete;
  VizServer& operator=(const VizServer&) = delete;

  int port() const;
  int viewers() const;  // WebSocket viewers connected

  // A map's new messages (from any thread): advertised and sent to its subscribers on the server's thread.
  void publish(VizUpdate update);
  // Told (on the server's thread) whenever the number of viewers or keyframe subscriptions changes; set before
  // publishing starts and cleared (nullptr) before its target goes.
  void onDemand(std::function<void(const VizDemand&)> listener);

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

// The page served at GET / (server/web/viewer.html).
extern const char* const kVizPage;

}  // namespace sglc::server
