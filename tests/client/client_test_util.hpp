// Helpers of the client tests: temporary directories, running a command with captured output, a real
// sglc-server on a free loopback port, and the real loop pair of ../shared/data.
#pragma once

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "sglc/client/client.hpp"
#include "sglc/io.hpp"

extern char** environ;

namespace sglc::client::test {

namespace fs = std::filesystem;

class TempDir {
 public:
  TempDir() {
    std::string pattern = (fs::temp_directory_path() / "sglc-client-test-XXXXXX").string();
    if (!::mkdtemp(pattern.data())) throw std::runtime_error("mkdtemp failed");
    path_ = pattern;
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const fs::path& path() const { return path_; }
  std::string operator/(const std::string& name) const { return (path_ / name).string(); }

 private:
  fs::path path_;
};

inline std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

inline void writeFile(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

inline std::vector<std::string> lines(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream ss(text);
  for (std::string l; std::getline(ss, l);)
    if (!l.empty()) out.push_back(l);
  return out;
}

// Starts `argv` with stdout and stderr sent to files (no shell). Throws when it cannot start.
inline pid_t spawn(const std::vector<std::string>& argv, const std::string& out_path, const std::string& err_path) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, argv[0].c_str(), &actions, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) throw std::runtime_error("cannot start " + argv[0] + ": " + std::strerror(rc));
  return pid;
}

struct RunResult {
  int exit_code = -1;  // -1: killed by a signal
  std::string out, err;
};

// Runs a command to completion (killed after `timeout`, which then fails the caller's checks).
inline RunResult run(const std::vector<std::string>& argv, std::chrono::seconds timeout = std::chrono::seconds(120)) {
  TempDir tmp;
  const std::string out = tmp / "out", err = tmp / "err";
  const pid_t pid = spawn(argv, out, err);
  int status = 0;
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (::waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() > end) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  RunResult r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = readFile(out);
  r.err = readFile(err);
  return r;
}

// A TCP port on 127.0.0.1 that was free a moment ago.
inline int freePort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = 0;
  socklen_t len = sizeof(addr);
  if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0) {
    if (fd >= 0) ::close(fd);
    throw std::runtime_error("no free loopback port");
  }
  const int port = ntohs(addr.sin_port);
  ::close(fd);
  return port;
}

inline std::string cliBinary() { return SGLC_CLI_BIN; }

// The sglc-server binary: $SGLC_SERVER_BIN, else the one of this build tree, else build/bin/sglc-server.
inline std::optional<std::string> serverBinary(std::string* looked_at = nullptr) {
  std::vector<std::string> candidates;
  if (const char* env = std::getenv("SGLC_SERVER_BIN"); env && *env) candidates.push_back(env);
  candidates.push_back(SGLC_SERVER_BIN);
  candidates.push_back(SGLC_SERVER_FALLBACK);
  std::string seen;
  for (const auto& c : candidates) {
    if (::access(c.c_str(), X_OK) == 0) return c;
    seen += (seen.empty() ? "" : ", ") + c;
  }
  if (looked_at) *looked_at = seen;
  return std::nullopt;
}

// A real sglc-server with a fresh database, on a free loopback port, stopped on destruction.
class ServerProcess {
 public:
  // Returns an empty optional (and why) when the binary is absent; throws when it is there but does not come up.
  static std::optional<ServerProcess> start(const std::vector<std::string>& extra_args = {},
                                            std::string* why = nullptr) {
    std::string looked_at;
    const auto binary = serverBinary(&looked_at);
    if (!binary) {
      if (why) *why = "sglc-server not built (looked at " + looked_at + "); end-to-end test skipped";
      return std::nullopt;
    }
    std::optional<ServerProcess> server;
    server.emplace(*binary, extra_args);
    return server;
  }

  ServerProcess(const std::string& binary, const std::vector<std::string>& extra_args)
      : dir_(std::make_unique<TempDir>()) {
    std::string last_log;
    for (int attempt = 0; attempt < 3; ++attempt) {  // the free port may be taken in between: retry
      port_ = freePort();
      std::vector<std::string> argv = {binary, "--db", *dir_ / "map.db", "--listen", address()};
      argv.insert(argv.end(), extra_args.begin(), extra_args.end());
      pid_ = spawn(argv, *dir_ / "server.out", *dir_ / "server.log");
      if (waitUntilServing()) return;
      stop();
      last_log = readFile(*dir_ / "server.log");
    }
    throw std::runtime_error("sglc-server did not start; its log: " + last_log);
  }
  ServerProcess(ServerProcess&& o) noexcept : dir_(std::move(o.dir_)), pid_(o.pid_), port_(o.port_) { o.pid_ = -1; }
  ServerProcess& operator=(ServerProcess&& o) noexcept {
    if (this != &o) {
      stop();
      dir_ = std::move(o.dir_);
      pid_ = o.pid_;
      port_ = o.port_;
      o.pid_ = -1;
    }
    return *this;
  }
  ~ServerProcess() { stop(); }

  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  const TempDir& dir() const { return *dir_; }
  std::string log() const { return readFile(*dir_ / "server.log") + readFile(*dir_ / "server.out"); }

  Client client(const std::string& token = "", std::size_t chunk_bytes = kDefaultChunkBytes) const {
    ConnectOptions o;
    o.token = token;
    o.chunk_bytes = chunk_bytes;
    o.default_deadline = std::chrono::seconds(60);
    return Client::connect(address(), o);
  }

  void stop() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGTERM);
    int status = 0;
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(15);
    while (::waitpid(pid_, &status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() > end) {
        ::kill(pid_, SIGKILL);
        ::waitpid(pid_, &status, 0);
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    pid_ = -1;
  }

 private:
  // Serving = a call gets an answer other than UNAVAILABLE (UNAUTHENTICATED counts: the server is up).
  bool waitUntilServing() {
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (std::chrono::steady_clock::now() < end) {
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        return false;
      }
      try {
        // A fresh channel per attempt: a channel that was refused waits out gRPC's reconnect backoff (~1-5 s).
        Client::connect(address()).listMaps(CallOptions{std::chrono::milliseconds(1000)});
        return true;
      } catch (const RpcError& e) {
        if (e.code() != grpc::StatusCode::UNAVAILABLE && e.code() != grpc::StatusCode::DEADLINE_EXCEEDED) return true;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return false;
  }

  std::unique_ptr<TempDir> dir_;
  pid_t pid_ = -1;
  int port_ = 0;
};

// ---------------------------------------------------------------------------------------------------------
// The real loop pair: KITTI 00 frames 52 and 4501.

inline std::string sharedData() { return SGLC_SHARED_DATA; }
inline std::string sequence00() { return sharedData() + "/semantickitti_scans/sequences/00"; }
inline bool haveRealData() { return fs::is_regular_file(sequence00() + "/velodyne/000052.bin"); }

inline LabelledScan realScan(const std::string& frame) {
  return readScan(sequence00() + "/velodyne/" + frame + ".bin", sequence00() + "/labels/" + frame + ".label");
}

// T_a_b from pairs.txt for 000052 (a) and 004501 (b): maps points of 4501 into 52's frame.
inline std::optional<Mat4d> referenceT52from4501() {
  std::ifstream in(sharedData() + "/semantickitti_scans/pairs.txt");
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    std::string seq, a, b, is_loop, d1, d2, gap;
    ss >> seq >> a >> b >> is_loop >> d1 >> d2 >> gap;
    if (seq != "00" || a != "000052" || b != "004501") continue;
    Mat4d T = Mat4d::Identity();
    for (int k = 0; k < 12; ++k)
      if (!(ss >> T(k / 4, k % 4))) return std::nullopt;
    return T;
  }
  return std::nullopt;
}

// Translation error (m) and rotation error (deg) between two rigid transforms.
inline std::pair<double, double> poseError(const Mat4d& T, const Mat4d& ref) {
  const double t = (T.block<3, 1>(0, 3) - ref.block<3, 1>(0, 3)).norm();
  const Eigen::Matrix3d dR = T.block<3, 3>(0, 0).transpose() * ref.block<3, 3>(0, 0);
  const double c = std::clamp((dR.trace() - 1.0) / 2.0, -1.0, 1.0);
  return {t, std::acos(c) * 180.0 / M_PI};
}

// Pose tolerance of the end-to-end checks: generous against the engine's accuracy (sglc-pair's contract
// test holds 0.10 m / 0.5 deg), far below what a transposed or inverted transform would give (~6 m).
inline constexpr double kMaxTranslationError = 0.2;
inline constexpr double kMaxRotationErrorDeg = 1.0;

}  // namespace sglc::client::test
