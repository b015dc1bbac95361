#include "viz_server.hpp"

#include <array>
#include <atomic>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/write.hpp>
#include <boost/beast/core/buffers_to_string.hpp>
#include <boost/beast/core/error.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/core/tcp_stream.hpp>
#include <boost/beast/http/empty_body.hpp>
#include <boost/beast/http/error.hpp>
#include <boost/beast/http/parser.hpp>
#include <boost/beast/http/read.hpp>
#include <boost/beast/websocket/rfc6455.hpp>
#include <boost/beast/websocket/stream.hpp>
#include <deque>
#include <limits>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <stdexcept>
#include <thread>

#include "connection_slots.hpp"
#include "net_address.hpp"
#include "rpc_error.hpp"
#include "sglc/names.hpp"
#include "sglc/posegraph/foxglove_scene.hpp"
#include "sglc/version.hpp"

namespace sglc::server {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
using Json = nlohmann::json;

constexpr const char* kSubprotocol = "foxglove.websocket.v1";
constexpr const char* kConnections = "sglc_viz_connections_total";
constexpr const char* kMessages = "sglc_viz_messages_total";
constexpr std::chrono::milliseconds kWriteTimeout{30000};  // one message to a viewer
constexpr std::size_t kMaxRequestBytes = 8192;

std::string httpResponse(int code, const char* reason, const std::string& body, const char* type,
                         bool head_only = false) {
  std::string out = "HTTP/1.1 " + std::to_string(code) + ' ' + reason + "\r\nContent-Type: " + type +
                    "\r\nContent-Length: " + std::to_string(body.size()) +
                    "\r\nCache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\nConnection: close\r\n";
  if (code == 405) out += "Allow: GET, HEAD\r\n";
  if (code == 401) out += "WWW-Authenticate: Bearer\r\n";
  out += "\r\n";
  if (!head_only) out += body;
  return out;
}

// The value of `key` in a URL's query ("?a=1&token=x"), percent-decoded ('+' is a space); nullopt when absent.
std::optional<std::string> queryValue(std::string_view target, std::string_view key) {
  const auto q = target.find('?');
  if (q == std::string_view::npos) return std::nullopt;
  std::string_view rest = target.substr(q + 1);
  while (!rest.empty()) {
    const auto amp = rest.find('&');
    const auto pair = rest.substr(0, amp);
    const auto eq = pair.find('=');
    if (pair.substr(0, eq) == key) {
      std::string value(eq == std::string_view::npos ? std::string_view{} : pair.substr(eq + 1));
      for (auto& c : value)
        if (c == '+') c = ' ';
      return percentDecoded(value);
    }
    if (amp == std::string_view::npos) break;
    rest = rest.substr(amp + 1);
  }
  return std::nullopt;
}

bool offersSubprotocol(std::string_view header) {
  while (!header.empty()) {
    const auto comma = header.find(',');
    auto item = header.substr(0, comma);
    while (!item.empty() && (item.front() == ' ' || item.front() == '\t')) item.remove_prefix(1);
    while (!item.empty() && (item.back() == ' ' || item.back() == '\t')) item.remove_suffix(1);
    if (item == kSubprotocol) return true;
    if (comma == std::string_view::npos) break;
    header.remove_prefix(comma + 1);
  }
  return false;
}

class Connection;

}  // namespace

struct VizServer::Impl {
  Impl(const TokenTable& t, Metrics* m, Limits l)
      : tokens(t), metrics(m), limits(l), slots(limits.max_viewers, limits.max_per_peer) {}

  struct Channel {
    std::uint32_t id = 0;
    std::string map, relative, topic, schema_name;
    std::shared_ptr<const std::string> payload;  // null until its first message
    std::uint64_t stamp_ns = 0;
  };

  void admit(tcp::socket socket);
  void apply(VizUpdate update);
  // Adds the channel (advertised to the viewers allowed its map) or returns the one there is.
  Channel& channel(const std::string& map, const std::string& relative, const std::string& schema_name,
                   std::vector<std::uint32_t>* advertised);
  void removeChannels(const std::vector<std::uint32_t>& ids);
  void demandChanged();
  void count(const char* family, const char* result, double n = 1) {
    if (metrics) metrics->add(family, {{"result", result}}, n);
  }
  Json advertisement(const std::vector<std::uint32_t>& ids, const TokenTable::Grant& grant) const;

  const TokenTable& tokens;
  Metrics* const metrics;
  const Limits limits;
  ConnectionSlots slots;
  std::map<ConnectionSlots::Id, std::weak_ptr<Connection>> connections;
  std::map<std::uint32_t, Channel> channels;
  std::map<std::string, std::map<std::string, std::uint32_t>> by_map;  // map -> relative topic -> channel id
  std::uint32_t next_channel = 1;
  std::atomic<int> viewers{0};
  VizDemand told;
  bool told_once = false;
  std::mutex listener_mutex;
  std::function<void(const VizDemand&)> listener;
  TcpEndpoint net;  // last: its connections use the members above
};

namespace {

using Server = VizServer::Impl;

// One connection: an HTTP request (the page), or a viewer once its WebSocket handshake is done.
class Connection : public std::enable_shared_from_this<Connection> {
 public:
  Connection(tcp::socket socket, Server& server, ConnectionSlots::Id id)
      : stream_(std::move(socket)), server_(server), id_(id), write_timer_(stream_.get_executor()) {
    parser_.header_limit(kMaxRequestBytes);
  }
  ~Connection() {
    server_.slots.leave(id_);
    server_.connections.erase(id_);
    if (ws_) {
      --server_.viewers;
      server_.demandChanged();
    }
  }
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  void start() {
    stream_.expires_after(server_.limits.request_timeout);
    http::async_read_header(stream_, buffer_, parser_,
                            [self = shared_from_this()](beast::error_code ec, std::size_t) { self->onHead(ec); });
  }
  // Closes the connection (its slot went to a newcomer, or it fell behind).
  void evict() {
    beast::error_code ignored;
    if (ws_)
      beast::get_lowest_layer(*ws_).socket().close(ignored);
    else
      stream_.socket().close(ignored);
  }

  bool viewer() const { return ws_ && open_; }
  const TokenTable::Grant& grant() const { return grant_; }
  // The maps whose keyframe topic this viewer subscribes to, added to `maps`.
  void keyframeMaps(std::set<std::string>* maps) const {
    for (const auto& [channel, sub] : subscription_of_)
      if (const auto c = server_.channels.find(channel);
          c != server_.channels.end() && c->second.relative == "keyframe")
        maps->insert(c->second.map);
  }
  // Protocol messages (advertise, status, ...), in order; a viewer too far behind on them is dropped.
  void sendText(std::string text) {
    if (!viewer()) return;
    if (control_.size() >= server_.limits.max_control) {
      server_.count(kConnections, "dropped_slow");
      open_ = false;
      evict();
      return;
    }
    control_.push_back(std::move(text));
    writeNext();
  }
  // A channel's new message for this viewer, if it subscribes: replaces one still waiting (skipped).
  void sendData(const Server::Channel& c) {
    const auto sub = subscription_of_.find(c.id);
    if (!viewer() || sub == subscription_of_.end() || !c.payload) return;
    auto& slot = data_[c.id];
    if (slot.payload) server_.count(kMessages, "skipped");
    slot = {sub->second, c.payload, c.stamp_ns};
    writeNext();
  }
  // The channels went away: their subscriptions end.
  void channelsRemoved(const std::vector<std::uint32_t>& ids) {
    for (const auto id : ids) {
      const auto sub = subscription_of_.find(id);
      if (sub == subscription_of_.end()) continue;
      subscriptions_.erase(sub->second);
      subscription_of_.erase(sub);
      data_.erase(id);
    }
  }

 private:
  struct Pending {
    std::uint32_t subscription = 0;
    std::shared_ptr<const std::string> payload;
    std::uint64_t stamp_ns = 0;
  };

  void onHead(beast::error_code ec) {
    server_.slots.requestReceived(id_);
    if (ec == beast::error::timeout || ec == http::error::end_of_stream || ec == asio::error::operation_aborted) return;
    if (ec == http::error::header_limit || ec == http::error::buffer_overflow)
      return reply(httpResponse(431, "Request Header Fields Too Large", "request too large\n", "text/plain"));
    if (ec) return reply(httpResponse(400, "Bad Request", "malformed HTTP request\n", "text/plain"));
    const auto& request = parser_.get();
    const auto target = std::string_view(request.target().data(), request.target().size());
    const auto path = target.substr(0, target.find('?'));
    if (websocket::is_upgrade(request)) return upgrade(target);
    const bool head = request.method() == http::verb::head;
    if (request.method() != http::verb::get && !head)
      return reply(httpResponse(405, "Method Not Allowed", "only GET and HEAD\n", "text/plain"));
    if (path != "/" && path != "/index.html")
      return reply(httpResponse(404, "Not Found", "the live view is at /\n", "text/plain", head));
    reply(httpResponse(200, "OK", kVizPage, "text/html; charset=utf-8", head));
  }

  void upgrade(std::string_view target) {
    const auto& request = parser_.get();
    const auto offered = request[http::field::sec_websocket_protocol];
    if (!offersSubprotocol(std::string_view(offered.data(), offered.size()))) {
      server_.count(kConnections, "bad_request");
      return reply(httpResponse(400, "Bad Request",
                                std::string("the live view speaks the WebSocket subprotocol ") + kSubprotocol + "\n",
                                "text/plain"));
    }
    if (server_.tokens.enabled()) {
      std::string token;
      const auto auth = request[http::field::authorization];
      const std::string_view header(auth.data(), auth.size());
      if (header.substr(0, 7) == "Bearer ")
        token = std::string(header.substr(7));
      else if (const auto q = queryValue(target, "token"))
        token = *q;
      try {
        grant_ = server_.tokens.grantOf(token);
      } catch (const RpcError&) {
        server_.count(kConnections, "unauthenticated");
        return reply(httpResponse(401, "Unauthorized",
                                  "the live view needs a token of the server's token file: "
                                  "'Authorization: Bearer TOKEN' or ?token=TOKEN\n",
                                  "text/plain"));
      }
    } else {
      grant_.all = true;
    }
    ws_.emplace(std::move(stream_));
    beast::get_lowest_layer(*ws_).expires_never();
    websocket::stream_base::timeout timeout{};
    timeout.handshake_timeout = server_.limits.request_timeout;
    timeout.idle_timeout = server_.limits.idle_timeout;
    timeout.keep_alive_pings = true;
    ws_->set_option(timeout);
    ws_->read_message_max(server_.limits.max_message_bytes);
    ws_->set_option(websocket::stream_base::decorator([](websocket::response_type& res) {
      res.set(http::field::sec_websocket_protocol, kSubprotocol);
      res.set(http::field::server, std::string("sglc-server ") + kVersion);
    }));
    ++server_.viewers;  // counted from here: the destructor uncounts every connection with ws_
    // open_ (frames may be written) only once the handshake is done: before, Beast would write as a client.
    ws_->async_accept(request, [self = shared_from_this()](beast::error_code e) { self->onAccepted(e); });
  }

  void onAccepted(beast::error_code ec) {
    if (ec) return;
    open_ = true;
    server_.count(kConnections, "accepted");
    server_.demandChanged();
    sendText(Json({{"op", "serverInfo"},
                   {"name", std::string("sglc-server ") + kVersion},
                   {"capabilities", Json::array()},
                   {"supportedEncodings", Json::array()},
                   {"metadata", Json::object()},
                   {"sessionId", std::to_string(id_)}})
                 .dump());
    std::vector<std::uint32_t> ids;
    for (const auto& [id, c] : server_.channels) ids.push_back(id);
    if (!ids.empty()) sendText(server_.advertisement(ids, grant_).dump());
    read();
  }

  void read() {
    ws_->async_read(in_, [self = shared_from_this()](beast::error_code ec, std::size_t) {
      if (ec) {
        self->open_ = false;
        return;
      }
      self->onMessage();
      self->in_.consume(self->in_.size());
      if (self->open_) self->read();
    });
  }

  void status(int level, const std::string& message) {
    // The message may quote a client's text cut anywhere: invalid UTF-8 is replaced, never thrown on.
    sendText(Json({{"op", "status"}, {"level", level}, {"message", message}})
                 .dump(-1, ' ', false, Json::error_handler_t::replace));
  }

  void onMessage() {
    if (!ws_->got_text()) return status(2, "binary messages (client publishing, services) are not supported");
    const auto text = beast::buffers_to_string(in_.data());
    const Json m = Json::parse(text, nullptr, false);
    if (m.is_discarded() || !m.is_object() || !m.contains("op") || !m["op"].is_string())
      return status(2, "a message must be a JSON object with a string 'op'");
    const auto op = m["op"].get<std::string>();
    if (op == "subscribe") return subscribe(m);
    if (op == "unsubscribe") return unsubscribe(m);
    status(1, "unsupported op '" + op.substr(0, 64) + "': this server takes subscribe and unsubscribe");
  }

  static bool isU32(const Json& j) {
    return j.is_number_unsigned() && j.get<std::uint64_t>() <= std::numeric_limits<std::uint32_t>::max();
  }

  void subscribe(const Json& m) {
    if (!m.contains("subscriptions") || !m["subscriptions"].is_array())
      return status(2, "subscribe needs an array 'subscriptions'");
    for (const auto& s : m["subscriptions"]) {
      if (!s.is_object() || !s.contains("id") || !isU32(s["id"]) || !s.contains("channelId") ||
          !isU32(s["channelId"])) {
        status(2, "a subscription needs 'id' and 'channelId', unsigned 32-bit integers");
        continue;
      }
      const auto sub = s["id"].get<std::uint32_t>();
      const auto channel_id = s["channelId"].get<std::uint32_t>();
      const auto c = server_.channels.find(channel_id);
      if (c == server_.channels.end() || !grant_.allows(c->second.map)) {
        status(1, "no channel " + std::to_string(channel_id) + " (gone, or never advertised to you)");
        continue;
      }
      if (subscriptions_.count(sub)) {
        status(2, "subscription id " + std::to_string(sub) + " is in use");
        continue;
      }
      if (subscription_of_.count(channel_id)) {
        status(1, "channel " + std::to_string(channel_id) + " is subscribed already");
        continue;
      }
      subscriptions_[sub] = channel_id;
      subscription_of_[channel_id] = sub;
      if (isKeyframe(channel_id)) server_.demandChanged();
      sendData(c->second);
    }
  }

  void unsubscribe(const Json& m) {
    if (!m.contains("subscriptionIds") || !m["subscriptionIds"].is_array())
      return status(2, "unsubscribe needs an array 'subscriptionIds'");
    for (const auto& s : m["subscriptionIds"]) {
      const auto it = isU32(s) ? subscriptions_.find(s.get<std::uint32_t>()) : subscriptions_.end();
      if (it == subscriptions_.end()) {
        status(1, "no subscription " + s.dump().substr(0, 32));
        continue;
      }
      const bool keyframe = isKeyframe(it->second);
      data_.erase(it->second);
      subscription_of_.erase(it->second);
      subscriptions_.erase(it);
      if (keyframe) server_.demandChanged();
    }
  }

  bool isKeyframe(std::uint32_t channel) const {
    const auto c = server_.channels.find(channel);
    return c != server_.channels.end() && c->second.relative == "keyframe";
  }

  // One write at a time: protocol messages first, then the data waiting, channel after channel.
  void writeNext() {
    if (writing_ || !viewer()) return;
    // A write that does not finish within kWriteTimeout (a viewer that reads nothing but keeps sending, which
    // keeps the idle timeout from firing) drops the viewer.
    write_timer_.expires_after(kWriteTimeout);
    write_timer_.async_wait([weak = weak_from_this()](beast::error_code ec) {
      const auto self = weak.lock();
      if (ec || !self || !self->writing_) return;
      self->server_.count(kConnections, "dropped_slow");
      self->open_ = false;
      self->evict();
    });
    auto done = [self = shared_from_this()](beast::error_code ec, std::size_t) {
      self->writing_ = false;
      self->write_timer_.cancel();
      if (ec) {
        self->open_ = false;
        self->evict();
        return;
      }
      if (self->sent_data_) self->server_.count(kMessages, "sent");
      self->writeNext();
    };
    if (!control_.empty()) {
      text_ = std::move(control_.front());
      control_.pop_front();
      writing_ = true;
      sent_data_ = false;
      ws_->text(true);
      ws_->async_write(asio::buffer(text_), std::move(done));
      return;
    }
    if (data_.empty()) return;
    auto it = data_.upper_bound(cursor_);
    if (it == data_.end()) it = data_.begin();
    cursor_ = it->first;
    in_flight_ = std::move(it->second);
    data_.erase(it);
    header_[0] = 0x01;  // Message Data
    for (int i = 0; i < 4; ++i) header_[1 + i] = static_cast<unsigned char>(in_flight_.subscription >> (8 * i));
    for (int i = 0; i < 8; ++i) header_[5 + i] = static_cast<unsigned char>(in_flight_.stamp_ns >> (8 * i));
    writing_ = true;
    sent_data_ = true;
    ws_->binary(true);
    ws_->async_write(std::array<asio::const_buffer, 2>{asio::buffer(header_), asio::buffer(*in_flight_.payload)},
                     std::move(done));
  }

  void reply(std::string text) {
    out_ = std::move(text);
    stream_.expires_after(kWriteTimeout);
    asio::async_write(stream_, asio::buffer(out_), [self = shared_from_this()](beast::error_code ec, std::size_t) {
      beast::error_code ignored;
      if (!ec) self->stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
    });
  }

  beast::tcp_stream stream_;
  Server& server_;
  const ConnectionSlots::Id id_;
  beast::flat_buffer buffer_{kMaxRequestBytes};
  http::request_parser<http::empty_body> parser_;
  std::string out_;

  std::optional<websocket::stream<beast::tcp_stream>> ws_;
  bool open_ = false;
  TokenTable::Grant grant_;
  beast::flat_buffer in_;
  std::map<std::uint32_t, std::uint32_t> subscriptions_;    // subscription id -> channel
  std::map<std::uint32_t, std::uint32_t> subscription_of_;  // channel -> subscription id
  std::deque<std::string> control_;
  std::map<std::uint32_t, Pending> data_;  // channel -> its newest message not yet sent
  std::uint32_t cursor_ = 0;
  bool writing_ = false, sent_data_ = false;
  std::string text_;
  Pending in_flight_;
  std::array<unsigned char, 13> header_{};
  asio::steady_timer write_timer_;
};

}  // namespace

Json VizServer::Impl::advertisement(const std::vector<std::uint32_t>& ids, const TokenTable::Grant& grant) const {
  Json list = Json::array();
  for (const auto id : ids) {
    const auto& c = channels.at(id);
    if (!grant.allows(c.map)) continue;
    list.push_back({{"id", c.id},
                    {"topic", c.topic},
                    {"encoding", "json"},
                    {"schemaName", c.schema_name},
                    {"schema", posegraph::foxgloveSchema(c.schema_name)},
                    {"schemaEncoding", "jsonschema"}});
  }
  return {{"op", "advertise"}, {"channels", list}};
}

VizServer::Impl::Channel& VizServer::Impl::channel(const std::string& map, const std::string& relative,
                                                   const std::string& schema_name,
                                                   std::vector<std::uint32_t>* advertised) {
  auto& topics = by_map[map];
  if (const auto it = topics.find(relative); it != topics.end()) return channels.at(it->second);
  Channel c;
  c.id = next_channel++;
  c.map = map;
  c.relative = relative;
  c.topic = "/sglc/" + posegraph::topicName(map) + "/" + relative;
  c.schema_name = schema_name;
  topics[relative] = c.id;
  advertised->push_back(c.id);
  return channels[c.id] = std::move(c);
}

void VizServer::Impl::removeChannels(const std::vector<std::uint32_t>& ids) {
  if (ids.empty()) return;
  for (const auto& [cid, weak] : connections) {
    const auto conn = weak.lock();
    if (!conn) continue;
    conn->channelsRemoved(ids);  // also one dropped but not yet gone: its keyframe subscriptions end here
    if (!conn->viewer()) continue;
    Json gone = Json::array();
    for (const auto id : ids)
      if (conn->grant().allows(channels.at(id).map)) gone.push_back(id);
    if (!gone.empty()) conn->sendText(Json({{"op", "unadvertise"}, {"channelIds", gone}}).dump());
  }
  for (const auto id : ids) {
    const auto& c = channels.at(id);
    by_map[c.map].erase(c.relative);
    if (by_map[c.map].empty()) by_map.erase(c.map);
    channels.erase(id);
  }
  demandChanged();
}

void VizServer::Impl::apply(VizUpdate update) {
  if (update.deleted) {
    std::vector<std::uint32_t> ids;
    if (const auto m = by_map.find(update.map); m != by_map.end())
      for (const auto& [relative, id] : m->second) ids.push_back(id);
    removeChannels(ids);
    return;
  }
  std::vector<std::uint32_t> advertised;
  // Every map has its keyframe and events topics from the start: a viewer subscribes before they carry anything.
  channel(update.map, "keyframe", "foxglove.PointCloud", &advertised);
  channel(update.map, "events", "sglc.MapEvent", &advertised);
  if (update.complete) {
    std::set<std::string> present;
    for (const auto& m : update.messages) present.insert(m.topic);
    std::vector<std::uint32_t> gone;
    for (const auto& [relative, id] : by_map[update.map])
      if (relative != "keyframe" && relative != "events" && !present.count(relative)) gone.push_back(id);
    removeChannels(gone);
  }
  std::vector<std::uint32_t> changed;
  for (auto& m : update.messages) {
    auto& c = channel(update.map, m.topic, m.schema_name, &advertised);
    c.payload = std::move(m.payload);
    c.stamp_ns = m.stamp_ns;
    changed.push_back(c.id);
  }
  for (const auto& [cid, weak] : connections) {
    const auto conn = weak.lock();
    if (!conn || !conn->viewer()) continue;
    if (!advertised.empty() && conn->grant().allows(update.map))
      conn->sendText(advertisement(advertised, conn->grant()).dump());
    for (const auto id : changed) conn->sendData(channels.at(id));
  }
}

void VizServer::Impl::demandChanged() {
  VizDemand now{viewers.load(), {}};
  for (const auto& [id, weak] : connections)
    if (const auto conn = weak.lock(); conn && conn->viewer()) conn->keyframeMaps(&now.keyframe_maps);
  if (told_once && now.viewers == told.viewers && now.keyframe_maps == told.keyframe_maps) return;
  told = now;
  told_once = true;
  std::lock_guard lock(listener_mutex);
  if (listener) listener(now);
}

void VizServer::Impl::admit(tcp::socket socket) {
  const bool admitted = admitConnection(slots, connections, std::move(socket), [this](tcp::socket s, auto id) {
    return std::make_shared<Connection>(std::move(s), *this, id);
  });
  if (!admitted) count(kConnections, "refused");
}

VizServer::VizServer(const std::string& address, const TokenTable& tokens, Metrics* metrics, Limits limits)
    : impl_(std::make_unique<Impl>(tokens, metrics, limits)) {
  if (metrics) {  // before the first connection counts
    metrics->counter(kConnections,
                     "Live-view WebSocket connections by result: accepted, unauthenticated, bad_request (no "
                     "foxglove.websocket.v1), refused (no free slot), dropped_slow (too far behind)");
    metrics->counter(kMessages,
                     "Live-view messages to viewers: sent, or skipped (a newer one of the topic came first)");
  }
  impl_->net.start(address, "the live view",
                   [impl = impl_.get()](tcp::socket socket) { impl->admit(std::move(socket)); });
  // After the bind: the gauge reads this server, which must not have failed to start.
  if (metrics)
    metrics->gauge("sglc_viz_viewers", "Live-view WebSocket viewers connected", [impl = impl_.get()] {
      return std::vector<Metrics::Sample>{{{}, static_cast<double>(impl->viewers.load())}};
    });
}

VizServer::~VizServer() { impl_->net.stop(); }

int VizServer::port() const { return impl_->net.port(); }
int VizServer::viewers() const { return impl_->viewers.load(); }

void VizServer::publish(VizUpdate update) {
  asio::post(impl_->net.io, [impl = impl_.get(), u = std::move(update)]() mutable { impl->apply(std::move(u)); });
}

void VizServer::onDemand(std::function<void(const VizDemand&)> listener) {
  {
    std::lock_guard lock(impl_->listener_mutex);
    impl_->listener = std::move(listener);
  }
  // The demand as it is now, to the new listener (viewers may have come before it).
  asio::post(impl_->net.io, [impl = impl_.get()] {
    impl->told_once = false;
    impl->demandChanged();
  });
}

}  // namespace sglc::server
