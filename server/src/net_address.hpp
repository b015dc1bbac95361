// Addresses of the server's small HTTP endpoints (metrics, live view): "host:port" split for the resolver, and
// what one peer is for their per-peer connection limits.
#pragma once

#include <boost/asio/ip/address.hpp>
#include <string>
#include <utility>

namespace sglc::server {

// Splits "host:port" ("[::1]:9090" for IPv6). Throws std::runtime_error naming `what` and the address when there
// is no port or it is not a number 0..65535.
std::pair<std::string, std::string> hostPort(const std::string& address, const std::string& what);

// One peer: an IPv4 address (also when it comes IPv4-mapped), or an IPv6 /64 (what one host or site is given).
std::string peerKey(const boost::asio::ip::address& a);

}  // namespace sglc::server
