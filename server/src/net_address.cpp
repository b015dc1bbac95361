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
