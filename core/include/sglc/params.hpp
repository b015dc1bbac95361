// A registry of settings: each one declared once with its key, kind, valid range and a line of documentation,
// bound to a field of a plain settings struct. One table per layer (the engine's Config, the map store's
// options, the pose graph's options, the server's settings); tables nest under a section prefix. The same table
// assigns values by key (with the range checked before the field is written), validates a whole struct
// (ranges, then the rules that tie several keys together), and describes itself for a dump or a docs table.
// Files and command lines are read elsewhere (sglc/config/): this header is plain C++.
#pragma once

#include <algorithm>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace sglc::params {

// A list of ids with a name, as `{name: vehicle, ids: [10, 18]}`.
struct NamedIds {
  std::string name;
  std::vector<std::uint32_t> ids;
  bool operator==(const NamedIds&) const = default;
};

enum class Kind : std::uint8_t { kBool, kInt, kUnsigned, kReal, kText, kIds, kNamedIds };
using Value = std::variant<bool, std::int64_t, std::uint64_t, double, std::string, std::vector<std::uint32_t>,
                           std::vector<NamedIds>>;

// Valid values of a number: finite, between lo and hi, each end open or closed.
struct Range {
  double lo = -std::numeric_limits<double>::infinity();
  double hi = std::numeric_limits<double>::infinity();
  bool lo_open = false, hi_open = false;
  bool contains(double v) const;
  std::string text() const;  // "in (0, 90]", "> 0", ">= 1", "finite"
};
inline Range closed(double lo, double hi) { return {lo, hi, false, false}; }
inline Range openClosed(double lo, double hi) { return {lo, hi, true, false}; }
inline Range open(double lo, double hi) { return {lo, hi, true, true}; }
inline Range above(double lo) { return {lo, std::numeric_limits<double>::infinity(), true, false}; }
inline Range atLeast(double lo) { return {lo, std::numeric_limits<double>::infinity(), false, false}; }
inline Range finite() { return {}; }

// What a setting is, independent of the struct it lives in.
struct Info {
  std::string key;  // "section.name"
  Kind kind = Kind::kReal;
  Range range;                       // numbers
  std::vector<std::string> choices;  // text: the allowed values (empty: any text)
  std::string doc;
};

std::string kindName(Kind kind);  // "number", "integer", "true/false", ...
// Shortest text that reads back to the same value ("0.45", "1e-05", "[40, 44]", "true").
std::string format(const Value& value);
// Throws InputError "config: KEY must be ..." unless the value has the setting's kind and lies in its range
// (an integer also within its field's type) or among its choices.
void check(const Info& info, const Value& value);

template <class Root>
struct Param {
  Info info;
  std::function<Value(const Root&)> get;
  std::function<void(Root&, const Value&)> set;  // called with checked values only
};

// A condition on several settings, checked after each setting's own range: "config: KEYS must be TEXT".
template <class Root>
struct Rule {
  std::vector<std::string> keys;
  std::string text;
  std::function<bool(const Root&)> holds;
};

template <class Root>
class Table {
 public:
  void add(Param<Root> p) { params_.push_back(std::move(p)); }
  void rule(std::vector<std::string> keys, std::string text, std::function<bool(const Root&)> holds) {
    rules_.push_back({std::move(keys), std::move(text), std::move(holds)});
  }
  // Run after a file or command line has assigned its values (e.g. naming edited label lists "custom").
  void onAssigned(std::function<void(Root&)> fn) { finish_.push_back(std::move(fn)); }

  const std::vector<Param<Root>>& params() const { return params_; }
  const std::vector<Rule<Root>>& rules() const { return rules_; }
  const Param<Root>* find(const std::string& key) const {
    for (const auto& p : params_)
      if (p.info.key == key) return &p;
    return nullptr;
  }
  // Checks the value (kind, range, choices) and writes it; throws InputError for an unknown key or a bad value.
  void assign(Root& root, const std::string& key, const Value& value) const;
  void finishAssignment(Root& root) const {
    for (const auto& fn : finish_) fn(root);
  }
  // Every field in its range, then every rule; throws InputError naming the first that is not.
  void validate(const Root& root) const;

  // This table as a section of Outer, reached through `at`; keys gain "prefix.".
  template <class Outer, class At>
  void nestInto(Table<Outer>& outer, const std::string& prefix, At at) const;

 private:
  std::vector<Param<Root>> params_;
  std::vector<Rule<Root>> rules_;
  std::vector<std::function<void(Root&)>> finish_;
};

[[noreturn]] void fail(const std::string& key, const std::string& rule);
[[noreturn]] void unknownKey(const std::string& key);

template <class Root>
void Table<Root>::assign(Root& root, const std::string& key, const Value& value) const {
  const auto* p = find(key);
  if (!p) unknownKey(key);
  check(p->info, value);
  p->set(root, value);
}

template <class Root>
void Table<Root>::validate(const Root& root) const {
  for (const auto& p : params_) check(p.info, p.get(root));
  for (const auto& r : rules_) {
    if (r.holds(root)) continue;
    std::string keys;
    for (const auto& k : r.keys) keys += (keys.empty() ? "" : " and ") + k;
    fail(keys, r.text);
  }
}

template <class Root>
template <class Outer, class At>
void Table<Root>::nestInto(Table<Outer>& outer, const std::string& prefix, At at) const {
  for (const auto& p : params_) {
    Info info = p.info;
    info.key = prefix + "." + info.key;
    outer.add({std::move(info), [get = p.get, at](const Outer& o) { return get(at(o)); },
               [set = p.set, at](Outer& o, const Value& v) { set(at(o), v); }});
  }
  for (const auto& r : rules_) {
    std::vector<std::string> keys;
    for (const auto& k : r.keys) keys.push_back(prefix + "." + k);
    outer.rule(std::move(keys), r.text, [holds = r.holds, at](const Outer& o) { return holds(at(o)); });
  }
  for (const auto& fn : finish_) outer.onAssigned([fn, at](Outer& o) { fn(at(o)); });
}

// ---- Declaring a setting: the field's type gives its kind. `at` is a generic lambda returning the field,
// `[](auto& c) -> auto& { return c.verify.min_probability; }`, so one accessor serves reading and writing.

template <class T>
struct KindOf;
template <>
struct KindOf<bool> {
  static constexpr Kind value = Kind::kBool;
  using Wire = bool;
};
template <>
struct KindOf<int> {
  static constexpr Kind value = Kind::kInt;
  using Wire = std::int64_t;
};
template <>
struct KindOf<std::uint64_t> {
  static constexpr Kind value = Kind::kUnsigned;
  using Wire = std::uint64_t;
};
template <>
struct KindOf<double> {
  static constexpr Kind value = Kind::kReal;
  using Wire = double;
};
template <>
struct KindOf<std::string> {
  static constexpr Kind value = Kind::kText;
  using Wire = std::string;
};
template <>
struct KindOf<std::vector<std::uint32_t>> {
  static constexpr Kind value = Kind::kIds;
  using Wire = std::vector<std::uint32_t>;
};

template <class Root, class At>
Param<Root> field(std::string key, At at, Range range, std::string doc, std::vector<std::string> choices = {}) {
  using T = std::decay_t<decltype(at(std::declval<Root&>()))>;
  using Wire = typename KindOf<T>::Wire;
  return {Info{std::move(key), KindOf<T>::value, range, std::move(choices), std::move(doc)},
          [at](const Root& r) { return Value(static_cast<Wire>(at(r))); },
          [at](Root& r, const Value& v) { at(r) = static_cast<T>(std::get<Wire>(v)); }};
}

// A text setting stored as an enum: names[i] stands for values[i].
template <class Root, class E, class At>
Param<Root> choice(std::string key, At at, std::vector<std::pair<std::string, E>> names, std::string doc) {
  std::vector<std::string> choices;
  for (const auto& n : names) choices.push_back(n.first);
  return {Info{std::move(key), Kind::kText, {}, std::move(choices), std::move(doc)},
          [at, names](const Root& r) {
            for (const auto& n : names)
              if (n.second == at(r)) return Value(n.first);
            return Value(std::string("?"));
          },
          [at, names](Root& r, const Value& v) {
            for (const auto& n : names)
              if (n.first == std::get<std::string>(v)) at(r) = n.second;
          }};
}

// A duration stored as milliseconds, read and written in `unit_ms` units (1000: seconds); fractions of a
// millisecond are dropped. The range never reaches past 1e12 ms (~30 years), so the conversion cannot overflow.
template <class Root, class At>
Param<Root> duration(std::string key, At at, double unit_ms, Range range, std::string doc) {
  range.hi = std::min(range.hi, 1e12 / unit_ms);
  range.lo = std::max(range.lo, -1e12 / unit_ms);
  return {Info{std::move(key), Kind::kReal, range, {}, std::move(doc)},
          [at, unit_ms](const Root& r) { return Value(static_cast<double>(at(r).count()) / unit_ms); },
          [at, unit_ms](Root& r, const Value& v) {
            at(r) = std::decay_t<decltype(at(r))>(static_cast<long>(std::get<double>(v) * unit_ms));
          }};
}

}  // namespace sglc::params
