// The service's storage: accounts, sessions, models, the algorithm list, jobs,
// share links and the run log. An interface, so the embedded SQLite default
// (sqlite_store.h) can be replaced by a server database without touching the
// job service. Every call is safe from several threads at once.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/status.h"

namespace collido::service {

// Seconds since the Unix epoch (wall clock: stored, compared across restarts).
double unix_now();

struct User {
  int64_t id = 0;
  std::string name;
  std::string role;  // "user" or "admin"
  double created_at = 0;
};

struct Model {
  int64_t id = 0;
  int64_t owner_id = 0;  // 0: a preset everyone may use
  std::string name;
  std::string kind;  // "preset", "parametric" or "stl"
  std::string spec;  // the shape spec ("wall1", "cylinder:r=..."); "" for an STL
  std::string params_json;  // what the user gave for a parametric model, "{}" else
  std::string stl_sha256;   // of the uploaded bytes ("" before the upload)
  uint64_t stl_bytes = 0;
  uint64_t triangles = 0;
  double created_at = 0;
};

// A place in a user's job list (newest first): a job's creation time and id.
struct JobCursor {
  double created_at = 0;
  std::string id;
};

// Job states: queued -> running -> done | failed | cancelled (and running ->
// queued again when the server restarts under a running job).
struct Job {
  std::string id;
  int64_t owner_id = 0;
  std::string state = "queued";
  std::string stage;       // prepare | simulate | render | done while it runs
  double progress = 0;     // 0..1
  std::string scene_json;  // the scene as submitted (canonical: keys sorted)
  std::string scene_key;   // hash of what decides the result, for reuse
  std::string run_dir;     // where its files are (shared by a reused result)
  std::string prediction_json = "{}";
  std::string cost_json = "{}";  // measured, when it ended
  std::string error;             // why it failed
  uint64_t predicted_host_bytes = 0;
  uint64_t predicted_output_bytes = 0;  // the disk its files were admitted by
  std::string reused_from;  // the job whose result this one is, when reused
  double created_at = 0, started_at = 0, finished_at = 0;
  int attempts = 0;
  // Where it runs outside the service ("" for the local workers): the Slurm job id.
  std::string executor_ref;
  // Cancelled while it ran: kept here, so a restarted service (or another
  // replica) ends it cancelled rather than running it again or on.
  bool cancel_requested = false;
};

// What of a job changes after submission, read without its documents (a status
// poll asks for it many times a second).
struct JobStatus {
  std::string id;
  int64_t owner_id = 0;
  std::string state, stage, error;
  double progress = 0, started_at = 0, finished_at = 0;
  int attempts = 0;
  uint64_t cost_bytes = 0;  // the size of cost_json
  std::string executor_ref;
};

struct Share {
  std::string token;
  std::string job_id;
  int64_t created_by = 0;
  double created_at = 0;
  double expires_at = 0;  // 0: never
};

// One finished job's row for the cost model: its inputs, what it cost, and what
// was predicted for it (the paper's Table 3, and more).
struct LogRow {
  int64_t id = 0;
  std::string job_id;
  std::string inputs_json;     // every input of the job predictor
  std::string measured_json;   // total_s, per_frame_s, peak_host_bytes, ...
  std::string predicted_json;  // the prediction given at submission
  double total_s = 0, per_frame_s = 0;
  uint64_t peak_host_bytes = 0, peak_device_bytes = 0;
  double gpu_load = 0;
  double predicted_total_s = -1;  // < 0: none was given
  uint64_t predicted_host_bytes = 0;
  double created_at = 0;
  // The job as a row of a job log (job/job_log.h: a header line and one row), what
  // the cost model retrains on; empty where none could be made.
  std::string job_record;
};

struct Algorithm {
  std::string name;
  std::string kind;  // "method" or "traversal"
  std::string description;
};

class Store {
 public:
  virtual ~Store() = default;

  // Accounts. create_user: kInvalidArgument when the name is taken.
  virtual Expected<User> create_user(const std::string& name, const std::string& password_hash,
                                     const std::string& role) = 0;
  virtual Expected<User> user_by_name(const std::string& name, std::string* password_hash) = 0;
  virtual Expected<User> user_by_id(int64_t id) = 0;
  virtual Expected<uint64_t> count_users() = 0;

  // Sessions, keyed by a hash of the token (the token itself is never stored).
  virtual Status create_session(const std::string& token_hash, int64_t user_id,
                                double expires_at) = 0;
  virtual Expected<User> session_user(const std::string& token_hash, double now) = 0;
  virtual Status delete_session(const std::string& token_hash) = 0;

  // Models: presets (owner 0) and the user's own.
  virtual Expected<Model> insert_model(const Model& m) = 0;
  virtual Expected<Model> model_by_id(int64_t id) = 0;
  virtual Expected<std::vector<Model>> models_visible_to(int64_t user_id) = 0;
  virtual Status set_model_stl(int64_t id, const std::string& sha256, uint64_t bytes,
                               uint64_t triangles) = 0;
  virtual Status delete_model(int64_t id) = 0;
  virtual Expected<std::optional<Model>> preset_by_name(const std::string& name) = 0;

  virtual Status put_algorithm(const Algorithm& a) = 0;
  virtual Expected<std::vector<Algorithm>> algorithms() = 0;

  // Jobs.
  virtual Status insert_job(const Job& j) = 0;
  virtual Expected<Job> job_by_id(const std::string& id) = 0;
  virtual Expected<JobStatus> job_status(const std::string& id) = 0;
  // A user's jobs, newest first (ties by id), at most `limit`; with `after`,
  // only those older than that place in the list.
  virtual Expected<std::vector<Job>> jobs_of(int64_t owner_id, size_t limit,
                                             const std::optional<JobCursor>& after) = 0;
  virtual Expected<uint64_t> count_jobs(int64_t owner_id, const std::string& state) = 0;
  // The disk the queued jobs were admitted by, summed (predicted_output_bytes;
  // 0 for jobs submitted before it was kept).
  virtual Expected<uint64_t> queued_output_bytes() = 0;
  // The newest finished job with this key, to reuse its result.
  virtual Expected<std::optional<Job>> done_job_with_key(const std::string& key) = 0;
  // Marks the oldest queued job whose predicted memory fits `host_bytes_free`
  // running and returns it; nullopt when none may start now.
  virtual Expected<std::optional<Job>> claim_next_job(uint64_t host_bytes_free, double now) = 0;
  virtual Status set_job_progress(const std::string& id, const std::string& stage,
                                  double progress) = 0;
  // Ends a running (or queued) job: state done | failed | cancelled. False when
  // it had ended already (another service replica ended it first). With `log`,
  // the job's run-log row goes in with it, in one transaction: whoever sees
  // the job ended sees its row.
  virtual Expected<bool> finish_job(const std::string& id, const std::string& state,
                                    const std::string& cost_json, const std::string& error,
                                    double now, const LogRow* log) = 0;
  // Records where a job runs outside the service (its Slurm job id).
  virtual Status set_job_executor_ref(const std::string& id, const std::string& ref) = 0;
  // Marks a running job cancelled-as-asked (Job::cancel_requested).
  virtual Status request_cancel(const std::string& id) = 0;
  // Takes a claimed job that never got an executor ref (its submitter died) for
  // submitting again: true for the one caller that moved its start from
  // seen_started_at to now; another replica that saw the same start gets false.
  virtual Expected<bool> claim_orphan(const std::string& id, double seen_started_at,
                                      double now) = 0;
  // The jobs running now (the Slurm executor follows them), oldest first.
  virtual Expected<std::vector<Job>> running_jobs() = 0;
  // A queued job becomes cancelled at once; true when it was queued.
  virtual Expected<bool> cancel_queued_job(const std::string& id, double now) = 0;
  // Local jobs left running by a server that stopped: queued again, in order,
  // but those asked to cancel (the caller ends them). Cluster jobs (an
  // executor_ref) are left alone: they run on under their scheduler, and the
  // Slurm executor follows them.
  virtual Expected<std::vector<std::string>> requeue_running_jobs() = 0;
  // Deletes a job that is not running; false when it was running (a worker
  // may claim a queued job between the caller's look and this).
  virtual Expected<bool> delete_job(const std::string& id) = 0;
  // Other jobs whose files are in run_dir (a reused result shares them).
  virtual Expected<uint64_t> count_jobs_in_dir(const std::string& run_dir,
                                               const std::string& except_id) = 0;
  // Jobs per state, for /metrics.
  virtual Expected<std::vector<std::pair<std::string, uint64_t>>> job_state_counts() = 0;

  // Share links.
  virtual Status insert_share(const Share& s) = 0;
  virtual Expected<Share> share_by_token(const std::string& token) = 0;
  virtual Status delete_share(const std::string& token) = 0;
  virtual Expected<std::vector<Share>> shares_of_job(const std::string& job_id) = 0;

  // The run log.
  virtual Status insert_log(const LogRow& row) = 0;
  virtual Expected<std::vector<LogRow>> logs(size_t limit, int64_t before_id) = 0;
  virtual Expected<uint64_t> count_logs() = 0;

  // "ok", or what PRAGMA integrity_check (or its like) found.
  virtual Expected<std::string> integrity_check() = 0;
};

// The embedded default: SQLite at `path` (WAL mode, prepared statements only,
// the schema migrated to the newest version on open).
Expected<std::unique_ptr<Store>> open_sqlite_store(const std::string& path);

// The schema version this build migrates to.
int store_schema_version();

}  // namespace collido::service
