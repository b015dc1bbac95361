// Settings tables (sglc/params.hpp) read from and written to YAML, set from the command line and described as a
// Markdown table. A key's dots are YAML's nesting: `verify: {t_g: 0.4}` sets verify.t_g.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "sglc/params.hpp"

namespace sglc::config {

using Entry = std::pair<std::string, params::Value>;

// The values a YAML text gives, in the order of `infos` (so a table decides which keys apply first). Throws
// InputError for text that is not YAML, an unknown section or key, a key given twice, or a value of the wrong
// kind; ranges are the table's to check.
std::vector<Entry> readYaml(const std::vector<params::Info>& infos, const std::string& text);
// One command-line setting "KEY=VALUE": the value in YAML (0.4, true, [40, 44]), text as given.
Entry readSetting(const std::vector<params::Info>& infos, const std::string& key_equals_value);
// YAML that readYaml reads back to the same values (numbers in their shortest exact form).
std::string writeYaml(const std::vector<std::pair<params::Info, params::Value>>& values);
// A Markdown table per section (key, default, valid values, meaning), then the rules between keys.
std::string writeMarkdown(const std::vector<std::pair<params::Info, params::Value>>& defaults,
                          const std::vector<std::pair<std::string, std::string>>& rules);

template <class Root>
std::vector<params::Info> infosOf(const params::Table<Root>& table) {
  std::vector<params::Info> out;
  for (const auto& p : table.params()) out.push_back(p.info);
  return out;
}

template <class Root>
std::vector<std::pair<params::Info, params::Value>> valuesOf(const params::Table<Root>& table, const Root& root) {
  std::vector<std::pair<params::Info, params::Value>> out;
  for (const auto& p : table.params()) out.emplace_back(p.info, p.get(root));
  return out;
}

// Assigns what the YAML text gives (each value range-checked), then the table's after-assignment steps.
template <class Root>
void applyYaml(const params::Table<Root>& table, const std::string& text, Root& root) {
  for (const auto& [key, value] : readYaml(infosOf(table), text)) table.assign(root, key, value);
  table.finishAssignment(root);
}

template <class Root>
void applySetting(const params::Table<Root>& table, const std::string& key_equals_value, Root& root) {
  const auto [key, value] = readSetting(infosOf(table), key_equals_value);
  table.assign(root, key, value);
  table.finishAssignment(root);
}

template <class Root>
std::string dumpYaml(const params::Table<Root>& table, const Root& root) {
  return writeYaml(valuesOf(table, root));
}

template <class Root>
std::string markdownOf(const params::Table<Root>& table, const Root& defaults) {
  std::vector<std::pair<std::string, std::string>> rules;
  for (const auto& r : table.rules()) {
    std::string keys;
    for (const auto& k : r.keys) keys += (keys.empty() ? "`" : "` and `") + k;
    rules.emplace_back(keys + "`", r.text);
  }
  return writeMarkdown(valuesOf(table, defaults), rules);
}

// The contents of a text file of at most 16 MiB; InputError naming the file and `what` it is otherwise.
std::string readTextFile(const std::string& path, const std::string& what = "config file");

}  // namespace sglc::config
