#include "sglc/mcap_writer.hpp"

#include <limits>
#include <stdexcept>

namespace sglc {
namespace {

constexpr char kMagic[] = "\x89MCAP0\r\n";
constexpr std::uint8_t kHeader = 0x01, kFooter = 0x02, kSchema = 0x03, kChannel = 0x04, kMessage = 0x05,
                       kStatistics = 0x0B, kDataEnd = 0x0F;

void putLe(std::string& out, std::uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
void putString(std::string& out, std::string_view s) {
  if (s.size() > std::numeric_limits<std::uint32_t>::max()) throw std::length_error("MCAP: string too long");
  putLe(out, s.size(), 4);
  out.append(s);
}

}  // namespace

McapWriter::McapWriter(std::ostream& out, std::string_view profile, std::string_view library) : out_(out) {
  out_.write(kMagic, 8);
  position_ = 8;
  std::string h;
  putString(h, profile);
  putString(h, library);
  record(kHeader, h);
}

void McapWriter::record(std::uint8_t opcode, const std::string& content) {
  std::string head(1, static_cast<char>(opcode));
  putLe(head, content.size(), 8);
  out_.write(head.data(), static_cast<std::streamsize>(head.size()));
  out_.write(content.data(), static_cast<std::streamsize>(content.size()));
  position_ += head.size() + content.size();
}

std::string McapWriter::schemaRecord(std::uint16_t id) const {
  const auto& s = schemas_[id - 1];
  std::string r;
  putLe(r, id, 2);
  putString(r, s.name);
  putString(r, s.encoding);
  putString(r, s.data);  // uint32 length prefix, as the spec's "bytes" of a schema
  return r;
}

std::string McapWriter::channelRecord(std::uint16_t id) const {
  const auto& c = channels_[id - 1];
  std::string r;
  putLe(r, id, 2);
  putLe(r, c.schema, 2);
  putString(r, c.topic);
  putString(r, c.encoding);
  std::string map;
  for (const auto& [k, v] : c.metadata) {
    putString(map, k);
    putString(map, v);
  }
  putString(r, map);  // a map is its byte length, then the pairs
  return r;
}

std::uint16_t McapWriter::addSchema(std::string_view name, std::string_view encoding, std::string_view data) {
  if (finished_ || schemas_.size() >= 0xFFFF) throw std::logic_error("MCAP: cannot add a schema");
  schemas_.push_back({std::string(name), std::string(encoding), std::string(data)});
  const auto id = static_cast<std::uint16_t>(schemas_.size());
  record(kSchema, schemaRecord(id));
  return id;
}

std::uint16_t McapWriter::addChannel(std::uint16_t schema, std::string_view topic, std::string_view message_encoding,
                                     const std::map<std::string, std::string>& metadata) {
  if (finished_ || channels_.size() >= 0xFFFF || schema == 0 || schema > schemas_.size())
    throw std::logic_error("MCAP: cannot add a channel");
  channels_.push_back({schema, std::string(topic), std::string(message_encoding), metadata});
  sequence_.push_back(0);
  const auto id = static_cast<std::uint16_t>(channels_.size());
  record(kChannel, channelRecord(id));
  return id;
}

void McapWriter::addMessage(std::uint16_t channel, std::uint64_t log_time_ns, std::string_view data) {
  if (finished_ || channel == 0 || channel > channels_.size()) throw std::logic_error("MCAP: unknown channel");
  std::string r;
  putLe(r, channel, 2);
  putLe(r, sequence_[channel - 1]++, 4);
  putLe(r, log_time_ns, 8);
  putLe(r, log_time_ns, 8);
  r.append(data);
  record(kMessage, r);
  start_ = messages_ == 0 ? log_time_ns : std::min(start_, log_time_ns);
  end_ = std::max(end_, log_time_ns);
  ++messages_;
  ++per_channel_[channel];
}

void McapWriter::finish() {
  if (finished_) return;
  finished_ = true;
  std::string data_end;
  putLe(data_end, 0, 4);  // no data section CRC
  record(kDataEnd, data_end);
  const std::uint64_t summary_start = position_;
  for (std::uint16_t id = 1; id <= schemas_.size(); ++id) record(kSchema, schemaRecord(id));
  for (std::uint16_t id = 1; id <= channels_.size(); ++id) record(kChannel, channelRecord(id));
  std::string stats;
  putLe(stats, messages_, 8);
  putLe(stats, schemas_.size(), 2);
  putLe(stats, channels_.size(), 4);
  putLe(stats, 0, 4);  // attachments
  putLe(stats, 0, 4);  // metadata
  putLe(stats, 0, 4);  // chunks
  putLe(stats, start_, 8);
  putLe(stats, end_, 8);
  std::string counts;
  for (const auto& [id, n] : per_channel_) {
    putLe(counts, id, 2);
    putLe(counts, n, 8);
  }
  putLe(stats, counts.size(), 4);
  stats += counts;
  record(kStatistics, stats);
  std::string footer;
  putLe(footer, summary_start, 8);
  putLe(footer, 0, 8);  // no summary offsets
  putLe(footer, 0, 4);  // no summary CRC
  record(kFooter, footer);
  out_.write(kMagic, 8);
  out_.flush();
}

}  // namespace sglc
