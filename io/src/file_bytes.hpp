// Whole-file reads and writes shared by the format readers of sglc_io (internal).
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace sglc::detail {

// The file's bytes; InputError naming the file when it is a directory, cannot be opened or read.
std::vector<char> readAll(const std::string& path);
void writeAll(const std::string& path, const void* data, std::size_t bytes);

}  // namespace sglc::detail
