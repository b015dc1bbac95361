// Values of ASCII PCD and PLY data, judged by their declared type before PCL parses them (internal). PCL
// converts ascii text to the field's type unchecked (-10 in an unsigned field wraps, 10.5 is cut to 10, 300 in a
// uchar wraps to 44): these checks refuse such a value instead.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace sglc::detail {

// A field's declared type: PCD TYPE I, U or F with its SIZE; PLY char, uchar, ..., double.
struct AsciiType {
  char kind = 'F';           // 'I' signed integer, 'U' unsigned integer, 'F' floating point
  int bytes = 4;             // 1, 2, 4 or 8
  std::string name() const;  // "U4", "F8", ...
};

// Why `text` is not a value of `type`, or nullopt. Integers: an optional sign and decimal digits, within the
// type's range (no fraction, no exponent). Floats: a whole decimal number (strtod syntax without hex) within the
// type's range, or nan (PCL's mark of a missing value); inf and values beyond the type's range are refused.
std::optional<std::string> asciiValueError(std::string_view text, const AsciiType& type);

// The vertex element of an ascii PLY file's `body` (which starts on line `header_lines` + 1): `vertices` times
// `types.size()` whitespace-separated values, each of its property's type. InputError naming the file, the
// vertex, its line, the property and the value otherwise.
void checkPlyAsciiVertices(const std::vector<char>& body, std::size_t header_lines, std::uint64_t vertices,
                           const std::vector<std::string>& names, const std::vector<AsciiType>& types,
                           const std::string& path);

}  // namespace sglc::detail
