// The Slurm executor: each queued job becomes an `sbatch --parsable` submission
// whose batch script runs `collidoscope job-exec` on a node, in the job's folder
// under the service's data directory (a filesystem the nodes share). One thread
// follows the cluster: it submits what is queued, reads each job's progress
// file, asks `squeue` for the state of every job it follows (`sacct` for jobs
// the controller has forgotten, where accounting exists), cancels with
// `scancel`, and ends a job from the scheduler's final state and reason.
//
// What the scheduler decides is the scheduler's: a job over its time limit or
// memory ends failed with Slurm's reason; a preempted or requeued job (--requeue)
// starts again on some node and continues from its last checkpoint
// (`job-exec --resume`). The service keeps each job's Slurm id in the store, so a
// restarted service follows its jobs again, and several service replicas on one
// store follow the same jobs without ending one twice (Store::finish_job).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "job/job.h"
#include "job/subprocess.h"
#include "service/executor.h"

namespace collido::service {

class JobService;

struct SlurmConfig {
  std::string partition;  // sbatch --partition ("" = the cluster's default)
  std::string account;    // sbatch --account ("" = the user's default)
  // The nodes have GPUs: a job whose backend is "auto" runs on CUDA, and a CUDA
  // job asks for `gres` (sbatch --gres).
  bool gpus = false;
  std::string gres = "gpu:1";
  int cpus = 4;  // sbatch --cpus-per-task, and the job's threads
  std::vector<std::string> extra_args;  // more sbatch flags, passed as given
  // The time limit: the predicted total time's 90th percentile × time_factor +
  // time_margin_s, or default_time_limit_s where no time is predicted; whole
  // minutes (Slurm's unit), at least one.
  double time_factor = 2.0;
  double time_margin_s = 300;
  double default_time_limit_s = 3600;
  // The memory request: the job's admitted memory × mem_factor + mem_margin_bytes.
  // The margin also covers the renderer where no cost model prices the job: the
  // engine's own estimate leaves it out, and a 720p render in three formats
  // measured 0.33 GB more than that estimate.
  double mem_factor = 1.25;
  uint64_t mem_margin_bytes = uint64_t(1) << 30;
  bool requeue = true;        // preempted or failed-node jobs go back to the queue
  double poll_s = 2;          // how often squeue is asked
  double command_timeout_s = 30;  // for each sbatch/squeue/scancel call
  // A job the store says is running but has no Slurm id (a service that died
  // between sbatch and recording the id, or another replica submitting it now)
  // is looked for by name after this long, and submitted again if not found.
  double orphan_grace_s = 60;
};

// What the scheduler said of one job.
struct SlurmJobState {
  std::string state;   // PENDING, RUNNING, COMPLETED, TIMEOUT, ... ("" = unknown)
  std::string reason;  // Slurm's reason ("TimeLimit", "Priority", "None", ...)
  std::string exit_code;  // "N:S" where known
};

// Slurm's states, sorted into what the service does with them.
enum class SlurmPhase { kWaiting, kRunning, kEnded, kUnknown };
SlurmPhase slurm_phase(const std::string& state);

// The service's view of a job the scheduler ended: state (done | failed |
// cancelled) and the message a user reads. `job_status` is what job-exec
// reported last (its status line), when it got that far.
struct SlurmOutcome {
  std::string state, error;
};
SlurmOutcome slurm_outcome(const SlurmJobState& s, const std::optional<Status>& job_status,
                           bool cancel_requested, int time_limit_min);

// Parses `squeue --format=%i|%j|%T|%r` lines into id -> (name, state).
struct SqueueRow {
  std::string id, name;
  SlurmJobState state;
};
std::vector<SqueueRow> parse_squeue(const std::string& text);

// The sbatch request of one job: time limit (minutes) and memory (MiB).
struct SlurmRequest {
  int time_limit_min = 1;
  uint64_t mem_mib = 1;
};
SlurmRequest slurm_request(const SlurmConfig& c, const Job& j);

// Whether a Slurm command failed for want of an answer: it timed out, was
// killed, or the controller or accounting daemon did not answer (busy,
// restarting), as opposed to a refusal (a bad account, partition or limit; no
// accounting). An sbatch so failed may have queued the job all the same.
bool scheduler_unreachable(const job::CommandOutput& out);

class SlurmExecutor final : public Executor {
 public:
  // Checks that the scheduler answers (squeue), then starts following.
  static Expected<std::unique_ptr<SlurmExecutor>> start(JobService* service, SlurmConfig config);
  ~SlurmExecutor() override;
  void notify() override;
  void cancel(const Job& job) override;
  void stop() override;
  int size() const override { return 0; }

 private:
  SlurmExecutor(JobService* service, SlurmConfig config);
  void loop();
  void submit_queued();
  void submit(const Job& j);
  void follow();
  // Reads what the job wrote to its progress file since the last look.
  void read_progress(const Job& j);
  // The state of a job the controller no longer lists (sacct, where accounting exists).
  // The job's state from accounting; *answered false when sacct got no
  // answer (the job may be alive: look again later).
  SlurmJobState ask_sacct(const std::string& id, bool* answered);
  void end(const Job& j, const SlurmJobState& s);

  JobService* service_;
  SlurmConfig config_;
  std::thread thread_;
  std::mutex mu_;
  std::condition_variable wake_;
  bool stopping_ = false;
  bool woken_ = false;
  // Per followed job: how far its progress file was read, what it last said.
  struct Followed {
    uint64_t offset = 0;
    std::optional<Status> status;  // job-exec's last status line
    job::Progress last;
    uint64_t peak_host_bytes = 0;
    std::string stage;             // as last written to the store
    double progress = -1;
    int render = -1;               // the job renders (1) or not (0); -1: not read yet
    bool cancel_sent = false;
    double ended_seen_at = 0;      // when an end state was first seen (0: not seen)
  };
  std::map<std::string, Followed> followed_;  // by service job id (loop thread only)
  bool recheck_soon_ = false;                  // an end to confirm (loop thread only)
  std::set<std::string> cancel_requested_;     // guarded by mu_
};

}  // namespace collido::service
