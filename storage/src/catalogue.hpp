// The catalogue of maps, robots and sessions, held in memory beside each map's descriptor index. Not
// thread-safe by itself: the store's state lock guards it (shared to read, exclusive to change).
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "descriptor_index.hpp"
#include "sglc/storage/map_store.hpp"
#include "sqlite.hpp"

namespace sglc::storage {

// The largest descriptor a map may be created with (and a map file may hold).
constexpr std::int64_t kMaxDescriptorDim = 65536;

struct MapState {
  std::int64_t id = 0;
  std::string name;
  int dim = 0;
  std::int64_t generation = 0;                 // bumped by every scan write; names the index snapshot that matches
  std::int64_t deletions = 0;                  // session and robot deletions since open (MapInfo::deletions)
  std::map<std::string, std::int64_t> robots;  // name -> id
  std::map<std::pair<std::int64_t, std::string>, std::int64_t> sessions;  // (robot id, name) -> id
  std::unique_ptr<DescriptorIndex> index;

  // -2 (matches nothing) for a name the map does not have.
  std::int64_t robotId(const std::string& robot) const;
  // The robot's id; StorageError kNotFound "map '...' has no robot '...'" for a name the map does not have.
  std::int64_t requireRobot(const std::string& robot) const;
  std::int64_t sessionId(std::int64_t robot_id, const std::string& session) const;
  // The session's id; StorageError kNotFound for a robot or session the map does not have.
  std::int64_t requireSession(const std::string& robot, const std::string& session) const;
  MapInfo info() const;
};

// The wall clock in seconds (created_at columns).
double nowSeconds();

// Throws StorageError kInvalidArgument ("<what> name ...") unless `name` follows the name rule (sglc/names.hpp).
void checkName(const std::string& what, const std::string& name);

class Catalogue {
 public:
  // Reads maps, robots and sessions from the database; each map gets an empty index of its dimension.
  void load(const sql::Db& db, const IndexOptions& index_options);

  // Throws StorageError kNotFound "no map named ..." for an unknown name.
  const MapState& map(const std::string& name) const;
  MapState& map(const std::string& name) { return const_cast<MapState&>(std::as_const(*this).map(name)); }
  const MapState* find(const std::string& name) const;
  // The name of map `id` ("" if there is none).
  std::string nameOf(std::int64_t id) const;
  MapState& add(MapState state);
  void remove(const std::string& name);

  // Every map's MapInfo, in name order; one map's, if there is one of that name.
  std::vector<MapInfo> infos() const;
  std::optional<MapInfo> info(const std::string& name) const;
  // Adds maps, robots, sessions and index entries of `map` (all maps when empty) to `s`; returns the map's id,
  // -1 for all (kNotFound for an unknown name).
  std::int64_t count(const std::string& map, Stats& s) const;

  const std::map<std::string, MapState>& maps() const { return maps_; }
  std::map<std::string, MapState>& maps() { return maps_; }

 private:
  std::map<std::string, MapState> maps_;
  std::map<std::int64_t, std::string> names_;  // id -> name
};

}  // namespace sglc::storage
