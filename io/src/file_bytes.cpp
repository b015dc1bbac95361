#include "file_bytes.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>

#include "sglc/scan_file.hpp"
#include "sglc/types.hpp"

namespace sglc::detail {
namespace {

// Why a file of mode `mode` is not one the readers read, or nullptr.
const char* notRegular(mode_t mode) {
  if (S_ISREG(mode)) return nullptr;
  if (S_ISDIR(mode)) return "is a directory, not a file";
  if (S_ISFIFO(mode)) return "is a FIFO (named pipe), not a regular file";
  if (S_ISSOCK(mode)) return "is a socket, not a regular file";
  if (S_ISCHR(mode) || S_ISBLK(mode)) return "is a device, not a regular file";
  return "is not a regular file";
}

}  // namespace

void requireRegularFile(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) throw InputError(path + ": cannot open (" + std::strerror(errno) + ")");
  if (const char* why = notRegular(st.st_mode)) throw InputError(path + ": " + why);
}

RegularFile::RegularFile(const std::string& path) : path_(path) {
  requireRegularFile(path);
  fd_ = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd_ < 0) throw InputError(path + ": cannot open (" + std::strerror(errno) + ")");
  struct stat st {};
  const char* why = ::fstat(fd_, &st) != 0 ? "cannot determine the file size" : notRegular(st.st_mode);
  if (why) {
    ::close(fd_);
    throw InputError(path + ": " + why);
  }
  size_ = static_cast<std::uint64_t>(st.st_size);
}

RegularFile::~RegularFile() {
  if (fd_ >= 0) ::close(fd_);
}

std::vector<char> RegularFile::read(std::uint64_t offset, std::size_t bytes) const {
  std::vector<char> data(bytes);
  readInto(offset, data.data(), bytes);
  return data;
}

void RegularFile::readInto(std::uint64_t offset, void* out, std::size_t bytes) const {
  char* to = static_cast<char*>(out);
  std::size_t done = 0;
  while (done < bytes) {
    const ssize_t n = ::pread(fd_, to + done, bytes - done, static_cast<off_t>(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw InputError(path_ + ": read failed (" + std::strerror(errno) + ")");
    if (n == 0) throw InputError(path_ + ": read failed (the file is shorter than it was)");
    done += static_cast<std::size_t>(n);
  }
}

void checkScanFileSize(const RegularFile& file) {
  if (file.size() > kMaxScanFileBytes)
    throw InputError(file.path() + ": " + std::to_string(file.size()) + " bytes, larger than the " +
                     std::to_string(kMaxScanFileBytes) + " a scan file may have (" + std::to_string(kMaxScanPoints) +
                     " points of at most 256 bytes)");
}

void checkScanPoints(const std::string& path, std::uint64_t points, const std::string& source) {
  if (points > kMaxScanPoints)
    throw InputError(path + ": " + std::to_string(points) + " points (" + source + "), more than the " +
                     std::to_string(kMaxScanPoints) + " a scan may have (the server's default max_points)");
}

std::vector<char> readAll(const std::string& path) { return RegularFile(path).readAll(); }

void writeAll(const std::string& path, const void* data, std::size_t bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw InputError(path + ": cannot create (" + std::strerror(errno) + ")");
  out.write(static_cast<const char*>(data), static_cast<std::streamsize>(bytes));
  if (!out) throw InputError(path + ": write failed");
}

}  // namespace sglc::detail
