// NumPy .npy arrays (format versions 1-3, as numpy.save writes them), read without Python.
//
// Points: a 2-D array of shape (N, C), C >= 3, float32 or float64, either byte order, C or Fortran order;
// columns 0-2 are x, y, z in metres, further columns (KITTI's reflectance) are ignored. Labels: a 1-D array
// of N, or (N, 1), of any integer type whose values fit uint32. Every failure throws InputError naming the
// file and what is wrong (structured dtypes, object arrays, a size that does not match the header, ...).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "sglc/types.hpp"

namespace sglc {

Points readNpyPoints(const std::string& path);
std::vector<std::uint32_t> readNpyLabels(const std::string& path);

// Writers for tests and tools: float32 (N, 3) and uint32 (N,), little-endian, C order.
void writeNpyPoints(const std::string& path, const Points& points);
void writeNpyLabels(const std::string& path, const std::vector<std::uint32_t>& labels);

}  // namespace sglc
