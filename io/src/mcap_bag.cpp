// MCAP (https://mcap.dev/spec) read without an MCAP library (none is packaged for Debian 12): a linear scan of
// the data section, chunks decompressed with Debian's libzstd and liblz4 and checked against their CRC-32.
#include "mcap_bag.hpp"

#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <map>

#include "byte_cursor.hpp"
#include "decompress.hpp"

namespace sglc {
namespace {

constexpr std::uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};
constexpr std::uint64_t kMaxChunkBytes = 1ull << 31;   // a chunk's records, uncompressed
constexpr std::uint64_t kMaxRecordBytes = 1ull << 31;  // any record read whole (schema, channel, chunk)
// A chunk may expand this much at most (LiDAR data compresses 1-3 times; all-zero data far more, so small chunks
// up to kPlainChunkBytes are taken whatever their ratio): memory is never claimed on a header's word alone.
constexpr std::uint64_t kMaxRatio = 256;
constexpr std::uint64_t kPlainChunkBytes = 64ull << 20;

enum Op : std::uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kDataEnd = 0x0F,
};

std::uint32_t crc32Of(const std::vector<std::uint8_t>& bytes) {
  uLong crc = crc32(0L, Z_NULL, 0);
  std::size_t done = 0;
  while (done < bytes.size()) {
    const auto n = static_cast<uInt>(std::min<std::size_t>(bytes.size() - done, 1u << 30));
    crc = crc32(crc, bytes.data() + done, n);
    done += n;
  }
  return static_cast<std::uint32_t>(crc);
}

}  // namespace

McapBag::McapBag(const std::string& path) : Bag(path), file_(path), size_(file_.size()) {
  std::uint8_t magic[8];
  if (size_ < 8 || !readAt(0, magic, 8) || std::memcmp(magic, kMagic, 8) != 0)
    throw InputError(path + ": not an MCAP file (no MCAP magic at its start)");
  scan();
  finish();
}

std::vector<std::uint8_t> McapBag::recordAt(std::uint64_t offset, std::uint64_t n, const char* what) {
  if (n > kMaxRecordBytes)
    throw InputError(path_ + ": " + what + " record at byte " + std::to_string(offset) + " claims " +
                     std::to_string(n) + " bytes (more than 2 GiB)");
  std::vector<std::uint8_t> bytes(n);
  if (!readAt(offset, bytes.data(), n))
    throw InputError(path_ + ": " + what + " record at byte " + std::to_string(offset) +
                     " runs past the end of the file");
  return bytes;
}

void McapBag::scan() {
  std::uint64_t at = 8;
  bool ended = false;
  while (!ended) {
    std::uint8_t head[9];
    if (!readAt(at, head, 9))
      throw InputError(path_ + ": truncated at byte " + std::to_string(at) +
                       " (no footer: the recording did not finish)");
    std::uint64_t len;
    std::memcpy(&len, head + 1, 8);
    const std::uint64_t body = at + 9;
    if (len > size_ - body)
      throw InputError(path_ + ": record at byte " + std::to_string(at) + " claims " + std::to_string(len) +
                       " bytes, past the end of the file (truncated or corrupt)");
    switch (head[0]) {
      case kSchema:
      case kChannel: {
        const auto bytes = recordAt(body, len, head[0] == kSchema ? "schema" : "channel");
        definition(head[0], bytes.data(), bytes.size(), "record at byte " + std::to_string(at));
        break;
      }
      case kMessage: {
        std::uint8_t m[22 + 16];
        const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(len, sizeof m));
        if (n < 22 || !readAt(body, m, n))
          throw InputError(path_ + ": message record at byte " + std::to_string(at) + " is too short");
        addMessage(m, n, 0, body + 22, len - 22, "message record at byte " + std::to_string(at));
        break;
      }
      case kChunk:
        chunk(at, body, len);
        break;
      case kFooter:
      case kDataEnd:
        ended = true;
        break;
      default:
        break;  // header, indexes, attachments, metadata, statistics: not needed to read messages
    }
    at = body + len;
  }
}

void McapBag::definition(std::uint8_t op, const std::uint8_t* p, std::size_t n, const std::string& where) {
  ByteCursor c(p, n, path_ + ": " + where);
  if (op == kSchema) {
    const auto id = c.le<std::uint16_t>("schema id");
    Schema s;
    s.name = c.str("schema name");
    s.encoding = c.str("schema encoding");
    if (id != 0) schemas_[id] = s;
    return;
  }
  const auto id = c.le<std::uint16_t>("channel id");
  const auto schema = c.le<std::uint16_t>("channel schema id");
  const std::string topic = c.str("channel topic");
  const std::string encoding = c.str("channel message encoding");
  if (channels_.count(id)) return;  // repeated in the summary or in later chunks
  const auto s = schemas_.find(schema);
  BagTopic t;
  t.name = topic;
  t.type = s == schemas_.end() ? "" : s->second.name;
  if (encoding == "cdr")
    t.encoding = MessageEncoding::kCdr;
  else if (encoding == "ros1")
    t.encoding = MessageEncoding::kRos1;
  else
    t.type = t.type + " (" + encoding + ")";  // neither ROS encoding: listed, refused when read as a ROS message
  // Two channels on one topic (two recorders) share the topic.
  const auto same = std::find_if(topics_.begin(), topics_.end(), [&](const BagTopic& o) { return o.name == topic; });
  if (same != topics_.end()) {
    channels_[id] = static_cast<std::size_t>(same - topics_.begin());
    return;
  }
  channels_[id] = topics_.size();
  topics_.push_back(t);
}

void McapBag::addMessage(const std::uint8_t* m, std::size_t n, std::uint64_t where, std::uint64_t slot,
                         std::uint64_t size, const std::string& what) {
  ByteCursor c(m, n, path_ + ": " + what);
  const auto channel = c.le<std::uint16_t>("channel id");
  c.skip(4, "sequence");
  const auto log_time = c.le<std::uint64_t>("log time");
  c.skip(8, "publish time");
  const auto ch = channels_.find(channel);
  if (ch == channels_.end())
    throw InputError(path_ + ": " + what + " is on channel " + std::to_string(channel) +
                     ", which no channel record defines");
  BagMessage msg;
  msg.topic = ch->second;
  msg.log_time_ns = log_time;
  msg.where = where;
  msg.slot = slot;
  msg.size = size;
  msg.head_size = static_cast<std::uint8_t>(std::min<std::uint64_t>(size, std::min<std::size_t>(c.left(), 16)));
  std::memcpy(msg.head.data(), c.here(), msg.head_size);
  ++topics_[msg.topic].messages;
  messages_.push_back(msg);
}

void McapBag::chunk(std::uint64_t at, std::uint64_t body, std::uint64_t len) {
  const std::string what = "chunk at byte " + std::to_string(at);
  // The fixed fields and the compression name: at most 8 * 3 + 4 + 4 + name + 8 bytes before the records.
  std::uint8_t fixed[28 + 4];
  if (len < sizeof fixed || !readAt(body, fixed, sizeof fixed)) throw InputError(path_ + ": " + what + " is too short");
  ByteCursor c(fixed, sizeof fixed, path_ + ": " + what);
  c.skip(16, "message times");
  Chunk k;
  k.uncompressed_size = c.le<std::uint64_t>("uncompressed size");
  k.crc = c.le<std::uint32_t>("uncompressed crc");
  const auto name_len = c.le<std::uint32_t>("compression");
  if (name_len > 64 || 32 + name_len + 8 > len)
    throw InputError(path_ + ": " + what + ": its compression name is corrupt");
  k.compression.resize(name_len);
  std::uint64_t records_len = 0;
  if (!readAt(body + 32, k.compression.data(), name_len) || !readAt(body + 32 + name_len, &records_len, 8))
    throw InputError(path_ + ": " + what + " is truncated");
  k.offset = body + 32 + name_len + 8;
  k.size = records_len;
  if (records_len > len - (32 + name_len + 8))
    throw InputError(path_ + ": " + what + ": its records claim " + std::to_string(records_len) +
                     " bytes, more than the chunk holds");
  if (k.compression != "" && k.compression != "zstd" && k.compression != "lz4")
    throw InputError(path_ + ": " + what + " uses compression '" + k.compression +
                     "'; this reader takes zstd, lz4 or none");
  if (k.uncompressed_size > kMaxChunkBytes)
    throw InputError(path_ + ": " + what + " claims " + std::to_string(k.uncompressed_size) +
                     " bytes uncompressed (more than 2 GiB)");
  if (!k.compression.empty() && k.uncompressed_size > std::max<std::uint64_t>(kPlainChunkBytes, kMaxRatio * k.size))
    throw InputError(path_ + ": " + what + " claims " + std::to_string(k.uncompressed_size) + " bytes from " +
                     std::to_string(k.size) + " compressed (more than " + std::to_string(kMaxRatio) +
                     " times: a decompression bomb, or corrupt)");
  chunks_.push_back(k);
  const std::uint64_t index = chunks_.size();  // BagMessage::where: 1-based chunk, 0 for a message outside chunks
  const auto& recs = records(index);
  ByteCursor r(recs.data(), recs.size(), path_ + ": " + what);
  while (r.left() > 0) {
    const auto op = r.le<std::uint8_t>("record opcode");
    const auto n = r.le<std::uint64_t>("record length");
    r.need(n, "record");
    const std::string inner = what + ", record at offset " + std::to_string(r.at() - 9);
    if (op == kSchema || op == kChannel) definition(op, r.here(), n, inner);
    if (op == kMessage) {
      if (n < 22) throw InputError(path_ + ": " + inner + ": message record is too short");
      addMessage(r.here(), static_cast<std::size_t>(std::min<std::uint64_t>(n, 22 + 16)), index, r.at() + 22, n - 22,
                 inner);
    }
    r.skip(n, "record");
  }
}

const std::vector<std::uint8_t>& McapBag::records(std::uint64_t index) {
  if (cached_ == index) return cache_;
  Chunk& k = chunks_.at(index - 1);
  const std::string what =
      path_ + ": chunk " + std::to_string(index) + " (records at byte " + std::to_string(k.offset) + ")";
  cached_ = 0;
  // The buffers are reused from chunk to chunk: no allocation, and no zeroing, once they are large enough.
  if (k.size > raw_.size()) raw_.resize(k.size);
  if (!readAt(k.offset, raw_.data(), k.size)) throw InputError(what + ": runs past the end of the file");
  cache_.resize(k.uncompressed_size);
  if (k.compression.empty()) {
    if (k.size != k.uncompressed_size)
      throw InputError(what + ": " + std::to_string(k.size) + " bytes of records, the chunk says " +
                       std::to_string(k.uncompressed_size));
    std::copy(raw_.begin(), raw_.begin() + static_cast<std::ptrdiff_t>(k.size), cache_.begin());
  } else if (k.compression == "zstd") {
    const std::size_t got = ZSTD_decompress(cache_.data(), cache_.size(), raw_.data(), k.size);
    if (ZSTD_isError(got)) throw InputError(what + ": zstd data is corrupt (" + ZSTD_getErrorName(got) + ")");
    if (got != k.uncompressed_size)
      throw InputError(what + ": zstd data gives " + std::to_string(got) + " bytes, the chunk says " +
                       std::to_string(k.uncompressed_size));
  } else {
    lz4Frame(raw_.data(), k.size, cache_, what);
  }
  // The CRC is checked the first time a chunk is decompressed (when the bag is opened); the same bytes read
  // again later are not checked twice.
  if (!k.checked) {
    if (k.crc != 0 && crc32Of(cache_) != k.crc) throw InputError(what + ": CRC mismatch (the records are corrupt)");
    k.checked = true;
  }
  cached_ = index;
  return cache_;
}

std::vector<std::uint8_t> McapBag::read(const BagMessage& m) {
  if (m.where == 0) return recordAt(m.slot, m.size, "message");
  const auto& records = this->records(m.where);
  if (m.slot > records.size() || m.size > records.size() - m.slot) throw InputError(where(m) + ": outside its chunk");
  return {records.begin() + static_cast<std::ptrdiff_t>(m.slot),
          records.begin() + static_cast<std::ptrdiff_t>(m.slot + m.size)};
}

}  // namespace sglc
