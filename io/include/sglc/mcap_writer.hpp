// Writing an MCAP file (https://mcap.dev/spec): schemas, channels and messages in one uncompressed data section,
// followed by a summary (every schema and channel again, and statistics) so that readers which seek (Foxglove,
// @mcap/core's indexed reader) find them without reading the whole file. No chunks and no message index: it
// is for exports of a few megabytes, not for recording.
#pragma once

#include <cstdint>
#include <map>
#include <ostream>
#include <string>
#include <string_view>
#include <vector>

namespace sglc {

class McapWriter {
 public:
  // Writes the magic and the header record.
  McapWriter(std::ostream& out, std::string_view profile, std::string_view library);
  // Ids count from 1. `data` is the schema's text (e.g. a JSON Schema for encoding "jsonschema").
  std::uint16_t addSchema(std::string_view name, std::string_view encoding, std::string_view data);
  std::uint16_t addChannel(std::uint16_t schema, std::string_view topic, std::string_view message_encoding,
                           const std::map<std::string, std::string>& metadata = {});
  // log_time and publish_time in nanoseconds.
  void addMessage(std::uint16_t channel, std::uint64_t log_time_ns, std::string_view data);
  // The data end, the summary, the footer and the closing magic. Nothing may be added afterwards.
  void finish();

 private:
  struct Schema {
    std::string name, encoding, data;
  };
  struct Channel {
    std::uint16_t schema;
    std::string topic, encoding;
    std::map<std::string, std::string> metadata;
  };
  void record(std::uint8_t opcode, const std::string& content);
  std::string schemaRecord(std::uint16_t id) const;
  std::string channelRecord(std::uint16_t id) const;

  std::ostream& out_;
  std::uint64_t position_ = 0;
  std::vector<Schema> schemas_;
  std::vector<Channel> channels_;
  std::map<std::uint16_t, std::uint64_t> per_channel_;
  std::vector<std::uint32_t> sequence_;
  std::uint64_t messages_ = 0, start_ = 0, end_ = 0;
  bool finished_ = false;
};

}  // namespace sglc
