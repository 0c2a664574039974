// The service with the Slurm executor, against a real single-node Slurm
// started from Debian's packages in a temporary folder (scripts/slurm-local.sh:
// munged, slurmctld, slurmd, no cgroups). Jobs go in through the REST API on
// 127.0.0.1, port 0, and run as sbatch jobs on the node. Skipped, with the
// reason, only where Slurm cannot start. Every wait is bounded.
#include <gtest/gtest.h>

#include <unistd.h>
#include <csignal>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "job/job.h"
#include "job/subprocess.h"
#include "service/http_server.h"
#include "service/job_service.h"
#include "service/slurm_executor.h"
#include "sim/snapshot.h"
#include "tests/service/service_client.h"

namespace collido::service {
namespace {

namespace fs = std::filesystem;
using collido::test::Client;
using collido::test::read_file;
using collido::test::temp_dir;
using collido::test::tiny_job;

const std::string kClusterScript = std::string(COLLIDO_SOURCE_DIR) + "/scripts/slurm-local.sh";

// A command's stdout ("" when it failed), for asking the scheduler directly.
std::string run(const std::vector<std::string>& argv) {
  auto r = job::run_command(argv, 30);
  return r && r->ok() ? r->out : std::string();
}

// The scheduler's state of a Slurm job ("" when unknown).
std::string slurm_state(const std::string& id) {
  std::string s = run({"squeue", "--noheader", "--states=all", "--jobs=" + id, "--format=%T|%r"});
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  return s;
}

class SlurmServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string name = ::testing::UnitTest::GetInstance()->current_test_info()->name();
    cluster_ = temp_dir("slurm_" + name);
    auto r = job::run_command({"bash", kClusterScript, "start", cluster_}, 90);
    ASSERT_TRUE(r) << r.status().message();
    if (r->exit.exit_code == 77) GTEST_SKIP() << "Slurm cannot start here: " << r->err;
    ASSERT_TRUE(r->ok()) << "the single-node cluster did not start: " << r->describe_failure()
                         << "\n" << r->out << r->err;
    const std::string conf = cluster_ + "/slurm.conf";
    ASSERT_NE(r->out.find("SLURM_CONF=" + conf), std::string::npos) << r->out;
    ::setenv("SLURM_CONF", conf.c_str(), 1);
    started_ = true;
    data_ = temp_dir("slurm_data_" + name);
    start_service();
  }

  void TearDown() override {
    stop_service();
    if (!started_) return;
    // Nothing of this test runs on after it: its jobs, then the daemons.
    run({"scancel", "--me"});
    for (int i = 0; i < 100 && !run({"squeue", "--me", "--noheader", "--states=PENDING,RUNNING,"
                                     "COMPLETING,CONFIGURING,REQUEUED"}).empty();
         ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    run({"bash", kClusterScript, "stop", cluster_});
  }

  void start_service() { start_replica(&svc_, &server_); }
  // A service process on this test's data folder and cluster (several may run at once).
  void start_replica(std::unique_ptr<JobService>* svc_out, std::unique_ptr<Server>* server_out) {
    ServiceConfig c;
    c.data_dir = data_;
    c.job_executable = COLLIDO_BINARY;
    c.job_threads = 1;
    c.retrain_every = 0;
    c.executor = "slurm";
    c.slurm.cpus = 1;
    c.slurm.default_time_limit_s = 60;  // no cost model here: every job gets a minute
    c.slurm.poll_s = 0.3;
    auto svc = JobService::open(c);
    ASSERT_TRUE(svc) << svc.status().message();
    *svc_out = std::move(*svc);
    ServerOptions o;
    o.port = 0;
    auto server = Server::start(svc_out->get(), o);
    ASSERT_TRUE(server) << server.status().message();
    *server_out = std::move(*server);
    (*svc_out)->set_public_url("http://127.0.0.1:" + std::to_string((*server_out)->port()));
    ASSERT_TRUE((*svc_out)->start_workers());
  }
  void stop_service() {
    server2_.reset();
    svc2_.reset();
    server_.reset();
    svc_.reset();
  }
  Client client() const { return Client("http://127.0.0.1:" + std::to_string(server_->port())); }

  // Polls until the job's view satisfies `done` (or the bound passes).
  template <class Pred>
  json wait_for(const Client& c, const std::string& id, Pred done, double bound_s) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(bound_s);
    json j;
    while (std::chrono::steady_clock::now() < end) {
      j = c.call_json("GET", "/api/v1/jobs/" + id);
      if (done(j)) return j;
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
    ADD_FAILURE() << "job " << id << " did not get there in " << bound_s << " s: " << j.dump();
    return j;
  }

  std::string cluster_, data_;
  bool started_ = false;
  std::unique_ptr<JobService> svc_, svc2_;  // svc2_: a second replica, where a test starts one
  std::unique_ptr<Server> server_, server2_;
};

bool ended(const json& v) {
  const std::string s = v.value("state", "");
  return s == "done" || s == "failed" || s == "cancelled";
}

// A job that runs for minutes on one thread (cancelled or stopped long before),
// rendered small.
json long_job(int particles = 300, double duration = 400) {
  return tiny_job("wall1", particles, duration);
}

TEST_F(SlurmServiceTest, ThreeJobsFinishTheirVideosAreServedAndAFourthIsCancelled) {
  Client c = client();
  c.sign_up("ada");
  std::vector<std::string> ids;
  for (int n : {40, 41, 42}) {
    json j = c.call_json("POST", "/api/v1/jobs", tiny_job("wall1", n), 202);
    ids.push_back(j["id"]);
  }
  const std::string long_id = c.call_json("POST", "/api/v1/jobs", long_job(), 202)["id"];

  // Each becomes a Slurm job, named after it.
  for (const std::string& id : ids) {
    json j = wait_for(c, id, [](const json& v) { return v.contains("scheduler"); }, 30);
    ASSERT_TRUE(j.contains("scheduler")) << j.dump();
    EXPECT_EQ(j["scheduler"]["kind"], "slurm");
    const std::string sid = j["scheduler"]["job_id"];
    EXPECT_NE(run({"squeue", "--noheader", "--states=all", "--jobs=" + sid, "--format=%j"}).find(
                  "collido-" + id),
              std::string::npos);
  }

  // The service restarts while its jobs are on the cluster: it follows them again.
  stop_service();
  start_service();
  c = Client("http://127.0.0.1:" + std::to_string(server_->port()));
  c.token = c.call_json("POST", "/api/v1/sessions",
                        {{"name", "ada"}, {"password", "correct horse"}})["token"];

  for (const std::string& id : ids) {
    const json j = c.wait_job(id, 120);
    ASSERT_EQ(j["state"], "done") << j.dump();
    EXPECT_EQ(j["progress"], 1.0);
    EXPECT_GT(j["cost"].value("total_s", 0.0), 0.0) << j.dump();
    // The video, served from the shared folder the node wrote it to.
    const auto video = c.call("GET", j["links"]["mp4"].get<std::string>());
    EXPECT_EQ(video.status, 200);
    EXPECT_GT(video.body.size(), 1000u);
    EXPECT_EQ(video.body.substr(4, 4), "ftyp");  // an MP4 box header
    const auto gif = c.call("GET", j["links"]["gif"].get<std::string>());
    EXPECT_EQ(gif.status, 200);
    EXPECT_EQ(gif.body.substr(0, 3), "GIF");
  }

  // The fourth: cancelled once it runs, through scancel.
  json running = wait_for(c, long_id, [](const json& v) {
    return v.value("stage", "") == "simulate" || ended(v);
  }, 60);
  ASSERT_EQ(running["state"], "running") << running.dump();
  const std::string sid = running["scheduler"]["job_id"];
  c.call_json("POST", "/api/v1/jobs/" + long_id + "/cancel", nullptr, 202);
  const json cancelled = c.wait_job(long_id, 60);
  EXPECT_EQ(cancelled["state"], "cancelled") << cancelled.dump();
  EXPECT_EQ(slurm_state(sid).substr(0, 9), "CANCELLED");
  // A job that has ended cannot be cancelled again.
  c.call_json("POST", "/api/v1/jobs/" + long_id + "/cancel", nullptr, 409);
}

// Two service replicas on one store (as behind nginx, docs/deploy.md): each job
// is submitted to Slurm once and ended and logged once, whichever replica
// took it, and a cancel sent to either reaches the job.
TEST_F(SlurmServiceTest, TwoReplicasSubmitEachJobOnceAndEndItOnce) {
  start_replica(&svc2_, &server2_);
  Client a = client();
  a.sign_up("dee");
  Client b("http://127.0.0.1:" + std::to_string(server2_->port()));
  b.token = b.call_json("POST", "/api/v1/sessions", {{"name", "dee"}, {"password", "correct horse"}})["token"];
  std::vector<std::string> ids;
  for (int n : {43, 44, 45, 46})
    ids.push_back((n % 2 ? a : b).call_json("POST", "/api/v1/jobs", tiny_job("wall1", n), 202)["id"]);
  const std::string long_id = a.call_json("POST", "/api/v1/jobs", long_job(), 202)["id"];
  for (const std::string& id : ids) {
    const json j = (id == ids[0] ? b : a).wait_job(id, 120);
    EXPECT_EQ(j["state"], "done") << j.dump();
  }
  const std::string names = run({"squeue", "--me", "--noheader", "--states=all", "--format=%j"});
  for (const std::string& id : ids) {
    size_t count = 0;
    for (size_t at = names.find("collido-" + id); at != std::string::npos;
         at = names.find("collido-" + id, at + 1))
      ++count;
    EXPECT_EQ(count, 1u) << id << " was submitted " << count << " times:\n" << names;
  }
  wait_for(b, long_id, [](const json& v) { return v.contains("scheduler") || ended(v); }, 30);
  b.call_json("POST", "/api/v1/jobs/" + long_id + "/cancel", nullptr, 202);
  EXPECT_EQ(a.wait_job(long_id, 60)["state"], "cancelled");
  auto logs = svc_->store().logs(100, 0);
  ASSERT_TRUE(logs);
  EXPECT_EQ(logs->size(), ids.size());  // the done jobs, each once; a cancelled job is not logged
}

TEST_F(SlurmServiceTest, AJobOverItsTimeLimitFailsWithTheSchedulersReason) {
  Client c = client();
  c.sign_up("bo");
  const std::string id = c.call_json("POST", "/api/v1/jobs", long_job(), 202)["id"];
  // Slurm checks time limits every 30 s: a one-minute limit ends it within 100 s.
  const json j = c.wait_job(id, 180);
  ASSERT_EQ(j["state"], "failed") << j.dump();
  const std::string error = j.value("error", "");
  EXPECT_NE(error.find("time limit of 1 min"), std::string::npos) << error;
  EXPECT_NE(error.find("TIMEOUT"), std::string::npos) << error;
  // Its log row keeps what was measured before the scheduler ended it.
  auto logs = svc_->store().logs(100, 0);
  ASSERT_TRUE(logs);
  ASSERT_EQ(logs->size(), 1u);
  const json m = json::parse(logs->front().measured_json);
  EXPECT_EQ(m["outcome"], "failed");
  EXPECT_EQ(m["scheduler_state"], "TIMEOUT");
  EXPECT_GT(m["frames_done"].get<int>(), 0) << m.dump();
  EXPECT_GT(m["elapsed_s"].get<double>(), 30.0) << m.dump();
  EXPECT_GT(m["peak_host_bytes"].get<double>(), 1e6) << m.dump();
  EXPECT_EQ(logs->front().total_s, 0.0);  // it did not finish: no total to learn from
}

TEST_F(SlurmServiceTest, APreemptedJobResumesFromItsCheckpointToTheSameResult) {
  Client c = client();
  c.sign_up("cy");
  // About ten seconds on one thread; a checkpoint every second.
  const std::string id = c.call_json("POST", "/api/v1/jobs", long_job(300, 30), 202)["id"];
  const std::string run_dir = data_ + "/jobs/" + id + "/run";
  // Running with its first checkpoint written (a second of work; 15 % of the
  // job came before it once the wall's lists made the job twice as fast).
  json j = wait_for(c, id, [&](const json& v) {
    return (v.value("state", "") == "running" && v.value("progress", 0.0) > 0.15 &&
            fs::exists(run_dir + "/checkpoint.bin")) ||
           ended(v);
  }, 60);
  ASSERT_EQ(j["state"], "running") << j.dump();
  ASSERT_TRUE(fs::exists(run_dir + "/checkpoint.bin"));
  const std::string sid = j["scheduler"]["job_id"];
  // A job in a higher partition wants the whole node: the scheduler preempts
  // ours (PreemptMode=REQUEUE), which stops and goes back to the queue.
  auto urgent = job::run_command({"sbatch", "--parsable", "--partition=urgent", "--exclusive",
                                  "--output=/dev/null", "--wrap", "sleep 2"},
                                 30);
  ASSERT_TRUE(urgent && urgent->ok()) << (urgent ? urgent->describe_failure() : "");
  // Slurm holds a requeued job back for two minutes (reason BeginTime); this
  // test lets it go after two seconds. Not at once: slurmd refuses a launch in
  // the same second as the first run's credential was revoked, and the job
  // would end FAILED ("Job credential revoked").
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  bool requeued_seen = false;
  std::chrono::steady_clock::time_point held_since{};
  while (std::chrono::steady_clock::now() < end) {
    const std::string s = slurm_state(sid);
    if (s == "PENDING|BeginTime") {
      const auto now = std::chrono::steady_clock::now();
      if (!requeued_seen) held_since = now;
      requeued_seen = true;
      if (now - held_since > std::chrono::seconds(2))
        run({"scontrol", "update", "jobid=" + sid, "starttime=now"});
    }
    const json v = c.call_json("GET", "/api/v1/jobs/" + id);
    if (v.value("stage", "") == "requeued") requeued_seen = true;
    if (requeued_seen && s.rfind("RUNNING", 0) == 0) break;
    if (ended(v)) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  EXPECT_TRUE(requeued_seen);
  j = c.wait_job(id, 120);
  ASSERT_EQ(j["state"], "done") << j.dump() << read_file(data_ + "/jobs/" + id + "/job.log");
  const json manifest = json::parse(read_file(run_dir + "/result.json"));
  EXPECT_GT(manifest.value("resumed_from_frame", 0), 0) << manifest.dump();
  EXPECT_NE(run({"scontrol", "show", "job", sid}).find("Restarts=1"), std::string::npos);

  // The same spec run once without interruption gives the same frames and statistics.
  auto spec = job::spec_from_json(read_file(data_ + "/jobs/" + id + "/spec.run.json"));
  ASSERT_TRUE(spec);
  const std::string ref = temp_dir("slurm_uninterrupted");
  fs::remove_all(ref);
  spec->out_dir = ref;
  spec->dir_policy = job::DirPolicy::kRefuse;
  const job::JobResult r = job::run_job(*spec, {});
  ASSERT_TRUE(r.status) << r.status.message();
  // Every statistic of every frame but the last column (the wall-clock time of the frame).
  auto stats_rows = [](const std::string& dir) {
    std::ifstream in(dir + "/stats.csv");
    std::vector<std::string> rows;
    for (std::string l; std::getline(in, l);) rows.push_back(l.substr(0, l.rfind(',')));
    return rows;
  };
  const auto rows = stats_rows(run_dir);
  EXPECT_EQ(rows.size(), 302u);  // the header and frames 0..300
  EXPECT_EQ(rows, stats_rows(ref));
  const std::string last = sim::snapshot_path(ref, 300);
  ASSERT_TRUE(fs::exists(last));
  EXPECT_EQ(read_file(sim::snapshot_path(run_dir, 300)), read_file(last));
}

// What each Slurm state means to the service.
TEST(SlurmOutcome, EachSchedulerStateEndsAJobAsTheSchedulerSaid) {
  const Status ok = Status::ok();
  auto outcome = [](const std::string& state, std::optional<Status> st, bool cancel = false) {
    return slurm_outcome({state, state == "TIMEOUT" ? "TimeLimit" : "None", "0:0"}, st, cancel, 7);
  };
  EXPECT_EQ(outcome("COMPLETED", ok).state, "done");
  EXPECT_EQ(outcome("COMPLETED", std::nullopt).state, "failed");
  EXPECT_EQ(outcome("FAILED", invalid_argument("particles: bad")).error, "particles: bad");
  const SlurmOutcome t = outcome("TIMEOUT", std::nullopt);
  EXPECT_EQ(t.state, "failed");
  EXPECT_NE(t.error.find("time limit of 7 min (Slurm: TIMEOUT, TimeLimit)"), std::string::npos) << t.error;
  EXPECT_NE(outcome("OUT_OF_MEMORY", std::nullopt).error.find("more memory"), std::string::npos);
  EXPECT_NE(outcome("NODE_FAIL", std::nullopt).error.find("node failed"), std::string::npos);
  EXPECT_EQ(outcome("PREEMPTED", std::nullopt).state, "failed");
  EXPECT_EQ(outcome("CANCELLED", std::nullopt, true).error, "cancelled");
  EXPECT_EQ(outcome("CANCELLED by 1000", std::nullopt).state, "cancelled");
  // Forgotten by the controller, no accounting: the job's own last word.
  EXPECT_EQ(outcome("", ok).state, "done");
  EXPECT_EQ(outcome("", std::nullopt).state, "failed");
  for (const char* s : {"PENDING", "REQUEUED", "SUSPENDED"}) EXPECT_EQ(slurm_phase(s), SlurmPhase::kWaiting);
  for (const char* s : {"RUNNING", "COMPLETING"}) EXPECT_EQ(slurm_phase(s), SlurmPhase::kRunning);
  EXPECT_EQ(slurm_phase("CANCELLED by 0"), SlurmPhase::kEnded);
  EXPECT_EQ(slurm_phase("SOMETHING_NEW"), SlurmPhase::kUnknown);
}

TEST(SlurmOutcome, SqueueLinesAndRequestsAreReadAsWritten) {
  const auto rows = parse_squeue("12|collido-abc|RUNNING|None\n13_2|x|PENDING|Priority\nnoise\n|a|b\n");
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0].id, "12");
  EXPECT_EQ(rows[0].name, "collido-abc");
  EXPECT_EQ(rows[1].state.state, "PENDING");
  EXPECT_EQ(rows[1].state.reason, "Priority");

  SlurmConfig c;
  Job j;
  j.predicted_host_bytes = uint64_t(1) << 30;
  // No predicted time: the default limit; memory 1.25 x + 1 GiB.
  SlurmRequest r = slurm_request(c, j);
  EXPECT_EQ(r.time_limit_min, 60);
  EXPECT_EQ(r.mem_mib, 1280u + 1024u);
  // A predicted time: 2 x its 90th percentile + 5 min, whole minutes.
  j.prediction_json = R"({"total_time_s": {"value": 100, "low": 80, "high": 150}})";
  r = slurm_request(c, j);
  EXPECT_EQ(r.time_limit_min, 10);  // (2 * 150 + 300) / 60
  j.prediction_json = "not json";
  EXPECT_EQ(slurm_request(c, j).time_limit_min, 60);
  // A model far outside its training: a year at most, not an overflowed int.
  j.prediction_json = R"({"total_time_s": {"value": 1e300, "high": 1e300}})";
  EXPECT_EQ(slurm_request(c, j).time_limit_min, 365 * 24 * 60);

  // An sbatch that may have queued the job all the same is not taken for a refusal.
  job::CommandOutput refused, busy, slow, killed;
  refused.exit.exit_code = busy.exit.exit_code = 1;
  refused.err =
      "sbatch: error: Batch job submission failed: Invalid account or account/partition "
      "combination specified\n";
  busy.err =
      "sbatch: error: Batch job submission failed: Socket timed out on send/recv operation\n";
  slow.timed_out = true;
  killed.exit.signal = SIGKILL;
  EXPECT_FALSE(scheduler_unreachable(refused));
  EXPECT_TRUE(scheduler_unreachable(busy));
  EXPECT_TRUE(scheduler_unreachable(slow));
  EXPECT_TRUE(scheduler_unreachable(killed));
}

}  // namespace
}  // namespace collido::service
