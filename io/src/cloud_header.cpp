#include "cloud_header.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <set>
#include <sstream>
#include <vector>

#include "ascii_value.hpp"
#include "file_bytes.hpp"
#include "sglc/types.hpp"

namespace sglc::detail {
namespace {

const std::vector<std::string> kPcdKeys{"VERSION", "FIELDS", "SIZE",      "TYPE",   "COUNT",
                                        "WIDTH",   "HEIGHT", "VIEWPOINT", "POINTS", "DATA"};

constexpr std::size_t kMaxHeaderBytes = 1 << 16;
constexpr std::uint64_t kMaxPoints = 500'000'000;  // elements other than points (PLY faces), header sanity

[[noreturn]] void fail(const std::string& path, const std::string& what) { throw InputError(path + ": " + what); }

// A file's header lines (up to and including `last_key`'s line), read from its first 64 KiB alone, and where
// the data starts; the data itself (`body`) is read by loadBody once the header passed its checks.
struct Header {
  explicit Header(const std::string& path) : file(path) {}
  RegularFile file;
  std::vector<std::string> lines;
  std::uint64_t data_offset = 0;
  std::uint64_t file_size = 0;
  std::vector<char> body;  // the bytes after the header, once loaded

  void loadBody() { body = file.read(data_offset, static_cast<std::size_t>(file_size - data_offset)); }
};

// The header of a scan file, after the file limits (a regular file no larger than kMaxScanFileBytes).
std::unique_ptr<Header> readHeader(const std::string& path, const std::string& last_key, const char* format) {
  auto h = std::make_unique<Header>(path);
  checkScanFileSize(h->file);
  h->file_size = h->file.size();
  const auto head = h->file.read(0, static_cast<std::size_t>(std::min<std::uint64_t>(h->file_size, kMaxHeaderBytes)));
  std::size_t pos = 0;
  while (pos < head.size()) {
    const auto* nl = static_cast<const char*>(std::memchr(head.data() + pos, '\n', head.size() - pos));
    if (!nl) break;
    std::string line(head.data() + pos, nl);
    pos = static_cast<std::size_t>(nl - head.data()) + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    h->lines.push_back(line);
    if (line.rfind(last_key, 0) == 0) {
      h->data_offset = pos;
      return h;
    }
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

// PCL 1.13 goes on reading header keys after DATA (a "COUNT ..." line at the start of the data changes the
// layout after the buffer was sized: heap overflow), and turns an ascii line with the wrong number of values
// into a point at the origin. So: no line of the data may start with a header key, and ascii data must be
// exactly `points` lines of `values` numbers, each a value of its field's declared type.
struct PcdField {
  std::string name;
  AsciiType type;
  std::uint64_t count = 1;
};

void checkPcdBody(const Header& h, const std::string& path, bool ascii, std::uint64_t points,
                  const std::vector<PcdField>& fields, std::uint64_t values) {
  const char* begin = h.body.data();
  const char* end = h.body.data() + h.body.size();
  std::uint64_t lines = 0;
  std::uint64_t file_line = h.lines.size();
  for (const char* line = begin; line < end;) {
    ++file_line;
    const char* nl = static_cast<const char*>(std::memchr(line, '\n', static_cast<std::size_t>(end - line)));
    const char* stop = nl ? nl : end;
    for (const auto& key : kPcdKeys)
      if (static_cast<std::size_t>(stop - line) > key.size() && std::memcmp(line, key.data(), key.size()) == 0 &&
          (line[key.size()] == ' ' || line[key.size()] == '\t'))
        fail(path, "PCD data holds a '" + key + "' header line");
    if (ascii) {
      std::string text(line, stop);
      if (text.find_first_not_of(" \t\r") != std::string::npos) {
        if (++lines > points) fail(path, "PCD ascii data has more than POINTS " + std::to_string(points) + " lines");
        const auto w = words(text);
        if (w.size() != values)
          fail(path, "PCD ascii line " + std::to_string(lines) + " has " + std::to_string(w.size()) +
                         " values, the header declares " + std::to_string(values));
        std::size_t k = 0;
        for (const auto& f : fields)
          for (std::uint64_t c = 0; c < f.count; ++c, ++k)
            if (const auto why = asciiValueError(w[k], f.type))
              fail(path, "PCD ascii line " + std::to_string(lines) + " (line " + std::to_string(file_line) +
                             " of the file), field '" + f.name + "' (" + f.type.name() + "): value '" +
                             w[k].substr(0, 40) + "' " + *why);
      }
    }
    line = stop + 1;
  }
  if (ascii && lines != points)
    fail(path, "PCD ascii data has " + std::to_string(lines) + " lines for POINTS " + std::to_string(points));
}

}  // namespace

void checkPcdHeader(const std::string& path) {
  const auto header = readHeader(path, "DATA", "PCD");
  Header& h = *header;
  // Only the keys of the PCD v0.7 specification, each at most once and in its order (PCL 1.13 crashes on an
  // unknown line, and reads SIZE/TYPE/COUNT against the FIELDS seen before them).
  const std::vector<std::string>& kOrder = kPcdKeys;
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
  std::uint64_t point_bytes = 0, values = 0;
  std::vector<PcdField> value_fields;
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
    values += n;
    value_fields.push_back({keys["FIELDS"][i], AsciiType{type[0], static_cast<int>(size)}, n});
  }
  const auto width = count(keys["WIDTH"][0], path, "PCD WIDTH");
  const auto height = count(keys["HEIGHT"][0], path, "PCD HEIGHT");
  const auto points = count(keys["POINTS"][0], path, "PCD POINTS");
  checkScanPoints(path, points, "POINTS in the PCD header");
  if (height == 0 || width > kMaxPoints || height > kMaxPoints || width * height != points || points > kMaxPoints)
    fail(path, "PCD header: WIDTH x HEIGHT must equal POINTS (at most " + std::to_string(kMaxPoints) + ")");
  const std::string& data = keys["DATA"][0];
  const std::uint64_t left = h.file_size - std::min(h.file_size, h.data_offset);
  if (data == "binary" && left < points * point_bytes)
    fail(path, "PCD binary data holds " + std::to_string(left) + " bytes for " + std::to_string(points) +
                   " points of " + std::to_string(point_bytes) + " bytes");
  h.loadBody();  // the header is sound and within the limits
  if (data == "binary_compressed") {
    // Two uint32 (compressed size, uncompressed size), then the LZF data: both must fit the file and the points.
    if (left < 8) fail(path, "PCD binary_compressed data is truncated");
    const auto* b = reinterpret_cast<const unsigned char*>(h.body.data());
    const std::uint64_t compressed = b[0] | (b[1] << 8) | (b[2] << 16) | (std::uint64_t(b[3]) << 24);
    const std::uint64_t uncompressed = b[4] | (b[5] << 8) | (b[6] << 16) | (std::uint64_t(b[7]) << 24);
    if (compressed > left - 8 || uncompressed != points * point_bytes || (points > 0 && compressed == 0))
      fail(path, "PCD binary_compressed sizes (" + std::to_string(compressed) + " compressed, " +
                     std::to_string(uncompressed) + " uncompressed) do not match the file and " +
                     std::to_string(points) + " points");
  }
  if (data != "ascii" && data != "binary" && data != "binary_compressed")
    fail(path, "PCD DATA '" + data + "' is not ascii, binary or binary_compressed");
  checkPcdBody(h, path, data == "ascii", points, value_fields, values);
}

namespace {

// PCL 1.13's PLY reader writes colour properties by its own layout (a lone or reordered red/green/blue shifts
// or overruns the point), sizes organised clouds by obj_info num_cols x num_rows, and reads camera and
// range_grid elements into the cloud's size: only what it handles safely gets through.
void checkPlyVertexProperties(const std::vector<std::string>& names, const std::string& path) {
  static const std::set<std::string> kColour{"red",           "green",        "blue", "alpha", "diffuse_red",
                                             "diffuse_green", "diffuse_blue", "rgb",  "rgba"};
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (!kColour.count(names[i])) continue;
    const bool rgb = names[i] == "red" && i + 2 < names.size() && names[i + 1] == "green" && names[i + 2] == "blue";
    if (!rgb) fail(path, "PLY colour property '" + names[i] + "' is supported only as red, green, blue in that order");
    i += (i + 3 < names.size() && names[i + 3] == "alpha") ? 3 : 2;
  }
}

}  // namespace

void checkPlyHeader(const std::string& path) {
  const auto header = readHeader(path, "end_header", "PLY");
  Header& h = *header;
  if (h.lines.empty() || h.lines[0] != "ply") fail(path, "not a PLY file (first line is not 'ply')");
  std::string format;
  std::uint64_t vertices = 0, vertex_bytes = 0;
  std::vector<std::string> names;
  std::vector<AsciiType> types;
  bool in_vertex = false, seen_vertex = false;
  static const std::map<std::string, AsciiType> kTypes{
      {"char", {'I', 1}},  {"uchar", {'U', 1}},   {"int8", {'I', 1}},   {"uint8", {'U', 1}},
      {"short", {'I', 2}}, {"ushort", {'U', 2}},  {"int16", {'I', 2}},  {"uint16", {'U', 2}},
      {"int", {'I', 4}},   {"uint", {'U', 4}},    {"int32", {'I', 4}},  {"uint32", {'U', 4}},
      {"float", {'F', 4}}, {"float32", {'F', 4}}, {"double", {'F', 8}}, {"float64", {'F', 8}}};
  for (std::size_t i = 1; i < h.lines.size(); ++i) {
    const auto w = words(h.lines[i]);
    if (w.empty()) continue;
    if (w[0] == "format" && w.size() == 3) {
      format = w[1];
    } else if (w[0] == "obj_info" && w.size() >= 2 && (w[1] == "num_cols" || w[1] == "num_rows")) {
      fail(path, "organised PLY (obj_info " + w[1] + ") is not supported");
    } else if (w[0] == "element") {
      if (w.size() != 3) fail(path, "PLY: malformed line '" + h.lines[i] + "'");
      const auto n = count(w[2], path, "PLY element count");
      if (n > kMaxPoints) fail(path, "PLY element '" + w[1] + "' count " + w[2] + " is too large");
      if (w[1] != "vertex" && w[1] != "face") fail(path, "PLY element '" + w[1] + "' is not supported (vertex, face)");
      if (!seen_vertex && w[1] != "vertex") fail(path, "PLY: the vertex element must come first");
      in_vertex = w[1] == "vertex";
      if (in_vertex) {
        if (seen_vertex) fail(path, "PLY: two vertex elements");
        seen_vertex = true;
        vertices = n;
        checkScanPoints(path, vertices, "the PLY vertex count");
      }
    } else if (w[0] == "property" && in_vertex) {
      if (w.size() != 3) fail(path, "PLY vertex property '" + h.lines[i] + "': only scalar properties are supported");
      const auto it = kTypes.find(w[1]);
      if (it == kTypes.end()) fail(path, "PLY vertex property type '" + w[1] + "' is unknown");
      vertex_bytes += static_cast<std::uint64_t>(it->second.bytes);
      names.push_back(w[2]);
      types.push_back(it->second);
    }
  }
  if (format != "ascii" && format != "binary_little_endian" && format != "binary_big_endian")
    fail(path, "PLY: format must be ascii, binary_little_endian or binary_big_endian");
  if (!seen_vertex) fail(path, "PLY: no vertex element");
  checkPlyVertexProperties(names, path);
  const std::uint64_t left = h.file_size - std::min(h.file_size, h.data_offset);
  // ascii: at least "v " per value; binary: the declared bytes.
  const std::uint64_t need =
      format == "ascii" ? vertices * std::max<std::uint64_t>(names.size(), 1) * 2 : vertices * vertex_bytes;
  if (left < need)
    fail(path,
         "PLY data holds " + std::to_string(left) + " bytes, too few for " + std::to_string(vertices) + " vertices");
  if (format == "ascii") {
    h.loadBody();
    checkPlyAsciiVertices(h.body, h.lines.size(), vertices, names, types, path);
  }
}

}  // namespace sglc::detail
