#include "sglc/npy.hpp"

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
  const unsigned char* data = nullptr;  // the elements, right after the header
  std::size_t elements = 0;
};

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

NpyArray parseNpy(const std::vector<char>& bytes, const std::string& path) {
  static constexpr std::string_view kMagic("\x93NUMPY", 6);
  if (bytes.size() < 10 || std::string_view(bytes.data(), 6) != kMagic)
    fail(path, "not an .npy file (no \\x93NUMPY magic)");
  const auto* u = reinterpret_cast<const unsigned char*>(bytes.data());
  const unsigned major = u[6];
  std::size_t header_len = 0;
  std::size_t offset = 0;
  if (major == 1) {
    header_len = u[8] | (std::size_t(u[9]) << 8);
    offset = 10;
  } else if (major == 2 || major == 3) {
    if (bytes.size() < 12) fail(path, "truncated .npy header");
    header_len = u[8] | (std::size_t(u[9]) << 8) | (std::size_t(u[10]) << 16) | (std::size_t(u[11]) << 24);
    offset = 12;
  } else {
    fail(path, "npy format version " + std::to_string(major) + " is not supported (1, 2 or 3)");
  }
  if (header_len > bytes.size() - offset) fail(path, "truncated .npy header");
  const std::string_view header(bytes.data() + offset, header_len);
  NpyArray a;
  parseDescr(dictValue(header, "descr", path), a, path);
  const auto fortran = dictValue(header, "fortran_order", path);
  if (fortran != "False" && fortran != "True") fail(path, "npy fortran_order is neither True nor False");
  a.fortran = fortran == "True";
  parseShape(dictValue(header, "shape", path), a, path);
  const std::size_t data_bytes = bytes.size() - offset - header_len;
  if (a.elements > std::numeric_limits<std::size_t>::max() / a.width || a.elements * a.width != data_bytes)
    fail(path, "npy data is " + std::to_string(data_bytes) + " bytes but the header declares " +
                   std::to_string(a.elements) + " elements of " + std::to_string(a.width) + " bytes");
  a.data = u + offset + header_len;
  return a;
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
  const auto bytes = detail::readAll(path);
  const NpyArray a = parseNpy(bytes, path);
  if (a.kind != 'f' || (a.width != 4 && a.width != 8))
    fail(path, "npy points must be float32 or float64, not " + std::string(1, a.kind) + std::to_string(a.width));
  if (a.shape.size() != 2 || a.shape[1] < 3)
    fail(path, "npy points must have shape (N, 3) or (N, C >= 3), not " + shapeText(a));
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
  const auto bytes = detail::readAll(path);
  const NpyArray a = parseNpy(bytes, path);
  if (a.kind != 'i' && a.kind != 'u')
    fail(path, "npy labels must be integers, not " + std::string(1, a.kind) + std::to_string(a.width));
  if (!(a.shape.size() == 1 || (a.shape.size() == 2 && a.shape[1] == 1)))
    fail(path, "npy labels must have shape (N,) or (N, 1), not " + shapeText(a));
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
