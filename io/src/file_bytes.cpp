#include "file_bytes.hpp"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "sglc/types.hpp"

namespace sglc::detail {

std::vector<char> readAll(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw InputError(path + ": is a directory, not a file");
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) throw InputError(path + ": cannot open (" + std::strerror(errno) + ")");
  const std::streamsize size = in.tellg();
  if (size < 0) throw InputError(path + ": cannot determine the file size");
  in.seekg(0);
  std::vector<char> data(static_cast<std::size_t>(size));
  if (size > 0 && !in.read(data.data(), size)) throw InputError(path + ": read failed");
  return data;
}

void writeAll(const std::string& path, const void* data, std::size_t bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw InputError(path + ": cannot create (" + std::strerror(errno) + ")");
  out.write(static_cast<const char*>(data), static_cast<std::streamsize>(bytes));
  if (!out) throw InputError(path + ": write failed");
}

}  // namespace sglc::detail
