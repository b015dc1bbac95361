#include "sglc/params.hpp"

#include <charconv>
#include <cmath>

#include "sglc/types.hpp"

namespace sglc::params {
namespace {

std::string number(double v) {
  if (std::isfinite(v) && v == std::floor(v) && std::abs(v) < 1e15) return std::to_string(static_cast<long long>(v));
  char buf[32];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);  // shortest text that reads back to v
  return std::string(buf, res.ptr);
}

std::string ids(const std::vector<std::uint32_t>& list) {
  std::string s = "[";
  for (std::size_t i = 0; i < list.size(); ++i) s += (i ? ", " : "") + std::to_string(list[i]);
  return s + "]";
}

template <class Int>
void checkInteger(const Info& info, Int v, double lo, double hi) {
  const auto d = static_cast<double>(v);
  if (d < lo || d > hi) fail(info.key, "an integer in [" + number(lo) + ", " + number(hi) + "]");
  if (!info.range.contains(d)) fail(info.key, info.range.text());
}

}  // namespace

bool Range::contains(double v) const {
  if (!std::isfinite(v)) return false;
  if (lo_open ? !(v > lo) : !(v >= lo)) return false;
  return hi_open ? v < hi : v <= hi;
}

std::string Range::text() const {
  const bool has_lo = std::isfinite(lo), has_hi = std::isfinite(hi);
  if (has_lo && has_hi)
    return std::string("in ") + (lo_open ? "(" : "[") + number(lo) + ", " + number(hi) + (hi_open ? ")" : "]");
  if (has_lo) return (lo_open ? "> " : ">= ") + number(lo);
  if (has_hi) return (hi_open ? "< " : "<= ") + number(hi);
  return "finite";
}

std::string kindName(Kind kind) {
  switch (kind) {
    case Kind::kBool:
      return "true or false";
    case Kind::kInt:
      return "integer";
    case Kind::kUnsigned:
      return "unsigned integer";
    case Kind::kReal:
      return "number";
    case Kind::kText:
      return "text";
    case Kind::kIds:
      return "list of ids";
    case Kind::kNamedIds:
      return "list of {name, ids}";
  }
  return "?";
}

std::string format(const Value& value) {
  struct Formatter {
    std::string operator()(bool v) const { return v ? "true" : "false"; }
    std::string operator()(std::int64_t v) const { return std::to_string(v); }
    std::string operator()(std::uint64_t v) const { return std::to_string(v); }
    std::string operator()(double v) const { return number(v); }
    std::string operator()(const std::string& v) const { return v; }
    std::string operator()(const std::vector<std::uint32_t>& v) const { return ids(v); }
    std::string operator()(const std::vector<NamedIds>& v) const {
      std::string s = "[";
      for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + ("{" + v[i].name + ": " + ids(v[i].ids) + "}");
      return s + "]";
    }
  };
  return std::visit(Formatter{}, value);
}

void fail(const std::string& key, const std::string& rule) { throw InputError("config: " + key + " must be " + rule); }

void unknownKey(const std::string& key) { throw InputError("config: unknown parameter '" + key + "'"); }

void check(const Info& info, const Value& value) {
  constexpr Kind kinds[] = {Kind::kBool, Kind::kInt, Kind::kUnsigned, Kind::kReal,
                            Kind::kText, Kind::kIds, Kind::kNamedIds};
  if (kinds[value.index()] != info.kind) fail(info.key, "a value of kind " + kindName(info.kind));
  if (const auto* d = std::get_if<double>(&value); d && !info.range.contains(*d)) fail(info.key, info.range.text());
  if (const auto* i = std::get_if<std::int64_t>(&value))
    checkInteger(info, *i, std::numeric_limits<int>::min(), std::numeric_limits<int>::max());
  if (const auto* u = std::get_if<std::uint64_t>(&value))
    checkInteger(info, *u, 0, static_cast<double>(std::numeric_limits<std::uint64_t>::max()));
  if (const auto* s = std::get_if<std::string>(&value); s && !info.choices.empty()) {
    for (const auto& c : info.choices)
      if (c == *s) return;
    std::string list;
    for (std::size_t i = 0; i < info.choices.size(); ++i)
      list += (i == 0 ? "" : i + 1 == info.choices.size() ? " or " : ", ") + info.choices[i];
    fail(info.key, list + " (not '" + *s + "')");
  }
}

}  // namespace sglc::params
