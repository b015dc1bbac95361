// Chunk decompression shared by the bag readers: LZ4 frames (MCAP's lz4, ROS 1's roslz4) and bzip2 (ROS 1),
// into a buffer already sized to what the chunk says it holds; a mismatch or corrupt data is an InputError.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace sglc {

void lz4Frame(const std::uint8_t* src, std::size_t n, std::vector<std::uint8_t>& out, const std::string& what);
void bzip2(const std::uint8_t* src, std::size_t n, std::vector<std::uint8_t>& out, const std::string& what);

}  // namespace sglc
