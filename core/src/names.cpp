#include "sglc/names.hpp"

namespace sglc {

std::optional<std::string> nameError(const std::string& name) {
  if (name.empty()) return std::string("is empty");
  if (name.size() > kMaxNameBytes) return "is longer than " + std::to_string(kMaxNameBytes) + " bytes";
  for (unsigned char c : name)
    if (c < 0x20 || c == 0x7f) return std::string("has a control character");
  return std::nullopt;
}

}  // namespace sglc
