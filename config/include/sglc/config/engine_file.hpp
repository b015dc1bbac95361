// The engine's configuration as YAML: sections mirror the struct (cluster:, graph:, ...). Keys not given keep
// their defaults; unknown keys are an error so that typos do not pass silently.
#pragma once

#include <string>

#include "sglc/config.hpp"

namespace sglc {

Config parseConfig(const std::string& yaml_text);
Config loadConfig(const std::string& path);
// The whole configuration as YAML that parseConfig reads back to the same values.
std::string dumpConfig(const Config& config);

}  // namespace sglc
