#include "catalogue.hpp"

#include "sglc/names.hpp"

namespace sglc::storage {

void checkName(const std::string& what, const std::string& name) {
  if (const auto error = nameError(name))
    throw StorageError(StorageError::Code::kInvalidArgument, what + " name " + *error);
}

std::int64_t MapState::robotId(const std::string& robot) const {
  const auto it = robots.find(robot);
  return it == robots.end() ? -2 : it->second;
}

std::int64_t MapState::requireRobot(const std::string& robot) const {
  const auto it = robots.find(robot);
  if (it == robots.end())
    throw StorageError(StorageError::Code::kNotFound, "map '" + name + "' has no robot '" + robot + "'");
  return it->second;
}

std::int64_t MapState::sessionId(std::int64_t robot_id, const std::string& session) const {
  const auto it = sessions.find({robot_id, session});
  return it == sessions.end() ? -2 : it->second;
}

std::int64_t MapState::requireSession(const std::string& robot, const std::string& session) const {
  const auto id = sessionId(requireRobot(robot), session);
  if (id < 0)
    throw StorageError(StorageError::Code::kNotFound, "robot '" + robot + "' has no session '" + session + "'");
  return id;
}

MapInfo MapState::info() const {
  MapInfo info;
  info.id = id;
  info.name = name;
  info.descriptor_dim = dim;
  info.scans = index->live();
  info.robots = static_cast<std::int64_t>(robots.size());
  info.sessions = static_cast<std::int64_t>(sessions.size());
  info.deletions = deletions;
  return info;
}

void Catalogue::load(const sql::Db& db, const IndexOptions& index_options) {
  {
    sql::Stmt st(db, "SELECT id, name, descriptor_dim, generation FROM maps ORDER BY id");
    while (st.step()) {
      MapState m;
      m.id = st.i64(0);
      m.name = st.text(1);
      const auto dim = st.i64(2);
      if (dim < 1 || dim > kMaxDescriptorDim)
        throw StorageError(StorageError::Code::kCorrupt, "map '" + m.name + "' has descriptor dimension " +
                                                             std::to_string(dim) + " (1.." +
                                                             std::to_string(kMaxDescriptorDim) + " expected)");
      m.dim = static_cast<int>(dim);
      m.generation = st.i64(3);
      m.index = std::make_unique<DescriptorIndex>(m.dim, index_options);
      add(std::move(m));
    }
  }
  for (auto& [name, m] : maps_) {
    sql::Stmt r(db, "SELECT id, name FROM robots WHERE map_id = ?");
    r.bind(1, m.id);
    while (r.step()) m.robots[r.text(1)] = r.i64(0);
    sql::Stmt s(db,
                "SELECT x.id, x.robot_id, x.name FROM sessions x JOIN robots r ON r.id = x.robot_id"
                " WHERE r.map_id = ?");
    s.bind(1, m.id);
    while (s.step()) m.sessions[{s.i64(1), s.text(2)}] = s.i64(0);
  }
}

std::vector<MapInfo> Catalogue::infos() const {
  std::vector<MapInfo> out;
  for (const auto& [name, m] : maps_) out.push_back(m.info());
  return out;
}

std::optional<MapInfo> Catalogue::info(const std::string& name) const {
  const auto* m = find(name);
  if (!m) return std::nullopt;
  return m->info();
}

std::int64_t Catalogue::count(const std::string& map, Stats& s) const {
  const std::int64_t map_id = map.empty() ? -1 : this->map(map).id;
  s.maps = map.empty() ? static_cast<std::int64_t>(maps_.size()) : 1;
  for (const auto& [name, m] : maps_) {
    if (map_id >= 0 && m.id != map_id) continue;
    s.robots += static_cast<std::int64_t>(m.robots.size());
    s.sessions += static_cast<std::int64_t>(m.sessions.size());
    s.index_entries += m.index->live();
  }
  return map_id;
}

const MapState& Catalogue::map(const std::string& name) const {
  const auto it = maps_.find(name);
  if (it == maps_.end()) throw StorageError(StorageError::Code::kNotFound, "no map named '" + name + "'");
  return it->second;
}

const MapState* Catalogue::find(const std::string& name) const {
  const auto it = maps_.find(name);
  return it == maps_.end() ? nullptr : &it->second;
}

std::string Catalogue::nameOf(std::int64_t id) const {
  const auto it = names_.find(id);
  return it == names_.end() ? std::string() : it->second;
}

MapState& Catalogue::add(MapState state) {
  auto& inserted = maps_[state.name] = std::move(state);
  names_[inserted.id] = inserted.name;
  return inserted;
}

void Catalogue::remove(const std::string& name) {
  const auto it = maps_.find(name);
  if (it == maps_.end()) return;
  names_.erase(it->second.id);
  maps_.erase(it);
}

}  // namespace sglc::storage
