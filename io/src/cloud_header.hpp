// Strict checks of PCD and PLY headers before PCL parses a file (internal). PCL 1.13's readers crash on some
// malformed headers (a file without a FIELDS line, a negative or huge PLY vertex count, a list property in
// the vertex element); these checks refuse such files with InputError first, so PCL only sees headers it
// handles. Data-section errors (short files, bad numbers) are left to PCL, which reports them.
#pragma once

#include <string>

namespace sglc::detail {

void checkPcdHeader(const std::string& path);
void checkPlyHeader(const std::string& path);

}  // namespace sglc::detail
