#include "job/subprocess.h"

#include <fcntl.h>
#include <poll.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>

extern char** environ;

namespace collido::job {

namespace {
// The child starts with default signal handling and nothing blocked: a
// service ignores SIGPIPE and may block signals in its threads, and both
// would otherwise pass through exec to the child. own_group: in a process
// group of its own, out of the terminal's reach: Ctrl-C on `serve` reached a
// job in the service's group and killed it (SIGINT's default) before the
// service could stop it to resume later, so the job ended failed. Its parent
// stops it (and PR_SET_PDEATHSIG, should the parent die).
void init_spawn_attr(posix_spawnattr_t* attr, bool own_group) {
  posix_spawnattr_init(attr);
  sigset_t none, defaults;
  sigemptyset(&none);
  sigemptyset(&defaults);
  for (int sig : {SIGPIPE, SIGINT, SIGTERM, SIGHUP, SIGCHLD}) sigaddset(&defaults, sig);
  posix_spawnattr_setsigmask(attr, &none);
  posix_spawnattr_setsigdefault(attr, &defaults);
  short flags = POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF;
  if (own_group) {
    posix_spawnattr_setpgroup(attr, 0);
    flags |= POSIX_SPAWN_SETPGROUP;
  }
  posix_spawnattr_setflags(attr, flags);
}
}  // namespace

std::string describe(const ExitInfo& e) {
  if (e.signal)
    return "killed by signal " + std::to_string(e.signal) + " (" + strsignal(e.signal) + ")";
  return "exit code " + std::to_string(e.exit_code);
}

Expected<std::unique_ptr<Subprocess>> Subprocess::start(const std::vector<std::string>& argv,
                                                        int report_fd, const std::string& log_path,
                                                        const std::vector<std::string>& given_env,
                                                        bool own_group) {
  std::vector<std::string> env_overrides = given_env;
  env_overrides.push_back(std::string(kParentPidVariable) + "=" + std::to_string(getpid()));
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
  posix_spawnattr_t attr;
  init_spawn_attr(&attr, own_group);
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
                          const std::atomic<bool>* cancel, int cancel_signal,
                          double kill_after_s) {
  ExitInfo out;
  if (reaped_) return out;
  bool cancel_sent = false, killed = false;
  std::chrono::steady_clock::time_point cancel_at;
  std::string buffer;
  char chunk[4096];
  for (;;) {
    if (cancel && cancel->load() && !cancel_sent) {
      send_signal(cancel_signal);
      cancel_sent = true;
      cancel_at = std::chrono::steady_clock::now();
    }
    if (cancel_sent && !killed && cancel_signal != SIGKILL &&
        std::chrono::duration<double>(std::chrono::steady_clock::now() - cancel_at).count() >
            kill_after_s) {
      send_signal(SIGKILL);
      killed = true;
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

std::string CommandOutput::describe_failure() const {
  if (timed_out) return "timed out";
  if (truncated) return "wrote more than the 1 MiB read of it";
  std::string last = err.empty() ? out : err;
  while (!last.empty() && (last.back() == '\n' || last.back() == ' ')) last.pop_back();
  if (const size_t nl = last.rfind('\n'); nl != std::string::npos) last = last.substr(nl + 1);
  return describe(exit) + (last.empty() ? "" : ": " + last);
}

Expected<CommandOutput> run_command(const std::vector<std::string>& argv, double timeout_s) {
  if (argv.empty()) return invalid_argument("no program to run");
  int out_pipe[2], err_pipe[2];
  if (pipe2(out_pipe, O_CLOEXEC) != 0) return io_error(std::string("pipe: ") + std::strerror(errno));
  if (pipe2(err_pipe, O_CLOEXEC) != 0) {
    close(out_pipe[0]);
    close(out_pipe[1]);
    return io_error(std::string("pipe: ") + std::strerror(errno));
  }
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_adddup2(&actions, out_pipe[1], STDOUT_FILENO);
  posix_spawn_file_actions_adddup2(&actions, err_pipe[1], STDERR_FILENO);
  // Nothing else of the parent's: an sbatch or squeue still waiting on a slow
  // controller when the service dies would keep its sockets and files open.
  posix_spawn_file_actions_addclosefrom_np(&actions, STDERR_FILENO + 1);
  posix_spawnattr_t attr;
  init_spawn_attr(&attr, /*own_group=*/false);
  std::vector<char*> cargv;
  for (const std::string& a : argv) cargv.push_back(const_cast<char*>(a.c_str()));
  cargv.push_back(nullptr);
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, argv[0].c_str(), &actions, &attr, cargv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  posix_spawnattr_destroy(&attr);
  close(out_pipe[1]);
  close(err_pipe[1]);
  if (rc != 0) {
    close(out_pipe[0]);
    close(err_pipe[0]);
    return backend_error("cannot run " + argv[0] + ": " + std::strerror(rc));
  }
  CommandOutput r;
  constexpr size_t kMaxBytes = size_t(1) << 20;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  pollfd fds[2] = {{out_pipe[0], POLLIN, 0}, {err_pipe[0], POLLIN, 0}};
  std::string* sinks[2] = {&r.out, &r.err};
  int open_fds = 2;
  char chunk[4096];
  while (open_fds > 0) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) {
      kill(pid, SIGKILL);
      r.timed_out = true;
      break;
    }
    const int ready = poll(fds, 2, int(std::min<int64_t>(left.count(), 1000)));
    if (ready < 0 && errno == EINTR) continue;
    if (ready <= 0) continue;
    for (int i = 0; i < 2; ++i) {
      if (fds[i].fd < 0 || !(fds[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
      const ssize_t n = read(fds[i].fd, chunk, sizeof chunk);
      if (n < 0 && (errno == EINTR || errno == EAGAIN)) continue;
      if (n <= 0) {
        close(fds[i].fd);
        fds[i].fd = -1;  // poll() skips negative descriptors
        --open_fds;
        continue;
      }
      if (sinks[i]->size() < kMaxBytes)
        sinks[i]->append(chunk, size_t(n));
      else
        r.truncated = true;
    }
  }
  for (const pollfd& p : fds)
    if (p.fd >= 0) close(p.fd);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (WIFEXITED(status)) r.exit.exit_code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) r.exit.signal = WTERMSIG(status);
  return r;
}

}  // namespace collido::job
