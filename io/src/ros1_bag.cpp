#include "ros1_bag.hpp"

#include <algorithm>
#include <cstring>

#include "byte_cursor.hpp"
#include "decompress.hpp"

namespace sglc {
namespace {

constexpr char kMagic[] = "#ROSBAG V2.0\n";
constexpr std::size_t kMagicSize = sizeof(kMagic) - 1;
constexpr std::uint64_t kMaxChunkBytes = 1ull << 31;
constexpr std::uint64_t kMaxHeaderBytes = 1u << 20;

enum Op : std::uint8_t {
  kMessage = 0x02,
  kBagHeader = 0x03,
  kIndex = 0x04,
  kChunk = 0x05,
  kChunkInfo = 0x06,
  kConnection = 0x07
};

// "name=value" fields, each with a uint32 length.
std::map<std::string, std::string> fieldsOf(const std::uint8_t* p, std::size_t n, const std::string& what) {
  std::map<std::string, std::string> out;
  ByteCursor c(p, n, what);
  while (c.left() > 0) {
    const std::string f = c.str("header field");
    const auto eq = f.find('=');
    if (eq == std::string::npos) throw InputError(what + ": a header field without '='");
    out[f.substr(0, eq)] = f.substr(eq + 1);
  }
  return out;
}

template <typename T>
T fieldValue(const std::map<std::string, std::string>& fields, const char* name, const std::string& what) {
  const auto it = fields.find(name);
  if (it == fields.end() || it->second.size() != sizeof(T))
    throw InputError(what + ": header field '" + name + "' is missing or not " + std::to_string(sizeof(T)) + " bytes");
  T v;
  std::memcpy(&v, it->second.data(), sizeof(T));
  return v;
}

// ROS 1 names types pkg/Name; the readers name them as ROS 2 does (pkg/msg/Name).
std::string ros2Name(const std::string& type) {
  const auto slash = type.find('/');
  if (slash == std::string::npos || type.find("/msg/") != std::string::npos) return type;
  return type.substr(0, slash) + "/msg" + type.substr(slash);
}

}  // namespace

Ros1Bag::Ros1Bag(const std::string& path) : Bag(path), file_(path), size_(file_.size()) {
  char magic[kMagicSize];
  if (!readAt(0, magic, kMagicSize) || std::memcmp(magic, kMagic, kMagicSize) != 0)
    throw InputError(path + ": not a ROS 1 bag of format 2.0 (no '#ROSBAG V2.0' line at its start)");
  // The file's records one by one; chunks decompressed for their connections and messages.
  std::uint64_t at = kMagicSize;
  std::vector<std::uint8_t> header;
  while (at < size_) {
    const std::string what = path + ": record at byte " + std::to_string(at);
    std::uint32_t header_len = 0, data_len = 0;
    if (!readAt(at, &header_len, 4) || header_len > kMaxHeaderBytes || header_len > size_ - at - 4)
      throw InputError(what + ": its header runs past the end of the file (truncated or corrupt)");
    header.resize(header_len);
    if (!readAt(at + 4, header.data(), header_len) || !readAt(at + 4 + header_len, &data_len, 4))
      throw InputError(what + ": truncated");
    const std::uint64_t data_at = at + 8 + header_len;
    if (data_len > size_ - data_at) throw InputError(what + ": its data runs past the end of the file (truncated)");
    const auto fields = fieldsOf(header.data(), header.size(), what);
    const auto op = fieldValue<std::uint8_t>(fields, "op", what);
    if (op == kChunk) {
      Chunk k;
      k.offset = data_at;
      k.size = data_len;
      k.compression = fields.count("compression") ? fields.at("compression") : "";
      k.uncompressed_size = fieldValue<std::uint32_t>(fields, "size", what);
      if (k.compression != "none" && k.compression != "bz2" && k.compression != "lz4")
        throw InputError(what + ": chunk compression '" + k.compression + "'; this reader takes none, bz2 or lz4");
      if (k.uncompressed_size > kMaxChunkBytes) throw InputError(what + ": chunk claims more than 2 GiB");
      // At most 256 times its compressed size (small chunks excepted): memory is never claimed on a word alone.
      if (k.compression != "none" && k.uncompressed_size > std::max<std::uint64_t>(64ull << 20, 256 * k.size))
        throw InputError(what + ": chunk claims " + std::to_string(k.uncompressed_size) + " bytes from " +
                         std::to_string(k.size) + " compressed (a decompression bomb, or corrupt)");
      chunks_.push_back(k);
      const auto& recs = chunk(chunks_.size());
      records(recs.data(), recs.size(), 0, chunks_.size(), what + " (chunk)");
    } else if (op == kConnection || op == kMessage) {
      std::vector<std::uint8_t> data(data_len);
      if (!readAt(data_at, data.data(), data_len)) throw InputError(what + ": truncated");
      record(op, fields, data.data(), data.size(), data_at, 0, what);
    }
    at = data_at + data_len;
  }
  finish();
}

void Ros1Bag::records(const std::uint8_t* p, std::size_t n, std::uint64_t base, std::uint64_t where,
                      const std::string& what) {
  ByteCursor c(p, n, what);
  while (c.left() > 0) {
    const std::string inner = what + ", record at offset " + std::to_string(c.at());
    const auto header_len = c.le<std::uint32_t>("record header length");
    c.need(header_len, "record header");
    const auto fields = fieldsOf(c.here(), header_len, inner);
    c.skip(header_len, "record header");
    const auto data_len = c.le<std::uint32_t>("record data length");
    c.need(data_len, "record data");
    record(fieldValue<std::uint8_t>(fields, "op", inner), fields, c.here(), data_len, base + c.at(), where, inner);
    c.skip(data_len, "record data");
  }
}

void Ros1Bag::record(std::uint8_t op, const std::map<std::string, std::string>& fields, const std::uint8_t* data,
                     std::size_t size, std::uint64_t slot, std::uint64_t where, const std::string& what) {
  const auto conn = fieldValue<std::uint32_t>(fields, "conn", what);
  if (op == kConnection) {
    if (connections_.count(conn)) return;  // repeated in every chunk that uses it, and in the index
    const auto topic = fields.find("topic");
    if (topic == fields.end()) throw InputError(what + ": connection without a topic");
    const auto meta = fieldsOf(data, size, what + " (connection header)");
    BagTopic t;
    t.name = topic->second;
    t.type = meta.count("type") ? ros2Name(meta.at("type")) : "";
    t.encoding = MessageEncoding::kRos1;
    const auto same = std::find_if(topics_.begin(), topics_.end(), [&](const BagTopic& o) { return o.name == t.name; });
    connections_[conn] = same != topics_.end() ? static_cast<std::size_t>(same - topics_.begin()) : topics_.size();
    if (same == topics_.end()) topics_.push_back(t);
    return;
  }
  const auto c = connections_.find(conn);
  if (c == connections_.end())
    throw InputError(what + ": a message on connection " + std::to_string(conn) +
                     ", which no connection record defines");
  const auto time = fieldValue<std::uint64_t>(fields, "time", what);  // uint32 sec, then uint32 nsec
  BagMessage m;
  m.topic = c->second;
  m.log_time_ns = (time & 0xffffffffULL) * 1000000000ULL + (time >> 32);
  m.where = where;
  m.slot = slot;
  m.size = size;
  m.head_size = static_cast<std::uint8_t>(std::min<std::size_t>(size, 16));
  std::memcpy(m.head.data(), data, m.head_size);
  ++topics_[m.topic].messages;
  messages_.push_back(m);
}

const std::vector<std::uint8_t>& Ros1Bag::chunk(std::uint64_t index) {
  if (cached_ == index) return cache_;
  const Chunk& k = chunks_.at(index - 1);
  const std::string what = path_ + ": chunk at byte " + std::to_string(k.offset);
  cached_ = 0;
  if (k.size > raw_.size()) raw_.resize(k.size);
  if (!readAt(k.offset, raw_.data(), k.size)) throw InputError(what + ": truncated");
  cache_.resize(k.uncompressed_size);
  if (k.compression == "none") {
    if (k.size != k.uncompressed_size)
      throw InputError(what + ": " + std::to_string(k.size) + " bytes, the chunk says " +
                       std::to_string(k.uncompressed_size));
    std::copy(raw_.begin(), raw_.begin() + static_cast<std::ptrdiff_t>(k.size), cache_.begin());
  } else if (k.compression == "bz2") {
    bzip2(raw_.data(), k.size, cache_, what);
  } else {
    lz4Frame(raw_.data(), k.size, cache_, what);
  }
  cached_ = index;
  return cache_;
}

std::vector<std::uint8_t> Ros1Bag::read(const BagMessage& m) {
  if (m.where == 0) {
    std::vector<std::uint8_t> out(m.size);
    if (!readAt(m.slot, out.data(), m.size)) throw InputError(where(m) + ": runs past the end of the file");
    return out;
  }
  const auto& recs = chunk(m.where);
  if (m.slot > recs.size() || m.size > recs.size() - m.slot) throw InputError(where(m) + ": outside its chunk");
  return {recs.begin() + static_cast<std::ptrdiff_t>(m.slot),
          recs.begin() + static_cast<std::ptrdiff_t>(m.slot + m.size)};
}

}  // namespace sglc
