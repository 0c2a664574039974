#include "service/job_service.h"

#include <sys/stat.h>
#include <sys/statvfs.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <thread>

#include "common/atomic_file.h"
#include "job/assess.h"
#include "job/budget.h"
#include "job/wall_source.h"
#include "scene/scene.h"
#include "service/workers.h"
#ifdef COLLIDO_HAVE_JOB_COST
#include "job/calibrate.h"
#include "job/cost_model.h"
#include "job/job_log.h"
#include "job/run_dir.h"
#include "service/cost_trainer.h"
#endif
#include "sim/detect.h"
#include "sim/mesh.h"
#include "sim/shapes.h"

namespace collido::service {

namespace fs = std::filesystem;

namespace {

// Bumped when a change of the engine or renderer changes what a scene gives, so
// a stored result is not handed out for a scene that would now look different.
constexpr const char* kResultVersion = "collidoscope-results-1";

constexpr size_t kMaxNameLength = 64;
constexpr size_t kMaxPasswordLength = 1024;
constexpr size_t kMinPasswordLength = 8;

// A name people can read and type: letters, digits, '.', '_', '-'.
bool valid_user_name(const std::string& name) {
  if (name.empty() || name.size() > kMaxNameLength) return false;
  return std::all_of(name.begin(), name.end(), [](unsigned char c) {
    return std::isalnum(c) || c == '.' || c == '_' || c == '-';
  });
}

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A string field of a JSON object, or an error naming it.
Expected<std::string> string_field(const json& body, const char* key, size_t max_len) {
  if (!body.is_object()) return invalid_argument("the body must be a JSON object");
  auto it = body.find(key);
  if (it == body.end()) return invalid_argument(std::string(key) + ": required");
  if (!it->is_string()) return invalid_argument(std::string(key) + ": must be a string");
  const std::string s = it->get<std::string>();
  if (s.size() > max_len)
    return invalid_argument(std::string(key) + ": longer than " + std::to_string(max_len) +
                            " bytes");
  return s;
}

json model_json(const Model& m) {
  json j = {{"id", m.id},
            {"name", m.name},
            {"kind", m.kind},
            {"preset", m.owner_id == 0},
            {"triangles", m.triangles},
            {"created_at", m.created_at},
            {"stl", "/api/v1/models/" + std::to_string(m.id) + "/stl"}};
  if (!m.spec.empty()) j["spec"] = m.spec;
  if (m.kind == "stl") {
    j["stl_bytes"] = m.stl_bytes;
    j["uploaded"] = !m.stl_sha256.empty();
  }
  if (m.kind == "parametric") j["params"] = json::parse(m.params_json, nullptr, false);
  // The wall a scene names to use this model.
  j["wall"] = {{"model", m.id}};
  return j;
}

// "cylinder:r=5,h=10+box:x=1,y=1,z=1" from [{"shape":"cylinder","r":5,"h":10}, ...].
Expected<std::string> spec_of_parts(const json& parts) {
  if (!parts.is_array() || parts.empty() || parts.size() > 64)
    return invalid_argument("parts: must be an array of 1 to 64 shapes");
  std::string spec;
  for (size_t i = 0; i < parts.size(); ++i) {
    const json& p = parts[i];
    const std::string where = "parts[" + std::to_string(i) + "]";
    if (!p.is_object()) return invalid_argument(where + ": must be an object");
    auto shape = p.find("shape");
    if (shape == p.end() || !shape->is_string())
      return invalid_argument(where + ".shape: required, a string");
    const std::string name = shape->get<std::string>();
    static const char* const kShapes[] = {"cylinder", "box", "sphere", "cone", "funnel"};
    if (std::find(std::begin(kShapes), std::end(kShapes), name) == std::end(kShapes))
      return invalid_argument(where + ".shape: '" + name +
                              "' is not one of cylinder, box, sphere, cone, funnel");
    if (!spec.empty()) spec += '+';
    spec += name;
    char sep = ':';
    for (auto it = p.begin(); it != p.end(); ++it) {
      if (it.key() == "shape") continue;
      const std::string& k = it.key();
      if (k.empty() || k.size() > 16 ||
          !std::all_of(k.begin(), k.end(), [](unsigned char c) { return std::isalnum(c); }))
        return invalid_argument(where + ": key '" + k + "' is not a shape parameter");
      if (!it->is_number() || !std::isfinite(it->get<double>()))
        return invalid_argument(where + "." + k + ": must be a finite number");
      char num[40];
      std::snprintf(num, sizeof num, "%.17g", it->get<double>());
      spec += sep + k + "=" + num;
      sep = ',';
    }
  }
  return spec;
}

}  // namespace

std::string Reply::text() const {
  if (serialized) return *serialized;
  // A string that is not UTF-8 (a message quoting a file's bytes) is sent
  // with U+FFFD in place of the bad bytes rather than failing the answer.
  return status == 204 ? std::string()
                       : body.dump(-1, ' ', false, json::error_handler_t::replace) + "\n";
}

Reply error_reply(int status, const std::string& message) {
  Reply r;
  r.status = status;
  r.body = {{"error", message}};
  return r;
}

int http_status_of(const Status& st) {
  switch (st.code()) {
    case ErrorCode::kOk: return 200;
    case ErrorCode::kInvalidArgument: return 400;
    case ErrorCode::kParse: return 422;
    case ErrorCode::kNotFound: return 404;
    case ErrorCode::kResourceExhausted: return 409;
    case ErrorCode::kCancelled: return 409;
    case ErrorCode::kIo:
    case ErrorCode::kBackend: return 500;
  }
  return 500;
}

static Reply status_reply(const Status& st) { return error_reply(http_status_of(st), st.message()); }

#ifdef COLLIDO_HAVE_JOB_COST
struct JobService::CostModels {
  CostModelSet set;
  std::unique_ptr<CostTrainer> trainer;  // made once the store is open
};
#else
struct JobService::CostModels {};
#endif

// The temporary files (common/atomic_file.h) in the data folder, its models
// and each job's folder (not their run folders, which claim_run_dir clears).
static void remove_stale_temporaries(const std::string& data_dir) {
  std::error_code ec;
  std::vector<fs::path> dirs = {data_dir, fs::path(data_dir) / "models"};
  for (auto it = fs::directory_iterator(fs::path(data_dir) / "jobs", ec);
       !ec && it != fs::directory_iterator(); it.increment(ec))
    if (it->is_directory(ec)) dirs.push_back(it->path());
  for (const fs::path& dir : dirs)
    for (auto it = fs::directory_iterator(dir, ec); !ec && it != fs::directory_iterator();
         it.increment(ec))
      if (is_temp_name(it->path().filename().string()) && it->is_regular_file(ec)) {
        std::error_code rm;
        fs::remove(it->path(), rm);
      }
}

Expected<std::unique_ptr<JobService>> JobService::open(const ServiceConfig& given) {
  if (!init_crypto()) return backend_error("libsodium did not start (no entropy source)");
  if (given.executor != "local" && given.executor != "slurm")
    return invalid_argument("executor: '" + given.executor + "' (local or slurm)");
  ServiceConfig config = given;
  // Cluster nodes find a job's files by the paths the service writes into its
  // spec and batch script: absolute ones (the same on every node, docs/deploy.md).
  if (config.executor == "slurm") config.data_dir = fs::absolute(config.data_dir).string();
  std::unique_ptr<JobService> svc(new JobService(config));
  std::error_code ec;
  for (const char* sub : {"", "models", "jobs"}) {
    fs::create_directories(fs::path(config.data_dir) / sub, ec);
    if (ec) return io_error(config.data_dir + "/" + sub + ": " + ec.message());
  }
  // A server killed while it wrote a spec, a batch script or an upload left
  // its temporary file; nothing else removes those (the run folders clear
  // their own). Not beside other replicas (Slurm), whose writes may be live.
  if (config.executor == "local") remove_stale_temporaries(config.data_dir);
#ifdef COLLIDO_HAVE_JOB_COST
  const std::string retrained_dir = (fs::path(config.data_dir) / "cost_models").string();
  std::vector<std::string> notes;
  if (Status st = load_cost_models(config.cost_models, retrained_dir, &svc->cost_->set, &notes); !st)
    return st;
  for (const std::string& n : notes) std::fprintf(stderr, "collidoscope serve: %s\n", n.c_str());
#else
  if (!config.cost_models.empty())
    return invalid_argument("this build has no job cost model (the gvm module was left out)");
#endif
  auto store = open_sqlite_store((fs::path(config.data_dir) / "collidoscope.db").string());
  if (!store) return store.status();
  svc->store_ = std::move(*store);
#ifdef COLLIDO_HAVE_JOB_COST
  CostTrainerConfig tc;
  tc.base_logs = config.training_logs;
  tc.every = config.retrain_every;
  tc.model_dir = retrained_dir;
  tc.options.gvm.epochs = config.retrain_epochs;
  svc->cost_->trainer = std::make_unique<CostTrainer>(tc, *svc->store_, svc->cost_->set);
#endif
  if (Status st = svc->seed(); !st) return st;
  // Local jobs a stopped server left running start again; cluster jobs run on
  // under the scheduler, and the Slurm executor follows them again.
  if (config.executor == "local") {
    // Those cancelled while they ran, stopped with the server before they
    // ended, end cancelled now: requeued, they would run after all.
    auto running = svc->store_->running_jobs();
    if (!running) return running.status();
    for (const Job& j : *running)
      if (j.executor_ref.empty() && j.cancel_requested)
        svc->job_finished(j, "cancelled", "cancelled (the service stopped before the job did)", {},
                          0);
    auto requeued = svc->store_->requeue_running_jobs();
    if (!requeued) return requeued.status();
  }
  return svc;
}

JobService::JobService(ServiceConfig config)
    : config_(std::move(config)), cost_(std::make_unique<CostModels>()) {}
JobService::~JobService() { stop_workers(); }

Status JobService::seed() {
  // The paper's walls exist from the start, as presets anyone may use.
  const std::pair<const char*, const char*> presets[] = {
      {"wall1", "the paper's wall1: a cylinder, 156 triangles"},
      {"wall2", "the paper's wall2: a spallation-target-like vessel, ~1,500 triangles"}};
  for (const auto& [name, what] : presets) {
    auto found = store_->preset_by_name(name);
    if (!found) return found.status();
    if (*found) continue;
    auto mesh = sim::make_shape(name);
    if (!mesh) return mesh.status();
    Model m;
    m.owner_id = 0;
    m.name = name;
    m.kind = "preset";
    m.spec = name;
    m.params_json = json{{"description", what}}.dump();
    m.triangles = mesh->triangles.size();
    if (auto added = store_->insert_model(m); !added) return added.status();
  }
  const Algorithm algorithms[] = {
      {"bin", "method",
       "No division: each wall triangle is binned into every grid cell it reaches and tested "
       "exactly. The default, exact and usually fastest."},
      {"bvh", "method",
       "No division: a bounding volume hierarchy over the wall's own triangles, walked from "
       "each particle. Exact; made for large CAD meshes that mix slivers with tiny facets."},
      {"octree", "method",
       "No division: bin's grid with each crowded cell split in eight, twice at most; the "
       "particles grouped by leaf, so neighbours test one list together. Exact; on the GPU "
       "the fastest on large CAD meshes (a third to under half of a GPU BVH library's time); "
       "for detection frames (collidoscope detect, bench detect)."},
      {"gravity", "method",
       "The paper's division by longest-edge bisection; each piece is stood in for by a "
       "sphere at its centroid (approximate)."},
      {"circumcircle", "method",
       "The paper's division with obtuse triangles split; pieces bounded by circumspheres."},
      {"midpoint4", "method",
       "The paper's four-way midpoint division to the particle's size."},
      {"reference", "method",
       "Exact brute force in double precision: every particle against every triangle. The "
       "test oracle; slow on large scenes."},
      {"particle", "traversal", "One thread per particle walks the cells it overlaps."},
      {"wall", "traversal", "One thread per wall piece visits the particles of its cells."},
  };
  for (const Algorithm& a : algorithms)
    if (Status st = store_->put_algorithm(a); !st) return st;
  return Status::ok();
}

Status JobService::start_workers() {
  if (executor()) return Status::ok();
  if (config_.executor == "slurm") {
    auto slurm = SlurmExecutor::start(this, config_.slurm);
    if (!slurm) return slurm.status();
    std::atomic_store(&workers_, std::shared_ptr<Executor>(std::move(*slurm)));
    return Status::ok();
  }
  // One worker per visible GPU (a GPU is driven by one job at a time), else
  // one on the CPU (a job takes every core); --workers sets the number.
  const std::vector<std::string> gpus = visible_gpus();
  int n = config_.workers;
  if (n < 0) n = gpus.empty() ? 1 : int(gpus.size());
  std::atomic_store(&workers_,
                    std::shared_ptr<Executor>(std::make_shared<WorkerPool>(this, n, gpus)));
  return Status::ok();
}

void JobService::stop_workers() {
  if (auto w = std::atomic_exchange(&workers_, std::shared_ptr<Executor>())) w->stop();
}

void JobService::notify_queued() {
  if (auto w = executor()) w->notify();
}

void JobService::set_public_url(const std::string& url) {
  std::lock_guard lock(url_mu_);
  config_.public_url = url;
}

std::string JobService::public_url() const {
  std::lock_guard lock(url_mu_);
  return config_.public_url;
}

uint64_t JobService::memory_for_jobs() const {
  return config_.host_bytes ? config_.host_bytes : job::machine_memory_bytes();
}

std::string JobService::job_dir(const std::string& id) const {
  return (fs::path(config_.data_dir) / "jobs" / id).string();
}

// ---- accounts ---------------------------------------------------------------

Reply JobService::create_account(const json& body) {
  auto name = string_field(body, "name", kMaxNameLength);
  if (!name) return status_reply(name.status());
  auto password = string_field(body, "password", kMaxPasswordLength);
  if (!password) return status_reply(password.status());
  if (!valid_user_name(*name))
    return error_reply(400, "name: 1 to 64 letters, digits, '.', '_' or '-'");
  if (password->size() < kMinPasswordLength)
    return error_reply(400, "password: at least 8 characters");
  auto hash = hash_password(*password);
  if (!hash) return status_reply(hash.status());
  auto user = store_->create_user(*name, *hash, "user");
  if (!user) return error_reply(user.status().code() == ErrorCode::kInvalidArgument ? 409 : 500,
                                user.status().message());
  Reply r;
  r.status = 201;
  r.body = {{"id", user->id}, {"name", user->name}, {"role", user->role}};
  return r;
}

Status JobService::create_admin(const std::string& name, const std::string& password) {
  if (!valid_user_name(name)) return invalid_argument("name: 1 to 64 letters, digits, '.', '_' or '-'");
  if (password.size() < kMinPasswordLength) return invalid_argument("password: at least 8 characters");
  auto hash = hash_password(password);
  if (!hash) return hash.status();
  auto user = store_->create_user(name, *hash, "admin");
  return user ? Status::ok() : user.status();
}

Reply JobService::create_session(const json& body, double now, std::string* token) {
  auto name = string_field(body, "name", kMaxNameLength);
  if (!name) return status_reply(name.status());
  auto password = string_field(body, "password", kMaxPasswordLength);
  if (!password) return status_reply(password.status());
  if (const double wait = throttle_.wait_s(*name, now); wait > 0) {
    Reply r = error_reply(429, "too many wrong passwords: try again in " +
                                   std::to_string(int(std::ceil(wait))) + " s");
    r.headers.emplace_back("Retry-After", std::to_string(int(std::ceil(wait))));
    return r;
  }
  std::string hash;
  auto user = store_->user_by_name(*name, &hash);
  // An unknown name costs a hash too, so the answer's timing does not tell
  // which names exist.
  static const std::string kDummyHash = [] {
    auto h = hash_password("not a password");
    return h ? *h : std::string();
  }();
  const bool ok = verify_password(user ? hash : kDummyHash, *password) && user;
  if (!ok) {
    throttle_.failed(*name, now);
    return error_reply(401, "wrong name or password");
  }
  throttle_.succeeded(*name);
  *token = random_token();
  if (Status st = store_->create_session(sha256_hex(*token), user->id, now + config_.session_ttl_s);
      !st)
    return status_reply(st);
  Reply r;
  r.body = {{"token", *token},
            {"user", {{"id", user->id}, {"name", user->name}, {"role", user->role}}},
            {"expires_in", config_.session_ttl_s}};
  return r;
}

Reply JobService::delete_session(const std::string& token) {
  {
    std::lock_guard lock(session_mu_);
    recent_sessions_.erase(token);
  }
  if (Status st = store_->delete_session(sha256_hex(token)); !st) return status_reply(st);
  Reply r;
  r.status = 204;
  r.body = nullptr;
  return r;
}

// How long a session found in the store is believed without asking again. A
// signed-out session ends at once (delete_session forgets it here); one that
// expires may serve this much longer.
constexpr double kSessionRecheckS = 2.0;
constexpr size_t kMaxRecentSessions = 10000;

Expected<User> JobService::authenticate(const std::string& token) {
  if (token.empty() || token.size() > 256) return not_found("no session");
  const double now = unix_now();
  {
    std::lock_guard lock(session_mu_);
    auto it = recent_sessions_.find(token);
    if (it != recent_sessions_.end() && now < it->second.until) return it->second.user;
  }
  auto user = store_->session_user(sha256_hex(token), now);
  if (user) {
    std::lock_guard lock(session_mu_);
    if (recent_sessions_.size() >= kMaxRecentSessions) recent_sessions_.clear();
    recent_sessions_[token] = {*user, now + kSessionRecheckS};
  }
  return user;
}

// ---- models -----------------------------------------------------------------

static Expected<Model> visible_model(Store& store, const User& u, int64_t id) {
  auto m = store.model_by_id(id);
  if (!m || (m->owner_id != 0 && m->owner_id != u.id))
    return not_found("no model " + std::to_string(id));
  return m;
}

Reply JobService::list_models(const User& u) {
  auto models = store_->models_visible_to(u.id);
  if (!models) return status_reply(models.status());
  Reply r;
  r.body = json::array();
  for (const Model& m : *models) r.body.push_back(model_json(m));
  return r;
}

Reply JobService::get_model(const User& u, int64_t id) {
  auto m = visible_model(*store_, u, id);
  if (!m) return status_reply(m.status());
  Reply r;
  r.body = model_json(*m);
  return r;
}

Reply JobService::create_model(const User& u, const json& body) {
  auto name = string_field(body, "name", 128);
  if (!name) return status_reply(name.status());
  if (name->empty()) return error_reply(400, "name: must not be empty");
  Model m;
  m.owner_id = u.id;
  m.name = *name;
  m.params_json = "{}";
  if (body.contains("kind") && !body["kind"].is_string())
    return error_reply(400, "kind: expected \"stl\" or \"parametric\"");
  const std::string kind = body.value("kind", std::string(body.contains("parts") || body.contains("spec") ? "parametric" : "stl"));
  if (kind == "stl") {
    m.kind = "stl";  // the bytes come with PUT /models/{id}/stl
  } else if (kind == "parametric") {
    m.kind = "parametric";
    Expected<std::string> spec = invalid_argument("parts or spec: one is required");
    if (body.contains("parts")) {
      spec = spec_of_parts(body["parts"]);
      if (spec) m.params_json = json{{"parts", body["parts"]}}.dump();
    } else if (body.contains("spec")) {
      spec = string_field(body, "spec", 4096);
    }
    if (!spec) return status_reply(spec.status());
    if (!job::is_shape_spec(*spec)) return error_reply(400, "spec: '" + *spec + "' names no shape");
    auto mesh = sim::make_shape(*spec);
    if (!mesh) return error_reply(400, "spec: " + mesh.status().message());
    m.spec = *spec;
    m.triangles = mesh->triangles.size();
  } else {
    return error_reply(400, "kind: must be parametric or stl");
  }
  auto added = store_->insert_model(m);
  if (!added) return status_reply(added.status());
  Reply r;
  r.status = 201;
  r.body = model_json(*added);
  return r;
}

Reply JobService::upload_stl(const User& u, int64_t id, const std::string& bytes) {
  auto m = store_->model_by_id(id);
  if (!m || m->owner_id != u.id) return error_reply(404, "no model " + std::to_string(id));
  if (m->kind != "stl") return error_reply(409, "model " + std::to_string(id) + " is parametric");
  if (bytes.size() > config_.max_upload_bytes)
    return error_reply(413, "the STL is larger than " + std::to_string(config_.max_upload_bytes) +
                                " bytes");
  sim::MeshReport report;
  auto mesh = sim::parse_stl(bytes, "upload", &report);
  if (!mesh) return error_reply(422, mesh.status().message());
  if (mesh->triangles.empty()) return error_reply(422, "upload: no triangle with an area");
  const std::string path = (fs::path(config_.data_dir) / "models" / (std::to_string(id) + ".stl")).string();
  if (Status st = write_file_atomic(path, bytes); !st) return status_reply(st);
  if (Status st = store_->set_model_stl(id, sha256_hex(bytes), bytes.size(), mesh->triangles.size());
      !st)
    return status_reply(st);
  auto updated = store_->model_by_id(id);
  if (!updated) return status_reply(updated.status());
  Reply r;
  r.body = model_json(*updated);
  r.body["format"] = report.format;
  r.body["dropped_zero_area"] = report.dropped_zero_area;
  return r;
}

Expected<std::string> JobService::model_stl_path(const User& u, int64_t id) {
  auto m = visible_model(*store_, u, id);
  if (!m) return m.status();
  const std::string path =
      (fs::path(config_.data_dir) / "models" / (std::to_string(id) + ".stl")).string();
  if (m->kind == "stl") {
    if (m->stl_sha256.empty()) return not_found("model " + std::to_string(id) + " has no STL yet");
    return path;
  }
  if (!fs::exists(path)) {
    auto mesh = sim::make_shape(m->spec);
    if (!mesh) return mesh.status();
    if (Status st = sim::save_stl(*mesh, path); !st) return st;
  }
  return path;
}

Reply JobService::delete_model(const User& u, int64_t id) {
  auto m = store_->model_by_id(id);
  if (!m || m->owner_id != u.id) return error_reply(404, "no model " + std::to_string(id));
  if (Status st = store_->delete_model(id); !st) return status_reply(st);
  // A job that used it keeps its own copy (wall.stl in its run directory).
  std::error_code ec;
  fs::remove(fs::path(config_.data_dir) / "models" / (std::to_string(id) + ".stl"), ec);
  Reply r;
  r.status = 204;
  r.body = nullptr;
  return r;
}

Reply JobService::algorithms() {
  auto list = store_->algorithms();
  if (!list) return status_reply(list.status());
  Reply r;
  r.body = {{"methods", json::array()}, {"traversals", json::array()}};
  for (const Algorithm& a : *list) {
    json entry = {{"name", a.name}, {"description", a.description}};
    if (a.kind == "method") {
      // Whether a job may choose it (the dynamics step with it): the form offers these.
      sim::Method m;
      entry["jobs"] = sim::parse_method(a.name, &m) && sim::dynamics_can_use(m);
    }
    r.body[a.kind == "method" ? "methods" : "traversals"].push_back(std::move(entry));
  }
  return r;
}

// ---- jobs -------------------------------------------------------------------

Expected<JobService::PreparedJob> JobService::prepare(const User& u, const json& body,
                                                      bool refuse_over_memory) {
  if (!body.is_object()) return invalid_argument("the body must be a JSON object");
  for (auto it = body.begin(); it != body.end(); ++it)
    if (it.key() != "scene" && it.key() != "render" && it.key() != "fresh")
      return invalid_argument(it.key() + ": unknown key (scene, render, fresh)");
  auto scene_it = body.find("scene");
  if (scene_it == body.end() || !scene_it->is_object())
    return invalid_argument("scene: required, a scene document (an object)");
  PreparedJob p;
  p.scene = *scene_it;
  json run_scene = p.scene;
  std::string wall_identity;  // what the wall is, for the result key
  auto wall = run_scene.find("wall");
  if (wall == run_scene.end()) return invalid_argument("scene.wall: required");
  if (wall->is_object() && wall->contains("model")) {
    if (wall->size() != 1 || !(*wall)["model"].is_number_integer())
      return invalid_argument("scene.wall: {\"model\": ID} with an integer id and nothing else");
    const int64_t id = (*wall)["model"].get<int64_t>();
    auto m = visible_model(*store_, u, id);
    if (!m) return invalid_argument("scene.wall.model: " + m.status().message());
    if (m->kind == "stl") {
      if (m->stl_sha256.empty())
        return invalid_argument("scene.wall.model: model " + std::to_string(id) +
                                " has no STL uploaded yet");
      *wall = json{{"file", fs::absolute(fs::path(config_.data_dir) / "models" /
                                         (std::to_string(id) + ".stl"))
                                .string()}};
      wall_identity = "stl:" + m->stl_sha256;
      p.model_sha256 = m->stl_sha256;
    } else {
      *wall = m->spec;
      wall_identity = "shape:" + m->spec;
    }
  } else if (wall->is_object() && wall->size() == 1 && wall->contains("shape") &&
             (*wall)["shape"].is_string() &&
             job::is_shape_spec((*wall)["shape"].get<std::string>())) {
    // {"shape": spec}, as a scene file (and the scene.json a run writes) may
    // give it: held as the plain spec, so both forms are one scene to reuse.
    const std::string spec = (*wall)["shape"].get<std::string>();
    *wall = spec;
    wall_identity = "shape:" + spec;
  } else if (wall->is_string() && job::is_shape_spec(wall->get<std::string>())) {
    wall_identity = "shape:" + wall->get<std::string>();
  } else {
    // Never a path on the server: that would read any file the service can.
    return invalid_argument(
        "scene.wall: a shape (\"wall1\", \"cylinder:r=5,h=10\" or {\"shape\": ...}) or a model "
        "{\"model\": ID}; upload a mesh as a model first");
  }
  job::JobSpec& spec = p.spec;
  spec.scene_json = run_scene.dump();
  spec.threads = config_.job_threads;
  spec.render = true;
  spec.render_settings = config_.render;
  if (auto r = body.find("render"); r != body.end()) {
    if (!r->is_object()) return invalid_argument("render: must be an object");
    job::RenderSettings& rs = spec.render_settings;
    for (auto it = r->begin(); it != r->end(); ++it) {
      const std::string& k = it.key();
      if (k == "width" || k == "height") {
        if (!it->is_number_integer()) return invalid_argument("render." + k + ": an integer");
        const int64_t v = it->get<int64_t>();
        if (v < 16 || v > 3840) return invalid_argument("render." + k + ": in [16, 3840]");
        (k == "width" ? rs.width : rs.height) = int(v);
      } else if (k == "formats") {
        if (!it->is_array()) return invalid_argument("render.formats: an array");
        rs.mp4 = rs.webm = rs.gif = false;
        for (const json& f : *it) {
          const std::string s = f.is_string() ? f.get<std::string>() : "";
          if (s == "mp4") rs.mp4 = true;
          else if (s == "webm") rs.webm = true;
          else if (s == "gif") rs.gif = true;
          else return invalid_argument("render.formats: each one of mp4, webm, gif");
        }
      } else if (k == "camera" || k == "color" || k == "wall") {
        if (!it->is_string()) return invalid_argument("render." + k + ": a string");
        (k == "camera" ? rs.camera : k == "color" ? rs.color : rs.wall) = it->get<std::string>();
      } else {
        return invalid_argument("render." + k + ": unknown key (width, height, formats, camera, "
                                "color, wall)");
      }
    }
  }
  job::Budget& budget = spec.budget;
  budget.host_bytes =
      refuse_over_memory ? config_.host_bytes : std::numeric_limits<uint64_t>::max();
  auto assessed = job::assess_job(spec);
  if (!assessed) {
    const Status& st = assessed.status();
    return Status(st.code(), st.code() == ErrorCode::kResourceExhausted ? st.message()
                                                                        : "scene: " + st.message());
  }
  const job::JobAssessment& a = *assessed;
  const scene::Scene& s = a.resolved.scene;
  p.assessment = {
      {"particles", a.particles},
      {"radius", {a.r_min, a.r_max}},
      {"triangles", a.triangles},
      {"wall_area_m2", a.wall_area},
      {"wall_box_m", {a.box[0], a.box[1], a.box[2]}},
      {"method", sim::to_string(s.dynamics.method)},
      {"particle_contacts", s.dynamics.particle_contacts},
      {"friction", s.dynamics.material.friction},
      {"duration_s", s.duration},
      {"fps", s.fps},
      {"frames", a.frames},
      {"render_pixels", a.render_pixels},
      {"formats", a.formats},
      {"pieces", a.work.pieces},
      {"wall_cells", a.work.wall_cells},
  };
  // Two submissions give the same result when the scene as run, the wall's
  // bytes, the render settings and the version are the same.
  json key_doc = {{"version", kResultVersion},
                  {"scene", json::parse(scene::to_json(s))},
                  {"wall", wall_identity},
                  {"render", {{"w", spec.render_settings.width},
                              {"h", spec.render_settings.height},
                              {"formats", a.formats},
                              {"camera", spec.render_settings.camera},
                              {"color", spec.render_settings.color},
                              {"wall", spec.render_settings.wall}}}};
  key_doc["scene"].erase("wall");
  p.key = sha256_hex(key_doc.dump());
  p.prediction = price(a, p.assessment, &p.host_bytes, &p.output_bytes);
  p.assessed = std::move(*assessed);
  return p;
}

// What is known of a job's cost before it runs. With a job cost model for the
// backend the job will run on: time, memory, output and (on the GPU) device memory
// and load, each {value (median), low, high} (the model's 10-90 % interval), and
// whether the job lies outside what the model was trained on. Memory admits by the
// interval's top inside the trained range; outside it, by the larger of that and
// the engine's own estimate (job/budget.h), which is also the whole answer where
// no model is loaded.
json JobService::price(const job::JobAssessment& a, const json& assessment, uint64_t* admit_bytes,
                       uint64_t* admit_output) const {
  const uint64_t analytic = uint64_t(a.work.host_bytes);
  const uint64_t output_estimate = uint64_t(std::ceil(job::output_bytes_estimate(a)));
  *admit_bytes = analytic;
  *admit_output = output_estimate;
  json p = {{"basis", "analytic"},
            {"peak_host_bytes", {{"value", analytic}, {"analytic", analytic}}},
            {"output_bytes",
             {{"value", output_estimate},
              {"estimate", output_estimate},
              {"admitted_by", output_estimate}}},
            {"total_time_s", nullptr},
            {"inputs", assessment}};
  const scene::Scene& sc = a.resolved.scene;
  // A pour that ends before its first particles land shows nothing collide.
  if (a.release.first_contact >= 0) p["first_contact_s"] = a.release.first_contact;
  if (const std::string w = job::landing_warning(a); !w.empty())
    p["warnings"] = json::array({{{"message", w}}});
  // The backend a worker runs it on: the scene's, "auto" = the GPU when one is visible.
  // With Slurm, "auto" means the GPU where the cluster's nodes have one.
  const bool gpus = config_.executor == "slurm" ? config_.slurm.gpus : !visible_gpus().empty();
  const std::string backend =
      sc.backend_auto ? (gpus ? "cuda" : "cpu") : sim::to_string(sc.dynamics.backend);
  p["backend"] = backend;
#ifdef COLLIDO_HAVE_JOB_COST
  if (const auto model = cost_->set.for_backend(backend)) {
    const int threads = config_.job_threads > 0
                            ? config_.job_threads
                            : int(std::max(1u, std::thread::hardware_concurrency()));
    auto c = model->predict(a, backend, threads);
    if (c) {
      auto iv = [](const job::CostInterval& v) {
        return json{{"value", v.p50}, {"low", v.p10}, {"high", v.p90}};
      };
      p["basis"] = "job cost model";
      // Times follow the machine's pace: how much slower or faster its last jobs ran
      // than the model priced them (service/cost_trainer.h).
      const job::Pace pace = cost_->set.pace(backend);
      p["total_time_s"] = iv(job::paced(c->total_s, pace));
      p["time_per_frame_s"] = iv(job::paced(c->per_frame_s, pace));
      if (pace.jobs > 0) p["pace"] = {{"factor", pace.factor}, {"jobs", pace.jobs}};
      p["output_bytes"] = iv(c->output_bytes);
      const uint64_t output_high = uint64_t(std::ceil(c->output_bytes.p90));
      *admit_output = c->outside_training ? std::max(output_high, output_estimate) : output_high;
      p["output_bytes"]["estimate"] = output_estimate;
      p["output_bytes"]["admitted_by"] = *admit_output;
      if (backend == "cuda") {
        p["peak_device_bytes"] = iv(c->peak_device_bytes);
        p["gpu_load"] = iv(c->gpu_load);
      }
      const uint64_t high = uint64_t(std::ceil(c->peak_host_bytes.p90));
      *admit_bytes = c->outside_training ? std::max(high, analytic) : high;
      p["peak_host_bytes"] = iv(c->peak_host_bytes);
      p["peak_host_bytes"]["analytic"] = analytic;
      p["peak_host_bytes"]["admitted_by"] = *admit_bytes;
      p["outside_training"] = c->outside_training;
      p["outside_reasons"] = c->outside_reasons;
      p["device"] = c->device;
      p["threads"] = c->threads;
      p["drivers"] = job::drivers_to_json(*c);  // as `collidoscope predict --json` gives them
      return p;
    }
    p["note"] = "the job cost model cannot price this job: " + c.status().message();
    return p;
  }
#endif
  p["note"] = "time is not predicted: no job cost model for the " + backend +
              " backend is loaded on this server (serve --cost-model)";
  return p;
}

// Admitted by its predicted memory's high end, which the engine's own
// estimate (checked when it was prepared) may stay under: a job whose figure
// is more than the jobs may ever use would wait for ever. The 409 that says
// so, or none.
std::optional<Reply> JobService::over_memory(uint64_t host_bytes) {
  const uint64_t total = memory_for_jobs();
  if (host_bytes <= total) return std::nullopt;
  char text[160];
  std::snprintf(text, sizeof text,
                "the job is admitted by its predicted peak memory, %.2f GiB, more than the %.2f "
                "GiB jobs may use here; use fewer particles",
                double(host_bytes) / double(1 << 30), double(total) / double(1 << 30));
  return error_reply(409, text);
}

uint64_t JobService::disk_free() const {
  if (config_.disk_free_bytes) return config_.disk_free_bytes;
  struct statvfs fs_stat {};
  if (::statvfs(config_.data_dir.c_str(), &fs_stat) != 0) return 0;
  return uint64_t(fs_stat.f_bavail) * uint64_t(fs_stat.f_frsize);
}

std::optional<Reply> JobService::over_disk(uint64_t output_bytes) {
  const uint64_t free_bytes = disk_free();
  if (free_bytes == 0) return std::nullopt;  // unknown: the job's own writes will tell
  // The queued jobs will write theirs first (a running job's files are
  // already partly in what is used).
  auto queued = store_->queued_output_bytes();
  const uint64_t taken = config_.disk_reserve_bytes + (queued ? *queued : 0);
  const uint64_t room = free_bytes > taken ? free_bytes - taken : 0;
  if (output_bytes <= room) return std::nullopt;
  auto size = [](uint64_t bytes) {
    char t[32];
    if (bytes >= (1ull << 30))
      std::snprintf(t, sizeof t, "%.2f GiB", double(bytes) / double(1ull << 30));
    else
      std::snprintf(t, sizeof t, "%.1f MiB", double(bytes) / double(1ull << 20));
    return std::string(t);
  };
  return error_reply(
      507, "the job's files, " + size(output_bytes) + " by its prediction, do not fit in the " +
               size(room) + " this server has free for results (" +
               size(config_.disk_reserve_bytes) + " is kept free" +
               (queued && *queued ? ", " + size(*queued) + " is for the queued jobs" : "") +
               "); use fewer frames, a smaller render or fewer particles, or "
               "delete finished jobs");
}

Reply JobService::predict(const User& u, const json& body) {
  auto p = prepare(u, body);
  if (!p) return status_reply(p.status());
  // What submitting it would answer: the form says so before the user submits.
  if (auto refused = over_memory(p->host_bytes)) return *refused;
  if (auto refused = over_disk(p->output_bytes)) return *refused;
  Reply r;
  r.body = p->prediction;
  return r;
}

Reply JobService::start_preview(const User& u, const json& body) {
  // A job too large for this server's memory still shows where its particles
  // would start: the form's view follows the form while the user cuts it down.
  auto p = prepare(u, body, /*refuse_over_memory=*/false);
  if (!p) return status_reply(p.status());
  const uint64_t count = p->assessment.value("particles", uint64_t(0));
  if (count > kStartPlacedMost) {
    // A job this server's memory refuses has no run to place them.
    const bool runs = !over_memory(p->host_bytes);
    Reply r;
    r.body = {{"particles", count},
              {"shown", json::array()},
              {"release_s", json::array()},
              {"note", "more than " + std::to_string(kStartPlacedMost) +
                           " particles are not placed for a preview" +
                           (runs ? "; the run places them" : "")}};
    return r;
  }
  auto start = job::preview_start(p->assessed, kStartShown);
  if (!start) return status_reply(Status(start.status().code(), "scene: " + start.status().message()));
  Reply r;
  r.body = {{"particles", start->particles}, {"shown", start->shown}, {"release_s", start->release_s}};
  return r;
}

json JobService::links_of(const std::string& base, const Job& j) {
  json links = {{"manifest", base + "result.json"},
                {"stats", base + "stats.csv"},
                {"scene", base + "scene.json"},
                {"wall", base + "wall.stl"}};
  const json pred = json::parse(j.prediction_json, nullptr, false);
  json formats = json::array({"mp4", "webm", "gif"});
  if (pred.is_object() && pred.contains("inputs") && pred["inputs"].contains("formats"))
    formats = pred["inputs"]["formats"];
  links["poster"] = base + "render/poster.png";
  for (const json& f : formats) {
    const std::string s = f.get<std::string>();
    if (s == "mp4") links["mp4"] = base + "render/video.mp4";
    if (s == "webm") links["webm"] = base + "render/video.webm";
    if (s == "gif") links["gif"] = base + "render/loop.gif";
  }
  return links;
}

json JobService::job_json(const Job& j) {
  json out = {{"id", j.id},
              {"state", j.state},
              {"stage", j.stage},
              {"progress", j.progress},
              {"created_at", j.created_at},
              {"started_at", j.started_at > 0 ? json(j.started_at) : json(nullptr)},
              {"finished_at", j.finished_at > 0 ? json(j.finished_at) : json(nullptr)},
              {"attempts", j.attempts},
              {"scene", json::parse(j.scene_json, nullptr, false)},
              {"prediction", json::parse(j.prediction_json, nullptr, false)},
              {"cost", json::parse(j.cost_json, nullptr, false)},
              {"links", links_of("/api/v1/jobs/" + j.id + "/files/", j)}};
  out["links"]["self"] = "/api/v1/jobs/" + j.id;
  if (!j.error.empty()) out["error"] = j.error;
  if (!j.reused_from.empty()) out["reused_from"] = j.reused_from;
  if (!j.executor_ref.empty()) out["scheduler"] = {{"kind", "slurm"}, {"job_id", j.executor_ref}};
  return out;
}

Reply JobService::submit(const User& u, const json& body) {
  if (body.is_object() && body.contains("fresh") && !body["fresh"].is_boolean())
    return error_reply(400, "fresh: expected true or false");
  auto p = prepare(u, body);
  if (!p) return status_reply(p.status());
  const bool fresh = body.value("fresh", false);
  const double now = unix_now();
  Job j;
  j.id = random_token(16);
  j.owner_id = u.id;
  j.scene_json = p->scene.dump();
  j.scene_key = p->key;
  j.prediction_json = p->prediction.dump();
  j.predicted_host_bytes = p->host_bytes;
  j.predicted_output_bytes = p->output_bytes;
  j.created_at = now;
  if (!fresh) {
    auto earlier = store_->done_job_with_key(p->key);
    if (!earlier) return status_reply(earlier.status());
    // An uploaded mesh's result goes only to its owner: an instant result
    // would tell anyone else that someone uploaded the same mesh, and the
    // reused files name the other job's copy of it.
    const bool shareable = *earlier && (p->model_sha256.empty() || (*earlier)->owner_id == u.id);
    if (shareable && fs::exists(fs::path((*earlier)->run_dir) / "result.json")) {
      // The same scene ran before: its result, at once.
      j.state = "done";
      j.stage = "done";
      j.progress = 1;
      j.run_dir = (*earlier)->run_dir;
      j.cost_json = (*earlier)->cost_json;
      j.reused_from = (*earlier)->id;
      j.started_at = j.finished_at = now;
      if (Status st = store_->insert_job(j); !st) return status_reply(st);
      Reply r;
      r.status = 200;
      r.body = job_json(j);
      return r;
    }
  }
  if (auto refused = over_memory(p->host_bytes)) return *refused;
  if (auto refused = over_disk(p->output_bytes)) return *refused;
  auto queued = store_->count_jobs(u.id, "queued");
  if (!queued) return status_reply(queued.status());
  if (*queued >= uint64_t(config_.max_queued_per_user))
    return error_reply(429, "you have " + std::to_string(*queued) +
                                " jobs waiting: wait for one to start, or cancel one");
  const std::string dir = job_dir(j.id);
  j.run_dir = (fs::path(dir) / "run").string();
  p->spec.out_dir = j.run_dir;
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return error_reply(500, dir + ": " + ec.message());
  auto pinned = pin_model_wall(&*p, dir);
  if (!pinned || !*pinned) {
    fs::remove_all(dir, ec);
    if (!pinned) return status_reply(pinned.status());
    return error_reply(409, "the model's STL changed or went while the job was submitted: submit it again");
  }
  if (Status st = write_file_atomic((fs::path(dir) / "spec.json").string(),
                                    job::spec_to_json(p->spec) + "\n");
      !st)
    return status_reply(st);
  if (Status st = store_->insert_job(j); !st) return status_reply(st);
  notify_queued();
  Reply r;
  r.status = 202;
  r.body = job_json(j);
  r.headers.emplace_back("Location", "/api/v1/jobs/" + j.id);
  return r;
}

Expected<bool> JobService::pin_model_wall(PreparedJob* p, const std::string& job_dir) {
  if (p->model_sha256.empty()) return true;
  json scene = json::parse(p->spec.scene_json);
  const std::string source = scene["wall"]["file"].get<std::string>();
  const std::string pinned = fs::absolute(fs::path(job_dir) / "model.stl").string();
  // A second name for the upload's file: an upload after this one renames a
  // new file over the model's name (write_file_atomic) and leaves this one be.
  std::error_code ec;
  fs::create_hard_link(source, pinned, ec);
  if (ec) fs::copy_file(source, pinned, ec);  // another file system
  if (ec) return ec.value() == ENOENT ? Expected<bool>(false)
                                      : Expected<bool>(io_error(pinned + ": " + ec.message()));
  // An upload between pricing and the link would change what the result's key says.
  std::ifstream in(pinned, std::ios::binary);
  std::stringstream bytes;
  bytes << in.rdbuf();
  if (!in || sha256_hex(bytes.str()) != p->model_sha256) return false;
  scene["wall"]["file"] = pinned;
  p->spec.scene_json = scene.dump();
  return true;
}

Expected<Job> JobService::own_job(const User& u, const std::string& id) {
  auto j = store_->job_by_id(id);
  // Another user's job is as unknown as one that never was.
  if (!j || j->owner_id != u.id) return not_found("no job '" + id + "'");
  return j;
}

constexpr size_t kMaxJobViews = 20000;

// Everything of a job's row that changes after submission: its view is made again
// only when this does.
static std::string view_fingerprint(const JobStatus& j) {
  char numbers[112];
  std::snprintf(numbers, sizeof numbers, "%.17g|%d|%.17g|%.17g|%llu", j.progress, j.attempts,
                j.started_at, j.finished_at, static_cast<unsigned long long>(j.cost_bytes));
  return j.state + "|" + j.stage + "|" + numbers + "|" + j.executor_ref + "|" + j.error;
}

static JobStatus status_of(const Job& j) {
  JobStatus s;
  s.id = j.id;
  s.owner_id = j.owner_id;
  s.state = j.state, s.stage = j.stage, s.error = j.error, s.executor_ref = j.executor_ref;
  s.progress = j.progress, s.started_at = j.started_at, s.finished_at = j.finished_at;
  s.attempts = j.attempts;
  s.cost_bytes = j.cost_json.size();
  return s;
}

std::shared_ptr<const std::string> JobService::cached_view(const JobStatus& s) {
  const std::string fingerprint = view_fingerprint(s);
  std::lock_guard lock(view_mu_);
  auto it = job_views_.find(s.id);
  if (it != job_views_.end() && it->second.fingerprint == fingerprint) return it->second.text;
  return nullptr;
}

std::shared_ptr<const std::string> JobService::job_view(const Job& j) {
  const JobStatus s = status_of(j);
  if (auto text = cached_view(s)) return text;
  auto text = std::make_shared<const std::string>(job_json(j).dump());
  std::lock_guard lock(view_mu_);
  if (job_views_.size() >= kMaxJobViews) job_views_.clear();
  job_views_[j.id] = {view_fingerprint(s), text};
  return text;
}

std::string job_cursor_text(const JobCursor& c) {
  uint64_t bits;
  std::memcpy(&bits, &c.created_at, sizeof bits);
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(bits));
  return std::string(hex) + "." + c.id;
}

std::optional<JobCursor> parse_job_cursor(const std::string& text) {
  if (text.size() < 18 || text.size() > 17 + 64 || text[16] != '.') return std::nullopt;
  uint64_t bits = 0;
  for (size_t i = 0; i < 16; ++i) {
    const char c = text[i];
    const int digit = c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10 : -1;
    if (digit < 0) return std::nullopt;
    bits = bits << 4 | uint64_t(digit);
  }
  JobCursor c;
  std::memcpy(&c.created_at, &bits, sizeof bits);
  c.id = text.substr(17);
  if (!std::isfinite(c.created_at) || !std::all_of(c.id.begin(), c.id.end(), [](char ch) {
        return std::isalnum(static_cast<unsigned char>(ch)) || ch == '-' || ch == '_';
      }))
    return std::nullopt;
  return c;
}

Reply JobService::list_jobs(const User& u, size_t limit, const std::string& before) {
  limit = std::clamp<size_t>(limit, 1, kMaxJobsAPage);
  std::optional<JobCursor> after;
  if (!before.empty() && !(after = parse_job_cursor(before)))
    return error_reply(400,
                       "'before' is not a place in the job list (take it from the Link header)");
  auto jobs = store_->jobs_of(u.id, limit + 1, after);  // one more: is there a next page?
  if (!jobs) return status_reply(jobs.status());
  const bool more = jobs->size() > limit;
  if (more) jobs->pop_back();
  std::string text = "[";
  for (size_t i = 0; i < jobs->size(); ++i) {
    if (i) text += ",";
    text += *job_view((*jobs)[i]);
  }
  text += "]\n";
  Reply r;
  r.serialized = std::make_shared<const std::string>(std::move(text));
  if (more) {
    const Job& last = jobs->back();
    r.headers.emplace_back("Link", "</api/v1/jobs?limit=" + std::to_string(limit) +
                                       "&before=" + job_cursor_text({last.created_at, last.id}) +
                                       ">; rel=\"next\"");
  }
  return r;
}

Reply JobService::get_job(const User& u, const std::string& id) {
  // A poll of a job whose row has not changed is answered from its view, read
  // without the row's documents.
  auto s = store_->job_status(id);
  if (!s || s->owner_id != u.id) return status_reply(not_found("no job '" + id + "'"));
  std::shared_ptr<const std::string> text = cached_view(*s);
  if (!text) {
    auto j = own_job(u, id);
    if (!j) return status_reply(j.status());
    text = job_view(*j);
  }
  Reply r;
  r.serialized = std::make_shared<const std::string>(*text + "\n");
  return r;
}

Reply JobService::cancel_job(const User& u, const std::string& id) {
  auto j = own_job(u, id);
  if (!j) return status_reply(j.status());
  bool cancelled = false;
  if (j->state == "queued") {
    auto was = store_->cancel_queued_job(id, unix_now());
    if (!was) return status_reply(was.status());
    cancelled = *was;
    // Else a worker claimed it between the look above and the update: cancel the run.
    if (!cancelled) {
      j = store_->job_by_id(id);
      if (!j) return status_reply(j.status());
    }
  }
  if (!cancelled) {
    if (j->state != "running") return error_reply(409, "job '" + id + "' has ended (" + j->state + ")");
    // Kept in the store first: a restart, another replica, or an executor not
    // yet started ends it cancelled (in memory alone the request was lost).
    if (Status st = store_->request_cancel(id); !st) return status_reply(st);
    if (auto w = executor())
      w->cancel(*j);
    else
      cancel_flag(id)->store(true);  // no executor now: its next start sees the flag
  }
  auto now = store_->job_by_id(id);
  if (!now) return status_reply(now.status());
  Reply r;
  r.status = 202;
  r.body = job_json(*now);
  return r;
}

Reply JobService::delete_job(const User& u, const std::string& id) {
  auto j = own_job(u, id);
  if (!j) return status_reply(j.status());
  const Reply running = error_reply(409, "job '" + id + "' is running: cancel it first");
  if (j->state == "running") return running;
  auto deleted = store_->delete_job(id);
  if (!deleted) return status_reply(deleted.status());
  if (!*deleted) return running;  // a worker claimed it since the look above
  // Its files go once no job is left whose result they are: a job that
  // reused another's result names that job's folder, which goes with the last
  // of the jobs that name it, the original or one that reused it.
  auto sharing = store_->count_jobs_in_dir(j->run_dir, id);
  std::error_code ec;
  const fs::path folder = fs::path(j->run_dir).parent_path();
  if (sharing && *sharing == 0 && folder.parent_path() == fs::path(job_dir(id)).parent_path())
    fs::remove_all(folder, ec);
  Reply r;
  r.status = 204;
  r.body = nullptr;
  return r;
}

// A result path people and links may name: relative, no "." or ".." part, no
// empty part, no hidden or temporary file, and inside the run directory once
// symbolic links are followed.
Expected<std::string> JobService::file_in_run(const Job& j, const std::string& file) {
  const Status missing = not_found("no file '" + file + "'");
  if (file.empty() || file.size() > 512 || file.front() == '/') return missing;
  std::string part;
  std::istringstream parts(file);
  while (std::getline(parts, part, '/'))
    if (part.empty() || part.front() == '.' || is_temp_name(part)) return missing;
  if (file.back() == '/') return missing;
  std::error_code ec;
  const fs::path root = fs::canonical(j.run_dir, ec);
  if (ec) return missing;
  const fs::path full = fs::canonical(root / file, ec);
  if (ec) return missing;
  const std::string r = root.string() + "/";
  if (full.string().compare(0, r.size(), r) != 0) return missing;
  if (!fs::is_regular_file(full, ec)) return missing;
  // A job still running has files that are not its results yet (the checkpoint).
  if (full.filename() == "checkpoint.bin" || full.filename() == "job.json") return missing;
  return full.string();
}

Expected<std::string> JobService::job_file(const User& u, const std::string& id,
                                           const std::string& file) {
  auto j = own_job(u, id);
  if (!j) return j.status();
  return file_in_run(*j, file);
}

Expected<std::string> JobService::shared_file(const std::string& token, const std::string& file) {
  auto sh = store_->share_by_token(token);
  if (!sh || (sh->expires_at > 0 && sh->expires_at < unix_now())) return not_found("no such share");
  auto j = store_->job_by_id(sh->job_id);
  if (!j) return not_found("no such share");
  return file_in_run(*j, file);
}

// ---- shares -----------------------------------------------------------------

Reply JobService::create_share(const User& u, const std::string& job_id, const json& body) {
  auto j = own_job(u, job_id);
  if (!j) return status_reply(j.status());
  if (!body.is_null() && !body.is_object()) return error_reply(400, "the body must be a JSON object");
  Share sh;
  sh.token = random_token();
  sh.job_id = job_id;
  sh.created_by = u.id;
  sh.created_at = unix_now();
  if (body.is_object() && body.contains("expires_in_s")) {
    const json& e = body["expires_in_s"];
    if (!e.is_number() || !std::isfinite(e.get<double>()) || e.get<double>() <= 0 ||
        e.get<double>() > 10 * 365 * 86400.0)
      return error_reply(400, "expires_in_s: seconds, in (0, 10 years]");
    sh.expires_at = sh.created_at + e.get<double>();
  }
  if (Status st = store_->insert_share(sh); !st) return status_reply(st);
  Reply r;
  r.status = 201;
  r.body = share_view(sh);
  return r;
}

json JobService::share_view(const Share& sh) {
  return {{"token", sh.token},
          {"url", public_url() + "/s/" + sh.token},
          {"embed", public_url() + "/embed/" + sh.token},
          {"created_at", sh.created_at},
          {"expires_at", sh.expires_at > 0 ? json(sh.expires_at) : json(nullptr)}};
}

Reply JobService::list_shares(const User& u, const std::string& job_id) {
  auto j = own_job(u, job_id);
  if (!j) return status_reply(j.status());
  auto shares = store_->shares_of_job(job_id);
  if (!shares) return status_reply(shares.status());
  const double now = unix_now();
  Reply r;
  r.body = json::array();
  for (const Share& sh : *shares)
    if (sh.created_by == u.id && !(sh.expires_at > 0 && sh.expires_at < now))
      r.body.push_back(share_view(sh));
  return r;
}

Reply JobService::delete_share(const User& u, const std::string& token) {
  auto sh = store_->share_by_token(token);
  if (!sh || sh->created_by != u.id) return error_reply(404, "no such share");
  if (Status st = store_->delete_share(token); !st) return status_reply(st);
  Reply r;
  r.status = 204;
  r.body = nullptr;
  return r;
}

Reply JobService::share_info(const std::string& token) {
  auto sh = store_->share_by_token(token);
  if (!sh || (sh->expires_at > 0 && sh->expires_at < unix_now()))
    return error_reply(404, "no such share");
  auto j = store_->job_by_id(sh->job_id);
  if (!j) return error_reply(404, "no such share");
  Reply r;
  const json scene = json::parse(j->scene_json, nullptr, false);
  r.body = {{"state", j->state},
            {"progress", j->progress},
            {"links", links_of("/s/" + token + "/", *j)},
            {"scene", scene},
            {"expires_at", sh->expires_at > 0 ? json(sh->expires_at) : json(nullptr)}};
  return r;
}

// ---- the demo ---------------------------------------------------------------

json JobService::demo_request() {
  // The inlet 20 m over wall1's floor: the first particles land after 1.8 s
  // and the rest pile for the run's last 2 s. (From 60 m, the fall took
  // 3.3 s, and a 3 s demo showed particles falling and never touching.)
  return {{"scene",
           {{"wall", "wall1"},
            {"particles", {{"count", 1500}, {"radius", 1.0}, {"density", 2500}}},
            {"placement",
             {{"kind", "pour"},
              {"inlet", {0, 0, 20}},
              {"inlet_radius", 25},
              {"rate", 800},
              {"velocity", {0, 0, -2}}}},
            {"material", {{"restitution", 0.4}, {"friction", 0.3}, {"impact_speed", 35}}},
            {"particle_contacts", true},
            {"duration", 4},
            {"fps", 24}}},
          {"render", {{"width", 640}, {"height", 360}}}};
}

Expected<JobService::Demo> JobService::start_demo() {
  Demo d;
  d.name = "demo";
  const std::string pw_path = (fs::path(config_.data_dir) / "demo-password").string();
  std::string hash;
  auto user = store_->user_by_name(d.name, &hash);
  d.password = read_file(pw_path);
  while (!d.password.empty() && std::isspace((unsigned char)d.password.back())) d.password.pop_back();
  if (!user || d.password.empty() || !verify_password(hash, d.password)) {
    if (user) return invalid_argument("a user 'demo' exists whose password is not in " + pw_path);
    d.password = random_token(12);
    if (Status st = write_file_atomic(pw_path, d.password + "\n"); !st) return st;
    ::chmod(pw_path.c_str(), 0600);
    auto hashed = hash_password(d.password);
    if (!hashed) return hashed.status();
    auto made = store_->create_user(d.name, *hashed, "user");
    if (!made) return made.status();
    user = made;
  }
  Reply r = submit(*user, demo_request());
  if (r.status != 200 && r.status != 202)
    return backend_error("the demo job was refused: " + r.body.value("error", ""));
  d.job_id = r.body["id"].get<std::string>();
  d.state = r.body["state"].get<std::string>();
  return d;
}

// ---- administration, health, metrics ----------------------------------------

Reply JobService::admin_logs(const User& u, size_t limit, int64_t before_id) {
  if (u.role != "admin") return error_reply(403, "administrators only");
  auto rows = store_->logs(std::min<size_t>(limit, 1000), before_id);
  if (!rows) return status_reply(rows.status());
  Reply r;
  r.body = json::array();
  for (const LogRow& l : *rows)
    r.body.push_back({{"id", l.id},
                      {"job_id", l.job_id},
                      {"inputs", json::parse(l.inputs_json, nullptr, false)},
                      {"measured", json::parse(l.measured_json, nullptr, false)},
                      {"predicted", json::parse(l.predicted_json, nullptr, false)},
                      {"created_at", l.created_at}});
  return r;
}

Reply JobService::admin_predictor(const User& u) {
  if (u.role != "admin") return error_reply(403, "administrators only");
  Reply r;
  r.body = {{"models", json::array()}};
#ifdef COLLIDO_HAVE_JOB_COST
  for (const CostModelSet::Entry& e : cost_->set.all()) {
    json m = e.model->summary();
    m["file"] = fs::path(e.file).filename().string();
    r.body["models"].push_back(std::move(m));
  }
  r.body["retrain"] = cost_->trainer->status();
#endif
  return r;
}

Reply JobService::admin_retrain(const User& u) {
  if (u.role != "admin") return error_reply(403, "administrators only");
#ifdef COLLIDO_HAVE_JOB_COST
  if (!cost_->trainer->start()) return error_reply(409, "a retraining is running");
  Reply r;
  r.status = 202;
  r.body = {{"retrain", cost_->trainer->status()}};
  return r;
#else
  return error_reply(409, "this build has no job cost model (the gvm module was left out)");
#endif
}

void JobService::wait_retrained() {
#ifdef COLLIDO_HAVE_JOB_COST
  cost_->trainer->wait_idle();
#endif
}

Reply JobService::health() {
  Reply r;
  auto users = store_->count_users();
  r.body = {{"status", users ? "ok" : "degraded"},
            {"schema_version", store_schema_version()},
            {"executor", config_.executor},
            {"workers", [&] {
               auto w = executor();
               return w ? w->size() : 0;
             }()}};
  if (!users) r.status = 503;
  return r;
}

std::string JobService::metrics() {
  std::ostringstream m;
  auto counts = store_->job_state_counts();
  uint64_t queued = 0;
  m << "# HELP collidoscope_jobs Jobs in the store by state.\n"
       "# TYPE collidoscope_jobs gauge\n";
  for (const char* state : {"queued", "running", "done", "failed", "cancelled"}) {
    uint64_t n = 0;
    if (counts)
      for (const auto& [s, c] : *counts)
        if (s == state) n = c;
    if (std::string(state) == "queued") queued = n;
    m << "collidoscope_jobs{state=\"" << state << "\"} " << n << "\n";
  }
  m << "# HELP collidoscope_queue_length Jobs waiting for a worker.\n"
       "# TYPE collidoscope_queue_length gauge\n"
       "collidoscope_queue_length "
    << queued << "\n";
  // Prediction error of finished jobs: mean |predicted - measured| / measured
  // over the newest 1000 log rows that had a prediction.
  auto rows = store_->logs(1000, 0);
  double mem_err = 0, time_err = 0;
  uint64_t mem_n = 0, time_n = 0;
  if (rows)
    for (const LogRow& l : *rows) {
      if (l.predicted_host_bytes > 0 && l.peak_host_bytes > 0) {
        mem_err += std::fabs(double(l.predicted_host_bytes) - double(l.peak_host_bytes)) /
                   double(l.peak_host_bytes);
        ++mem_n;
      }
      if (l.predicted_total_s >= 0 && l.total_s > 0) {
        time_err += std::fabs(l.predicted_total_s - l.total_s) / l.total_s;
        ++time_n;
      }
    }
  m << "# HELP collidoscope_prediction_error Mean relative error of the prediction of finished "
       "jobs (newest 1000).\n"
       "# TYPE collidoscope_prediction_error gauge\n";
  if (mem_n) m << "collidoscope_prediction_error{figure=\"peak_host_bytes\"} " << mem_err / double(mem_n) << "\n";
  if (time_n) m << "collidoscope_prediction_error{figure=\"total_time_s\"} " << time_err / double(time_n) << "\n";
  m << "# HELP collidoscope_log_rows Finished jobs in the run log.\n"
       "# TYPE collidoscope_log_rows gauge\n"
       "collidoscope_log_rows "
    << (rows ? rows->size() : 0) << "\n";
  return m.str();
}

// ---- worker callbacks -------------------------------------------------------

std::shared_ptr<std::atomic<bool>> JobService::cancel_flag(const std::string& id) {
  std::lock_guard lock(cancel_mu_);
  auto& f = cancel_flags_[id];
  if (!f) f = std::make_shared<std::atomic<bool>>(false);
  return f;
}

void JobService::forget_cancel_flag(const std::string& id) {
  std::lock_guard lock(cancel_mu_);
  cancel_flags_.erase(id);
}

Expected<job::JobSpec> JobService::read_spec(const Job& j) {
  const std::string path = (fs::path(job_dir(j.id)) / "spec.json").string();
  std::ifstream in(path);
  if (!in) return not_found(path + ": cannot read");
  std::stringstream text;
  text << in.rdbuf();
  auto spec = job::spec_from_json(text.str());
  if (!spec) return Status(spec.status().code(), "the job's spec.json: " + spec.status().message());
  return spec;
}

Expected<job::JobSpec> JobService::write_run_spec(const Job& j, int threads) {
  auto spec = read_spec(j);
  if (!spec) return spec;
  // A later attempt continues the run it left, if it had started one: stopped
  // while it prepared (the wall, the placement, the automatic choice), it has
  // no run folder yet, and resuming would fail where starting over works.
  if (j.attempts > 1 && job::holds_a_run(j.run_dir)) spec->dir_policy = job::DirPolicy::kResume;
  if (threads > 0) spec->threads = threads;
  const std::string path = (fs::path(job_dir(j.id)) / "spec.run.json").string();
  if (Status st = write_file_atomic(path, job::spec_to_json(*spec) + "\n"); !st) return st;
  return spec;
}

json JobService::run_manifest(const Job& j) {
  std::ifstream in((fs::path(j.run_dir) / "result.json").string());
  std::stringstream text;
  text << in.rdbuf();
  const json m = json::parse(text.str(), nullptr, false);
  return m.is_object() ? m : json::object();
}

void JobService::job_started(const Job& j) { store_->set_job_progress(j.id, "prepare", j.progress); }

void JobService::job_progress(const std::string& id, const std::string& stage, double progress) {
  store_->set_job_progress(id, stage, progress);
}

void JobService::job_finished(const Job& j, const std::string& state, const std::string& error,
                              const json& manifest, uint64_t peak_host_bytes, const json& partial) {
  json cost = manifest.is_object() && manifest.contains("cost") ? manifest["cost"] : json::object();
  // The job's own peak (VmHWM) as it reported it; wait4()'s figure, which
  // carries the server's own peak into the child, only when it did not.
  if (!cost.contains("peak_host_bytes") && peak_host_bytes > 0) cost["peak_host_bytes"] = peak_host_bytes;
  const std::optional<LogRow> row = log_row_of(j, state, error, manifest, cost, partial);
  // The job ends and its log row is written in one transaction: whoever sees
  // it ended sees its row.
  auto ended = store_->finish_job(j.id, state, cost.dump(), error, unix_now(),
                                  row ? &*row : nullptr);
  forget_cancel_flag(j.id);
  if (!ended || !*ended) return;  // ended already (another replica): logged there
  if (!row || state != "done") return;
  finished_since_start_.fetch_add(1);
#ifdef COLLIDO_HAVE_JOB_COST
  if (!row->job_record.empty()) cost_->trainer->job_logged(manifest.value("backend", ""));
#endif
}

std::optional<LogRow> JobService::log_row_of(const Job& j, const std::string& state,
                                             const std::string& error, const json& manifest,
                                             const json& cost, const json& partial) {
  if (state != "done" && !partial.is_object()) return std::nullopt;
  // The run log row: the inputs the cost model prices by, what it cost (or, for
  // a run the scheduler or a failure ended, what was measured of it), and what
  // was predicted at submission.
  const json pred = json::parse(j.prediction_json, nullptr, false);
  LogRow row;
  row.job_id = j.id;
  json inputs = pred.is_object() && pred.contains("inputs") ? pred["inputs"] : json::object();
  row.predicted_json = j.prediction_json;
  row.predicted_host_bytes = j.predicted_host_bytes;
  row.created_at = unix_now();
  if (state != "done") {
    // No total time (it did not finish), so the prediction-error metrics and
    // the retraining leave it out.
    json measured = partial;
    measured["outcome"] = state;
    measured["error"] = error;
    row.inputs_json = inputs.dump();
    row.measured_json = measured.dump();
    row.peak_host_bytes = partial.value("peak_host_bytes", uint64_t(0));
    return row;
  }
  inputs["backend"] = manifest.value("backend", "");
  inputs["threads"] = manifest.value("threads", 0);
  inputs["steps"] = cost.value("steps", 0);
  row.inputs_json = inputs.dump();
  row.measured_json = cost.dump();
  row.total_s = cost.value("total_s", 0.0);
  const double frames = std::max(1.0, double(cost.value("frames", 1)));
  row.per_frame_s = cost.value("simulate_s", 0.0) / frames;
  row.peak_host_bytes = cost.value("peak_host_bytes", uint64_t(0));
  row.peak_device_bytes = cost.value("peak_device_bytes", uint64_t(0));
  row.gpu_load = cost.value("gpu_busy_fraction", 0.0);
  if (pred.is_object() && pred.contains("total_time_s") && pred["total_time_s"].is_object())
    row.predicted_total_s = pred["total_time_s"].value("value", -1.0);
#ifdef COLLIDO_HAVE_JOB_COST
  row.job_record = job_record_of(j, pred, manifest);
#endif
  return row;
}

#ifdef COLLIDO_HAVE_JOB_COST
// A finished job as a job-log row (job/job_log.h), what the cost model retrains on:
// its inputs from its spec, assessed again as at submission, and its measure from
// its manifest. "" when either cannot be made (the row is then left out of training).
std::string JobService::job_record_of(const Job& j, const json& prediction, const json& manifest) {
  std::ifstream in((fs::path(job_dir(j.id)) / "spec.json").string());
  std::stringstream text;
  text << in.rdbuf();
  auto spec = job::spec_from_json(text.str());
  if (!in || !spec) return "";
  auto a = job::assess_job(*spec);
  auto m = job::job_measure_from_manifest(manifest.dump());
  if (!a || !m) return "";
  const std::string backend = manifest.value("backend", "");
  // The device: the one the job was priced for on the GPU (its name is not in the
  // manifest), this machine's CPU otherwise.
  std::string device = job::cpu_model_name();
  if (backend == "cuda")
    device = prediction.is_object() ? prediction.value("device", std::string()) : std::string();
  job::JobRecord rec{job::job_inputs(*a, backend, device, manifest.value("threads", 0)), *m};
  if (!job::validate(rec.inputs) || !job::validate(rec.measure)) return "";
  return job::format_job_log({rec});
}
#endif

}  // namespace collido::service
