// The SQLite store: one connection in WAL mode behind a mutex (SQLite
// serialises writers anyway, and the service's statements are short), every
// statement prepared once with bound parameters, and the schema migrated step
// by step through PRAGMA user_version.
#include <sqlite3.h>

#include <chrono>
#include <cstring>
#include <map>
#include <mutex>

#include "service/store.h"

namespace collido::service {

double unix_now() {
  using namespace std::chrono;
  return duration<double>(system_clock::now().time_since_epoch()).count();
}

namespace {

// Each entry moves the schema one version up; never edit a released one.
const char* const kMigrations[] = {
    // 1: the paper's tables (admin and user as one table with a role; model,
    // algorithm, log) and the service's own (sessions, jobs, shares).
    R"sql(
CREATE TABLE users (
  id INTEGER PRIMARY KEY,
  name TEXT NOT NULL UNIQUE,
  password_hash TEXT NOT NULL,
  role TEXT NOT NULL CHECK (role IN ('user', 'admin')),
  created_at REAL NOT NULL);
CREATE TABLE sessions (
  token_hash TEXT PRIMARY KEY,
  user_id INTEGER NOT NULL REFERENCES users(id) ON DELETE CASCADE,
  created_at REAL NOT NULL,
  expires_at REAL NOT NULL);
CREATE TABLE models (
  id INTEGER PRIMARY KEY,
  owner_id INTEGER NOT NULL,
  name TEXT NOT NULL,
  kind TEXT NOT NULL CHECK (kind IN ('preset', 'parametric', 'stl')),
  spec TEXT NOT NULL,
  params_json TEXT NOT NULL,
  stl_sha256 TEXT NOT NULL,
  stl_bytes INTEGER NOT NULL,
  triangles INTEGER NOT NULL,
  created_at REAL NOT NULL);
CREATE INDEX models_owner ON models(owner_id);
CREATE TABLE algorithms (
  name TEXT PRIMARY KEY,
  kind TEXT NOT NULL,
  description TEXT NOT NULL);
CREATE TABLE jobs (
  id TEXT PRIMARY KEY,
  owner_id INTEGER NOT NULL,
  state TEXT NOT NULL CHECK (state IN ('queued', 'running', 'done', 'failed', 'cancelled')),
  stage TEXT NOT NULL,
  progress REAL NOT NULL,
  scene_json TEXT NOT NULL,
  scene_key TEXT NOT NULL,
  run_dir TEXT NOT NULL,
  prediction_json TEXT NOT NULL,
  cost_json TEXT NOT NULL,
  error TEXT NOT NULL,
  predicted_host_bytes INTEGER NOT NULL,
  reused_from TEXT NOT NULL,
  created_at REAL NOT NULL,
  started_at REAL NOT NULL,
  finished_at REAL NOT NULL,
  attempts INTEGER NOT NULL);
CREATE INDEX jobs_owner ON jobs(owner_id, created_at);
CREATE INDEX jobs_state ON jobs(state, created_at);
CREATE INDEX jobs_key ON jobs(scene_key, state);
CREATE TABLE shares (
  token TEXT PRIMARY KEY,
  job_id TEXT NOT NULL REFERENCES jobs(id) ON DELETE CASCADE,
  created_by INTEGER NOT NULL,
  created_at REAL NOT NULL,
  expires_at REAL NOT NULL);
CREATE INDEX shares_job ON shares(job_id);
CREATE TABLE logs (
  id INTEGER PRIMARY KEY,
  job_id TEXT NOT NULL,
  inputs_json TEXT NOT NULL,
  measured_json TEXT NOT NULL,
  predicted_json TEXT NOT NULL,
  total_s REAL NOT NULL,
  per_frame_s REAL NOT NULL,
  peak_host_bytes INTEGER NOT NULL,
  peak_device_bytes INTEGER NOT NULL,
  gpu_load REAL NOT NULL,
  predicted_total_s REAL NOT NULL,
  predicted_host_bytes INTEGER NOT NULL,
  created_at REAL NOT NULL);
)sql",
    // 2: each log row keeps its job as a job-log row, for retraining the cost model.
    "ALTER TABLE logs ADD COLUMN job_record TEXT NOT NULL DEFAULT '';",
    // 3: a user's queued jobs counted from an index alone (every submission counts
    // them; without it the count read every row of theirs, documents and all).
    "CREATE INDEX jobs_owner_state ON jobs(owner_id, state);",
    // 4: where a job runs outside the service (a Slurm job id), so a restarted
    // service finds its cluster jobs again instead of running them twice.
    "ALTER TABLE jobs ADD COLUMN executor_ref TEXT NOT NULL DEFAULT '';",
    // 5: a cancel asked while the job ran, kept so that a restart (or another
    // replica) ends it cancelled instead of running it again.
    "ALTER TABLE jobs ADD COLUMN cancel_requested INTEGER NOT NULL DEFAULT 0;",
    // 6: the disk a job was admitted by, summed over the queued jobs at every
    // submission from an index alone (summed from their predictions' JSON, a
    // queue of 2,000 took 10 ms a submission).
    "ALTER TABLE jobs ADD COLUMN predicted_output_bytes INTEGER NOT NULL DEFAULT 0;"
    "CREATE INDEX jobs_state_output ON jobs(state, predicted_output_bytes);",
};

constexpr int kSchemaVersion = int(sizeof kMigrations / sizeof kMigrations[0]);

const char* const kJobColumns =
    "id, owner_id, state, stage, progress, scene_json, scene_key, run_dir, prediction_json, "
    "cost_json, error, predicted_host_bytes, reused_from, created_at, started_at, finished_at, "
    "attempts, executor_ref, cancel_requested, predicted_output_bytes";
const char* const kModelColumns =
    "id, owner_id, name, kind, spec, params_json, stl_sha256, stl_bytes, triangles, created_at";
const char* const kLogColumns =
    "id, job_id, inputs_json, measured_json, predicted_json, total_s, per_frame_s, "
    "peak_host_bytes, peak_device_bytes, gpu_load, predicted_total_s, predicted_host_bytes, "
    "created_at, job_record";

// A prepared statement, reset for reuse when a call ends.
class Stmt {
 public:
  explicit Stmt(sqlite3_stmt* s) : s_(s) {}
  ~Stmt() {
    sqlite3_reset(s_);
    sqlite3_clear_bindings(s_);
  }
  Stmt& bind(int i, const std::string& v) {
    sqlite3_bind_text(s_, i, v.data(), int(v.size()), SQLITE_TRANSIENT);
    return *this;
  }
  Stmt& bind(int i, int64_t v) {
    sqlite3_bind_int64(s_, i, v);
    return *this;
  }
  Stmt& bind(int i, uint64_t v) { return bind(i, int64_t(v)); }
  Stmt& bind(int i, int v) { return bind(i, int64_t(v)); }
  Stmt& bind(int i, double v) {
    sqlite3_bind_double(s_, i, v);
    return *this;
  }
  int step() { return sqlite3_step(s_); }
  std::string text(int c) const {
    const auto* p = reinterpret_cast<const char*>(sqlite3_column_text(s_, c));
    return p ? std::string(p, size_t(sqlite3_column_bytes(s_, c))) : std::string();
  }
  int64_t i64(int c) const { return sqlite3_column_int64(s_, c); }
  double real(int c) const { return sqlite3_column_double(s_, c); }

 private:
  sqlite3_stmt* s_;
};

class SqliteStore final : public Store {
 public:
  ~SqliteStore() override {
    for (auto& [sql, s] : cache_) sqlite3_finalize(s);
    if (db_) sqlite3_close(db_);
  }

  Status open(const std::string& path) {
    if (sqlite3_open_v2(path.c_str(), &db_,
                        SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX,
                        nullptr) != SQLITE_OK)
      return io_error(path + ": " + (db_ ? sqlite3_errmsg(db_) : "cannot open"));
    sqlite3_busy_timeout(db_, 5000);  // another process (an admin command) may hold the lock
    for (const char* pragma : {"PRAGMA journal_mode=WAL", "PRAGMA synchronous=NORMAL",
                               "PRAGMA foreign_keys=ON"})
      if (Status st = exec(pragma); !st) return st;
    return migrate();
  }

  Expected<User> create_user(const std::string& name, const std::string& hash,
                             const std::string& role) override {
    std::lock_guard lock(mu_);
    const double now = unix_now();
    Stmt s = stmt("INSERT INTO users(name, password_hash, role, created_at) VALUES (?,?,?,?)");
    s.bind(1, name).bind(2, hash).bind(3, role).bind(4, now);
    const int rc = s.step();
    if (rc == SQLITE_CONSTRAINT) return invalid_argument("name: '" + name + "' is taken");
    if (rc != SQLITE_DONE) return error("create_user");
    return User{sqlite3_last_insert_rowid(db_), name, role, now};
  }

  Expected<User> user_by_name(const std::string& name, std::string* hash) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("SELECT id, name, role, created_at, password_hash FROM users WHERE name = ?");
    s.bind(1, name);
    if (s.step() != SQLITE_ROW) return not_found("no user '" + name + "'");
    if (hash) *hash = s.text(4);
    return user_of(s);
  }

  Expected<User> user_by_id(int64_t id) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("SELECT id, name, role, created_at FROM users WHERE id = ?");
    s.bind(1, id);
    if (s.step() != SQLITE_ROW) return not_found("no user " + std::to_string(id));
    return user_of(s);
  }

  Expected<uint64_t> count_users() override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("SELECT COUNT(*) FROM users");
    if (s.step() != SQLITE_ROW) return error("count_users");
    return uint64_t(s.i64(0));
  }

  Status create_session(const std::string& token_hash, int64_t user_id,
                        double expires_at) override {
    std::lock_guard lock(mu_);
    // Expired sessions are swept here, where sessions are made, not on a timer.
    const double now = unix_now();
    {
      Stmt d = stmt("DELETE FROM sessions WHERE expires_at < ?");
      d.bind(1, now);
      d.step();
    }
    Stmt s = stmt("INSERT INTO sessions(token_hash, user_id, created_at, expires_at) VALUES (?,?,?,?)");
    s.bind(1, token_hash).bind(2, user_id).bind(3, now).bind(4, expires_at);
    return s.step() == SQLITE_DONE ? Status::ok() : error("create_session");
  }

  Expected<User> session_user(const std::string& token_hash, double now) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(
        "SELECT u.id, u.name, u.role, u.created_at FROM sessions s JOIN users u ON u.id = s.user_id "
        "WHERE s.token_hash = ? AND s.expires_at >= ?");
    s.bind(1, token_hash).bind(2, now);
    if (s.step() != SQLITE_ROW) return not_found("no such session");
    return user_of(s);
  }

  Status delete_session(const std::string& token_hash) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("DELETE FROM sessions WHERE token_hash = ?");
    s.bind(1, token_hash);
    return s.step() == SQLITE_DONE ? Status::ok() : error("delete_session");
  }

  Expected<Model> insert_model(const Model& m) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(
        "INSERT INTO models(owner_id, name, kind, spec, params_json, stl_sha256, stl_bytes, "
        "triangles, created_at) VALUES (?,?,?,?,?,?,?,?,?)");
    Model out = m;
    out.created_at = unix_now();
    s.bind(1, m.owner_id).bind(2, m.name).bind(3, m.kind).bind(4, m.spec).bind(5, m.params_json);
    s.bind(6, m.stl_sha256).bind(7, m.stl_bytes).bind(8, m.triangles).bind(9, out.created_at);
    if (s.step() != SQLITE_DONE) return error("insert_model");
    out.id = sqlite3_last_insert_rowid(db_);
    return out;
  }

  Expected<Model> model_by_id(int64_t id) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(std::string("SELECT ") + kModelColumns + " FROM models WHERE id = ?");
    s.bind(1, id);
    if (s.step() != SQLITE_ROW) return not_found("no model " + std::to_string(id));
    return model_of(s);
  }

  Expected<std::vector<Model>> models_visible_to(int64_t user_id) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(std::string("SELECT ") + kModelColumns +
                  " FROM models WHERE owner_id = 0 OR owner_id = ? ORDER BY id");
    s.bind(1, user_id);
    std::vector<Model> out;
    int rc;
    while ((rc = s.step()) == SQLITE_ROW) out.push_back(model_of(s));
    if (rc != SQLITE_DONE) return error("models");
    return out;
  }

  Status set_model_stl(int64_t id, const std::string& sha, uint64_t bytes,
                       uint64_t triangles) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("UPDATE models SET stl_sha256 = ?, stl_bytes = ?, triangles = ? WHERE id = ?");
    s.bind(1, sha).bind(2, bytes).bind(3, triangles).bind(4, id);
    return s.step() == SQLITE_DONE ? Status::ok() : error("set_model_stl");
  }

  Status delete_model(int64_t id) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("DELETE FROM models WHERE id = ?");
    s.bind(1, id);
    return s.step() == SQLITE_DONE ? Status::ok() : error("delete_model");
  }

  Expected<std::optional<Model>> preset_by_name(const std::string& name) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(std::string("SELECT ") + kModelColumns +
                  " FROM models WHERE owner_id = 0 AND name = ?");
    s.bind(1, name);
    const int rc = s.step();
    if (rc == SQLITE_DONE) return std::optional<Model>();
    if (rc != SQLITE_ROW) return error("preset_by_name");
    return std::optional<Model>(model_of(s));
  }

  Status put_algorithm(const Algorithm& a) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("INSERT OR REPLACE INTO algorithms(name, kind, description) VALUES (?,?,?)");
    s.bind(1, a.name).bind(2, a.kind).bind(3, a.description);
    return s.step() == SQLITE_DONE ? Status::ok() : error("put_algorithm");
  }

  Expected<std::vector<Algorithm>> algorithms() override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("SELECT name, kind, description FROM algorithms ORDER BY kind, rowid");
    std::vector<Algorithm> out;
    int rc;
    while ((rc = s.step()) == SQLITE_ROW) out.push_back({s.text(0), s.text(1), s.text(2)});
    if (rc != SQLITE_DONE) return error("algorithms");
    return out;
  }

  Status insert_job(const Job& j) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(std::string("INSERT INTO jobs(") + kJobColumns +
                  ") VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
    s.bind(1, j.id).bind(2, j.owner_id).bind(3, j.state).bind(4, j.stage).bind(5, j.progress);
    s.bind(6, j.scene_json).bind(7, j.scene_key).bind(8, j.run_dir).bind(9, j.prediction_json);
    s.bind(10, j.cost_json).bind(11, j.error).bind(12, j.predicted_host_bytes);
    s.bind(13, j.reused_from).bind(14, j.created_at).bind(15, j.started_at);
    s.bind(16, j.finished_at).bind(17, j.attempts).bind(18, j.executor_ref);
    s.bind(19, int64_t(j.cancel_requested ? 1 : 0)).bind(20, j.predicted_output_bytes);
    return s.step() == SQLITE_DONE ? Status::ok() : error("insert_job");
  }

  Expected<Job> job_by_id(const std::string& id) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(std::string("SELECT ") + kJobColumns + " FROM jobs WHERE id = ?");
    s.bind(1, id);
    if (s.step() != SQLITE_ROW) return not_found("no job '" + id + "'");
    return job_of(s);
  }

  Expected<JobStatus> job_status(const std::string& id) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(
        "SELECT owner_id, state, stage, progress, started_at, finished_at, attempts, "
        "length(CAST(cost_json AS BLOB)), error, executor_ref FROM jobs WHERE id = ?");
    s.bind(1, id);
    if (s.step() != SQLITE_ROW) return not_found("no job '" + id + "'");
    JobStatus j;
    j.id = id;
    j.owner_id = s.i64(0);
    j.state = s.text(1);
    j.stage = s.text(2);
    j.progress = s.real(3);
    j.started_at = s.real(4);
    j.finished_at = s.real(5);
    j.attempts = int(s.i64(6));
    j.cost_bytes = uint64_t(s.i64(7));
    j.error = s.text(8);
    j.executor_ref = s.text(9);
    return j;
  }

  Expected<std::vector<Job>> jobs_of(int64_t owner_id, size_t limit,
                                     const std::optional<JobCursor>& after) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(std::string("SELECT ") + kJobColumns +
                  " FROM jobs WHERE owner_id = ?1 AND (?2 IS NULL OR created_at < ?2 OR "
                  "(created_at = ?2 AND id < ?3)) ORDER BY created_at DESC, id DESC LIMIT ?4");
    s.bind(1, owner_id).bind(4, uint64_t(limit));
    if (after) s.bind(2, after->created_at).bind(3, after->id);
    std::vector<Job> out;
    int rc;
    while ((rc = s.step()) == SQLITE_ROW) out.push_back(job_of(s));
    if (rc != SQLITE_DONE) return error("jobs_of");
    return out;
  }

  Expected<uint64_t> queued_output_bytes() override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("SELECT COALESCE(SUM(predicted_output_bytes), 0) FROM jobs WHERE state = 'queued'");
    if (s.step() != SQLITE_ROW) return error("queued_output_bytes");
    return uint64_t(s.i64(0));
  }

  Expected<uint64_t> count_jobs(int64_t owner_id, const std::string& state) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("SELECT COUNT(*) FROM jobs WHERE owner_id = ? AND state = ?");
    s.bind(1, owner_id).bind(2, state);
    if (s.step() != SQLITE_ROW) return error("count_jobs");
    return uint64_t(s.i64(0));
  }

  Expected<std::optional<Job>> done_job_with_key(const std::string& key) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(std::string("SELECT ") + kJobColumns +
                  " FROM jobs WHERE scene_key = ? AND state = 'done' AND reused_from = '' "
                  "ORDER BY finished_at DESC LIMIT 1");
    s.bind(1, key);
    const int rc = s.step();
    if (rc == SQLITE_DONE) return std::optional<Job>();
    if (rc != SQLITE_ROW) return error("done_job_with_key");
    return std::optional<Job>(job_of(s));
  }

  Expected<std::optional<Job>> claim_next_job(uint64_t host_bytes_free, double now) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(std::string("UPDATE jobs SET state = 'running', started_at = ?, attempts = attempts + 1 "
                              "WHERE id = (SELECT id FROM jobs WHERE state = 'queued' AND "
                              "predicted_host_bytes <= ? ORDER BY created_at, rowid LIMIT 1) "
                              "RETURNING ") +
                  kJobColumns);
    s.bind(1, now).bind(2, host_bytes_free);
    const int rc = s.step();
    if (rc == SQLITE_DONE) return std::optional<Job>();
    if (rc != SQLITE_ROW) return error("claim_next_job");
    Job j = job_of(s);
    while (s.step() == SQLITE_ROW) {
    }
    return std::optional<Job>(std::move(j));
  }

  Status set_job_progress(const std::string& id, const std::string& stage,
                          double progress) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("UPDATE jobs SET stage = ?, progress = ? WHERE id = ? AND state = 'running'");
    s.bind(1, stage).bind(2, progress).bind(3, id);
    return s.step() == SQLITE_DONE ? Status::ok() : error("set_job_progress");
  }

  Expected<bool> finish_job(const std::string& id, const std::string& state,
                            const std::string& cost, const std::string& err, double now,
                            const LogRow* log) override {
    std::lock_guard lock(mu_);
    if (Status b = exec("BEGIN IMMEDIATE"); !b) return b;
    bool updated = false, ended = false;
    {
      Stmt s = stmt(
          "UPDATE jobs SET state = ?, cost_json = ?, error = ?, finished_at = ?, "
          "progress = CASE WHEN ? = 'done' THEN 1.0 ELSE progress END, "
          "stage = CASE WHEN ? = 'done' THEN 'done' ELSE stage END "
          "WHERE id = ? AND state IN ('queued', 'running')");
      s.bind(1, state).bind(2, cost).bind(3, err).bind(4, now).bind(5, state).bind(6, state);
      s.bind(7, id);
      updated = s.step() == SQLITE_DONE;
      ended = updated && sqlite3_changes(db_) > 0;
    }
    if (!updated || (ended && log && !insert_log_locked(*log))) {
      Status e = error("finish_job");
      exec("ROLLBACK");
      return e;
    }
    if (Status c = exec("COMMIT"); !c) {
      exec("ROLLBACK");
      return c;
    }
    return ended;
  }

  Status request_cancel(const std::string& id) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("UPDATE jobs SET cancel_requested = 1 WHERE id = ? AND state = 'running'");
    s.bind(1, id);
    return s.step() == SQLITE_DONE ? Status::ok() : error("request_cancel");
  }

  Status set_job_executor_ref(const std::string& id, const std::string& ref) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("UPDATE jobs SET executor_ref = ? WHERE id = ?");
    s.bind(1, ref).bind(2, id);
    return s.step() == SQLITE_DONE ? Status::ok() : error("set_job_executor_ref");
  }

  Expected<bool> claim_orphan(const std::string& id, double seen_started_at,
                              double now) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("UPDATE jobs SET started_at = ? WHERE id = ? AND state = 'running' AND "
                  "executor_ref = '' AND started_at = ?");
    s.bind(1, now).bind(2, id).bind(3, seen_started_at);
    if (s.step() != SQLITE_DONE) return error("claim_orphan");
    return sqlite3_changes(db_) > 0;
  }

  Expected<std::vector<Job>> running_jobs() override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(std::string("SELECT ") + kJobColumns +
                  " FROM jobs WHERE state = 'running' ORDER BY started_at, rowid");
    std::vector<Job> out;
    int rc;
    while ((rc = s.step()) == SQLITE_ROW) out.push_back(job_of(s));
    if (rc != SQLITE_DONE) return error("running_jobs");
    return out;
  }

  Expected<bool> cancel_queued_job(const std::string& id, double now) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(
        "UPDATE jobs SET state = 'cancelled', finished_at = ? WHERE id = ? AND state = 'queued'");
    s.bind(1, now).bind(2, id);
    if (s.step() != SQLITE_DONE) return error("cancel_queued_job");
    return sqlite3_changes(db_) > 0;
  }

  Expected<std::vector<std::string>> requeue_running_jobs() override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(
        "UPDATE jobs SET state = 'queued' WHERE state = 'running' AND executor_ref = '' AND "
        "cancel_requested = 0 RETURNING id");
    std::vector<std::string> ids;
    int rc;
    while ((rc = s.step()) == SQLITE_ROW) ids.push_back(s.text(0));
    if (rc != SQLITE_DONE) return error("requeue_running_jobs");
    return ids;
  }

  Expected<bool> delete_job(const std::string& id) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("DELETE FROM jobs WHERE id = ? AND state != 'running'");
    s.bind(1, id);
    if (s.step() != SQLITE_DONE) return error("delete_job");
    return sqlite3_changes(db_) > 0;
  }

  Expected<uint64_t> count_jobs_in_dir(const std::string& run_dir,
                                       const std::string& except_id) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("SELECT COUNT(*) FROM jobs WHERE run_dir = ? AND id != ?");
    s.bind(1, run_dir).bind(2, except_id);
    if (s.step() != SQLITE_ROW) return error("count_jobs_in_dir");
    return uint64_t(s.i64(0));
  }

  Expected<std::vector<std::pair<std::string, uint64_t>>> job_state_counts() override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("SELECT state, COUNT(*) FROM jobs GROUP BY state");
    std::vector<std::pair<std::string, uint64_t>> out;
    int rc;
    while ((rc = s.step()) == SQLITE_ROW) out.emplace_back(s.text(0), uint64_t(s.i64(1)));
    if (rc != SQLITE_DONE) return error("job_state_counts");
    return out;
  }

  Status insert_share(const Share& sh) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(
        "INSERT INTO shares(token, job_id, created_by, created_at, expires_at) VALUES (?,?,?,?,?)");
    s.bind(1, sh.token).bind(2, sh.job_id).bind(3, sh.created_by).bind(4, sh.created_at);
    s.bind(5, sh.expires_at);
    return s.step() == SQLITE_DONE ? Status::ok() : error("insert_share");
  }

  Expected<Share> share_by_token(const std::string& token) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(
        "SELECT token, job_id, created_by, created_at, expires_at FROM shares WHERE token = ?");
    s.bind(1, token);
    if (s.step() != SQLITE_ROW) return not_found("no such share");
    return Share{s.text(0), s.text(1), s.i64(2), s.real(3), s.real(4)};
  }

  Status delete_share(const std::string& token) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("DELETE FROM shares WHERE token = ?");
    s.bind(1, token);
    return s.step() == SQLITE_DONE ? Status::ok() : error("delete_share");
  }

  Expected<std::vector<Share>> shares_of_job(const std::string& job_id) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(
        "SELECT token, job_id, created_by, created_at, expires_at FROM shares WHERE job_id = ? "
        "ORDER BY created_at");
    s.bind(1, job_id);
    std::vector<Share> out;
    int rc;
    while ((rc = s.step()) == SQLITE_ROW)
      out.push_back(Share{s.text(0), s.text(1), s.i64(2), s.real(3), s.real(4)});
    if (rc != SQLITE_DONE) return error("shares_of_job");
    return out;
  }

  Status insert_log(const LogRow& r) override {
    std::lock_guard lock(mu_);
    return insert_log_locked(r) ? Status::ok() : error("insert_log");
  }
  // With mu_ held.
  bool insert_log_locked(const LogRow& r) {
    Stmt s = stmt(std::string("INSERT INTO logs(") + kLogColumns +
                  ") VALUES (NULL,?,?,?,?,?,?,?,?,?,?,?,?,?)");
    s.bind(1, r.job_id).bind(2, r.inputs_json).bind(3, r.measured_json).bind(4, r.predicted_json);
    s.bind(5, r.total_s).bind(6, r.per_frame_s).bind(7, r.peak_host_bytes);
    s.bind(8, r.peak_device_bytes).bind(9, r.gpu_load).bind(10, r.predicted_total_s);
    s.bind(11, r.predicted_host_bytes).bind(12, r.created_at).bind(13, r.job_record);
    return s.step() == SQLITE_DONE;
  }

  Expected<std::vector<LogRow>> logs(size_t limit, int64_t before_id) override {
    std::lock_guard lock(mu_);
    Stmt s = stmt(std::string("SELECT ") + kLogColumns +
                  " FROM logs WHERE id < ? ORDER BY id DESC LIMIT ?");
    s.bind(1, before_id > 0 ? before_id : INT64_MAX).bind(2, uint64_t(limit));
    std::vector<LogRow> out;
    int rc;
    while ((rc = s.step()) == SQLITE_ROW) {
      LogRow r;
      r.id = s.i64(0);
      r.job_id = s.text(1);
      r.inputs_json = s.text(2);
      r.measured_json = s.text(3);
      r.predicted_json = s.text(4);
      r.total_s = s.real(5);
      r.per_frame_s = s.real(6);
      r.peak_host_bytes = uint64_t(s.i64(7));
      r.peak_device_bytes = uint64_t(s.i64(8));
      r.gpu_load = s.real(9);
      r.predicted_total_s = s.real(10);
      r.predicted_host_bytes = uint64_t(s.i64(11));
      r.created_at = s.real(12);
      r.job_record = s.text(13);
      out.push_back(std::move(r));
    }
    if (rc != SQLITE_DONE) return error("logs");
    return out;
  }

  Expected<uint64_t> count_logs() override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("SELECT COUNT(*) FROM logs");
    if (s.step() != SQLITE_ROW) return error("count_logs");
    return uint64_t(s.i64(0));
  }

  Expected<std::string> integrity_check() override {
    std::lock_guard lock(mu_);
    Stmt s = stmt("PRAGMA integrity_check");
    std::string out;
    while (s.step() == SQLITE_ROW) out += (out.empty() ? "" : "; ") + s.text(0);
    return out;
  }

 private:
  // The statement for this SQL text, prepared on first use and kept.
  Stmt stmt(const std::string& sql) {
    auto it = cache_.find(sql);
    if (it == cache_.end()) {
      sqlite3_stmt* s = nullptr;
      if (sqlite3_prepare_v2(db_, sql.c_str(), -1, &s, nullptr) != SQLITE_OK) {
        // A statement of ours that does not prepare is a bug; the step on a
        // null statement reports SQLITE_MISUSE and the call returns an error.
        return Stmt(nullptr);
      }
      it = cache_.emplace(sql, s).first;
    }
    return Stmt(it->second);
  }

  Status exec(const char* sql) {
    char* msg = nullptr;
    if (sqlite3_exec(db_, sql, nullptr, nullptr, &msg) != SQLITE_OK) {
      Status st = io_error(std::string("sqlite: ") + (msg ? msg : "error") + " in: " + sql);
      sqlite3_free(msg);
      return st;
    }
    return Status::ok();
  }

  Status migrate() {
    int version = 0;
    {
      Stmt s = stmt("PRAGMA user_version");
      if (s.step() == SQLITE_ROW) version = int(s.i64(0));
    }
    if (version > kSchemaVersion)
      return invalid_argument("the database has schema version " + std::to_string(version) +
                              ", newer than this build's " + std::to_string(kSchemaVersion));
    for (int v = version; v < kSchemaVersion; ++v) {
      // Each step and its version number commit together or not at all.
      const std::string sql = std::string("BEGIN IMMEDIATE;") + kMigrations[v] +
                              "PRAGMA user_version = " + std::to_string(v + 1) + "; COMMIT;";
      if (Status st = exec(sql.c_str()); !st) {
        exec("ROLLBACK");
        return st;
      }
    }
    return Status::ok();
  }

  Status error(const char* what) {
    return io_error(std::string("sqlite (") + what + "): " + sqlite3_errmsg(db_));
  }

  static User user_of(const Stmt& s) { return User{s.i64(0), s.text(1), s.text(2), s.real(3)}; }
  static Model model_of(const Stmt& s) {
    Model m;
    m.id = s.i64(0);
    m.owner_id = s.i64(1);
    m.name = s.text(2);
    m.kind = s.text(3);
    m.spec = s.text(4);
    m.params_json = s.text(5);
    m.stl_sha256 = s.text(6);
    m.stl_bytes = uint64_t(s.i64(7));
    m.triangles = uint64_t(s.i64(8));
    m.created_at = s.real(9);
    return m;
  }
  static Job job_of(const Stmt& s) {
    Job j;
    j.id = s.text(0);
    j.owner_id = s.i64(1);
    j.state = s.text(2);
    j.stage = s.text(3);
    j.progress = s.real(4);
    j.scene_json = s.text(5);
    j.scene_key = s.text(6);
    j.run_dir = s.text(7);
    j.prediction_json = s.text(8);
    j.cost_json = s.text(9);
    j.error = s.text(10);
    j.predicted_host_bytes = uint64_t(s.i64(11));
    j.reused_from = s.text(12);
    j.created_at = s.real(13);
    j.started_at = s.real(14);
    j.finished_at = s.real(15);
    j.attempts = int(s.i64(16));
    j.executor_ref = s.text(17);
    j.cancel_requested = s.i64(18) != 0;
    j.predicted_output_bytes = uint64_t(s.i64(19));
    return j;
  }

  std::mutex mu_;
  sqlite3* db_ = nullptr;
  std::map<std::string, sqlite3_stmt*> cache_;
};

}  // namespace

int store_schema_version() { return kSchemaVersion; }

Expected<std::unique_ptr<Store>> open_sqlite_store(const std::string& path) {
  auto store = std::make_unique<SqliteStore>();
  if (Status st = store->open(path); !st) return st;
  return std::unique_ptr<Store>(std::move(store));
}

}  // namespace collido::service
