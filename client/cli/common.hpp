// The parts every subcommand of `sglc` shares: connection options, query flags, JSON / text output of
// candidates, and the subcommand registry main() dispatches through.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "sglc/client/client.hpp"

namespace sglc::cli {

using json = nlohmann::ordered_json;
namespace sc = sglc::client;
namespace v1 = sglc::v1;

// A mistake in the command line (exit status 2, "see sglc --help").
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// `s` with line breaks turned into spaces, for one-line error messages.
std::string oneLine(std::string s);

// Options shared by every subcommand.
struct Common {
  std::string server = "127.0.0.1:50051";
  std::string token;
  std::string tls_ca;
  double timeout_s = 30;
  bool json = false;
};
void addCommon(CLI::App* app, Common& c);
// Calls that fail with UNAVAILABLE are retried (ConnectOptions::max_attempts) except where max_attempts says.
sc::Client connectClient(const Common& c, std::size_t chunk_bytes = sc::kDefaultChunkBytes, int max_attempts = 5);

// Query options of `ingest --query` and `query`.
struct QueryFlags {
  unsigned top_k = 0;                // 0: the server's default (5)
  std::int64_t exclude_recent = 50;  // the server's default (sglc.proto), sent explicitly
  double exclude_seconds = 0;
  std::string scope = "all";
  std::string sessions;  // comma separated robot/session names
  unsigned candidates = 0;
  bool no_refine = false;
  bool include_rejected = false;
  bool known_loops = false;
  bool evidence = false;
  std::vector<std::int64_t> verify_scan_ids;
  double min_score = 0;
  CLI::Option* min_score_opt = nullptr;
};
void addQueryFlags(CLI::App* app, QueryFlags& q, bool with_rejected);
v1::QueryOptions toQueryOptions(const QueryFlags& q);

json transformJson(const v1::Transform& t);
std::string poseText(const v1::Transform& t);  // translation and yaw, for text output
json evidenceJson(const v1::Evidence& e);
json candidateJson(const v1::Candidate& c);
std::string candidateText(const v1::Candidate& c);
json timingJson(const v1::Timing& t);

// One subcommand: its CLI11 app and what runs when it was chosen (the exit status).
struct Command {
  CLI::App* app = nullptr;
  std::function<int()> run;
};
using Commands = std::vector<Command>;

// The subcommands, by file: ingest.cpp, query.cpp, admin.cpp (maps, robots, sessions, scan, stats, delete,
// backup, create-map), trajectory.cpp.
void addIngest(CLI::App& app, Common& common, Commands& out);
void addQuery(CLI::App& app, Common& common, Commands& out);
void addAdmin(CLI::App& app, Common& common, Commands& out);
void addTrajectory(CLI::App& app, Common& common, Commands& out);

}  // namespace sglc::cli
