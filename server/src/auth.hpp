// Bearer-token authorisation: a token file lists tokens and the maps each may use.
#pragma once

#include <grpcpp/grpcpp.h>

#include <map>
#include <optional>
#include <set>
#include <string>

namespace sglc::server {

class TokenTable {
 public:
  // No file: every call is allowed. File format: one token per line, `TOKEN map1,map2` or `TOKEN *`
  // ('#' starts a comment). In a map name, "%XX" (two hex digits) is the byte 0xXX, so that any map can be
  // named: "%2C" for ',', "%23" for '#', "%20" for a space, "%25" for '%', "%2A" for a map named "*"; any other
  // '%' is itself. Throws std::runtime_error naming the line on a malformed file or a name no map can have.
  static TokenTable load(const std::string& path);
  bool enabled() const { return enabled_; }

  // The caller's grant, from its `authorization: Bearer TOKEN` metadata. Throws RpcError(UNAUTHENTICATED).
  struct Grant {
    bool all = false;
    const std::set<std::string>* maps = nullptr;
    bool allows(const std::string& map) const { return all || (maps && maps->count(map)); }
  };
  Grant authenticate(const grpc::ServerContextBase& ctx) const;
  // The grant of a token (what authenticate does once it has the token). Throws RpcError(UNAUTHENTICATED).
  Grant grantOf(const std::string& token) const;
  // Throws RpcError(PERMISSION_DENIED) unless the grant covers the map ("" = the whole database).
  static void require(const Grant& grant, const std::string& map);

 private:
  bool enabled_ = false;
  // A grant's mark for every map: not a name any map can have (a control character), unlike "*".
  static constexpr const char* kAllMaps = "\x01*";
  std::map<std::string, std::set<std::string>> tokens_;  // token -> maps (kAllMaps = all)
};

}  // namespace sglc::server
