// What the REST handlers call: accounts and sessions, models, predictions,
// jobs and their queue, share links, health and metrics. Each call validates
// its input and answers with an HTTP status and a JSON body, so a handler is
// one line over it (parse the request, call, send). Long work never happens
// here: a submitted job goes to the queue and a worker (workers.h) runs it in
// a `collidoscope job-exec` child process.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "common/status.h"
#include "job/assess.h"
#include "job/job.h"
#include "service/auth.h"
#include "service/executor.h"
#include "service/slurm_executor.h"
#include "service/store.h"

namespace collido::service {

using json = nlohmann::json;

struct ServiceConfig {
  std::string data_dir = "var";  // the database, uploaded models and job results
  std::string job_executable;    // `collidoscope`, run as `job-exec` for each job
  uint64_t max_upload_bytes = 64ull << 20;  // an STL body
  int workers = -1;              // -1: one per visible GPU, else one on the CPU
  int job_threads = 0;           // CPU threads per job; 0 = the CPUs it may use
  int max_queued_per_user = 8;
  double session_ttl_s = 7 * 24 * 3600.0;
  std::string public_url;        // "http://host:port", for share links and oEmbed
  // Memory the jobs of this machine may use in all (0 = its physical memory):
  // a job predicted above it is refused, one above what is free now waits.
  uint64_t host_bytes = 0;
  // Disk for results: a job whose files, by its prediction, would not fit in
  // what the data folder's file system has free, less the reserve, is refused
  // (507). disk_free_bytes 0 = measure it (statvfs); tests set it.
  uint64_t disk_free_bytes = 0;
  uint64_t disk_reserve_bytes = 1ull << 30;  // kept for the database, logs and running jobs
  job::RenderSettings render = job::job_render_defaults();
  // Job cost model files (`collidoscope gvm train` on a job log; one per backend, or
  // one trained on both). Without one, time is not predicted and memory is the
  // engine's own estimate (job/budget.h).
  std::vector<std::string> cost_models;
  // Retraining (service/cost_trainer.h): the job logs a candidate trains on besides
  // the service's own finished jobs, and how many new jobs of a backend start one
  // (0: only when an administrator asks). Retrained models go to DATA/cost_models.
  std::vector<std::string> training_logs;
  int retrain_every = 25;
  int retrain_epochs = 1500;  // per machine (fewer in tests)
  // Where jobs run: "local" (worker threads and job-exec children on this
  // machine) or "slurm" (each job an sbatch submission; slurm_executor.h). With
  // Slurm, data_dir must be on a filesystem the nodes share, at the same path,
  // and job_executable must run there.
  std::string executor = "local";
  SlurmConfig slurm;
};

// An answer: the HTTP status, a JSON body, extra headers.
struct Reply {
  int status = 200;
  json body = json::object();
  std::vector<std::pair<std::string, std::string>> headers;
  // When set, the body as it is sent, made earlier (a cached job view);
  // `body` is then left empty.
  std::shared_ptr<const std::string> serialized;
  // The body as sent: `serialized`, else body's JSON text.
  std::string text() const;
};
Reply error_reply(int status, const std::string& message);

inline constexpr size_t kDefaultJobsAPage = 200, kMaxJobsAPage = 1000;
// A place in a job list as the API writes it in its next-page links: the
// job's creation time (its double's bits in hex, exact) and id; nullopt for
// text that is not one.
std::string job_cursor_text(const JobCursor& c);
std::optional<JobCursor> parse_job_cursor(const std::string& text);
// The HTTP status of a library error (400, 404, 409, 422, 500, ...).
int http_status_of(const Status& st);

class JobService {
 public:
  // Opens (or creates) the store under config.data_dir, adds the preset models
  // and the algorithm list, and queues again the jobs a stopped server left running.
  static Expected<std::unique_ptr<JobService>> open(const ServiceConfig& config);
  ~JobService();

  // Starts the executor: config.workers local workers, or the Slurm executor
  // (an error when the scheduler does not answer). stop_workers() cancels
  // nothing: a local job running then is left for the next start to resume from
  // its checkpoint; a cluster job runs on, and the next start follows it again.
  Status start_workers();
  void stop_workers();
  // Wakes a worker: a job was queued.
  void notify_queued();

  const ServiceConfig& config() const { return config_; }
  // The base URL of share links; set once the port is known (requests may already come).
  void set_public_url(const std::string& url);
  std::string public_url() const;
  // The memory the jobs of this machine may use in all (ServiceConfig::host_bytes,
  // else the machine's): what a job is admitted against.
  uint64_t memory_for_jobs() const;
  // What the data folder's file system has free (ServiceConfig::disk_free_bytes
  // where set); 0 when it cannot be read.
  uint64_t disk_free() const;
  Store& store() { return *store_; }

  // Accounts and sessions.
  Reply create_account(const json& body);
  // On success *token is the new session's token (for the cookie).
  Reply create_session(const json& body, double now, std::string* token);
  Reply delete_session(const std::string& token);
  // The user a session token belongs to; kNotFound when none (expired, unknown).
  Expected<User> authenticate(const std::string& token);
  // The first administrator (`collidoscope admin create`); kInvalidArgument when taken.
  Status create_admin(const std::string& name, const std::string& password);

  // Models.
  Reply list_models(const User& u);
  Reply get_model(const User& u, int64_t id);
  Reply create_model(const User& u, const json& body);
  Reply upload_stl(const User& u, int64_t id, const std::string& bytes);
  // The path of a model's STL (an uploaded file, or the parametric shape
  // written once on first request).
  Expected<std::string> model_stl_path(const User& u, int64_t id);
  Reply delete_model(const User& u, int64_t id);

  Reply algorithms();

  // Jobs.
  Reply predict(const User& u, const json& body);
  // Where the particles of a job (predict's body) start, placed as the run
  // will place them: {"particles": N, "shown": [[x, y, z, r], ...] (at most
  // kStartShown, spread over the set, in the wall's units), "release_s": [...]}.
  Reply start_preview(const User& u, const json& body);
  static constexpr size_t kStartShown = 3000;
  // More particles are not placed for a preview: the placement runs on the
  // Pistache reactor thread that owns the connection, which it stalls, and
  // the server would hold them all. The answer has the count, none shown,
  // and a note that says so.
  static constexpr uint64_t kStartPlacedMost = 200000;
  Reply submit(const User& u, const json& body);
  // A page of the user's jobs, newest first: at most `limit` (1..kMaxJobsAPage)
  // older than the place `before` names (empty: from the newest). A page
  // with more after it says where they start in a Link header (rel="next").
  Reply list_jobs(const User& u, size_t limit = kDefaultJobsAPage, const std::string& before = "");
  Reply get_job(const User& u, const std::string& id);
  Reply cancel_job(const User& u, const std::string& id);
  Reply delete_job(const User& u, const std::string& id);
  // A result file of the caller's job, or of a shared one; "" file = the
  // manifest. kNotFound for anything outside the run directory.
  Expected<std::string> job_file(const User& u, const std::string& id, const std::string& file);
  Expected<std::string> shared_file(const std::string& token, const std::string& file);

  // Share links.
  Reply create_share(const User& u, const std::string& job_id, const json& body);
  // The caller's live share links to their job, oldest first: revocable later,
  // not only on the page that made them.
  Reply list_shares(const User& u, const std::string& job_id);
  Reply delete_share(const User& u, const std::string& token);
  // The shared job's public view: state, links, poster, video.
  Reply share_info(const std::string& token);

  // The demo `serve --demo` starts with (make run): the account "demo", its
  // password kept in DATA/demo-password (made on the first start, mode 0600),
  // and a short pour into the paper's wall1, submitted (or its earlier result reused).
  struct Demo {
    std::string name, password, job_id, state;
  };
  Expected<Demo> start_demo();
  // The demo job's request (POST /api/v1/jobs body): a pour into the paper's
  // wall1 that lands and piles within its duration, rendered to video.
  static json demo_request();

  // Administration.
  Reply admin_logs(const User& u, size_t limit, int64_t before_id);
  // The job cost models in use: their training (loss per epoch, held-out predictions
  // against measurements) and intervals; an empty list when none is loaded.
  Reply admin_predictor(const User& u);
  // Starts retraining the job cost models on the base logs and the service's jobs
  // (202); 409 while one runs. Its outcome appears in admin_predictor's "retrain".
  Reply admin_retrain(const User& u);
  // Blocks until no retraining runs (tests).
  void wait_retrained();

  Reply health();
  // Prometheus text: queue length, jobs by state, prediction error of finished jobs.
  std::string metrics();

  // Used by the executors.
  void job_started(const Job& j);
  void job_progress(const std::string& id, const std::string& stage, double progress);
  // Ends the job (unless another replica ended it first) and logs it: a done job
  // with its measured cost; one that did not finish with `partial`, what was
  // measured of it (how far it got, the scheduler's reason), when given.
  void job_finished(const Job& j, const std::string& state, const std::string& error,
                    const json& manifest, uint64_t peak_host_bytes, const json& partial = nullptr);
  // The job's spec as submitted (spec.json in its folder).
  Expected<job::JobSpec> read_spec(const Job& j);
  // Writes spec.run.json, what job-exec runs: the submitted spec, continuing
  // the run a stopped server left when the job started before; threads > 0
  // sets the job's CPU threads.
  Expected<job::JobSpec> write_run_spec(const Job& j, int threads = 0);
  // The job's result.json (an empty object when it wrote none).
  json run_manifest(const Job& j);
  std::shared_ptr<std::atomic<bool>> cancel_flag(const std::string& id);
  void forget_cancel_flag(const std::string& id);
  std::string job_dir(const std::string& id) const;

 private:
  explicit JobService(ServiceConfig config);
  Status seed();
  // The scene of a request with its wall resolved to what job-exec can load,
  // and the key that says when two submissions give the same result.
  struct PreparedJob {
    json scene;            // as submitted (canonical)
    job::JobSpec spec;     // what job-exec runs (out_dir not yet set)
    std::string key;
    json assessment;       // what is known before it runs
    json prediction;       // its cost, as the predict route answers
    uint64_t host_bytes = 0;  // the memory the job is admitted by (waits and fits)
    uint64_t output_bytes = 0;    // the disk its files are admitted by
    job::JobAssessment assessed;  // with its wall loaded: a start preview places on it
    std::string model_sha256;     // an uploaded model's wall: the STL the key names
  };
  // Gives a submitted job its own copy of an uploaded model's STL (its owner
  // may upload again or delete the model while the job waits) and points the
  // spec at it; false when the file no longer holds the STL the job was priced on.
  Expected<bool> pin_model_wall(PreparedJob* p, const std::string& job_dir);
  // refuse_over_memory false: a job the engine's memory bound refuses is
  // assessed all the same (a start preview places a bounded share of it).
  Expected<PreparedJob> prepare(const User& u, const json& body, bool refuse_over_memory = true);
  // The predicted cost of an assessed job; *admit_bytes: the memory it is
  // admitted by, *admit_output: the disk its files are.
  json price(const job::JobAssessment& a, const json& assessment, uint64_t* admit_bytes,
             uint64_t* admit_output) const;
  json job_json(const Job& j);
  // A finished job as a one-row job log (cost_trainer.h); "" when it cannot be made.
  std::string job_record_of(const Job& j, const json& prediction, const json& manifest);
  // An ended job's run-log row: none for one that did not finish and left no `partial`.
  std::optional<LogRow> log_row_of(const Job& j, const std::string& state, const std::string& error,
                                   const json& manifest, const json& cost, const json& partial);
  // job_json's text, rebuilt only when the job's row has changed since.
  std::shared_ptr<const std::string> job_view(const Job& j);
  json share_view(const Share& sh);
  std::optional<Reply> over_memory(uint64_t host_bytes);
  // The 507 for a job whose files would not fit on the results' disk, or none.
  std::optional<Reply> over_disk(uint64_t output_bytes);
  // The view made for a job in this state, if one is kept; null otherwise.
  std::shared_ptr<const std::string> cached_view(const JobStatus& s);
  json links_of(const std::string& base, const Job& j);
  Expected<Job> own_job(const User& u, const std::string& id);
  Expected<std::string> file_in_run(const Job& j, const std::string& file);

  ServiceConfig config_;
  std::unique_ptr<Store> store_;
  struct CostModels;  // the loaded job cost models (none where the gvm module is left out)
  std::unique_ptr<CostModels> cost_;
  LoginThrottle throttle_;
  // Set and reset by the main thread (start_workers, stop_workers) while the
  // request threads read it: taken and swapped atomically, each use holding
  // its own reference.
  std::shared_ptr<Executor> workers_;
  std::shared_ptr<Executor> executor() const { return std::atomic_load(&workers_); }
  mutable std::mutex url_mu_;
  std::mutex cancel_mu_;
  // What a job status poll needs without parsing and printing three JSON
  // documents each time (the UI polls every job it lists), and the sessions
  // checked against the store in the last seconds (every request checks one).
  struct JobView {
    std::string fingerprint;  // the row's changing fields when `text` was made
    std::shared_ptr<const std::string> text;
  };
  std::mutex view_mu_;
  std::unordered_map<std::string, JobView> job_views_;
  struct RecentSession {
    User user;
    double until = 0;
  };
  std::mutex session_mu_;
  std::unordered_map<std::string, RecentSession> recent_sessions_;
  std::map<std::string, std::shared_ptr<std::atomic<bool>>> cancel_flags_;
  std::atomic<uint64_t> finished_since_start_{0};
};

}  // namespace collido::service
