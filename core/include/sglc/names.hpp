// Names of maps, robots and sessions: the one rule the wire codec and the map store both apply.
#pragma once

#include <cstddef>
#include <optional>
#include <string>

namespace sglc {

inline constexpr std::size_t kMaxNameBytes = 256;

// Why `name` cannot name a map, robot or session ("is empty", "is longer than 256 bytes", "has a control
// character"), or nullopt. Any other bytes are allowed (UTF-8 names are common); names are compared as bytes.
std::optional<std::string> nameError(const std::string& name);

// Names as text files and URLs write them: "%XX" (two hex digits) is the byte 0xXX; any other '%' stands for
// itself. (The token file's map names; a PostgreSQL URL's parameter names, which libpq decodes the same way.)
std::string percentDecoded(const std::string& text);

}  // namespace sglc
