// Administration of the PostgreSQL map database: backups with pg_dump, a consistency check, statistics.
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <utility>

#include "pg_parts.hpp"
#include "validate.hpp"

extern char** environ;

namespace sglc::storage::pg::admin {
namespace {

namespace fs = std::filesystem;
using Code = StorageError::Code;

// The environment for a libpq client program: ours (PG* variables included, as the store's own connections
// see them), with the URL's settings as PG* variables over them, so that the password never appears on a
// command line.
std::vector<std::string> clientEnvironment(const std::string& url) {
  char* error = nullptr;
  PQconninfoOption* options = PQconninfoParse(url.c_str(), &error);
  PQfreemem(error);
  std::vector<std::string> from_url;
  for (auto* o = options; o && o->keyword; ++o)
    if (o->val && o->envvar) from_url.push_back(std::string(o->envvar) + "=" + o->val);
  PQconninfoFree(options);
  std::vector<std::string> env;
  for (char** e = environ; *e; ++e) {
    const std::string var(*e);
    const auto name = var.substr(0, var.find('=') + 1);
    if (std::none_of(from_url.begin(), from_url.end(), [&](const auto& u) { return u.rfind(name, 0) == 0; }))
      env.push_back(var);
  }
  env.insert(env.end(), from_url.begin(), from_url.end());
  return env;
}

// Runs `argv` with `env`; returns its exit status (-1 if it could not start) and what it wrote to stderr.
std::pair<int, std::string> run(const std::vector<std::string>& argv, const std::vector<std::string>& env) {
  std::array<int, 2> pipe_fds{};
  if (::pipe2(pipe_fds.data(), O_CLOEXEC) != 0) return {-1, std::strerror(errno)};
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, pipe_fds[1], STDERR_FILENO);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
  std::vector<char*> args, envp;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  for (const auto& e : env) envp.push_back(const_cast<char*>(e.c_str()));
  args.push_back(nullptr);
  envp.push_back(nullptr);
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, args[0], &actions, nullptr, args.data(), envp.data());
  posix_spawn_file_actions_destroy(&actions);
  ::close(pipe_fds[1]);
  std::string err;
  if (rc == 0) {
    std::array<char, 4096> buf{};
    for (ssize_t n; (n = ::read(pipe_fds[0], buf.data(), buf.size())) != 0;)
      if (n > 0)
        err.append(buf.data(), static_cast<std::size_t>(n));
      else if (errno != EINTR)
        break;
  } else {
    err = argv[0] + ": " + std::strerror(rc);
  }
  ::close(pipe_fds[0]);
  int status = 0;
  if (rc != 0 || ::waitpid(pid, &status, 0) < 0) return {-1, err};
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, err};
}

// The count `query` returns, as a line of the report when it is not 0.
void count(const Conn& db, const char* query, const char* what, std::string& report) {
  const auto n = db.query(query).i64(0, 0);
  if (n != 0) report += (report.empty() ? "" : "\n") + std::to_string(n) + " " + what;
}

}  // namespace

void backup(const Core& core, const std::string& dest) {
  validate::claimBackupFile(dest);
  const auto [status, err] = run({"pg_dump", "--format=custom", "--no-owner", "--no-password", "--file=" + dest},
                                 clientEnvironment(core.options.path));
  if (status != 0) {
    std::error_code ec;
    fs::remove(dest, ec);
    throw StorageError(status < 0 ? Code::kIo : Code::kUnavailable, "the backup could not be written (pg_dump failed)",
                       "pg_dump: " + err);
  }
}

std::string integrityCheck(const Core& core) {
  auto db = core.readers.acquire();
  std::string report;
  count(*db, "SELECT count(*) FROM scans s LEFT JOIN scan_blobs b ON b.scan_id = s.id WHERE b.scan_id IS NULL",
        "scans have no fingerprint", report);
  count(
      *db,
      "SELECT count(*) FROM scans s JOIN maps m ON m.id = s.map_id WHERE length(s.descriptor) <> 4 * m.descriptor_dim",
      "scans have a descriptor of the wrong length", report);
  count(*db,
        "SELECT count(*) FROM scans s JOIN sessions x ON x.id = s.session_id JOIN robots r ON r.id = x.robot_id"
        " WHERE r.id <> s.robot_id OR r.map_id <> s.map_id",
        "scans belong to a session of another robot or map", report);
  count(*db,
        "SELECT count(*) FROM loops l JOIN scans a ON a.id = l.query_scan JOIN scans b ON b.id = l.candidate_scan"
        " WHERE a.map_id <> l.map_id OR b.map_id <> l.map_id OR length(l.t) <> 96",
        "loops join scans of another map or have a damaged transform", report);
  count(*db, "SELECT count(*) FROM optimised_poses WHERE length(pose) <> 96", "optimised poses are damaged", report);
  count(*db, "SELECT count(*) FROM session_frames WHERE length(t) <> 96", "session frames are damaged", report);
  return report.empty() ? "ok" : report;
}

std::int64_t databaseBytes(const Conn& conn) {
  return conn
      .query(
          "SELECT coalesce(sum(pg_total_relation_size(c.oid)), 0)::bigint FROM pg_class c"
          " JOIN pg_namespace n ON n.oid = c.relnamespace WHERE n.nspname = current_schema() AND c.relkind = 'r'")
      .i64(0, 0);
}

Stats stats(const Core& core, const std::string& map) {
  Stats s;
  std::int64_t map_id = -1;
  {
    std::shared_lock lock(core.state_mutex);
    map_id = core.catalogue.count(map, s);
  }
  auto db = core.readers.acquire();
  const auto r = db->query(
      "SELECT count(*), coalesce(sum(fingerprint_bytes), 0)::bigint FROM scans WHERE $1::bigint < 0 OR map_id = $1",
      {map_id});
  s.scans = r.i64(0, 0);
  s.fingerprint_bytes = r.i64(0, 1);
  s.db_bytes = databaseBytes(*db);
  places::count(*db, map_id, s);
  core.cache.report(s);
  return s;
}

}  // namespace sglc::storage::pg::admin
