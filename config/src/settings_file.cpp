#include "sglc/config/settings_file.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>

#include "sglc/types.hpp"

namespace sglc::config {
namespace {

using params::Info;
using params::Kind;
using params::Value;

bool isSection(const std::vector<Info>& infos, const std::string& path) {
  for (const auto& i : infos)
    if (i.key.size() > path.size() && i.key.compare(0, path.size(), path) == 0 && i.key[path.size()] == '.')
      return true;
  return false;
}

// The names one level below `prefix` ("" for the top), for messages.
std::string sectionsBelow(const std::vector<Info>& infos, const std::string& prefix) {
  std::string out;
  std::vector<std::string> seen;
  for (const auto& i : infos) {
    if (!prefix.empty() && i.key.compare(0, prefix.size() + 1, prefix + ".") != 0) continue;
    const auto rest = prefix.empty() ? i.key : i.key.substr(prefix.size() + 1);
    const auto name = rest.substr(0, rest.find('.'));
    if (std::find(seen.begin(), seen.end(), name) != seen.end()) continue;
    seen.push_back(name);
    out += (out.empty() ? "" : ", ") + name;
  }
  return out;
}

// Collects the leaves of a mapping by their dotted key.
void collect(const std::vector<Info>& infos, const YAML::Node& map, const std::string& prefix,
             std::map<std::string, YAML::Node>& leaves) {
  const std::string where = prefix.empty() ? "the top level" : "section '" + prefix + "'";
  for (const auto& item : map) {
    if (!item.first.IsScalar()) throw InputError("config: " + where + " has a key that is not a plain name");
    const auto path = prefix.empty() ? item.first.Scalar() : prefix + "." + item.first.Scalar();
    const bool leaf = std::any_of(infos.begin(), infos.end(), [&](const Info& i) { return i.key == path; });
    if (leaf) {
      if (!leaves.emplace(path, item.second).second) throw InputError("config: '" + path + "' is given twice");
    } else if (isSection(infos, path)) {
      if (!item.second.IsMap()) throw InputError("config: section '" + path + "' must be a mapping");
      collect(infos, item.second, path, leaves);
    } else if (item.second.IsMap()) {
      throw InputError("config: unknown section '" + path + "' (known: " + sectionsBelow(infos, prefix) + ")");
    } else {
      throw InputError("config: unknown parameter '" + path + "'");
    }
  }
}

Value convert(const Info& info, const YAML::Node& node) {
  switch (info.kind) {
    case Kind::kBool:
      return node.as<bool>();
    case Kind::kInt:
      return node.as<std::int64_t>();
    case Kind::kUnsigned:
      return node.as<std::uint64_t>();
    case Kind::kReal:
      return node.as<double>();
    case Kind::kText:
      if (!node.IsScalar()) throw InputError("config: " + info.key + " must be text");
      return node.as<std::string>();
    case Kind::kIds:
      return node.as<std::vector<std::uint32_t>>();
    case Kind::kNamedIds: {
      if (!node.IsSequence()) throw InputError("config: " + info.key + " must be a list of {name, ids}");
      std::vector<params::NamedIds> out;
      for (const auto& entry : node)
        out.push_back({entry["name"].as<std::string>(), entry["ids"].as<std::vector<std::uint32_t>>()});
      return out;
    }
  }
  throw InputError("config: " + info.key + ": unknown kind");
}

Value convertChecked(const Info& info, const YAML::Node& node) {
  try {
    return convert(info, node);
  } catch (const YAML::Exception& e) {
    throw InputError("config: bad value for '" + info.key + "': " + e.what());
  }
}

void emit(YAML::Emitter& out, const Value& value) {
  if (const auto* b = std::get_if<bool>(&value)) {
    out << *b;
  } else if (const auto* s = std::get_if<std::string>(&value)) {
    out << *s;
  } else if (const auto* ids = std::get_if<std::vector<std::uint32_t>>(&value)) {
    out << YAML::Flow << *ids;
  } else if (const auto* named = std::get_if<std::vector<params::NamedIds>>(&value)) {
    out << YAML::BeginSeq;
    for (const auto& n : *named)
      out << YAML::Flow << YAML::BeginMap << YAML::Key << "name" << YAML::Value << n.name << YAML::Key << "ids"
          << YAML::Value << YAML::Flow << n.ids << YAML::EndMap;
    out << YAML::EndSeq;
  } else {
    out << params::format(value);  // numbers: the shortest text that reads back to the same value
  }
}

std::string cell(const std::string& text) {
  std::string out;
  for (char c : text) out += c == '|' ? std::string("\\|") : std::string(1, c);
  return out;
}

std::string validText(const Info& info) {
  if (!info.choices.empty()) {
    std::string s;
    for (const auto& c : info.choices) s += (s.empty() ? "" : ", ") + c;
    return s;
  }
  switch (info.kind) {
    case Kind::kInt:
    case Kind::kUnsigned:
    case Kind::kReal:
      return info.kind == Kind::kReal ? info.range.text() : "integer " + info.range.text();
    default:
      return params::kindName(info.kind);
  }
}

}  // namespace

std::vector<Entry> readYaml(const std::vector<Info>& infos, const std::string& text) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw InputError(std::string("config: not valid YAML: ") + e.what());
  }
  if (root.IsNull()) return {};
  if (!root.IsMap()) throw InputError("config: the top level must be a mapping of sections");
  std::map<std::string, YAML::Node> leaves;
  collect(infos, root, "", leaves);
  std::vector<Entry> out;
  for (const auto& info : infos)
    if (const auto it = leaves.find(info.key); it != leaves.end())
      out.emplace_back(info.key, convertChecked(info, it->second));
  return out;
}

Entry readSetting(const std::vector<Info>& infos, const std::string& key_equals_value) {
  const auto eq = key_equals_value.find('=');
  if (eq == std::string::npos) throw InputError("config: '" + key_equals_value + "' is not KEY=VALUE");
  const auto key = key_equals_value.substr(0, eq);
  const auto it = std::find_if(infos.begin(), infos.end(), [&](const Info& i) { return i.key == key; });
  if (it == infos.end() && isSection(infos, key))
    throw InputError("config: '" + key + "' is a section, not a key (its keys: " + sectionsBelow(infos, key) + ")");
  if (it == infos.end()) throw InputError("config: unknown parameter '" + key + "'");
  if (it->kind == Kind::kText) return {key, key_equals_value.substr(eq + 1)};  // as given: paths may hold '#', ': '
  YAML::Node node;
  try {
    node = YAML::Load(key_equals_value.substr(eq + 1));
  } catch (const YAML::Exception& e) {
    throw InputError("config: bad value for '" + key + "': " + e.what());
  }
  return {key, convertChecked(*it, node)};
}

std::string writeYaml(const std::vector<std::pair<Info, Value>>& values) {
  YAML::Emitter out;
  out << YAML::BeginMap;
  std::vector<std::string> open;  // the sections the emitter is inside
  for (const auto& [info, value] : values) {
    std::vector<std::string> parts;
    for (std::size_t a = 0, b; a <= info.key.size(); a = b + 1) {
      b = std::min(info.key.find('.', a), info.key.size());
      parts.push_back(info.key.substr(a, b - a));
    }
    std::size_t common = 0;
    while (common < open.size() && common + 1 < parts.size() && open[common] == parts[common]) ++common;
    for (; open.size() > common; open.pop_back()) out << YAML::EndMap;
    for (; open.size() + 1 < parts.size(); open.push_back(parts[open.size()]))
      out << YAML::Key << parts[open.size()] << YAML::Value << YAML::BeginMap;
    out << YAML::Key << parts.back() << YAML::Value;
    emit(out, value);
  }
  for (; !open.empty(); open.pop_back()) out << YAML::EndMap;
  out << YAML::EndMap;
  return std::string(out.c_str()) + "\n";
}

std::string writeMarkdown(const std::vector<std::pair<Info, Value>>& defaults,
                          const std::vector<std::pair<std::string, std::string>>& rules) {
  std::ostringstream md;
  std::optional<std::string> section;  // the one whose table is open
  for (const auto& [info, value] : defaults) {
    const auto dot = info.key.rfind('.');
    const auto sec = dot == std::string::npos ? std::string() : info.key.substr(0, dot);
    if (sec != section) {
      md << (section ? "\n" : "") << (sec.empty() ? "### Top level" : "### `" + sec + "`") << "\n\n"
         << "| Key | Default | Valid values | Meaning |\n|---|---|---|---|\n";
      section = sec;
    }
    md << "| `" << info.key.substr(dot + 1) << "` | ";
    if (const auto shown = params::format(value); !shown.empty()) md << '`' << cell(shown) << '`';
    md << " | " << cell(validText(info)) << " | " << cell(info.doc) << " |\n";
  }
  if (!rules.empty()) {
    md << "\n### Rules between keys\n\n";
    for (const auto& [keys, text] : rules) md << "- " << keys << " must be " << cell(text) << "\n";
  }
  return md.str();
}

std::string readTextFile(const std::string& path, const std::string& what) {
  constexpr std::size_t kMaxBytes = 16 << 20;
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path + ": cannot open " + what);
  // Read in blocks up to the bound, so /dev/zero or a runaway pipe ends with an error instead of all memory.
  std::string text;
  char block[65536];
  while (in.read(block, sizeof block) || in.gcount() > 0) {
    text.append(block, static_cast<std::size_t>(in.gcount()));
    if (text.size() > kMaxBytes) throw InputError(path + ": " + what + " larger than 16 MiB");
  }
  if (in.bad()) throw InputError(path + ": cannot read " + what);
  return text;
}

}  // namespace sglc::config
