#include "db3_bag.hpp"

#include <algorithm>
#include <cstring>
#include <map>

#include "sglc/types.hpp"

namespace sglc {

Db3Bag::Db3Bag(const std::string& path) : Bag(path) {
  if (sqlite3_open_v2(path.c_str(), &db_, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) fail("cannot open");
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT id, name, type, serialization_format FROM topics ORDER BY id", -1, &st,
                         nullptr) != SQLITE_OK)
    fail("not a rosbag2 SQLite file (no topics table)");
  std::map<std::int64_t, std::size_t> ids;
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    auto text = [&](int col) {
      const auto* t = sqlite3_column_text(st, col);
      return t ? std::string(reinterpret_cast<const char*>(t)) : std::string();
    };
    BagTopic t;
    t.name = text(1);
    t.type = text(2);
    const std::string format = text(3);
    if (format == "cdr")
      t.encoding = MessageEncoding::kCdr;
    else
      t.type += " (" + format + ")";
    ids[sqlite3_column_int64(st, 0)] = topics_.size();
    topics_.push_back(t);
  }
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) fail("cannot read its topics");
  if (sqlite3_prepare_v2(db_,
                         "SELECT id, topic_id, timestamp, substr(data, 1, 16), length(data) FROM messages ORDER BY id",
                         -1, &st, nullptr) != SQLITE_OK)
    fail("not a rosbag2 SQLite file (no messages table)");
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    const auto topic = ids.find(sqlite3_column_int64(st, 1));
    if (topic == ids.end())
      fail("message " + std::to_string(sqlite3_column_int64(st, 0)) + " is on topic id " +
           std::to_string(sqlite3_column_int64(st, 1)) + ", which the topics table does not list");
    BagMessage m;
    m.topic = topic->second;
    const auto stamp = sqlite3_column_int64(st, 2);
    m.log_time_ns = stamp < 0 ? 0 : static_cast<std::uint64_t>(stamp);
    m.where = static_cast<std::uint64_t>(sqlite3_column_int64(st, 0));
    m.size = static_cast<std::uint64_t>(std::max<sqlite3_int64>(0, sqlite3_column_int64(st, 4)));
    const int n = sqlite3_column_bytes(st, 3);
    m.head_size = static_cast<std::uint8_t>(std::min(n, 16));
    if (m.head_size) std::memcpy(m.head.data(), sqlite3_column_blob(st, 3), m.head_size);
    ++topics_[m.topic].messages;
    messages_.push_back(m);
  }
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) fail("cannot read its messages (" + std::string(sqlite3_errmsg(db_)) + ")");
  if (sqlite3_prepare_v2(db_, "SELECT data FROM messages WHERE id = ?", -1, &read_, nullptr) != SQLITE_OK)
    fail("cannot prepare reading");
  finish();
}

Db3Bag::~Db3Bag() {
  sqlite3_finalize(read_);
  sqlite3_close(db_);
}

void Db3Bag::fail(const std::string& what) const {
  const std::string why = db_ ? sqlite3_errmsg(db_) : "";
  throw InputError(path_ + ": " + what + (why.empty() || why == "not an error" ? "" : " (" + why + ")"));
}

std::vector<std::uint8_t> Db3Bag::read(const BagMessage& m) {
  sqlite3_reset(read_);
  sqlite3_bind_int64(read_, 1, static_cast<sqlite3_int64>(m.where));
  if (sqlite3_step(read_) != SQLITE_ROW) fail(where(m) + ": gone from the file");
  const auto* p = static_cast<const std::uint8_t*>(sqlite3_column_blob(read_, 0));
  const int n = sqlite3_column_bytes(read_, 0);
  std::vector<std::uint8_t> out(p, p + n);
  sqlite3_reset(read_);
  return out;
}

}  // namespace sglc
