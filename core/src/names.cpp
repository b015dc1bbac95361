#include "sglc/names.hpp"

namespace sglc {

std::optional<std::string> nameError(const std::string& name) {
  if (name.empty()) return std::string("is empty");
  if (name.size() > kMaxNameBytes) return "is longer than " + std::to_string(kMaxNameBytes) + " bytes";
  for (unsigned char c : name)
    if (c < 0x20 || c == 0x7f) return std::string("has a control character");
  return std::nullopt;
}

namespace {

int hexDigit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

}  // namespace

std::string percentDecoded(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size(); ++i) {
    const int hi = text[i] == '%' && i + 2 < text.size() ? hexDigit(text[i + 1]) : -1;
    const int lo = hi >= 0 ? hexDigit(text[i + 2]) : -1;
    if (lo >= 0) {
      out += static_cast<char>(hi * 16 + lo);
      i += 2;
    } else {
      out += text[i];
    }
  }
  return out;
}

}  // namespace sglc
