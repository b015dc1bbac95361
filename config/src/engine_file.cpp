#include "sglc/config/engine_file.hpp"

#include "sglc/config/settings_file.hpp"
#include "sglc/types.hpp"

namespace sglc {

Config parseConfig(const std::string& yaml_text) {
  Config config;
  config::applyYaml(engineParams(), yaml_text, config);
  validateConfig(config);
  return config;
}

Config loadConfig(const std::string& path) {
  const auto text = config::readTextFile(path);
  try {
    return parseConfig(text);
  } catch (const InputError& e) {
    throw InputError(path + ": " + e.what());
  }
}

std::string dumpConfig(const Config& config) { return config::dumpYaml(engineParams(), config); }

}  // namespace sglc
