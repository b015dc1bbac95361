#include "auth.hpp"

#include <fstream>
#include <sstream>

#include "rpc_error.hpp"
#include "sglc/names.hpp"

namespace sglc::server {

TokenTable TokenTable::load(const std::string& path) {
  TokenTable table;
  if (path.empty()) return table;
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot read token file");
  table.enabled_ = true;
  std::string line;
  int no = 0;
  while (std::getline(in, line)) {
    ++no;
    const std::string where = path + ":" + std::to_string(no);
    if (auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    std::istringstream ss(line);
    std::string token, maps, extra;
    if (!(ss >> token)) continue;
    if (!(ss >> maps) || (ss >> extra)) throw std::runtime_error(where + ": expected 'TOKEN map1,map2' or 'TOKEN *'");
    if (token.size() < 8) throw std::runtime_error(where + ": token shorter than 8 characters");
    auto& set = table.tokens_[token];
    std::istringstream ms(maps);
    std::string map;
    while (std::getline(ms, map, ',')) {
      if (map.empty()) continue;
      if (map == "*") {
        set.insert(kAllMaps);
        continue;
      }
      map = percentDecoded(map);  // "%2C" a comma, "%23" a '#', "%2A" a map named "*"
      if (const auto why = nameError(map))
        throw std::runtime_error(where + ": map name '" + maps.substr(0, 80) + "' " + *why);
      set.insert(map);
    }
  }
  if (table.tokens_.empty()) throw std::runtime_error(path + ": no tokens");
  return table;
}

TokenTable::Grant TokenTable::grantOf(const std::string& token) const {
  auto t = tokens_.find(token);
  if (t == tokens_.end()) throw RpcError(grpc::StatusCode::UNAUTHENTICATED, "unknown token");
  Grant grant;
  grant.all = t->second.count(kAllMaps) > 0;
  grant.maps = &t->second;
  return grant;
}

TokenTable::Grant TokenTable::authenticate(const grpc::ServerContextBase& ctx) const {
  Grant grant;
  if (!enabled_) {
    grant.all = true;
    return grant;
  }
  const auto& md = ctx.client_metadata();
  auto it = md.find("authorization");
  if (it == md.end())
    throw RpcError(grpc::StatusCode::UNAUTHENTICATED, "missing 'authorization: Bearer TOKEN' metadata");
  const std::string value(it->second.data(), it->second.size());
  const std::string prefix = "Bearer ";
  if (value.rfind(prefix, 0) != 0)
    throw RpcError(grpc::StatusCode::UNAUTHENTICATED, "authorization metadata must be 'Bearer TOKEN'");
  return grantOf(value.substr(prefix.size()));
}

void TokenTable::require(const Grant& grant, const std::string& map) {
  if (map.empty() ? grant.all : grant.allows(map)) return;
  throw RpcError(grpc::StatusCode::PERMISSION_DENIED,
                 map.empty() ? "this token is limited to some maps; the call needs access to all"
                             : "this token is not allowed on map '" + map + "'");
}

}  // namespace sglc::server
