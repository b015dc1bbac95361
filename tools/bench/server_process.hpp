// A sglc-server child process for sglc-bench: started on a scratch database, stopped with SIGTERM (graceful
// shutdown) on destruction; and the loopback port and /proc memory figures that go with it.
#pragma once

#include <sys/types.h>

#include <string>

namespace sglc::bench {

// A TCP port on the loopback interface that is free now.
int freePort();

// A server child process on a scratch database; SIGTERM (graceful shutdown) on destruction.
class ServerProcess {
 public:
  // Runs `binary --db DB --listen LISTEN` with stdout and stderr going to `log`.
  ServerProcess(const std::string& binary, const std::string& db, const std::string& listen, const std::string& log);
  ~ServerProcess();
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  pid_t pid() const { return pid_; }
  bool alive() const;

 private:
  pid_t pid_ = -1;
};

// CPU time a process has used so far, ms (user and system, /proc/<pid>/stat), and its minor page faults (pages
// first touched, or reclaimed and touched again); all -1 when they cannot be read.
struct CpuMs {
  double user = -1, system = -1;
  double minor_faults = -1;
  double total() const { return user + system; }
};
CpuMs procCpuMs(pid_t pid);

// kB figures of /proc/<pid>/status ("VmRSS", "VmHWM"); -1 when the field is absent.
long procStatusKb(pid_t pid, const std::string& field);

}  // namespace sglc::bench
