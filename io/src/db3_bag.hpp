// A rosbag2 SQLite file (.db3) as a Bag (sglc/bag.hpp): tables topics(id, name, type, serialization_format)
// and messages(id, topic_id, timestamp, data), read with the SQLite the project already links.
#pragma once

#include <sqlite3.h>

#include "sglc/bag.hpp"

namespace sglc {

class Db3Bag final : public Bag {
 public:
  explicit Db3Bag(const std::string& path);
  ~Db3Bag() override;
  Db3Bag(const Db3Bag&) = delete;
  Db3Bag& operator=(const Db3Bag&) = delete;
  std::vector<std::uint8_t> read(const BagMessage& m) override;

 private:
  [[noreturn]] void fail(const std::string& what) const;
  sqlite3* db_ = nullptr;
  sqlite3_stmt* read_ = nullptr;
};

}  // namespace sglc
