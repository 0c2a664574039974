#include "job/subprocess.h"

#include <fcntl.h>
#include <poll.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

extern char** environ;

namespace collido::job {

std::string describe(const ExitInfo& e) {
  if (e.signal)
    return "killed by signal " + std::to_string(e.signal) + " (" + strsignal(e.signal) + ")";
  return "exit code " + std::to_string(e.exit_code);
}

Expected<std::unique_ptr<Subprocess>> Subprocess::start(const std::vector<std::string>& argv,
                                                        int report_fd,
                                                        const std::string& log_path,
                                                        const std::vector<std::string>& env_overrides) {
  if (argv.empty()) return invalid_argument("no program to start");
  int fds[2];
  if (pipe2(fds, O_CLOEXEC) != 0) return io_error(std::string("pipe: ") + std::strerror(errno));
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  // dup2 clears close-on-exec on the copy: the child keeps report_fd and nothing else of ours.
  posix_spawn_file_actions_adddup2(&actions, fds[1], report_fd);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  if (!log_path.empty()) {
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log_path.c_str(),
                                     O_WRONLY | O_CREAT | O_APPEND, 0644);
    posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  }
  // Nothing else of the parent's reaches the child: a service's sockets
  // (its listening port, its clients) would otherwise stay open in every job.
  posix_spawn_file_actions_addclosefrom_np(&actions, report_fd + 1);
  // The child starts with default signal handling and nothing blocked: a
  // service ignores SIGPIPE and may block signals in its threads, and both
  // would otherwise pass through exec to the job.
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  sigset_t none, defaults;
  sigemptyset(&none);
  sigemptyset(&defaults);
  for (int sig : {SIGPIPE, SIGINT, SIGTERM, SIGHUP, SIGCHLD}) sigaddset(&defaults, sig);
  posix_spawnattr_setsigmask(&attr, &none);
  posix_spawnattr_setsigdefault(&attr, &defaults);
  posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  std::vector<std::string> args = argv;
  std::vector<char*> cargv;
  for (auto& a : args) cargv.push_back(a.data());
  cargv.push_back(nullptr);
  // The environment: the parent's, with the overrides replacing their names.
  std::vector<std::string> env_strings;
  for (char** e = environ; *e; ++e) {
    const std::string entry(*e);
    const std::string name = entry.substr(0, entry.find('='));
    bool overridden = false;
    for (const std::string& o : env_overrides) overridden |= o.substr(0, o.find('=')) == name;
    if (!overridden) env_strings.push_back(entry);
  }
  for (const std::string& o : env_overrides) env_strings.push_back(o);
  std::vector<char*> cenv;
  for (auto& e : env_strings) cenv.push_back(e.data());
  cenv.push_back(nullptr);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, args[0].c_str(), &actions, &attr, cargv.data(), cenv.data());
  posix_spawn_file_actions_destroy(&actions);
  posix_spawnattr_destroy(&attr);
  close(fds[1]);
  if (rc != 0) {
    close(fds[0]);
    return backend_error("cannot start " + args[0] + ": " + std::strerror(rc));
  }
  return std::unique_ptr<Subprocess>(new Subprocess(pid, fds[0]));
}

Subprocess::~Subprocess() {
  if (!reaped_) {
    kill(pid_, SIGKILL);
    int status = 0;
    while (waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
    }
  }
  if (fd_ >= 0) close(fd_);
}

void Subprocess::send_signal(int sig) {
  if (!reaped_) kill(pid_, sig);
}

ExitInfo Subprocess::wait(const std::function<void(const std::string&)>& on_line,
                          const std::atomic<bool>* cancel, int cancel_signal) {
  ExitInfo out;
  if (reaped_) return out;
  bool cancel_sent = false;
  std::string buffer;
  char chunk[4096];
  for (;;) {
    if (cancel && cancel->load() && !cancel_sent) {
      send_signal(cancel_signal);
      cancel_sent = true;
    }
    pollfd p{fd_, POLLIN, 0};
    const int ready = poll(&p, 1, 100);
    if (ready < 0 && errno == EINTR) continue;
    if (ready == 0) continue;
    const ssize_t n = read(fd_, chunk, sizeof chunk);
    if (n < 0 && (errno == EINTR || errno == EAGAIN)) continue;
    if (n <= 0) break;  // the child closed its end: it has ended
    buffer.append(chunk, size_t(n));
    for (size_t nl; (nl = buffer.find('\n')) != std::string::npos; buffer.erase(0, nl + 1))
      if (on_line) on_line(buffer.substr(0, nl));
  }
  int status = 0;
  struct rusage ru {};
  while (wait4(pid_, &status, 0, &ru) < 0 && errno == EINTR) {
  }
  reaped_ = true;
  out.peak_host_bytes = uint64_t(ru.ru_maxrss) * 1024;  // KiB on Linux
  if (WIFEXITED(status)) out.exit_code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) out.signal = WTERMSIG(status);
  return out;
}

}  // namespace collido::job
