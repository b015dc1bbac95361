#include "cloud_header.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <vector>

#include "sglc/types.hpp"

namespace sglc::detail {
namespace {

constexpr std::size_t kMaxHeaderBytes = 1 << 16;
constexpr std::uint64_t kMaxPoints = 500'000'000;  // far above any LiDAR scan, below what would exhaust memory

[[noreturn]] void fail(const std::string& path, const std::string& what) { throw InputError(path + ": " + what); }

// The header lines (up to and including `last_key`'s line) and the byte offset where the data starts.
struct Header {
  std::vector<std::string> lines;
  std::uint64_t data_offset = 0;
  std::uint64_t file_size = 0;
};

Header readHeader(const std::string& path, const std::string& last_key, const char* format) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, std::string("cannot open (") + std::strerror(errno) + ")");
  Header h;
  std::error_code ec;
  h.file_size = std::filesystem::file_size(path, ec);
  std::string line;
  while (h.data_offset < kMaxHeaderBytes && std::getline(in, line)) {
    h.data_offset += line.size() + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    h.lines.push_back(line);
    if (line.rfind(last_key, 0) == 0) return h;
  }
  fail(path, std::string("not a ") + format + " file (no '" + last_key + "' line in its first 64 KiB)");
}

std::vector<std::string> words(const std::string& line) {
  std::istringstream ss(line);
  std::vector<std::string> out;
  for (std::string w; ss >> w;) out.push_back(w);
  return out;
}

std::uint64_t count(const std::string& text, const std::string& path, const std::string& what) {
  if (text.empty() || text.size() > 12 || text.find_first_not_of("0123456789") != std::string::npos)
    fail(path, what + " '" + text + "' is not a non-negative integer");
  return std::stoull(text);
}

}  // namespace

void checkPcdHeader(const std::string& path) {
  const Header h = readHeader(path, "DATA", "PCD");
  // Only the keys of the PCD v0.7 specification, each at most once and in its order (PCL 1.13 crashes on an
  // unknown line, and reads SIZE/TYPE/COUNT against the FIELDS seen before them).
  static const std::vector<std::string> kOrder{"VERSION", "FIELDS", "SIZE",      "TYPE",   "COUNT",
                                               "WIDTH",   "HEIGHT", "VIEWPOINT", "POINTS", "DATA"};
  std::map<std::string, std::vector<std::string>> keys;
  std::size_t next = 0;
  for (const auto& line : h.lines) {
    if (!line.empty() && line[0] == '#') continue;
    auto w = words(line);
    const auto at = w.empty() ? kOrder.end() : std::find(kOrder.begin(), kOrder.end(), w[0]);
    if (at == kOrder.end() || line.find('\0') != std::string::npos)
      fail(path, "PCD header line '" + line.substr(0, 40) + "' is not a PCD header key");
    const auto index = static_cast<std::size_t>(at - kOrder.begin());
    if (index < next) fail(path, "PCD header: " + w[0] + " is repeated or out of order");
    next = index + 1;
    w.erase(w.begin());
    keys[kOrder[index]] = w;
  }
  for (const char* k : {"FIELDS", "SIZE", "TYPE", "WIDTH", "HEIGHT", "POINTS", "DATA"})
    if (!keys.count(k) || keys[k].empty()) fail(path, std::string("PCD header has no ") + k + " line");
  const std::size_t fields = keys["FIELDS"].size();
  if (keys["SIZE"].size() != fields || keys["TYPE"].size() != fields ||
      (keys.count("COUNT") && keys["COUNT"].size() != fields))
    fail(path, "PCD header: FIELDS, SIZE, TYPE and COUNT list different numbers of entries");
  std::uint64_t point_bytes = 0;
  for (std::size_t i = 0; i < fields; ++i) {
    const auto size = count(keys["SIZE"][i], path, "PCD SIZE");
    const std::string& type = keys["TYPE"][i];
    const bool ok = (type == "F" && (size == 4 || size == 8)) ||
                    ((type == "I" || type == "U") && (size == 1 || size == 2 || size == 4));
    if (!ok)
      fail(path,
           "PCD field '" + keys["FIELDS"][i] + "': TYPE " + type + " SIZE " + keys["SIZE"][i] + " is not supported");
    const auto n = keys.count("COUNT") ? count(keys["COUNT"][i], path, "PCD COUNT") : 1;
    if (n < 1 || n > 4096) fail(path, "PCD field '" + keys["FIELDS"][i] + "': COUNT must be 1..4096");
    point_bytes += size * n;
  }
  const auto width = count(keys["WIDTH"][0], path, "PCD WIDTH");
  const auto height = count(keys["HEIGHT"][0], path, "PCD HEIGHT");
  const auto points = count(keys["POINTS"][0], path, "PCD POINTS");
  if (height == 0 || width > kMaxPoints || height > kMaxPoints || width * height != points || points > kMaxPoints)
    fail(path, "PCD header: WIDTH x HEIGHT must equal POINTS (at most " + std::to_string(kMaxPoints) + ")");
  const std::string& data = keys["DATA"][0];
  const std::uint64_t left = h.file_size - std::min(h.file_size, h.data_offset);
  if (data == "binary" && left < points * point_bytes)
    fail(path, "PCD binary data holds " + std::to_string(left) + " bytes for " + std::to_string(points) +
                   " points of " + std::to_string(point_bytes) + " bytes");
  if (data == "binary_compressed") {
    // Two uint32 (compressed size, uncompressed size), then the LZF data: both must fit the file and the points.
    std::ifstream in(path, std::ios::binary);
    in.seekg(static_cast<std::streamoff>(h.data_offset));
    unsigned char b[8] = {};
    if (left < 8 || !in.read(reinterpret_cast<char*>(b), 8)) fail(path, "PCD binary_compressed data is truncated");
    const std::uint64_t compressed = b[0] | (b[1] << 8) | (b[2] << 16) | (std::uint64_t(b[3]) << 24);
    const std::uint64_t uncompressed = b[4] | (b[5] << 8) | (b[6] << 16) | (std::uint64_t(b[7]) << 24);
    if (compressed > left - 8 || uncompressed != points * point_bytes || (points > 0 && compressed == 0))
      fail(path, "PCD binary_compressed sizes (" + std::to_string(compressed) + " compressed, " +
                     std::to_string(uncompressed) + " uncompressed) do not match the file and " +
                     std::to_string(points) + " points");
  }
  if (data != "ascii" && data != "binary" && data != "binary_compressed")
    fail(path, "PCD DATA '" + data + "' is not ascii, binary or binary_compressed");
}

void checkPlyHeader(const std::string& path) {
  const Header h = readHeader(path, "end_header", "PLY");
  if (h.lines.empty() || h.lines[0] != "ply") fail(path, "not a PLY file (first line is not 'ply')");
  std::string format;
  std::uint64_t vertices = 0, vertex_bytes = 0;
  bool in_vertex = false, seen_vertex = false, vertex_first = false, any_element = false;
  for (std::size_t i = 1; i < h.lines.size(); ++i) {
    const auto w = words(h.lines[i]);
    if (w.empty()) continue;
    if (w[0] == "format" && w.size() == 3) {
      format = w[1];
    } else if (w[0] == "element") {
      if (w.size() != 3) fail(path, "PLY: malformed line '" + h.lines[i] + "'");
      const auto n = count(w[2], path, "PLY element count");
      if (n > kMaxPoints) fail(path, "PLY element '" + w[1] + "' count " + w[2] + " is too large");
      in_vertex = w[1] == "vertex";
      if (in_vertex) {
        if (seen_vertex) fail(path, "PLY: two vertex elements");
        seen_vertex = true;
        vertex_first = !any_element;
        vertices = n;
      }
      any_element = true;
    } else if (w[0] == "property" && in_vertex) {
      if (w.size() != 3) fail(path, "PLY vertex property '" + h.lines[i] + "': only scalar properties are supported");
      static const std::map<std::string, int> kSizes{{"char", 1},  {"uchar", 1},   {"int8", 1},   {"uint8", 1},
                                                     {"short", 2}, {"ushort", 2},  {"int16", 2},  {"uint16", 2},
                                                     {"int", 4},   {"uint", 4},    {"int32", 4},  {"uint32", 4},
                                                     {"float", 4}, {"float32", 4}, {"double", 8}, {"float64", 8}};
      const auto it = kSizes.find(w[1]);
      if (it == kSizes.end()) fail(path, "PLY vertex property type '" + w[1] + "' is unknown");
      vertex_bytes += static_cast<std::uint64_t>(it->second);
    }
  }
  if (format != "ascii" && format != "binary_little_endian" && format != "binary_big_endian")
    fail(path, "PLY: format must be ascii, binary_little_endian or binary_big_endian");
  if (!seen_vertex) fail(path, "PLY: no vertex element");
  const std::uint64_t left = h.file_size - std::min(h.file_size, h.data_offset);
  const std::uint64_t need = format == "ascii" ? vertices * 2 : vertices * vertex_bytes;  // ascii: "v\n" at least
  if (vertex_first && left < need)
    fail(path,
         "PLY data holds " + std::to_string(left) + " bytes, too few for " + std::to_string(vertices) + " vertices");
}

}  // namespace sglc::detail
