#include "service/cost_trainer.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "common/stopwatch.h"

namespace collido::service {

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

// FNV-1a: a stable hash of a job id, the same on every machine and every start.
uint64_t stable_hash(const std::string& s) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) h = (h ^ c) * 1099511628211ull;
  return h;
}

// The score two models are compared by: the mean of their errors on the costs
// both predict (lower is better).
double score(const json& errors) {
  double sum = 0;
  int n = 0;
  for (const auto& [name, value] : errors.items())
    if (value.is_number()) sum += value.get<double>(), ++n;
  return n ? sum / n : INFINITY;
}

}  // namespace

// ---- The set of models in use ---------------------------------------------------------

std::shared_ptr<const job::JobCostModel> CostModelSet::for_backend(const std::string& backend) const {
  std::lock_guard lock(mu_);
  for (const Entry& e : entries_)
    if (e.model->trained_for(backend)) return e.model;
  return nullptr;
}

std::vector<CostModelSet::Entry> CostModelSet::all() const {
  std::lock_guard lock(mu_);
  return entries_;
}

void CostModelSet::put(std::shared_ptr<const job::JobCostModel> model, const std::string& file) {
  std::lock_guard lock(mu_);
  // The new model answers first for its backends; an older one that covers no other
  // backend goes (one trained on both backends stays for the other).
  std::vector<Entry> kept{{model, file}};
  for (Entry& e : entries_) {
    bool covered = true;
    for (const std::string& b : e.model->backends()) covered = covered && model->trained_for(b);
    if (!covered) kept.push_back(std::move(e));
  }
  entries_ = std::move(kept);
}

job::Pace CostModelSet::pace(const std::string& backend) const {
  std::lock_guard lock(mu_);
  const auto it = pace_.find(backend);
  return it == pace_.end() ? job::Pace{} : it->second;
}

void CostModelSet::set_pace(const std::string& backend, const job::Pace& pace) {
  std::lock_guard lock(mu_);
  pace_[backend] = pace;
}

Status load_cost_models(const std::vector<std::string>& files, const std::string& retrained_dir,
                        CostModelSet* set, std::vector<std::string>* notes) {
  for (const std::string& path : files) {
    auto m = job::JobCostModel::load(path);
    if (!m) return Status(m.status().code(), "cost model: " + m.status().message());
    set->put(std::make_shared<const job::JobCostModel>(std::move(*m)), path);
  }
  if (retrained_dir.empty()) return Status::ok();
  for (const char* backend : {"cpu", "cuda"}) {
    const fs::path path = fs::path(retrained_dir) / (std::string("job_model_") + backend + ".json");
    std::error_code ec, configured_ec;
    const auto retrained_at = fs::last_write_time(path, ec);
    if (ec) continue;  // never retrained
    // A configured file newer than the retrained model (a new sweep) is kept.
    std::string configured;
    for (const CostModelSet::Entry& e : set->all())  // the one answering for the backend
      if (configured.empty() && e.model->trained_for(backend)) configured = e.file;
    if (!configured.empty() && fs::last_write_time(configured, configured_ec) > retrained_at &&
        !configured_ec)
      continue;
    // One this build cannot read (a file of an older version, after an upgrade)
    // gives way to the configured model: the trainer writes a new one from the
    // service's log after its next jobs, so the service still starts.
    auto m = job::JobCostModel::load(path.string());
    if (!m) {
      if (notes) notes->push_back("retrained cost model " + path.string() + " left unused: " +
                                  m.status().message());
      continue;
    }
    set->put(std::make_shared<const job::JobCostModel>(std::move(*m)), path.string());
  }
  return Status::ok();
}

// ---- Comparing models -----------------------------------------------------------------

bool held_out_job(const std::string& job_id, int held_out_percent) {
  return int(stable_hash(job_id) % 100) < held_out_percent;
}

json held_out_errors(const job::JobCostModel& model, const std::vector<job::JobRecord>& rows) {
  double sums[job::kJobOutputs] = {};
  int counts[job::kJobOutputs] = {};
  const size_t used[] = {0, 2, 3};  // total time, peak host, peak device
  for (const job::JobRecord& r : rows) {
    double predicted[job::kJobOutputs], measured[job::kJobOutputs];
    model.predict_point(r.inputs, predicted);
    job::job_measure_to_array(r.measure, measured);
    for (size_t k : used) {
      if (!(measured[k] > 0)) continue;  // no device memory on the CPU
      sums[k] += std::abs(predicted[k] - measured[k]) / measured[k];
      ++counts[k];
    }
  }
  json out = json::object();
  for (size_t k : used)
    if (counts[k]) out[job::job_output_names()[k]] = 100.0 * sums[k] / counts[k];
  return out;
}

// ---- The trainer ------------------------------------------------------------------------

CostTrainer::CostTrainer(CostTrainerConfig config, Store& store, CostModelSet& models)
    : config_(std::move(config)), store_(store), models_(models) {
  for (const char* backend : {"cpu", "cuda"}) update_pace(backend);  // the log's last jobs
}

CostTrainer::~CostTrainer() { wait_idle(); }

void CostTrainer::wait_idle() {
  std::thread t;
  {
    std::lock_guard lock(mu_);
    t = std::move(thread_);
  }
  if (t.joinable()) t.join();
}

void CostTrainer::update_pace(const std::string& backend) {
  const auto model = models_.for_backend(backend);
  if (!model) return;
  // The backend's newest rows: a page of the log is enough unless the other backend
  // ran most of the last jobs; at most a few pages are read.
  std::vector<job::JobRecord> newest;
  int64_t before = 0;
  for (int page_no = 0; page_no < 4 && newest.size() < job::kPaceWindow; ++page_no) {
    auto page = store_.logs(100, before);
    if (!page || page->empty()) break;
    for (const LogRow& l : *page) {
      if (newest.size() == job::kPaceWindow) break;
      before = l.id;
      if (l.job_record.empty()) continue;
      auto rec = job::parse_job_log(l.job_record);
      if (rec && rec->size() == 1 && rec->front().inputs.backend == backend)
        newest.push_back(rec->front());
    }
  }
  models_.set_pace(backend, job::pace_of(*model, newest));
}

void CostTrainer::job_logged(const std::string& backend) {
  update_pace(backend);
  {
    std::lock_guard lock(mu_);
    if (config_.every <= 0 || ++new_rows_[backend] < config_.every) return;
  }
  start();
}

bool CostTrainer::start() {
  std::lock_guard lock(mu_);
  if (running_) return false;
  if (thread_.joinable()) thread_.join();  // the last one has ended: running_ is false
  running_ = true;
  new_rows_.clear();
  thread_ = std::thread([this] { run(); });
  return true;
}

json CostTrainer::status() const {
  std::lock_guard lock(mu_);
  json pace = json::object();
  for (const char* backend : {"cpu", "cuda"}) {
    const job::Pace p = models_.pace(backend);
    if (p.jobs > 0) pace[backend] = {{"factor", p.factor}, {"jobs", p.jobs}};
  }
  return {{"running", running_},
          {"retrainings", retrainings_},
          {"every", config_.every},
          {"held_out_percent", config_.held_out_percent},
          {"last", last_},
          {"pace", pace}};
}

void CostTrainer::run() {
  // Training takes every core for seconds: below the jobs and the requests.
  setpriority(PRIO_PROCESS, pid_t(syscall(SYS_gettid)), 10);
  const double started = unix_now();
  json result = json::object();
  std::vector<job::JobRecord> base;
  json base_errors = json::array();
  for (const std::string& path : config_.base_logs) {
    auto rows = job::read_job_log(path);
    if (!rows) {
      base_errors.push_back(rows.status().message());
      continue;
    }
    base.insert(base.end(), rows->begin(), rows->end());
  }
  // The service's rows: every log row that kept its job record.
  std::vector<std::pair<std::string, job::JobRecord>> service_rows;
  int64_t before = 0;
  for (;;) {
    auto page = store_.logs(1000, before);
    if (!page || page->empty()) break;
    for (const LogRow& l : *page) {
      before = l.id;
      if (l.job_record.empty()) continue;
      auto rec = job::parse_job_log(l.job_record);
      if (rec && rec->size() == 1) service_rows.push_back({l.job_id, rec->front()});
    }
  }
  for (const char* backend : {"cpu", "cuda"}) {
    json r = retrain(backend, base, service_rows);
    if (!r.is_null()) result[backend] = std::move(r);
    update_pace(backend);  // against the model now in use
  }
  std::lock_guard lock(mu_);
  last_ = {{"started_at", started},
           {"took_s", unix_now() - started},
           {"backends", std::move(result)}};
  if (!base_errors.empty()) last_["base_log_errors"] = std::move(base_errors);
  ++retrainings_;
  running_ = false;
}

json CostTrainer::retrain(const std::string& backend, const std::vector<job::JobRecord>& base,
                          const std::vector<std::pair<std::string, job::JobRecord>>& service_rows) {
  std::vector<job::JobRecord> train, held;
  size_t from_base = 0, from_service = 0;
  for (const job::JobRecord& r : base)
    if (r.inputs.backend == backend) train.push_back(r), ++from_base;
  for (const auto& [id, r] : service_rows) {
    if (r.inputs.backend != backend) continue;
    if (held_out_job(id, config_.held_out_percent)) {
      held.push_back(r);
    } else {
      train.push_back(r);
      ++from_service;
    }
  }
  const auto current = models_.for_backend(backend);
  if (train.empty() && held.empty() && !current) return nullptr;  // nothing of this backend
  json r = {{"rows", {{"base", from_base}, {"service", from_service}, {"held_out", held.size()}}},
            {"swapped", false}};
  if (train.size() < config_.min_rows) {
    r["decision"] = "too few rows to train on (" + std::to_string(train.size()) + ", at least " +
                    std::to_string(config_.min_rows) + ")";
    return r;
  }
  if (current && held.size() < config_.min_held_out) {
    r["decision"] = "too few held-out rows to compare on (" + std::to_string(held.size()) +
                    ", at least " + std::to_string(config_.min_held_out) + "): the model in use stays";
    return r;
  }
  const auto t0 = SteadyClock::now();
  job::JobTrainReport report;
  auto candidate = job::JobCostModel::train(train, config_.options, &report);
  r["train_s"] = seconds_since(t0);
  if (!candidate) {
    r["decision"] = "training failed: " + candidate.status().message();
    return r;
  }
  const json cand_err = held_out_errors(*candidate, held);
  r["candidate_errors"] = cand_err;
  bool better = !current;
  if (current) {
    const json cur_err = held_out_errors(*current, held);
    r["current_errors"] = cur_err;
    better = score(cand_err) < score(cur_err);
  }
  if (!better) {
    r["decision"] = "the model in use misses the held-out rows by less: it stays";
    return r;
  }
  const std::string path = (fs::path(config_.model_dir) / ("job_model_" + backend + ".json")).string();
  std::error_code ec;
  fs::create_directories(config_.model_dir, ec);
  if (Status st = candidate->save(path); !st) {
    r["decision"] = "better, but not saved: " + st.message();
    return r;
  }
  models_.put(std::make_shared<const job::JobCostModel>(std::move(*candidate)), path);
  r["swapped"] = true;
  r["decision"] = current ? "better on the held-out rows: swapped in" : "no model before: put in use";
  return r;
}

}  // namespace collido::service
