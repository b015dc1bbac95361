// Whole-file reads and writes shared by the format readers of sglc_io (internal).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace sglc::detail {

// A file opened for reading that is known to be a regular file: a directory, FIFO, socket or device is refused
// with InputError naming the file (checked with stat before opening, and on the opened descriptor, which is
// opened non-blocking so that a FIFO swapped in between cannot block the open).
class RegularFile {
 public:
  explicit RegularFile(const std::string& path);
  ~RegularFile();
  RegularFile(const RegularFile&) = delete;
  RegularFile& operator=(const RegularFile&) = delete;

  const std::string& path() const { return path_; }
  std::uint64_t size() const { return size_; }
  // `bytes` bytes from `offset`; InputError naming the file on a short or failed read.
  std::vector<char> read(std::uint64_t offset, std::size_t bytes) const;
  std::vector<char> readAll() const { return read(0, static_cast<std::size_t>(size_)); }
  // The same into `out` (no allocation).
  void readInto(std::uint64_t offset, void* out, std::size_t bytes) const;

 private:
  std::string path_;
  int fd_ = -1;
  std::uint64_t size_ = 0;
};

// The scan file limits of sglc/scan_file.hpp: InputError naming the file when it is larger than
// kMaxScanFileBytes, or declares more than kMaxScanPoints points (`source`: where the count comes from, e.g.
// "POINTS in the header").
void checkScanFileSize(const RegularFile& file);
void checkScanPoints(const std::string& path, std::uint64_t points, const std::string& source);

// InputError naming the file unless `path` is a regular file (for readers that open it as a stream).
void requireRegularFile(const std::string& path);

// The file's bytes; InputError naming the file when it is not a regular file, cannot be opened or read.
std::vector<char> readAll(const std::string& path);
void writeAll(const std::string& path, const void* data, std::size_t bytes);

}  // namespace sglc::detail
