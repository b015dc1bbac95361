#include "ascii_value.hpp"

#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <string>

#include "sglc/types.hpp"

namespace sglc::detail {

std::string AsciiType::name() const { return std::string(1, kind) + std::to_string(bytes); }

namespace {

std::optional<std::string> integerError(std::string_view text, const AsciiType& type) {
  const int bits = 8 * type.bytes;
  std::string_view digits = text;
  const bool negative = !digits.empty() && digits.front() == '-';
  if (!digits.empty() && (digits.front() == '-' || digits.front() == '+')) digits.remove_prefix(1);
  std::uint64_t magnitude = 0;
  const auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), magnitude);
  if (digits.empty() || end != digits.data() + digits.size() ||
      (ec != std::errc() && ec != std::errc::result_out_of_range))
    return "is not an integer";
  const bool huge = ec == std::errc::result_out_of_range;
  std::int64_t low = 0;
  std::uint64_t high = 0;
  if (type.kind == 'U') {
    high = bits == 64 ? std::numeric_limits<std::uint64_t>::max() : (std::uint64_t{1} << bits) - 1;
  } else {
    high = (std::uint64_t{1} << (bits - 1)) - 1;
    low = bits == 64 ? std::numeric_limits<std::int64_t>::min() : -(std::int64_t{1} << (bits - 1));
  }
  const bool fits =
      !huge && (negative ? (magnitude == 0 || (type.kind == 'I' && magnitude - 1 <= high)) : magnitude <= high);
  if (fits) return std::nullopt;
  return "is out of range for " + type.name() + " (" + std::to_string(low) + ".." + std::to_string(high) + ")";
}

// Parsed as T itself, so that the text rounds as the reader will round it (3.4028235e38 is float's largest).
template <typename T>
std::optional<std::string> floatError(std::string_view number, const AsciiType& type) {
  T value = 0;
  const auto [end, ec] = std::from_chars(number.data(), number.data() + number.size(), value);
  if (number.empty() || end != number.data() + number.size() ||
      (ec != std::errc() && ec != std::errc::result_out_of_range))
    return "is not a number";
  if (ec == std::errc::result_out_of_range) {
    // Overflow is refused; underflow (a value too small for T) becomes a denormal or zero, which fits.
    if (std::abs(std::strtod(std::string(number).c_str(), nullptr)) < 1) return std::nullopt;
    return "is not a finite " + type.name() + " value (out of range)";
  }
  if (std::isinf(value)) return "is not a finite " + type.name() + " value";
  return std::nullopt;  // a number, or nan (PCL's mark of a missing value)
}

}  // namespace

std::optional<std::string> asciiValueError(std::string_view text, const AsciiType& type) {
  if (type.kind != 'F') return integerError(text, type);
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);  // strtod's syntax, which from_chars lacks
  return type.bytes == 4 ? floatError<float>(text, type) : floatError<double>(text, type);
}

void checkPlyAsciiVertices(const std::vector<char>& body, std::size_t header_lines, std::uint64_t vertices,
                           const std::vector<std::string>& names, const std::vector<AsciiType>& types,
                           const std::string& path) {
  if (types.empty()) return;
  const char* p = body.data();
  const char* const end = body.data() + body.size();
  std::uint64_t line = header_lines + 1;
  const std::uint64_t total = vertices * types.size();
  for (std::uint64_t k = 0; k < total; ++k) {
    while (p < end && (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n')) line += *p++ == '\n';
    const char* start = p;
    while (p < end && *p != ' ' && *p != '\t' && *p != '\r' && *p != '\n') ++p;
    const std::uint64_t vertex = k / types.size();
    if (start == p)
      throw InputError(path + ": PLY ascii data ends in vertex " + std::to_string(vertex) + " of " +
                       std::to_string(vertices));
    const std::string_view text(start, static_cast<std::size_t>(p - start));
    const std::size_t j = k % types.size();
    if (const auto why = asciiValueError(text, types[j]))
      throw InputError(path + ": PLY vertex " + std::to_string(vertex) + " (line " + std::to_string(line) +
                       "), property '" + names[j] + "' (" + types[j].name() + "): value '" +
                       std::string(text.substr(0, 40)) + "' " + *why);
  }
}

}  // namespace sglc::detail
