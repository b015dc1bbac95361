// `sglc`: the command-line client of the sglc.v1 service. Each subcommand lives in its own file (common.hpp
// lists them); main() builds the command line, names an unknown subcommand, and maps errors to exit codes:
// 2 for a usage mistake, 1 for a failed call or a bad file.
#include <iostream>

#include "common.hpp"
#include "sglc/version.hpp"

namespace {

using namespace sglc::cli;

// CLI11 reports an unknown subcommand as "A subcommand is required"; this names it instead (or returns "").
std::string unknownSubcommand(CLI::App& app, int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--server" || arg == "--token" || arg == "--tls-ca" || arg == "--timeout") {
      ++i;  // its value
      continue;
    }
    if (!arg.empty() && arg[0] == '-') continue;
    std::string names;
    for (const auto* sub : app.get_subcommands({})) {
      if (sub->get_name() == arg) return "";
      names += (names.empty() ? "" : ", ") + sub->get_name();
    }
    return "unknown subcommand '" + oneLine(arg) + "' (expected one of " + names + ")";
  }
  return "";
}

int run(const Commands& commands, const Common& common) {
  try {
    for (const auto& c : commands)
      if (*c.app) return c.run();
    throw UsageError("no subcommand");
  } catch (const UsageError& e) {
    std::cerr << "sglc: error: " << oneLine(e.what()) << " (see sglc --help)" << std::endl;
    return 2;
  } catch (const sc::RpcError& e) {
    std::cerr << "sglc: error: " << oneLine(e.what()) << " [server " << common.server << "]" << std::endl;
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "sglc: error: " << oneLine(e.what()) << std::endl;
    return 1;
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"sglc: client of the SGLC LiDAR loop-closure service"};
  app.set_version_flag("--version", std::string("sglc ") + sglc::kVersion);
  app.require_subcommand(1);
  Common common;
  if (const char* s = std::getenv("SGLC_SERVER"); s && *s) common.server = s;
  if (const char* t = std::getenv("SGLC_TOKEN"); t && *t) common.token = t;
  addCommon(&app, common);
  Commands commands;
  addIngest(app, common, commands);
  addQuery(app, common, commands);
  addAdmin(app, common, commands);
  addTrajectory(app, common, commands);

  if (const std::string unknown = unknownSubcommand(app, argc, argv); !unknown.empty()) {
    std::cerr << "sglc: error: " << unknown << std::endl;
    return 2;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "sglc: error: " << oneLine(e.what()) << " (see sglc --help)" << std::endl;
    return 2;
  }
  return run(commands, common);
}
