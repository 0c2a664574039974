#include "job/child.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <nlohmann/json.hpp>

extern char** environ;

namespace collido::job {

using json = nlohmann::json;

namespace {
constexpr int kProgressFd = 3;

ErrorCode code_from_name(const std::string& name) {
  for (ErrorCode c : {ErrorCode::kOk, ErrorCode::kInvalidArgument, ErrorCode::kNotFound,
                      ErrorCode::kIo, ErrorCode::kParse, ErrorCode::kResourceExhausted,
                      ErrorCode::kCancelled, ErrorCode::kBackend})
    if (name == to_string(c)) return c;
  return ErrorCode::kBackend;
}

Stage stage_from_name(const std::string& name) {
  for (Stage s : {Stage::kPrepare, Stage::kSimulate, Stage::kRender, Stage::kDone})
    if (name == to_string(s)) return s;
  return Stage::kPrepare;
}
}  // namespace

std::string progress_line(const Progress& p) {
  return json{{"stage", to_string(p.stage)}, {"done", p.done},         {"total", p.total},
              {"elapsed_s", p.elapsed_s},    {"eta_s", p.eta_s},       {"steps", p.steps},
              {"sim_time", p.sim_time},      {"contacts", p.contacts}}
             .dump() +
         "\n";
}
std::string note_line(const std::string& note) { return json{{"note", note}}.dump() + "\n"; }
std::string status_line(const Status& s) {
  return json{{"status", to_string(s.code())}, {"message", s.message()}}.dump() + "\n";
}

Expected<std::unique_ptr<ChildJob>> ChildJob::start(const std::string& executable,
                                                    const std::string& spec_path,
                                                    const std::string& log_path) {
  int fds[2];
  if (pipe2(fds, O_CLOEXEC) != 0) return io_error(std::string("pipe: ") + std::strerror(errno));
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  // dup2 clears close-on-exec on the copy: the child keeps fd 3 and nothing else of ours.
  posix_spawn_file_actions_adddup2(&actions, fds[1], kProgressFd);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  if (!log_path.empty()) {
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log_path.c_str(),
                                     O_WRONLY | O_CREAT | O_APPEND, 0644);
    posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  }
  const std::string fd_text = std::to_string(kProgressFd);
  std::vector<std::string> args = {executable, "job-exec", spec_path, "--progress-fd", fd_text};
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, executable.c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  close(fds[1]);
  if (rc != 0) {
    close(fds[0]);
    return backend_error("cannot start " + executable + ": " + std::strerror(rc));
  }
  return std::unique_ptr<ChildJob>(new ChildJob(pid, fds[0]));
}

ChildJob::~ChildJob() {
  if (!reaped_) {
    kill(pid_, SIGKILL);
    int status = 0;
    while (waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
    }
  }
  if (fd_ >= 0) close(fd_);
}

void ChildJob::request_cancel() {
  if (!reaped_) kill(pid_, SIGTERM);
}

ChildResult ChildJob::wait(const std::function<void(const Progress&)>& on_progress,
                           const std::atomic<bool>* cancel) {
  ChildResult out;
  bool have_status = false, cancel_sent = false;
  std::string buffer;
  char chunk[4096];
  for (;;) {
    if (cancel && cancel->load() && !cancel_sent) {
      request_cancel();
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
    for (size_t nl; (nl = buffer.find('\n')) != std::string::npos; buffer.erase(0, nl + 1)) {
      const json j = json::parse(buffer.substr(0, nl), nullptr, false);
      if (!j.is_object()) continue;  // not ours: ignore rather than trust
      if (j.contains("note") && j["note"].is_string()) {
        out.notes.push_back(j["note"].get<std::string>());
      } else if (j.contains("status") && j["status"].is_string()) {
        const std::string msg = j.value("message", std::string());
        out.status = Status(code_from_name(j["status"].get<std::string>()), msg);
        have_status = true;
      } else if (j.contains("stage") && on_progress) {
        Progress pr;
        pr.stage = stage_from_name(j.value("stage", std::string()));
        pr.done = j.value("done", uint64_t(0));
        pr.total = j.value("total", uint64_t(0));
        pr.elapsed_s = j.value("elapsed_s", 0.0);
        pr.eta_s = j.value("eta_s", -1.0);
        pr.steps = j.value("steps", uint64_t(0));
        pr.sim_time = j.value("sim_time", 0.0);
        pr.contacts = j.value("contacts", uint64_t(0));
        on_progress(pr);
      }
    }
  }
  int status = 0;
  struct rusage ru {};
  while (wait4(pid_, &status, 0, &ru) < 0 && errno == EINTR) {
  }
  reaped_ = true;
  out.peak_host_bytes = uint64_t(ru.ru_maxrss) * 1024;
  if (WIFEXITED(status)) out.exit_code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) out.signal = WTERMSIG(status);
  if (!have_status) {
    if (out.signal)
      out.status = backend_error("the job process was killed by signal " +
                                 std::to_string(out.signal) + " (" + strsignal(out.signal) + ")");
    else
      out.status = backend_error("the job process ended (exit code " +
                                 std::to_string(out.exit_code) + ") without a status");
  }
  return out;
}

}  // namespace collido::job
