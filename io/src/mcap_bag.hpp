// An MCAP file as a Bag (sglc/bag.hpp).
#pragma once

#include <map>

#include "bag_file.hpp"
#include "sglc/bag.hpp"

namespace sglc {

class McapBag final : public Bag {
 public:
  explicit McapBag(const std::string& path);
  std::vector<std::uint8_t> read(const BagMessage& m) override;

 private:
  struct Schema {
    std::string name, encoding;
  };
  struct Chunk {
    std::uint64_t offset = 0, size = 0;  // the (compressed) records in the file
    std::uint64_t uncompressed_size = 0;
    std::uint32_t crc = 0;
    std::string compression;
    bool checked = false;  // its CRC was checked once
  };
  bool readAt(std::uint64_t offset, void* out, std::size_t n) { return file_.readAt(offset, out, n); }
  std::vector<std::uint8_t> recordAt(std::uint64_t offset, std::uint64_t n, const char* what);
  void scan();
  void definition(std::uint8_t op, const std::uint8_t* p, std::size_t n, const std::string& where);
  void addMessage(const std::uint8_t* m, std::size_t n, std::uint64_t where, std::uint64_t slot, std::uint64_t size,
                  const std::string& what);
  void chunk(std::uint64_t at, std::uint64_t body, std::uint64_t len);
  const std::vector<std::uint8_t>& records(std::uint64_t index);  // chunk `index` (1-based), decompressed, checked

  BagFile file_;
  std::uint64_t size_ = 0;  // file_.size()
  std::map<std::uint16_t, Schema> schemas_;
  std::map<std::uint16_t, std::size_t> channels_;  // channel id -> topic
  std::vector<Chunk> chunks_;
  std::uint64_t cached_ = 0;  // the chunk in cache_ (0: none)
  std::vector<std::uint8_t> cache_;
  std::vector<std::uint8_t> raw_;  // the last chunk's compressed records
};

}  // namespace sglc
