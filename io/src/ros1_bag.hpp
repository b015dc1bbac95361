// A ROS 1 bag (format 2.0: http://wiki.ros.org/Bags/Format/2.0) as a Bag (sglc/bag.hpp): records of
// "name=value" header fields and data, messages inside chunks (uncompressed, bz2 or lz4), read without ROS.
#pragma once

#include <map>

#include "bag_file.hpp"
#include "sglc/bag.hpp"

namespace sglc {

class Ros1Bag final : public Bag {
 public:
  explicit Ros1Bag(const std::string& path);
  std::vector<std::uint8_t> read(const BagMessage& m) override;

 private:
  struct Chunk {
    std::uint64_t offset = 0, size = 0;  // its (compressed) data in the file
    std::uint64_t uncompressed_size = 0;
    std::string compression;
  };
  bool readAt(std::uint64_t offset, void* out, std::size_t n) { return file_.readAt(offset, out, n); }
  // The records in [p, p + n): connections and messages (where: 0 in the file, else the 1-based chunk).
  void records(const std::uint8_t* p, std::size_t n, std::uint64_t base, std::uint64_t where, const std::string& what);
  void record(std::uint8_t op, const std::map<std::string, std::string>& fields, const std::uint8_t* data,
              std::size_t size, std::uint64_t slot, std::uint64_t where, const std::string& what);
  const std::vector<std::uint8_t>& chunk(std::uint64_t index);

  BagFile file_;
  std::uint64_t size_ = 0;                            // file_.size()
  std::map<std::uint32_t, std::size_t> connections_;  // connection id -> topic
  std::vector<Chunk> chunks_;
  std::uint64_t cached_ = 0;
  std::vector<std::uint8_t> cache_, raw_;
};

}  // namespace sglc
