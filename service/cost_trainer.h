// The service's job cost models, and their retraining from the jobs it ran.
//
// Every finished job leaves a log row with its job-log record (store.h). After
// `every` new rows of a backend, or when an administrator asks, a background thread
// trains a candidate on the base logs (the committed sweeps) plus the service's own
// rows, and swaps it in only when it misses the held-out rows by less than the
// model in use. Held out are the service's rows whose job id hashes into the
// held-out share: the same rows on every retraining, so no model in use has ever
// been trained on them and the comparison stays fair. A model swapped in is written
// to DIR/job_model_BACKEND.json (temporary name, renamed), which the next start
// loads in place of an older configured file.
//
// Between retrainings the machine's speed moves (a shared VM ran the same jobs 17 %
// slower one session than another; docs/gvm.md): the trainer also keeps each
// backend's pace, the median of measured over predicted total time of its last jobs
// where they lean one way beyond chance (job/cost_model.h), by which the service
// scales its time prices.
#pragma once

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "common/status.h"
#include "job/cost_model.h"
#include "job/job_log.h"
#include "service/store.h"

namespace collido::service {

// The models in use, one per backend; read by request threads, replaced by the trainer.
class CostModelSet {
 public:
  struct Entry {
    std::shared_ptr<const job::JobCostModel> model;
    std::string file;
  };
  // The model trained for a backend ("cpu", "cuda"); null when none.
  std::shared_ptr<const job::JobCostModel> for_backend(const std::string& backend) const;
  std::vector<Entry> all() const;
  // Adds a model, which answers first for its backends; one it covers entirely goes.
  void put(std::shared_ptr<const job::JobCostModel> model, const std::string& file);
  // The machine's pace against a backend's model (factor 1 until jobs have run).
  job::Pace pace(const std::string& backend) const;
  void set_pace(const std::string& backend, const job::Pace& pace);

 private:
  mutable std::mutex mu_;
  std::vector<Entry> entries_;
  std::map<std::string, job::Pace> pace_;
};

// Loads model files into a set. A retrained model in retrained_dir
// (job_model_BACKEND.json) takes the place of a configured one of its backend when
// it is newer; one whose backend no configured file has is added. A configured file
// that does not load is an error; a retrained one is left with a line in *notes.
Status load_cost_models(const std::vector<std::string>& files, const std::string& retrained_dir,
                        CostModelSet* set, std::vector<std::string>* notes = nullptr);

struct CostTrainerConfig {
  std::vector<std::string> base_logs;  // job logs a candidate trains on besides the service's rows
  int every = 25;                      // new log rows of a backend that start a retraining; 0: asked only
  std::string model_dir;               // where swapped-in models are written
  job::JobCostOptions options;
  int held_out_percent = 30;           // of the service's rows, by job id
  size_t min_held_out = 3;             // fewer: nothing to compare on, the model in use stays
  size_t min_rows = 20;                // training rows a candidate needs
};

// The held-out rule: whether a job's log row is never trained on.
bool held_out_job(const std::string& job_id, int held_out_percent);

// Mean absolute percentage error (%) of a model on records, per cost it predicts:
// total time and peak host memory, and peak device memory on the GPU.
nlohmann::json held_out_errors(const job::JobCostModel& model,
                               const std::vector<job::JobRecord>& rows);

class CostTrainer {
 public:
  CostTrainer(CostTrainerConfig config, Store& store, CostModelSet& models);
  ~CostTrainer();  // waits for a retraining in progress
  CostTrainer(const CostTrainer&) = delete;
  CostTrainer& operator=(const CostTrainer&) = delete;

  // A job of `backend` wrote its log row: its pace is measured again, and a
  // retraining starts once `every` rows have come.
  void job_logged(const std::string& backend);
  // Measures a backend's pace again: its model on the newest log rows of the backend.
  void update_pace(const std::string& backend);
  // Starts a retraining of every backend now; false when one is running.
  bool start();
  // {"running", "retrainings", "every", "last": {per backend: rows, errors, decision},
  //  "pace": {per backend: factor, jobs}}.
  nlohmann::json status() const;
  // Blocks until no retraining runs (tests).
  void wait_idle();

 private:
  void run();
  nlohmann::json retrain(const std::string& backend, const std::vector<job::JobRecord>& base,
                         const std::vector<std::pair<std::string, job::JobRecord>>& service_rows);

  CostTrainerConfig config_;
  Store& store_;
  CostModelSet& models_;
  mutable std::mutex mu_;
  std::thread thread_;
  bool running_ = false;
  int retrainings_ = 0;
  std::map<std::string, int> new_rows_;
  nlohmann::json last_ = nlohmann::json::object();
};

}  // namespace collido::service
