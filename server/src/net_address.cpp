#include "net_address.hpp"

#include <algorithm>
#include <stdexcept>

namespace sglc::server {

std::pair<std::string, std::string> hostPort(const std::string& address, const std::string& what) {
  const auto colon = address.rfind(':');
  if (colon == std::string::npos || colon + 1 == address.size())
    throw std::runtime_error(what + " address '" + address + "' is not host:port");
  const std::string port = address.substr(colon + 1);
  if (port.size() > 5 || port.find_first_not_of("0123456789") != std::string::npos || std::stoi(port) > 65535)
    throw std::runtime_error(what + " address '" + address + "': port must be a number 0..65535");
  std::string host = address.substr(0, colon);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  return {host, port};
}

int listenOn(boost::asio::ip::tcp::acceptor& acceptor, const std::string& address, const std::string& what) {
  namespace asio = boost::asio;
  using tcp = asio::ip::tcp;
  const auto [host, service] = hostPort(address, what);
  boost::system::error_code ec;
  tcp::resolver resolver(acceptor.get_executor());
  const auto found = resolver.resolve(host, service, tcp::resolver::passive | tcp::resolver::numeric_service, ec);
  if (ec) throw std::runtime_error(what + " address '" + address + "': " + ec.message());
  std::string why = "no address";
  for (const auto& entry : found) {
    boost::system::error_code failed;
    acceptor.open(entry.endpoint().protocol(), failed);
    if (!failed) acceptor.set_option(asio::socket_base::reuse_address(true), failed);
    if (!failed) acceptor.bind(entry.endpoint(), failed);
    if (!failed) acceptor.listen(asio::socket_base::max_listen_connections, failed);
    if (!failed) return acceptor.local_endpoint().port();
    why = failed.message();
    acceptor.close(failed);
  }
  throw std::runtime_error("cannot serve " + what + " on " + address + ": " + why);
}

void acceptForever(boost::asio::ip::tcp::acceptor& acceptor, boost::asio::steady_timer& backoff,
                   std::function<void(boost::asio::ip::tcp::socket)> admit) {
  namespace asio = boost::asio;
  acceptor.async_accept([&acceptor, &backoff, admit = std::move(admit)](boost::system::error_code ec,
                                                                        asio::ip::tcp::socket socket) mutable {
    if (ec == asio::error::operation_aborted) return;
    if (ec) {
      backoff.expires_after(std::chrono::milliseconds(100));
      backoff.async_wait([&acceptor, &backoff, admit = std::move(admit)](boost::system::error_code e) mutable {
        if (!e) acceptForever(acceptor, backoff, std::move(admit));
      });
      return;
    }
    try {
      admit(std::move(socket));
    } catch (const std::exception&) {
      // Out of memory for this connection: it is closed; accepting goes on.
    }
    acceptForever(acceptor, backoff, std::move(admit));
  });
}

std::thread runIo(boost::asio::io_context& io) {
  return std::thread([&io] {
    for (;;) {
      try {
        io.run();
        return;
      } catch (const std::exception&) {
        // A handler failed (out of memory): its connection is dropped, the others go on.
      }
    }
  });
}

std::string peerKey(const boost::asio::ip::address& a) {
  namespace ip = boost::asio::ip;
  if (!a.is_v6()) return a.to_string();
  const auto v6 = a.to_v6();
  if (v6.is_v4_mapped()) return ip::make_address_v4(ip::v4_mapped, v6).to_string();
  auto bytes = v6.to_bytes();
  std::fill(bytes.begin() + 8, bytes.end(), 0);
  return ip::address_v6(bytes).to_string() + "/64";
}

}  // namespace sglc::server
