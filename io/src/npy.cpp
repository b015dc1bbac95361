#include "sglc/npy.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <string_view>

#include "file_bytes.hpp"

namespace sglc {
namespace {

// What the header of an .npy file declares.
struct NpyArray {
  char kind = 0;          // 'f' float, 'i' signed, 'u' unsigned, 'b' bool
  std::size_t width = 0;  // bytes per element
  bool big_endian = false;
  bool fortran = false;
  std::vector<std::size_t> shape;
  std::size_t elements = 0;
  std::uint64_t data_offset = 0;        // where the elements start in the file
  std::vector<char> bytes;              // the elements, once read
  const unsigned char* data = nullptr;  // bytes.data()
};

constexpr std::size_t kMaxHeaderBytes = 1 << 16;

[[noreturn]] void fail(const std::string& path, const std::string& what) { throw InputError(path + ": " + what); }

// The value of `key` in the header dictionary, as written: "'<f4'", "False", "(40000, 4)".
std::string_view dictValue(std::string_view header, std::string_view key, const std::string& path) {
  const std::string quoted = std::string("'").append(key).append("'");
  const auto at = header.find(quoted);
  if (at == std::string_view::npos) fail(path, "npy header has no " + quoted + " entry");
  auto pos = header.find(':', at + quoted.size());
  if (pos == std::string_view::npos) fail(path, "npy header: no ':' after " + quoted);
  ++pos;
  while (pos < header.size() && header[pos] == ' ') ++pos;
  std::size_t end = pos;
  if (end < header.size() && header[end] == '(') {
    end = header.find(')', end);
    if (end == std::string_view::npos) fail(path, "npy header: unterminated shape");
    ++end;
  } else {
    while (end < header.size() && header[end] != ',' && header[end] != '}') ++end;
  }
  return header.substr(pos, end - pos);
}

void parseDescr(std::string_view descr, NpyArray& a, const std::string& path) {
  // A plain dtype is a quoted string such as '<f4'; a structured one is a list, which is refused.
  if (descr.size() < 5 || descr.front() != '\'' || descr.back() != '\'')
    fail(path,
         "npy dtype " + std::string(descr) + " is not a plain numeric type (structured arrays are not supported)");
  descr = descr.substr(1, descr.size() - 2);
  const char order = descr[0];
  if (order != '<' && order != '>' && order != '|' && order != '=')
    fail(path, "npy dtype '" + std::string(descr) + "': unknown byte order");
  a.big_endian = order == '>' || (order == '=' && std::endian::native == std::endian::big);
  a.kind = descr[1];
  const std::string_view digits = descr.substr(2);
  if (digits != "1" && digits != "2" && digits != "4" && digits != "8")
    fail(path, "npy dtype '" + std::string(descr) + "': unsupported element size");
  a.width = static_cast<std::size_t>(digits[0] - '0');
  if (a.kind != 'f' && a.kind != 'i' && a.kind != 'u' && a.kind != 'b')
    fail(path, "npy dtype '" + std::string(descr) + "' is not a number (float, int, uint or bool expected)");
}

void parseShape(std::string_view text, NpyArray& a, const std::string& path) {
  if (text.size() < 2 || text.front() != '(' || text.back() != ')') fail(path, "npy shape is not a tuple");
  text = text.substr(1, text.size() - 2);
  std::size_t total = 1;
  std::size_t i = 0;
  while (i < text.size()) {
    while (i < text.size() && (text[i] == ' ' || text[i] == ',')) ++i;
    if (i == text.size()) break;
    std::size_t v = 0;
    std::size_t digits = 0;
    for (; i < text.size() && text[i] >= '0' && text[i] <= '9'; ++i, ++digits) {
      if (v > (std::numeric_limits<std::size_t>::max() - 9) / 10) fail(path, "npy shape too large");
      v = v * 10 + static_cast<std::size_t>(text[i] - '0');
    }
    if (digits == 0) fail(path, "npy shape (" + std::string(text) + ") is not a tuple of sizes");
    if (v != 0 && total > std::numeric_limits<std::size_t>::max() / v) fail(path, "npy shape too large");
    total *= v;
    a.shape.push_back(v);
  }
  a.elements = total;
}

// The header alone is read first: the declared shape is checked against the file's size (and, by the caller,
// against the point cap) before any data is read.
NpyArray parseNpyHeader(const detail::RegularFile& file, const std::string& path) {
  static constexpr std::string_view kMagic("\x93NUMPY", 6);
  const auto prefix = file.read(0, static_cast<std::size_t>(std::min<std::uint64_t>(file.size(), 12)));
  if (prefix.size() < 10 || std::string_view(prefix.data(), 6) != kMagic)
    fail(path, "not an .npy file (no \\x93NUMPY magic)");
  const auto* u = reinterpret_cast<const unsigned char*>(prefix.data());
  const unsigned major = u[6];
  std::size_t header_len = 0;
  std::size_t offset = 0;
  if (major == 1) {
    header_len = u[8] | (std::size_t(u[9]) << 8);
    offset = 10;
  } else if (major == 2 || major == 3) {
    if (prefix.size() < 12) fail(path, "truncated .npy header");
    header_len = u[8] | (std::size_t(u[9]) << 8) | (std::size_t(u[10]) << 16) | (std::size_t(u[11]) << 24);
    offset = 12;
  } else {
    fail(path, "npy format version " + std::to_string(major) + " is not supported (1, 2 or 3)");
  }
  if (header_len > file.size() - offset) fail(path, "truncated .npy header");
  if (header_len > kMaxHeaderBytes)
    fail(path, "npy header of " + std::to_string(header_len) + " bytes is too long (at most 64 KiB)");
  const auto text = file.read(offset, header_len);
  const std::string_view header(text.data(), text.size());
  NpyArray a;
  parseDescr(dictValue(header, "descr", path), a, path);
  const auto fortran = dictValue(header, "fortran_order", path);
  if (fortran != "False" && fortran != "True") fail(path, "npy fortran_order is neither True nor False");
  a.fortran = fortran == "True";
  parseShape(dictValue(header, "shape", path), a, path);
  a.data_offset = offset + header_len;
  const std::uint64_t data_bytes = file.size() - a.data_offset;
  if (a.elements > std::numeric_limits<std::size_t>::max() / a.width || a.elements * a.width != data_bytes)
    fail(path, "npy data is " + std::to_string(data_bytes) + " bytes but the header declares " +
                   std::to_string(a.elements) + " elements of " + std::to_string(a.width) + " bytes");
  return a;
}

// The elements, once the header's shape passed the caller's checks.
void readNpyData(const detail::RegularFile& file, NpyArray& a) {
  a.bytes = file.read(a.data_offset, a.elements * a.width);
  a.data = reinterpret_cast<const unsigned char*>(a.bytes.data());
}

// Element `k` (in storage order) as raw little-endian-corrected bytes.
std::uint64_t rawElement(const NpyArray& a, std::size_t k) {
  std::uint64_t v = 0;
  const unsigned char* p = a.data + k * a.width;
  for (std::size_t b = 0; b < a.width; ++b) {
    const std::size_t shift = a.big_endian ? (a.width - 1 - b) : b;
    v |= std::uint64_t(p[b]) << (8 * shift);
  }
  return v;
}

double floatElement(const NpyArray& a, std::size_t k) {
  const std::uint64_t v = rawElement(a, k);
  if (a.width == 4) return std::bit_cast<float>(static_cast<std::uint32_t>(v));
  return std::bit_cast<double>(v);
}

// An integer element as a value that fits uint32, or nullopt.
std::optional<std::uint32_t> labelElement(const NpyArray& a, std::size_t k) {
  const std::uint64_t v = rawElement(a, k);
  if (a.kind == 'i') {
    const unsigned bits = static_cast<unsigned>(8 * a.width);
    const std::int64_t s =
        bits == 64 ? static_cast<std::int64_t>(v) : static_cast<std::int64_t>(v << (64 - bits)) >> (64 - bits);
    if (s < 0 || s > std::int64_t(std::numeric_limits<std::uint32_t>::max())) return std::nullopt;
    return static_cast<std::uint32_t>(s);
  }
  if (v > std::numeric_limits<std::uint32_t>::max()) return std::nullopt;
  return static_cast<std::uint32_t>(v);
}

std::string shapeText(const NpyArray& a) {
  std::string s = "(";
  for (std::size_t i = 0; i < a.shape.size(); ++i) s += (i ? ", " : "") + std::to_string(a.shape[i]);
  return s + (a.shape.size() == 1 ? ",)" : ")");
}

template <typename T>
void writeNpy(const std::string& path, const char* descr, const std::string& shape, const T* data, std::size_t n) {
  std::string header = std::string("{'descr': '") + descr + "', 'fortran_order': False, 'shape': " + shape + ", }";
  const std::size_t unpadded = 10 + header.size() + 1;  // magic, version, length, header, '\n'
  header.append((64 - unpadded % 64) % 64, ' ');
  header += '\n';
  std::string out("\x93NUMPY\x01\x00", 8);
  out += static_cast<char>(header.size() & 0xff);
  out += static_cast<char>(header.size() >> 8);
  out += header;
  for (std::size_t i = 0; i < n; ++i) {  // little-endian whatever the host
    auto bits = std::bit_cast<std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>>(data[i]);
    for (std::size_t b = 0; b < sizeof(T); ++b) out += static_cast<char>((bits >> (8 * b)) & 0xff);
  }
  detail::writeAll(path, out.data(), out.size());
}

}  // namespace

Points readNpyPoints(const std::string& path) {
  const detail::RegularFile file(path);
  detail::checkScanFileSize(file);
  NpyArray a = parseNpyHeader(file, path);
  if (a.kind != 'f' || (a.width != 4 && a.width != 8))
    fail(path, "npy points must be float32 or float64, not " + std::string(1, a.kind) + std::to_string(a.width));
  if (a.shape.size() != 2 || a.shape[1] < 3)
    fail(path, "npy points must have shape (N, 3) or (N, C >= 3), not " + shapeText(a));
  detail::checkScanPoints(path, a.shape[0], "rows of the header's shape " + shapeText(a));
  readNpyData(file, a);
  const std::size_t n = a.shape[0];
  const std::size_t cols = a.shape[1];
  Points points(n);
  for (std::size_t i = 0; i < n; ++i) {
    double xyz[3];
    for (std::size_t c = 0; c < 3; ++c) xyz[c] = floatElement(a, a.fortran ? c * n + i : i * cols + c);
    if (!std::isfinite(xyz[0]) || !std::isfinite(xyz[1]) || !std::isfinite(xyz[2]))
      fail(path, "point " + std::to_string(i) + " has a non-finite coordinate");
    points[i] = Vec3f(float(xyz[0]), float(xyz[1]), float(xyz[2]));
  }
  return points;
}

std::vector<std::uint32_t> readNpyLabels(const std::string& path) {
  const detail::RegularFile file(path);
  NpyArray a = parseNpyHeader(file, path);
  if (a.kind != 'i' && a.kind != 'u')
    fail(path, "npy labels must be integers, not " + std::string(1, a.kind) + std::to_string(a.width));
  if (!(a.shape.size() == 1 || (a.shape.size() == 2 && a.shape[1] == 1)))
    fail(path, "npy labels must have shape (N,) or (N, 1), not " + shapeText(a));
  detail::checkScanPoints(path, a.shape[0], "labels in the header's shape " + shapeText(a));
  readNpyData(file, a);
  std::vector<std::uint32_t> labels(a.shape[0]);
  for (std::size_t i = 0; i < labels.size(); ++i) {
    const auto v = labelElement(a, i);
    if (!v) fail(path, "label " + std::to_string(i) + " is negative or does not fit uint32");
    labels[i] = *v;
  }
  return labels;
}

void writeNpyPoints(const std::string& path, const Points& points) {
  std::vector<float> flat;
  flat.reserve(points.size() * 3);
  for (const auto& p : points) flat.insert(flat.end(), {p.x(), p.y(), p.z()});
  writeNpy(path, "<f4", std::string("(").append(std::to_string(points.size())).append(", 3)"), flat.data(),
           flat.size());
}

void writeNpyLabels(const std::string& path, const std::vector<std::uint32_t>& labels) {
  writeNpy(path, "<u4", std::string("(").append(std::to_string(labels.size())).append(",)"), labels.data(),
           labels.size());
}

}  // namespace sglc
