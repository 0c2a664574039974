// Retraining the job cost model from the service's log rows (service/cost_trainer.h):
// a candidate is swapped in only when it misses the held-out rows by less than the
// model in use, the held-out rows are the same on every retraining, and too few rows
// leave the model in use alone. The rows are real jobs: the committed CPU job log.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>

#include "job/job_log.h"
#include "service/cost_trainer.h"
#include "tests/scratch.h"

namespace collido::service {
namespace {

namespace fs = std::filesystem;

std::string temp_dir(const std::string& name) {
  return test::scratch_dir("cost_trainer_" + name);
}

std::vector<job::JobRecord> committed_rows() {
  auto rows = job::read_job_log(std::string(COLLIDO_SOURCE_DIR) + "/bench/data/jobs_cpu.csv");
  EXPECT_TRUE(rows) << rows.status().message();
  return rows ? *rows : std::vector<job::JobRecord>{};
}

// The same jobs, their memory and time measured 3x what they were: a model of them
// misses the real jobs by about 200 %.
std::vector<job::JobRecord> inflated(std::vector<job::JobRecord> rows) {
  for (job::JobRecord& r : rows) {
    r.measure.peak_host_bytes *= 3;
    r.measure.total_s *= 3;
    r.measure.per_frame_s *= 3;
  }
  return rows;
}

job::JobCostOptions small_options() {
  job::JobCostOptions o;
  o.gvm.hidden = 6;
  o.gvm.epochs = 40;
  o.folds = 3;
  return o;
}

std::shared_ptr<const job::JobCostModel> train(const std::vector<job::JobRecord>& rows) {
  auto m = job::JobCostModel::train(rows, small_options(), nullptr);
  EXPECT_TRUE(m) << m.status().message();
  return std::make_shared<const job::JobCostModel>(std::move(*m));
}

// A store whose log holds `n` of the committed jobs, each as the service writes it.
std::unique_ptr<Store> store_with_jobs(const std::string& dir, const std::vector<job::JobRecord>& rows,
                                       size_t n) {
  auto store = open_sqlite_store(dir + "/collidoscope.db");
  EXPECT_TRUE(store) << store.status().message();
  for (size_t i = 0; i < n && i < rows.size(); ++i) {
    LogRow l;
    l.job_id = "job-" + std::to_string(i);
    l.inputs_json = l.measured_json = l.predicted_json = "{}";
    l.job_record = job::format_job_log({rows[i]});
    EXPECT_TRUE((*store)->insert_log(l));
  }
  return std::move(*store);
}

CostTrainerConfig trainer_config(const std::string& dir) {
  CostTrainerConfig c;
  c.every = 0;
  c.model_dir = dir + "/cost_models";
  c.options = small_options();
  return c;
}

// The trainer keeps each backend's pace from the newest log rows: measured at its
// start from the log it finds, and again as jobs are logged, against the model in use.
TEST(CostTrainer, KeepsTheMachinesPaceFromItsNewestJobs) {
  const std::string dir = temp_dir("pace");
  std::vector<job::JobRecord> rows = committed_rows();
  rows.resize(120);
  const auto model = train(rows);
  // The first 60 ran 1.4 times what the model prices them at, the next 60 as priced.
  std::vector<job::JobRecord> slow(rows.begin(), rows.begin() + 60), even(rows.begin() + 60, rows.end());
  for (job::JobRecord& r : slow) r.measure.total_s = 1.4 * model->predict(r.inputs)->total_s.p50;
  for (job::JobRecord& r : even) r.measure.total_s = model->predict(r.inputs)->total_s.p50;
  auto store = store_with_jobs(dir, slow, slow.size());
  CostModelSet models;
  models.put(model, "cpu.json");
  EXPECT_EQ(models.pace("cpu").jobs, 0u);
  CostTrainer trainer(trainer_config(dir), *store, models);
  EXPECT_NEAR(models.pace("cpu").factor, 1.4, 1e-9);
  EXPECT_EQ(models.pace("cpu").jobs, job::kPaceWindow);
  EXPECT_EQ(models.pace("cuda").jobs, 0u);  // no model, no jobs
  EXPECT_NEAR(trainer.status()["pace"]["cpu"]["factor"].get<double>(), 1.4, 1e-9);
  for (size_t i = 0; i < even.size(); ++i) {
    LogRow l;
    l.job_id = "even-" + std::to_string(i);
    l.inputs_json = l.measured_json = l.predicted_json = "{}";
    l.job_record = job::format_job_log({even[i]});
    ASSERT_TRUE(store->insert_log(l));
    trainer.job_logged("cpu");
  }
  EXPECT_NEAR(models.pace("cpu").factor, 1.0, 1e-9);
}

TEST(CostModelSet, AModelOfOneBackendLeavesTheOtherToTheModelOfBoth) {
  auto cuda = job::read_job_log(std::string(COLLIDO_SOURCE_DIR) + "/bench/data/jobs_cuda.csv");
  ASSERT_TRUE(cuda) << cuda.status().message();
  std::vector<job::JobRecord> rows = committed_rows();
  const auto cpu_only = train(rows);
  rows.insert(rows.end(), cuda->begin(), cuda->begin() + 60);
  const auto both = train(rows);
  CostModelSet set;
  set.put(both, "both.json");
  set.put(cpu_only, "cpu.json");
  EXPECT_EQ(set.for_backend("cpu"), cpu_only);
  EXPECT_EQ(set.for_backend("cuda"), both);
  EXPECT_EQ(set.all().size(), 2u);
  set.put(both, "both-again.json");  // covers both: the CPU-only model goes
  EXPECT_EQ(set.for_backend("cpu"), both);
  ASSERT_EQ(set.all().size(), 1u);
  EXPECT_EQ(set.all()[0].file, "both-again.json");
}

// After an upgrade the data directory may hold a retrained model of an older format:
// the service starts on the configured model and says why it left the other.
TEST(CostModelSet, ARetrainedModelThisBuildCannotReadGivesWay) {
  const std::string dir = temp_dir("old_format");
  fs::create_directories(dir + "/cost_models");
  const auto cpu = train(committed_rows());
  const std::string configured = dir + "/configured.json";
  ASSERT_TRUE(cpu->save(configured));
  {
    std::ofstream old(dir + "/cost_models/job_model_cpu.json");
    old << R"({"kind": "collidoscope-job-cost-model", "version": 1})";
  }
  fs::last_write_time(configured, fs::file_time_type::clock::now() - std::chrono::seconds(60));
  CostModelSet set;
  std::vector<std::string> notes;
  ASSERT_TRUE(load_cost_models({configured}, dir + "/cost_models", &set, &notes));
  ASSERT_NE(set.for_backend("cpu"), nullptr);
  EXPECT_EQ(set.all()[0].file, configured);
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_NE(notes[0].find("job_model_cpu.json left unused"), std::string::npos) << notes[0];
  EXPECT_NE(notes[0].find("version"), std::string::npos) << notes[0];
  // A configured file that does not load is still an error.
  CostModelSet none;
  EXPECT_FALSE(load_cost_models({dir + "/cost_models/job_model_cpu.json"}, "", &none));
  fs::remove_all(dir);
}

TEST(CostTrainer, HeldOutJobsAreAFixedShareChosenByTheirId) {
  int held = 0;
  for (int i = 0; i < 2000; ++i) held += held_out_job("job-" + std::to_string(i), 30);
  EXPECT_GT(held, 500);
  EXPECT_LT(held, 700);
  for (int i = 0; i < 50; ++i)
    EXPECT_EQ(held_out_job("id" + std::to_string(i), 30), held_out_job("id" + std::to_string(i), 30));
  EXPECT_FALSE(held_out_job("anything", 0));
}

TEST(CostTrainer, ABetterCandidateIsSwappedInAndWritten) {
  const std::string dir = temp_dir("better");
  const auto rows = committed_rows();
  auto store = store_with_jobs(dir, rows, 120);
  CostModelSet models;
  const auto wrong = train(inflated(rows));
  models.put(wrong, "wrong.json");
  CostTrainer trainer(trainer_config(dir), *store, models);
  ASSERT_TRUE(trainer.start());
  trainer.wait_idle();
  const nlohmann::json s = trainer.status();
  const nlohmann::json& cpu = s["last"]["backends"]["cpu"];
  EXPECT_EQ(cpu["swapped"], true) << s.dump();
  EXPECT_GE(cpu["rows"]["held_out"].get<int>(), 20) << s.dump();
  EXPECT_EQ(cpu["rows"]["held_out"].get<int>() + cpu["rows"]["service"].get<int>(), 120);
  EXPECT_LT(cpu["candidate_errors"]["peak_host_bytes"].get<double>(),
            cpu["current_errors"]["peak_host_bytes"].get<double>());
  EXPECT_FALSE(s.contains("base_log_errors"));
  const auto now = models.for_backend("cpu");
  ASSERT_NE(now, nullptr);
  EXPECT_NE(now, wrong);
  EXPECT_EQ(now->training_rows(), cpu["rows"]["service"].get<size_t>());
  // Written where the next start finds it, and loaded in place of the older file.
  const std::string file = dir + "/cost_models/job_model_cpu.json";
  ASSERT_TRUE(fs::exists(file));
  CostModelSet reloaded;
  ASSERT_TRUE(load_cost_models({}, dir + "/cost_models", &reloaded));
  ASSERT_NE(reloaded.for_backend("cpu"), nullptr);
  EXPECT_EQ(reloaded.for_backend("cpu")->training_rows(), now->training_rows());
  // A configured file older than the retrained model gives way to it; a newer one (a
  // new sweep) is kept.
  const std::string configured = dir + "/configured.json";
  ASSERT_TRUE(wrong->save(configured));
  fs::last_write_time(configured, fs::last_write_time(file) - std::chrono::seconds(60));
  CostModelSet older;
  ASSERT_TRUE(load_cost_models({configured}, dir + "/cost_models", &older));
  EXPECT_EQ(older.for_backend("cpu")->training_rows(), now->training_rows());
  fs::last_write_time(configured, fs::last_write_time(file) + std::chrono::seconds(60));
  CostModelSet newer;
  ASSERT_TRUE(load_cost_models({configured}, dir + "/cost_models", &newer));
  EXPECT_EQ(newer.for_backend("cpu")->training_rows(), wrong->training_rows());
  EXPECT_EQ(trainer.status()["retrainings"], 1);
}

TEST(CostTrainer, AWorseCandidateLeavesTheModelInUse) {
  const std::string dir = temp_dir("worse");
  const auto rows = committed_rows();
  auto store = store_with_jobs(dir, rows, 60);
  // The base log the candidate learns from is mostly wrong (every job at 3x).
  const std::string base = dir + "/inflated.csv";
  ASSERT_TRUE(job::write_job_log(base, inflated(rows)));
  CostModelSet models;
  const auto good = train(rows);
  models.put(good, "good.json");
  CostTrainerConfig c = trainer_config(dir);
  c.base_logs = {base};
  CostTrainer trainer(c, *store, models);
  ASSERT_TRUE(trainer.start());
  trainer.wait_idle();
  const nlohmann::json cpu = trainer.status()["last"]["backends"]["cpu"];
  EXPECT_EQ(cpu["swapped"], false) << cpu.dump();
  EXPECT_EQ(cpu["rows"]["base"].get<size_t>(), rows.size());
  EXPECT_NE(cpu["decision"].get<std::string>().find("stays"), std::string::npos) << cpu.dump();
  EXPECT_EQ(models.for_backend("cpu"), good);
  EXPECT_FALSE(fs::exists(dir + "/cost_models/job_model_cpu.json"));
}

TEST(CostTrainer, TooFewRowsTrainNothing) {
  const std::string dir = temp_dir("few");
  const auto rows = committed_rows();
  auto store = store_with_jobs(dir, rows, 5);
  CostModelSet models;
  const auto good = train(rows);
  models.put(good, "good.json");
  CostTrainer trainer(trainer_config(dir), *store, models);
  ASSERT_TRUE(trainer.start());
  trainer.wait_idle();
  const nlohmann::json cpu = trainer.status()["last"]["backends"]["cpu"];
  EXPECT_EQ(cpu["swapped"], false);
  EXPECT_NE(cpu["decision"].get<std::string>().find("too few"), std::string::npos) << cpu.dump();
  EXPECT_EQ(models.for_backend("cpu"), good);
  // No backend the service has seen nothing of appears.
  EXPECT_FALSE(trainer.status()["last"]["backends"].contains("cuda"));
}

TEST(CostTrainer, EnoughNewJobsStartARetraining) {
  const std::string dir = temp_dir("every");
  const auto rows = committed_rows();
  auto store = store_with_jobs(dir, rows, 5);
  CostModelSet models;
  CostTrainerConfig c = trainer_config(dir);
  c.every = 3;
  CostTrainer trainer(c, *store, models);
  trainer.job_logged("cpu");
  trainer.job_logged("cpu");
  trainer.wait_idle();
  EXPECT_EQ(trainer.status()["retrainings"], 0);
  trainer.job_logged("cpu");
  trainer.wait_idle();
  EXPECT_EQ(trainer.status()["retrainings"], 1);
}

}  // namespace
}  // namespace collido::service
