// A job in a child process of its own: `collidoscope job-exec SPEC.json
// --progress-fd 3`, started with posix_spawn (a threaded parent such as the
// service must never fork() a running engine). The child writes one JSON
// line per progress report, note and final status to the pipe on fd 3; the
// parent reads them, can cancel (SIGTERM, which the child turns into its
// cancellation flag), and takes the child's peak memory from wait4().
#pragma once

#include <sys/types.h>

#include <atomic>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "common/status.h"
#include "job/job.h"
#include "job/subprocess.h"

namespace collido::job {

// One line of the progress protocol, as the child writes it; peak_host_bytes
// (the child's own peak so far) is left out when 0.
std::string progress_line(const Progress& p, uint64_t peak_host_bytes = 0);
std::string note_line(const std::string& note);
std::string status_line(const Status& s);

// One line read back: what the parent (a worker, or the Slurm executor reading
// a cluster job's progress file) learns from it. Lines that are not the
// protocol's are kNone, ignored rather than trusted.
struct ReportLine {
  enum class Kind { kNone, kProgress, kNote, kStatus } kind = Kind::kNone;
  Progress progress;
  uint64_t peak_host_bytes = 0;  // with a progress line, when the child sent it
  std::string note;
  Status status;
};
ReportLine parse_report_line(const std::string& line);

struct ChildResult {
  Status status;                 // the job's own status, or why the child failed
  int exit_code = -1;            // -1 when it ended by a signal
  int signal = 0;                // the signal that ended it, else 0
  uint64_t peak_host_bytes = 0;  // the child's peak resident set (wait4)
  std::vector<std::string> notes;
};

class ChildJob {
 public:
  // Starts `executable job-exec spec_path --progress-fd 3`; its stdout and
  // stderr go to log_path (appended) when given, else to the parent's;
  // env_overrides ("NAME=value") change its environment (a worker's GPU:
  // CUDA_VISIBLE_DEVICES).
  static Expected<std::unique_ptr<ChildJob>> start(const std::string& executable,
                                                   const std::string& spec_path,
                                                   const std::string& log_path = "",
                                                   const std::vector<std::string>& env_overrides = {});
  ~ChildJob();  // a child still running is killed and reaped

  // Reads the child's reports until it exits, calling on_progress for each;
  // polls `cancel` every 100 ms and asks the child to stop once it is set.
  ChildResult wait(const std::function<void(const Progress&)>& on_progress,
                   const std::atomic<bool>* cancel = nullptr);
  // Asks the child to stop at its next frame (SIGTERM).
  void request_cancel();
  pid_t pid() const { return process_->pid(); }

 private:
  explicit ChildJob(std::unique_ptr<Subprocess> process) : process_(std::move(process)) {}
  std::unique_ptr<Subprocess> process_;
};

}  // namespace collido::job
