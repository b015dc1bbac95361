#include "process_lock.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "sglc/storage/map_store.hpp"

namespace sglc::storage {

ProcessLock::ProcessLock(const std::string& database) {
  // One lock per file, however it is named (relative, with "..", through a symlink). Hard links still name
  // another path: one server per path is what the lock promises.
  std::error_code ec;
  auto canonical = std::filesystem::weakly_canonical(database, ec);
  const std::string path = (ec ? database : canonical.string()) + ".lock";
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) {
    const int e = errno;
    throw StorageError(
        e == EACCES || e == EROFS || e == EPERM ? StorageError::Code::kReadOnly : StorageError::Code::kIo,
        path + ": cannot create the database's lock file: " + std::strerror(e));
  }
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int e = errno;
    char buf[32] = {};
    const auto n = ::pread(fd_, buf, sizeof(buf) - 1, 0);
    ::close(fd_);
    fd_ = -1;
    if (e != EWOULDBLOCK) throw StorageError(StorageError::Code::kIo, path + ": cannot lock: " + std::strerror(e));
    std::string owner = n > 0 ? std::string(buf, static_cast<std::size_t>(n)) : "";
    owner.erase(owner.find_last_not_of(" \n") + 1);
    throw StorageError(StorageError::Code::kBusy, database + ": database in use by " +
                                                      (owner.empty() ? "another process" : "process " + owner) +
                                                      " (one server per map database)");
  }
  const std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(fd_, 0) != 0 || ::pwrite(fd_, pid.data(), pid.size(), 0) != static_cast<ssize_t>(pid.size())) {
    // The lock holds without the pid; a second process then says "another process".
  }
}

ProcessLock& ProcessLock::operator=(ProcessLock&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = other.fd_;
    other.fd_ = -1;
  }
  return *this;
}

ProcessLock::~ProcessLock() {
  if (fd_ >= 0) ::close(fd_);  // releases the flock
}

}  // namespace sglc::storage
