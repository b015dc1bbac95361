// A bag file read at offsets (MCAP and ROS 1 readers): a regular file only (detail::RegularFile refuses
// directories, FIFOs and devices), with reads that say whether the bytes were there.
#pragma once

#include <cstdint>
#include <string>

#include "file_bytes.hpp"

namespace sglc {

class BagFile {
 public:
  explicit BagFile(const std::string& path) : file_(path) {}
  std::uint64_t size() const { return file_.size(); }
  // Reads n bytes at offset into out; false when they are not all in the file.
  bool readAt(std::uint64_t offset, void* out, std::size_t n) const {
    if (offset > file_.size() || n > file_.size() - offset) return false;
    file_.readInto(offset, out, n);
    return true;
  }

 private:
  detail::RegularFile file_;
};

}  // namespace sglc
