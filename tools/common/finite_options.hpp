// NaN and infinity refused on a CLI11 command line, for every option at once.
//
// CLI11's Range, PositiveNumber and NonNegativeNumber checks compare with < and >, which NaN passes, and a
// program's own "not given" markers (-1, 1e9) are usually tested the same way: "nan" would run as whatever those
// comparisons make of it, silently. Call after parsing:
//
//   if (const auto problem = sglc::tools::nonFiniteValue(app); !problem.empty()) { ...; return 2; }
#pragma once

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdlib>
#include <string>

namespace sglc::tools {

// The first value given to a floating-point option (CLI11's type name FLOAT) that reads in full as a NaN or
// infinite number, named with its option, or "". Text options are not looked at: "nan" is a fine directory name.
inline std::string nonFiniteValue(const CLI::App& app) {
  for (const CLI::Option* opt : app.get_options()) {
    if (opt->get_type_name().rfind("FLOAT", 0) != 0) continue;
    for (const std::string& text : opt->results()) {
      char* end = nullptr;
      const double v = std::strtod(text.c_str(), &end);
      if (end != text.c_str() && *end == '\0' && !std::isfinite(v))
        return opt->get_name() + " must be a finite number, got '" + text + "'";
    }
  }
  return "";
}

}  // namespace sglc::tools
