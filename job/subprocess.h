// A child process that reports on a pipe: started with posix_spawn (a threaded
// parent such as the service must never fork() a running engine), it writes
// lines to an inherited descriptor (fd 3 by convention), and the parent reads
// them until the child closes it, then reaps the child with wait4() for its
// exit status and resource use. Used by `job-exec` (job/child.h) and by the
// calibration sweep's `calibrate-exec` runs (job/calibrate.h); the protocol
// spoken on the pipe (JSON lines) is theirs.
#pragma once

#include <signal.h>
#include <sys/types.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "common/status.h"

namespace collido::job {

// How a child ended.
struct ExitInfo {
  int exit_code = -1;  // -1 when it ended by a signal
  int signal = 0;      // the signal that ended it, else 0
  // wait4()'s ru_maxrss, bytes. Linux keeps the larger of the child's own
  // peak and the peak of the memory it was spawned from, which is the
  // parent's: it is the child's own only when the parent is smaller.
  uint64_t peak_host_bytes = 0;
};

// "exit code N" or "killed by signal N (Name)", for messages.
std::string describe(const ExitInfo& e);

// The variable a child finds its parent's pid in (Subprocess::start sets it):
// a child that must die with its parent checks it against getppid() after
// PR_SET_PDEATHSIG, which a parent that died before that call escapes.
inline constexpr const char* kParentPidVariable = "COLLIDO_PARENT_PID";

class Subprocess {
 public:
  // Starts argv[0] (a path, not searched in PATH) with argv, the write end of
  // a pipe as report_fd and stdin from /dev/null; stdout and stderr go to
  // log_path (appended) when given, else to the parent's. The environment is
  // the parent's with each "NAME=value" of env_overrides set, and
  // kParentPidVariable. own_group: in a process group of its own, which the
  // terminal's Ctrl-C does not reach (a job the service stops and resumes).
  static Expected<std::unique_ptr<Subprocess>> start(
      const std::vector<std::string>& argv, int report_fd = 3, const std::string& log_path = "",
      const std::vector<std::string>& env_overrides = {}, bool own_group = false);
  ~Subprocess();  // a child still running is killed (SIGKILL) and reaped
  Subprocess(const Subprocess&) = delete;
  Subprocess& operator=(const Subprocess&) = delete;

  // Calls on_line with each line the child writes (without its newline) until
  // the child closes the pipe, then reaps it. Polls `cancel` every 100 ms and
  // sends cancel_signal once it is set, then SIGKILL if the child is still
  // there kill_after_s later (a job answers a cancel between frames, and a
  // frame of a scene with an absurd step count would never end).
  ExitInfo wait(const std::function<void(const std::string&)>& on_line,
                const std::atomic<bool>* cancel = nullptr, int cancel_signal = SIGTERM,
                double kill_after_s = kCancelGraceSeconds);
  static constexpr double kCancelGraceSeconds = 30;
  // Sends sig unless the child has been reaped.
  void send_signal(int sig);
  pid_t pid() const { return pid_; }

 private:
  Subprocess(pid_t pid, int fd) : pid_(pid), fd_(fd) {}
  pid_t pid_;
  int fd_;
  bool reaped_ = false;
};

// A short command's outcome (a scheduler's client: sbatch, squeue, ...).
struct CommandOutput {
  ExitInfo exit;
  std::string out, err;    // its stdout and stderr, each up to 1 MiB
  bool timed_out = false;  // killed at the time limit
  bool truncated = false;  // it wrote more than the 1 MiB kept: what was read is not all it said
  bool ok() const { return !timed_out && !truncated && exit.exit_code == 0; }
  // "exit code N: <stderr's last line>" (or timed out), for messages.
  std::string describe_failure() const;
};

// Runs argv (argv[0] found in PATH when it has no slash) with stdin from
// /dev/null, to its end or until timeout_s passes (then SIGKILL). Posix_spawn,
// as above: safe from a threaded server. Fails only when it cannot start.
Expected<CommandOutput> run_command(const std::vector<std::string>& argv, double timeout_s);

}  // namespace collido::job
