// The service over real HTTP: a server on 127.0.0.1 port 0, libcurl as the
// client, jobs in collidoscope job-exec children. Every wait is bounded.
#include <arpa/inet.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

#include "common/atomic_file.h"
#include "job/cost_model.h"
#include "job/job_log.h"
#include "service/http_server.h"
#include "service/job_service.h"
#include "service/store.h"
#include "sim/shapes.h"
#include "sim/mesh.h"
#include "tests/service/http_client.h"
#include "tests/service/service_client.h"

extern char** environ;

namespace collido::service {
namespace {

namespace fs = std::filesystem;
using collido::test::Client;
using collido::test::http;
using collido::test::HttpResponse;
using collido::test::read_file;
using collido::test::temp_dir;
using collido::test::tiny_job;

// A raw TCP connection to the server, for what libcurl will not send; -1 on failure.
int connect_loopback(uint16_t port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (fd < 0 || ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    if (fd >= 0) ::close(fd);
    return -1;
  }
  return fd;
}

class ServiceTest : public ::testing::Test {
 protected:
  void SetUp() override { start(); }
  void TearDown() override {
    web_server_.reset();
    server_.reset();
    svc_.reset();
  }
  // A second server of this service, with a UI folder (the first has none).
  void start_web_server(const std::string& web_dir) {
    ServerOptions o;
    o.port = 0;
    o.web_dir = web_dir;
    start_second_server(o);
  }
  // A second server of this service with these options, at web_base_.
  void start_second_server(const ServerOptions& o) {
    auto server = Server::start(svc_.get(), o);
    ASSERT_TRUE(server) << server.status().message();
    web_server_ = std::move(*server);
    web_base_ = "http://127.0.0.1:" + std::to_string(web_server_->port());
  }
  void start(uint64_t host_bytes = 0, int max_queued = 8, std::vector<std::string> cost_models = {}) {
    if (dir_.empty()) dir_ = temp_dir(::testing::UnitTest::GetInstance()->current_test_info()->name());
    ServiceConfig c;
    c.data_dir = dir_;
    c.job_executable = COLLIDO_BINARY;
    c.workers = workers_;
    c.job_threads = 1;
    c.max_upload_bytes = 1 << 20;
    c.host_bytes = host_bytes;
    c.disk_free_bytes = disk_free_;  // 0: the temp folder's, less no reserve
    c.disk_reserve_bytes = 0;
    c.max_queued_per_user = max_queued;
    c.cost_models = std::move(cost_models);
    c.retrain_every = 0;  // retrained only when a test asks
    auto svc = JobService::open(c);
    ASSERT_TRUE(svc) << svc.status().message();
    svc_ = std::move(*svc);
    ServerOptions o;
    o.port = 0;
    o.max_json_bytes = 64 << 10;
    auto server = Server::start(svc_.get(), o);
    ASSERT_TRUE(server) << server.status().message();
    server_ = std::move(*server);
    base_ = "http://127.0.0.1:" + std::to_string(server_->port());
    svc_->set_public_url(base_);
    ASSERT_TRUE(svc_->start_workers());
  }
  Client client() const { return Client(base_); }
  // Runs a tiny job to its end, stops the service, and puts the job back as a
  // service stopped in its first attempt would have left it: running, its run
  // folder gone (stopped while it prepared), cancel asked or not.
  std::string stopped_in_first_attempt(Client& c, bool cancel_requested) {
    const std::string id = c.call_json("POST", "/api/v1/jobs", tiny_job("wall1"), 202)["id"];
    EXPECT_EQ(c.wait_job(id)["state"], "done");
    server_.reset();
    svc_.reset();
    auto store = open_sqlite_store(dir_ + "/collidoscope.db");
    EXPECT_TRUE(store) << store.status().message();
    auto j = (*store)->job_by_id(id);
    EXPECT_TRUE(j);
    EXPECT_TRUE(*(*store)->delete_job(id));
    j->state = "running", j->stage = "prepare", j->progress = 0, j->attempts = 1,
    j->finished_at = 0;
    EXPECT_TRUE((*store)->insert_job(*j));
    if (cancel_requested) {
      EXPECT_TRUE((*store)->request_cancel(id));
    }
    EXPECT_EQ((*store)->job_by_id(id)->cancel_requested, cancel_requested);
    fs::remove_all(j->run_dir);
    return id;
  }

  std::string dir_, base_;
  uint64_t disk_free_ = 0;
  int workers_ = 1;
  std::unique_ptr<JobService> svc_;
  std::unique_ptr<Server> server_;
  std::unique_ptr<Server> web_server_;
  std::string web_base_;
};

// Times are priced at the machine's pace: after jobs that ran 1.3 times what the
// model priced them at, the same job's times come 1.3 times the model's, and the
// answer says by what and on how many jobs.
TEST_F(ServiceTest, PricesTimesAtTheMachinesPace) {
  server_.reset();
  svc_.reset();
  const std::string data = std::string(COLLIDO_SOURCE_DIR) + "/bench/data/";
  const std::vector<std::string> models = {data + "job_model_cpu.json", data + "job_model_cuda.json"};
  start(0, 8, models);
  Client c = client();
  c.sign_up("ada");
  const json before = c.call_json("POST", "/api/v1/predict", tiny_job("wall1", 400, 1.0));
  ASSERT_TRUE(before["total_time_s"].is_object()) << before.dump();
  EXPECT_FALSE(before.contains("pace")) << before.dump();
  server_.reset();
  svc_.reset();
  {  // the log of a slower machine's jobs
    auto model = job::JobCostModel::load(models[0]);
    auto rows = job::read_job_log(data + "jobs_cpu.csv");
    ASSERT_TRUE(model && rows);
    auto store = open_sqlite_store(dir_ + "/collidoscope.db");
    ASSERT_TRUE(store) << store.status().message();
    for (size_t i = 0; i < 30; ++i) {
      job::JobRecord r = (*rows)[i];
      r.measure.total_s = 1.3 * model->predict(r.inputs)->total_s.p50;
      LogRow l;
      l.job_id = "slow-" + std::to_string(i);
      l.inputs_json = l.measured_json = l.predicted_json = "{}";
      l.job_record = job::format_job_log({r});
      ASSERT_TRUE((*store)->insert_log(l));
    }
  }
  start(0, 8, models);
  Client again = client();  // the new server's port; the session outlives the restart
  again.token = c.token;
  const json after = again.call_json("POST", "/api/v1/predict", tiny_job("wall1", 400, 1.0));
  ASSERT_TRUE(after.contains("pace")) << after.dump();
  EXPECT_NEAR(after["pace"]["factor"].get<double>(), 1.3, 1e-9);
  EXPECT_EQ(after["pace"]["jobs"], job::kPaceWindow);
  for (const char* k : {"total_time_s", "time_per_frame_s"})
    for (const char* q : {"low", "value", "high"})
      EXPECT_NEAR(after[k][q].get<double>(), 1.3 * before[k][q].get<double>(),
                  1e-9 * before[k][q].get<double>())
          << k << " " << q;
  EXPECT_EQ(after["peak_host_bytes"]["value"], before["peak_host_bytes"]["value"]);  // memory: as priced
}

// With the committed job cost models, a prediction gives time and memory with their
// ranges, says when a job lies outside the training, and admits memory by the range's
// top; the job keeps what it was told.
TEST_F(ServiceTest, PricesJobsWithTheJobCostModel) {
  server_.reset();
  svc_.reset();
  const std::string data = std::string(COLLIDO_SOURCE_DIR) + "/bench/data/";
  start(0, 8, {data + "job_model_cpu.json", data + "job_model_cuda.json"});
  Client c = client();
  c.sign_up("grace");
  json pred = c.call_json("POST", "/api/v1/predict", tiny_job("wall1", 400, 1.0));
  EXPECT_EQ(pred["basis"], "job cost model") << pred.dump();
  for (const char* k : {"total_time_s", "time_per_frame_s", "peak_host_bytes", "output_bytes"}) {
    ASSERT_TRUE(pred[k].is_object()) << k << ": " << pred.dump();
    const double lo = pred[k]["low"], mid = pred[k]["value"], hi = pred[k]["high"];
    EXPECT_GT(lo, 0) << k;
    EXPECT_LE(lo, mid) << k;
    EXPECT_LE(mid, hi) << k;
  }
  EXPECT_TRUE(pred["outside_training"].is_boolean());
  EXPECT_GE(pred["peak_host_bytes"]["admitted_by"].get<double>(),
            pred["peak_host_bytes"]["high"].get<double>() - 1);
  EXPECT_GT(pred["drivers"]["steps"].get<double>(), 0);
  EXPECT_GE(pred["drivers"]["list_builds"].get<double>(), 0);  // the builds the costs follow

  // Far more particles than any training job: said, and memory admitted by the larger figure.
  json big = tiny_job("wall1", 150000, 1.0);
  big["scene"]["particles"]["radius"] = 0.3;
  json far = c.call_json("POST", "/api/v1/predict", big);
  ASSERT_EQ(far["outside_training"], true) << far.dump();
  EXPECT_NE(far["outside_reasons"].dump().find("particles"), std::string::npos) << far.dump();
  EXPECT_GE(far["peak_host_bytes"]["admitted_by"].get<double>(),
            far["peak_host_bytes"]["analytic"].get<double>());

  // The models' training, for the admin page: loss curves and held-out predictions.
  EXPECT_EQ(c.call("GET", "/api/v1/admin/predictor").status, 403);
  ASSERT_TRUE(svc_->create_admin("root", "correct horse battery"));
  Client admin = client();
  admin.token = admin.call_json("POST", "/api/v1/sessions",
                                {{"name", "root"}, {"password", "correct horse battery"}})["token"];
  json models = admin.call_json("GET", "/api/v1/admin/predictor")["models"];
  ASSERT_EQ(models.size(), 2u) << models.dump().substr(0, 500);
  for (const json& m : models) {
    EXPECT_GT(m["rows"].get<int>(), 100);
    EXPECT_GT(m["curve"].size(), 10u);
    EXPECT_LE(m["curve"].size(), 300u);
    const json& held = m["costs"]["total_s"]["held_out"];
    EXPECT_EQ(held.size(), m["rows"].get<size_t>());
    EXPECT_LT(m["costs"]["total_s"]["interval_factors"][0].get<double>(), 1.0);
    EXPECT_GT(m["costs"]["total_s"]["interval_factors"][1].get<double>(), 1.0);
  }

  json job = c.call_json("POST", "/api/v1/jobs", tiny_job("wall1"), 202);
  EXPECT_EQ(job["prediction"]["basis"], "job cost model");
  EXPECT_GT(job["prediction"]["total_time_s"]["value"].get<double>(), 0);
  job = c.wait_job(job["id"]);
  EXPECT_EQ(job["state"], "done") << job.dump();

  // The finished job's log row holds it as a job-log row, what retraining learns from.
  auto logs = svc_->store().logs(100, 0);
  ASSERT_TRUE(logs && logs->size() == 1u);
  auto record = job::parse_job_log(logs->front().job_record);
  ASSERT_TRUE(record) << record.status().message() << "\n" << logs->front().job_record;
  ASSERT_EQ(record->size(), 1u);
  EXPECT_EQ(record->front().inputs.backend, "cpu");
  EXPECT_EQ(record->front().inputs.particles, 40u);
  EXPECT_EQ(record->front().inputs.formats, "mp4+gif");
  EXPECT_GT(record->front().measure.steps_taken, 0u);
  EXPECT_GT(record->front().measure.output_bytes, 0);

  // An administrator retrains; one job is too few to compare on, so the models stay.
  EXPECT_EQ(c.call("POST", "/api/v1/admin/predictor/retrain").status, 403);
  json started = admin.call_json("POST", "/api/v1/admin/predictor/retrain", json::object(), 202);
  EXPECT_TRUE(started["retrain"].contains("running")) << started.dump();
  svc_->wait_retrained();
  json after = admin.call_json("GET", "/api/v1/admin/predictor");
  const json& cpu = after["retrain"]["last"]["backends"]["cpu"];
  EXPECT_EQ(cpu["swapped"], false) << after["retrain"].dump();
  EXPECT_NE(cpu["decision"].get<std::string>().find("too few"), std::string::npos) << cpu.dump();
  EXPECT_EQ(after["retrain"]["retrainings"], 1);
}

// A pour that ends before its first particles land is said so before it runs:
// its video would show a fall that touches nothing (the web form's default, a
// 2 s pour from the top of wall1, did).
TEST_F(ServiceTest, WarnsOfAPourThatEndsBeforeItsParticlesLand) {
  Client c = client();
  c.sign_up("ada");
  // The default inlet 3 r under wall1's top (z = 98.5 for r = 0.5), 1 m/s down:
  // its particles touch the floor after falling 98 m, 2 x 98 / (1 + sqrt(1 + 2 g 98)) s.
  const double lands = 2 * 98 / (1 + std::sqrt(1 + 2 * 9.81 * 98));
  json short_pour = c.call_json("POST", "/api/v1/predict", tiny_job("wall1", 40, 2.0));
  EXPECT_NEAR(short_pour["first_contact_s"].get<double>(), lands, 1e-3 * lands)
      << short_pour.dump();
  ASSERT_EQ(short_pour["warnings"].size(), 1u) << short_pour.dump();
  EXPECT_NE(short_pour["warnings"][0]["message"].get<std::string>().find("nothing would touch"),
            std::string::npos);
  json long_pour = c.call_json("POST", "/api/v1/predict", tiny_job("wall1", 40, 6.0));
  EXPECT_FALSE(long_pour.contains("warnings")) << long_pour.dump();
  // A fill starts where it is: no fall to speak of.
  json fill = tiny_job("wall1", 40, 2.0);
  fill["scene"]["placement"]["kind"] = "fill";
  EXPECT_FALSE(c.call_json("POST", "/api/v1/predict", fill).contains("first_contact_s"));
}

// The algorithms list says which methods a job may choose (the new-job form
// offers those): every method the engine has is listed, and a job naming one
// the dynamics cannot step with is refused with the list of those it can.
TEST_F(ServiceTest, AlgorithmsSayWhichMethodsAJobMayChoose) {
  Client c = client();
  const json a = c.call_json("GET", "/api/v1/algorithms");  // public: no sign-in
  std::map<std::string, bool> jobs;
  for (const json& m : a["methods"]) jobs[m["name"].get<std::string>()] = m["jobs"].get<bool>();
  const std::map<std::string, bool> expected = {
      {"bin", true},       {"bvh", true},        {"gravity", true}, {"circumcircle", true},
      {"midpoint4", true}, {"reference", false}, {"octree", false}};
  EXPECT_EQ(jobs, expected) << a.dump();
  for (const json& t : a["traversals"]) EXPECT_FALSE(t.contains("jobs")) << t.dump();
  c.sign_up("ada");
  for (const auto& [name, allowed] : expected) {
    json job = tiny_job("wall1", 40, 1.0);
    job["scene"]["method"] = name;
    auto r = c.call("POST", "/api/v1/predict", job.dump());
    EXPECT_EQ(r.status, allowed ? 200 : 400) << name << ": " << r.body;
  }
}

TEST_F(ServiceTest, AModelFileThatIsNotAJobCostModelStopsTheStart) {
  ServiceConfig c;
  c.data_dir = dir_ + "/bad-model";
  c.job_executable = COLLIDO_BINARY;
  c.cost_models = {dir_ + "/absent-model.json"};
  auto svc = JobService::open(c);
  ASSERT_FALSE(svc);
  EXPECT_NE(svc.status().message().find("cost model"), std::string::npos) << svc.status().message();
}

TEST_F(ServiceTest, SubmitWatchDownloadShareRevoke) {
  Client c = client();
  c.sign_up("ada");
  // A parametric model, then a prediction and a job on it.
  json model = c.call_json("POST", "/api/v1/models",
                           {{"name", "mug"}, {"parts", {{{"shape", "cylinder"}, {"r", 5}, {"h", 10}, {"segments", 24}}}}},
                           201);
  ASSERT_TRUE(model.contains("id"));
  EXPECT_EQ(model["kind"], "parametric");
  EXPECT_GT(model["triangles"].get<int>(), 0);
  const json wall = {{"model", model["id"]}};
  json pred = c.call_json("POST", "/api/v1/predict", tiny_job(wall));
  EXPECT_GT(pred["peak_host_bytes"]["value"].get<double>(), 0);
  EXPECT_EQ(pred["inputs"]["particles"], 40);

  json job = c.call_json("POST", "/api/v1/jobs", tiny_job(wall), 202);
  const std::string id = job["id"];
  EXPECT_EQ(job["state"], "queued");
  EXPECT_TRUE(job["links"].contains("mp4"));
  EXPECT_FALSE(job["links"].contains("webm"));  // not asked for
  job = c.wait_job(id);
  ASSERT_EQ(job["state"], "done") << job.dump();
  EXPECT_DOUBLE_EQ(job["progress"].get<double>(), 1.0);
  EXPECT_GT(job["cost"]["total_s"].get<double>(), 0);
  EXPECT_GT(job["cost"]["peak_host_bytes"].get<double>(), 0);

  // The video whole, then by Range.
  const std::string mp4 = job["links"]["mp4"];
  auto whole = c.call("GET", mp4);
  ASSERT_EQ(whole.status, 200);
  EXPECT_EQ(whole.headers["content-type"], "video/mp4");
  EXPECT_EQ(whole.headers["accept-ranges"], "bytes");
  EXPECT_EQ(whole.headers.count("content-disposition"), 0u);  // plays inline
  ASSERT_GT(whole.body.size(), 1000u);
  EXPECT_EQ(whole.body.substr(4, 4), "ftyp");
  auto part = c.call("GET", mp4, "", {"Range: bytes=100-199"});
  EXPECT_EQ(part.status, 206);
  EXPECT_EQ(part.body, whole.body.substr(100, 100));
  EXPECT_EQ(part.headers["content-range"], "bytes 100-199/" + std::to_string(whole.body.size()));
  auto tail = c.call("GET", mp4, "", {"Range: bytes=-10"});
  EXPECT_EQ(tail.status, 206);
  EXPECT_EQ(tail.body, whole.body.substr(whole.body.size() - 10));
  auto beyond = c.call("GET", mp4, "", {"Range: bytes=" + std::to_string(whole.body.size()) + "-"});
  EXPECT_EQ(beyond.status, 416);
  EXPECT_EQ(beyond.headers["content-range"], "bytes */" + std::to_string(whole.body.size()));
  EXPECT_EQ(c.call("GET", job["links"]["gif"]).headers["content-type"], "image/gif");

  // Every artifact the manifest lists is there whole; no temporary file is left.
  json manifest = c.call_json("GET", job["links"]["manifest"]);
  for (const json& a : manifest["artifacts"]) {
    const std::string path = a["path"];
    if (path.back() == '/') continue;
    auto f = c.call("GET", "/api/v1/jobs/" + id + "/files/" + path);
    EXPECT_EQ(f.status, 200) << path;
    EXPECT_EQ(f.body.size(), a["bytes"].get<size_t>()) << path;
  }

  // Shared: opens without a session, then revoked.
  json share = c.call_json("POST", "/api/v1/jobs/" + id + "/shares", nullptr, 201);
  const std::string token = share["token"];
  // Paths out of this real job's folder, or to its working files, are not
  // files of it, through the owner's route or a share; its result is.
  Client stranger = client();
  for (const std::string& base : {"/api/v1/jobs/" + id + "/files/", "/s/" + token + "/"}) {
    Client& who = base[1] == 's' ? stranger : c;
    EXPECT_EQ(who.call("GET", base + "result.json").status, 200) << base;
    for (const char* path : {"../../collidoscope.db", "%2e%2e/%2e%2e/collidoscope.db",
                             "render/../../../collidoscope.db", "render/%2e%2e/job.json",
                             "checkpoint.bin", "job.json", ".hidden", "render/", "/etc/passwd"})
      EXPECT_EQ(who.call("GET", base + path).status, 404) << base << path;
  }
  EXPECT_EQ(share["url"], c.base() + "/s/" + token);
  Client anon = client();
  auto page = anon.call("GET", "/s/" + token);
  EXPECT_EQ(page.status, 200);
  EXPECT_NE(page.body.find("<video"), std::string::npos);
  auto shared_video = anon.call("GET", "/s/" + token + "/render/video.mp4", "", {"Range: bytes=0-99"});
  EXPECT_EQ(shared_video.status, 206);
  EXPECT_EQ(shared_video.body, whole.body.substr(0, 100));
  json oembed = anon.call_json("GET", "/api/v1/oembed?url=" + c.base() + "/s/" + token);
  EXPECT_EQ(oembed["type"], "video");
  EXPECT_NE(oembed["html"].get<std::string>().find("/embed/" + token), std::string::npos);
  EXPECT_EQ(anon.call("GET", "/embed/" + token).status, 200);
  EXPECT_EQ(anon.call("GET", mp4).status, 401);  // the owner's link needs the session
  // The owner's links are listed with the job (revocable from any later visit);
  // a second link is listed beside the first, and a revoked one is gone.
  json second = c.call_json("POST", "/api/v1/jobs/" + id + "/shares", json::object(), 201);
  json listed = c.call_json("GET", "/api/v1/jobs/" + id + "/shares");
  ASSERT_EQ(listed.size(), 2u) << listed.dump();
  EXPECT_EQ(listed[0]["token"], token);
  EXPECT_EQ(listed[0]["url"], share["url"]);
  EXPECT_EQ(listed[1]["token"], second["token"]);
  EXPECT_GT(listed[1]["created_at"].get<double>(), 0);
  EXPECT_EQ(anon.call("GET", "/api/v1/jobs/" + id + "/shares").status, 401);
  EXPECT_EQ(c.call("DELETE", "/api/v1/shares/" + second["token"].get<std::string>()).status, 204);
  EXPECT_EQ(c.call_json("GET", "/api/v1/jobs/" + id + "/shares").size(), 1u);
  EXPECT_EQ(c.call("DELETE", "/api/v1/shares/" + token).status, 204);
  EXPECT_EQ(c.call_json("GET", "/api/v1/jobs/" + id + "/shares"), json::array());
  EXPECT_EQ(anon.call("GET", "/s/" + token + "/render/video.mp4").status, 404);
  EXPECT_EQ(anon.call("GET", "/s/" + token).status, 404);

  // The same scene again: the earlier result at once; fresh runs it again.
  json again = c.call_json("POST", "/api/v1/jobs", tiny_job(wall), 200);
  EXPECT_EQ(again["state"], "done");
  EXPECT_EQ(again["reused_from"], id);
  EXPECT_EQ(c.call("GET", again["links"]["mp4"].get<std::string>()).body, whole.body);
  json fresh = tiny_job(wall);
  fresh["fresh"] = true;
  EXPECT_EQ(c.call_json("POST", "/api/v1/jobs", fresh, 202)["state"], "queued");

  // The finished job wrote its log row.
  auto rows = svc_->store().logs(100, 0);
  ASSERT_TRUE(rows);
  ASSERT_GE(rows->size(), 1u);
  EXPECT_EQ(rows->back().job_id, id);
  EXPECT_GT(rows->back().total_s, 0);
  EXPECT_GT(rows->back().predicted_host_bytes, 0u);

  // Deleted, the original's files stay for the job that reused them, and go
  // with it: no folder is left that no job names.
  EXPECT_EQ(c.call("DELETE", "/api/v1/jobs/" + id).status, 204);
  EXPECT_EQ(c.call("GET", again["links"]["mp4"].get<std::string>()).body, whole.body);
  EXPECT_TRUE(fs::exists(dir_ + "/jobs/" + id));
  EXPECT_EQ(c.call("DELETE", "/api/v1/jobs/" + again["id"].get<std::string>()).status, 204);
  EXPECT_FALSE(fs::exists(dir_ + "/jobs/" + id));
}

// A job runs on the STL it was submitted with, though its owner uploads
// another one to the model and deletes the model while it waits or runs.
TEST_F(ServiceTest, AJobKeepsTheModelItWasSubmittedWith) {
  Client c = client();
  c.sign_up("pia");
  auto stl_of = [&](const char* spec) {
    const std::string path = dir_ + "/shape.stl";
    EXPECT_TRUE(bool(collido::sim::save_stl(*collido::sim::make_shape(spec), path)));
    std::ifstream in(path, std::ios::binary);
    std::stringstream bytes;
    bytes << in.rdbuf();
    return bytes.str();
  };
  const std::string box = stl_of("box:x=20,y=20,z=20"), ball = stl_of("sphere:r=10,subdivisions=2");
  json model = c.call_json("POST", "/api/v1/models", {{"name", "vessel"}, {"kind", "stl"}}, 201);
  const std::string m = "/api/v1/models/" + std::to_string(model["id"].get<int>());
  ASSERT_EQ(c.call("PUT", m + "/stl", box).status, 200);
  json job = c.call_json("POST", "/api/v1/jobs", tiny_job({{"model", model["id"]}}), 202);
  // The job's spec names its own copy, which holds the box, whenever it runs.
  const std::string folder = dir_ + "/jobs/" + job["id"].get<std::string>();
  std::ifstream spec_file(folder + "/spec.json");
  std::stringstream spec;
  spec << spec_file.rdbuf();
  EXPECT_NE(spec.str().find(folder + "/model.stl"), std::string::npos) << spec.str();
  EXPECT_EQ(spec.str().find("/models/"), std::string::npos) << spec.str();
  std::ifstream pinned(folder + "/model.stl", std::ios::binary);
  std::stringstream pinned_bytes;
  pinned_bytes << pinned.rdbuf();
  EXPECT_EQ(pinned_bytes.str(), box);
  ASSERT_EQ(c.call("PUT", m + "/stl", ball).status, 200);
  ASSERT_EQ(c.call("DELETE", m).status, 204);
  job = c.wait_job(job["id"]);
  ASSERT_EQ(job["state"], "done") << job.dump();
  const auto wall = c.call("GET", "/api/v1/jobs/" + job["id"].get<std::string>() + "/files/wall.stl");
  ASSERT_EQ(wall.status, 200);
  EXPECT_EQ(wall.body.size(), 84u + 50u * 12u);  // the box's twelve triangles, not the ball's
  // The same mesh uploaded by someone else runs for them: an instant result
  // would say that another user has it.
  Client other = client();
  other.sign_up("quinn");
  json theirs = other.call_json("POST", "/api/v1/models", {{"name", "same"}, {"kind", "stl"}}, 201);
  const std::string t = "/api/v1/models/" + std::to_string(theirs["id"].get<int>());
  ASSERT_EQ(other.call("PUT", t + "/stl", box).status, 200);
  json run = other.call_json("POST", "/api/v1/jobs", tiny_job({{"model", theirs["id"]}}), 202);
  EXPECT_FALSE(run.contains("reused_from") && !run["reused_from"].is_null() &&
               !run["reused_from"].get<std::string>().empty())
      << run.dump();
  // Its owner gets their own result again at once.
  EXPECT_EQ(other.wait_job(run["id"])["state"], "done");
  EXPECT_EQ(other.call_json("POST", "/api/v1/jobs", tiny_job({{"model", theirs["id"]}}), 200)["reused_from"],
            run["id"]);
}

TEST_F(ServiceTest, AccountsSessionsAndOwnership) {
  Client a = client(), b = client();
  a.sign_up("alice");
  b.sign_up("bob");
  EXPECT_EQ(a.call("POST", "/api/v1/accounts", R"({"name":"alice","password":"another one"})").status, 409);
  EXPECT_EQ(a.call("POST", "/api/v1/accounts", R"({"name":"carol","password":"short"})").status, 400);
  EXPECT_EQ(a.call("POST", "/api/v1/accounts", R"({"name":"../x","password":"long enough"})").status, 400);
  // Wrong password: 401, and after three the name must wait (429, Retry-After).
  Client anon = client();
  for (int i = 0; i < 3; ++i)
    EXPECT_EQ(anon.call("POST", "/api/v1/sessions", R"({"name":"alice","password":"wrong guess"})").status, 401);
  auto slowed = anon.call("POST", "/api/v1/sessions", R"({"name":"alice","password":"correct horse"})");
  EXPECT_EQ(slowed.status, 429);
  EXPECT_FALSE(slowed.headers["retry-after"].empty());
  EXPECT_EQ(anon.call("POST", "/api/v1/sessions", R"({"name":"nobody","password":"whatever1"})").status, 401);
  // The cookie signs in as the token does.
  auto login = anon.call("POST", "/api/v1/sessions", R"({"name":"bob","password":"correct horse"})");
  ASSERT_EQ(login.status, 200);
  const std::string cookie = login.headers["set-cookie"];
  EXPECT_NE(cookie.find("HttpOnly"), std::string::npos);
  EXPECT_NE(cookie.find("SameSite=Strict"), std::string::npos);
  const std::string pair = cookie.substr(0, cookie.find(';'));
  auto me = anon.call("GET", "/api/v1/me", "", {"Cookie: " + pair});
  EXPECT_EQ(me.status, 200);
  EXPECT_EQ(json::parse(me.body)["name"], "bob");
  EXPECT_EQ(anon.call("GET", "/api/v1/me", "", {"Authorization: Bearer forged"}).status, 401);
  EXPECT_EQ(anon.call("GET", "/api/v1/jobs").status, 401);

  // Bob's job and model are not Alice's to see, fetch, cancel, share or delete.
  json job = b.call_json("POST", "/api/v1/jobs", tiny_job("wall1", 20, 0.2), 202);
  const std::string id = job["id"];
  for (auto [method, path] : std::vector<std::pair<std::string, std::string>>{
           {"GET", "/api/v1/jobs/" + id},
           {"POST", "/api/v1/jobs/" + id + "/cancel"},
           {"POST", "/api/v1/jobs/" + id + "/shares"},
           {"GET", "/api/v1/jobs/" + id + "/shares"},
           {"DELETE", "/api/v1/jobs/" + id},
           {"GET", "/api/v1/jobs/" + id + "/files/result.json"},
           {"GET", "/api/v1/jobs/nosuchjob"}})
    EXPECT_EQ(a.call(method, path).status, 404) << method << " " << path;
  json model = b.call_json("POST", "/api/v1/models", {{"name", "cup"}, {"spec", "cylinder:r=2,h=3"}}, 201);
  const std::string mid = std::to_string(model["id"].get<int>());
  EXPECT_EQ(a.call("GET", "/api/v1/models/" + mid).status, 404);
  EXPECT_EQ(a.call("DELETE", "/api/v1/models/" + mid).status, 404);
  EXPECT_EQ(a.call("POST", "/api/v1/jobs", tiny_job({{"model", model["id"]}}).dump()).status, 400);
  // Presets are everyone's; an admin route is not.
  json models = a.call_json("GET", "/api/v1/models");
  std::set<std::string> names;
  for (const json& m : models) names.insert(m["name"].get<std::string>());
  EXPECT_TRUE(names.count("wall1") && names.count("wall2"));
  EXPECT_FALSE(names.count("cup"));
  EXPECT_EQ(a.call("GET", "/api/v1/admin/logs").status, 403);
  EXPECT_EQ(b.call("DELETE", "/api/v1/sessions").status, 204);
  EXPECT_EQ(b.call("GET", "/api/v1/me").status, 401);
  EXPECT_EQ(b.call("GET", "/api/v1/jobs/" + id).status, 401);
}

TEST_F(ServiceTest, BadInputGetsClearErrorsAndTheServerGoesOn) {
  Client c = client();
  c.sign_up("mallory");
  auto bad = c.call("POST", "/api/v1/jobs", "{\"scene\": ");
  EXPECT_EQ(bad.status, 400);
  EXPECT_NE(json::parse(bad.body)["error"].get<std::string>().find("JSON"), std::string::npos);
  // Scenes: unknown keys, impossible values, a server path as the wall.
  json s = tiny_job("wall1");
  s["scene"]["particles"]["count"] = -5;
  EXPECT_EQ(c.call("POST", "/api/v1/jobs", s.dump()).status, 400);
  s = tiny_job("/etc/passwd");
  auto path_wall = c.call("POST", "/api/v1/jobs", s.dump());
  EXPECT_EQ(path_wall.status, 400);
  EXPECT_NE(path_wall.body.find("model"), std::string::npos);
  s = tiny_job({{"file", "/etc/passwd"}});
  EXPECT_EQ(c.call("POST", "/api/v1/jobs", s.dump()).status, 400);
  // A shape as {"shape": spec}, as scene files (and a run's scene.json) write
  // it, is the shape; a path in it is not.
  EXPECT_EQ(c.call("POST", "/api/v1/predict", tiny_job({{"shape", "wall1"}}).dump()).status, 200);
  EXPECT_EQ(c.call("POST", "/api/v1/predict", tiny_job({{"shape", "/etc/passwd"}}).dump()).status,
            400);
  s = tiny_job("wall1");
  s["scene"]["colour"] = "red";
  EXPECT_EQ(c.call("POST", "/api/v1/jobs", s.dump()).status, 400);
  s = tiny_job("wall1");
  s["render"]["width"] = 100000;
  EXPECT_EQ(c.call("POST", "/api/v1/predict", s.dump()).status, 400);
  // A body over the JSON limit, and a forged huge Content-Length: 413, and on.
  EXPECT_EQ(c.call("POST", "/api/v1/jobs", std::string(100 << 10, ' ')).status, 413);
  EXPECT_EQ(c.call("GET", "/api/v1/health").status, 200);
  auto forged = c.call("POST", "/api/v1/jobs", "{}", {"Content-Length: 99999999999999"});
  EXPECT_EQ(forged.status, 413);
  EXPECT_EQ(c.call("GET", "/api/v1/health").status, 200);
  // A body nested past any document of the API: refused before it is parsed
  // (copying such a value would overflow the stack), and the server goes on.
  const std::string deep = "{\"scene\":" + std::string(30000, '[') + std::string(30000, ']') + "}";
  auto nested = c.call("POST", "/api/v1/predict", deep);
  EXPECT_EQ(nested.status, 400) << nested.body;
  EXPECT_NE(json::parse(nested.body)["error"].get<std::string>().find("levels deep"), std::string::npos);
  // Brackets inside a string are text, not depth.
  auto in_text = c.call("POST", "/api/v1/predict", "{\"note\":\"" + std::string(100, '[') + "\"}");
  EXPECT_EQ(in_text.status, 400);
  EXPECT_EQ(json::parse(in_text.body)["error"].get<std::string>().find("levels deep"), std::string::npos);
  // A known key of the wrong type: 400, not an internal error.
  EXPECT_EQ(c.call("POST", "/api/v1/models", json{{"name", "n"}, {"kind", 5}}.dump()).status, 400);
  s = tiny_job("wall1");
  s["fresh"] = "yes";
  EXPECT_EQ(c.call("POST", "/api/v1/jobs", s.dump()).status, 400);
  // STL uploads: bytes that do not parse get the loader's message; too large, 413.
  json model = c.call_json("POST", "/api/v1/models", {{"name", "upload"}, {"kind", "stl"}}, 201);
  const std::string stl = "/api/v1/models/" + std::to_string(model["id"].get<int>()) + "/stl";
  // Signed out, an upload's body is refused at the JSON documents' limit,
  // before the server holds it (an upload's limit a connection, for anyone).
  EXPECT_EQ(client().call("PUT", stl, std::string(100 << 10, 'x')).status, 413);
  auto junk = c.call("PUT", stl, "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 zero\n");
  EXPECT_EQ(junk.status, 422);
  EXPECT_FALSE(json::parse(junk.body)["error"].get<std::string>().empty());
  EXPECT_EQ(c.call("PUT", stl, std::string(2 << 20, 'x')).status, 413);
  EXPECT_EQ(c.call("GET", stl).status, 404);  // nothing stored
  // A real STL is taken and served back byte for byte.
  const std::string ascii =
      "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
      "endloop\nendfacet\nendsolid t\n";
  auto ok = c.call("PUT", stl, ascii, {"Content-Type: model/stl"});
  EXPECT_EQ(ok.status, 200) << ok.body;
  EXPECT_EQ(json::parse(ok.body)["triangles"], 1);
  EXPECT_EQ(c.call("GET", stl).body, ascii);
  // Unknown ids, traversal, methods.
  EXPECT_EQ(c.call("GET", "/api/v1/models/999999").status, 404);
  EXPECT_EQ(c.call("GET", "/api/v1/models/abc").status, 404);
  EXPECT_EQ(c.call("GET", "/api/v1/jobs/x/files/../../collidoscope.db").status, 404);
  EXPECT_EQ(c.call("GET", "/api/v1/jobs/x/files/%2e%2e/%2e%2e/collidoscope.db").status, 404);
  EXPECT_EQ(c.call("GET", "/s/../collidoscope.db").status, 404);
  EXPECT_EQ(c.call("GET", "/nothing/here").status, 404);
  EXPECT_EQ(c.call("PATCH", "/api/v1/jobs").status, 405);
  // Strings that look like SQL are stored and returned as they are.
  const std::string sly = "x'); DROP TABLE users; --\"";
  json m2 = c.call_json("POST", "/api/v1/models", {{"name", sly}, {"spec", "box:x=1,y=1,z=1"}}, 201);
  EXPECT_EQ(c.call_json("GET", "/api/v1/models/" + std::to_string(m2["id"].get<int>()))["name"], sly);
  EXPECT_EQ(c.call("POST", "/api/v1/sessions", json{{"name", sly}, {"password", sly}}.dump()).status, 401);
  EXPECT_EQ(c.call("GET", "/api/v1/me").status, 200);
}

TEST_F(ServiceTest, ClientClosingMidVideoLeavesTheServerRunning) {
  Client c = client();
  c.sign_up("viewer");
  // A 1 MiB file to download: an STL upload is the quickest one to make.
  json model = c.call_json("POST", "/api/v1/models", {{"name", "big"}, {"kind", "stl"}}, 201);
  const std::string stl = "/api/v1/models/" + std::to_string(model["id"].get<int>()) + "/stl";
  std::string bin(80, ' ');
  const uint32_t n = 10000;
  bin.append(reinterpret_cast<const char*>(&n), 4);
  for (uint32_t i = 0; i < n; ++i) {
    float f[12] = {0, 0, 1, float(i), 0, 0, float(i) + 1, 0, 0, float(i), 1, 0};
    bin.append(reinterpret_cast<const char*>(f), sizeof f);
    bin.append(2, '\0');
  }
  ASSERT_EQ(c.call("PUT", stl, bin).status, 200);
  // Each round leaves a download behind, and the next connection (which
  // likely gets the same descriptor number) must get its own answer first.
  // (A pool thread's write racing the close is what PeerGuard's send lock
  // stops; this loop did not catch that race here with the lock taken out,
  // in 100 runs: it checks the answers, it does not force the race.)
  auto answer_head = [&](const std::string& path) {
    const int fd = connect_loopback(server_->port());
    if (fd < 0) return std::string("no connection");
    const std::string req =
        "GET " + path + " HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " + c.token + "\r\n\r\n";
    std::string got(64, '\0');
    ssize_t n = -1;
    if (::send(fd, req.data(), req.size(), 0) == ssize_t(req.size()))
      n = ::recv(fd, got.data(), got.size(), 0);
    linger l{1, 0};  // close with a reset, as a browser tab that goes away
    ::setsockopt(fd, SOL_SOCKET, SO_LINGER, &l, sizeof l);
    ::close(fd);
    got.resize(size_t(std::max<ssize_t>(n, 0)));
    return got;
  };
  for (int round = 0; round < 60; ++round) {
    const std::string download = answer_head(stl);
    ASSERT_EQ(download.rfind("HTTP/1.1 200", 0), 0u) << "round " << round << ": " << download;
    const std::string next = answer_head("/api/v1/health");
    ASSERT_EQ(next.rfind("HTTP/1.1 200", 0), 0u) << "round " << round << ": " << next;
  }
  const HttpResponse health = c.call("GET", "/api/v1/health");
  EXPECT_EQ(health.status, 200) << health.error;
  EXPECT_EQ(c.call("GET", stl).body.size(), bin.size());
}

// A refusal is written while its body is still coming in, and Pistache 0.0.5
// takes an event that finds the socket both readable and writable as a read
// only: the 413 once waited until the client, its body sent, gave up (curl
// after 30 s; 3 in 800 runs of BadInputGetsClearErrorsAndTheServerGoesOn).
// Bodies over the limit sent in small pieces make that event likely: 400
// refusals of 1 MiB bodies sent 4 KiB at a time by four clients at once,
// each answered within 3 s (without the fix 1 to 6 of them were not, in each
// of 5 runs; about 4 s, and at most 20 s plus one wait of 3 s in all).
TEST_F(ServiceTest, ARefusalGoesOutWhileItsBodyIsStillComing) {
  constexpr int kClients = 4, kEach = 100;
  constexpr size_t kBody = 1 << 20, kPiece = 4096;  // over the 64 KiB limit
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  std::atomic<int> answered{0}, silent{0};
  std::vector<std::thread> clients;
  for (int c = 0; c < kClients; ++c)
    clients.emplace_back([&] {
      const std::string head =
          "POST /api/v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Type: "
          "application/json\r\nContent-Length: " +
          std::to_string(kBody) + "\r\n\r\n";
      const std::string piece(kPiece, ' ');
      for (int i = 0; i < kEach && std::chrono::steady_clock::now() < deadline; ++i) {
        const int fd = connect_loopback(server_->port());
        if (fd < 0) continue;
        timeval tv{3, 0};
        ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
        bool sent = ::send(fd, head.data(), head.size(), MSG_NOSIGNAL) == ssize_t(head.size());
        for (size_t at = 0; sent && at < kBody; at += kPiece) {
          sent = ::send(fd, piece.data(), piece.size(), MSG_NOSIGNAL) == ssize_t(piece.size());
          std::this_thread::sleep_for(std::chrono::microseconds(100));
        }
        char buf[32] = {};
        const ssize_t n = ::recv(fd, buf, sizeof buf - 1, 0);
        if (n >= 12 && std::string(buf, 12) == "HTTP/1.1 413")
          ++answered;
        else
          ++silent;
        ::close(fd);
      }
    });
  for (auto& t : clients) t.join();
  EXPECT_EQ(silent.load(), 0);
  EXPECT_EQ(answered.load(), kClients * kEach);
  EXPECT_EQ(client().call("GET", "/api/v1/health").status, 200);
}

// Pistache 0.0.5 answers a request without a Connection header "Connection: Close";
// HTTP/1.1 keeps it open, and so does the server: two requests on one connection.
TEST_F(ServiceTest, AnHttp11ConnectionWithoutAConnectionHeaderStaysOpen) {
  const int fd = connect_loopback(server_->port());
  ASSERT_GE(fd, 0);
  timeval tv{10, 0};  // bounded: a server that closed or never answers fails, not hangs
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  const std::string req = "GET /api/v1/health HTTP/1.1\r\nHost: x\r\n\r\n";
  for (int i = 0; i < 2; ++i) {
    ASSERT_EQ(::send(fd, req.data(), req.size(), MSG_NOSIGNAL), ssize_t(req.size())) << "request " << i;
    std::string got;
    char buf[4096];
    while (got.find("\"status\"") == std::string::npos) {
      const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
      ASSERT_GT(n, 0) << "request " << i << " got no answer; so far: " << got;
      got.append(buf, size_t(n));
    }
    EXPECT_EQ(got.compare(0, 15, "HTTP/1.1 200 OK"), 0) << got;
    EXPECT_EQ(got.find("Connection: Close"), std::string::npos) << got;
  }
  ::close(fd);
}

// The open descriptors of this process (the server runs in it).
size_t open_descriptors() {
  size_t n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator("/proc/self/fd")) ++n;
  return n;
}

// Reads one answer to a GET from a raw connection: its head and a body of the
// Content-Length it states. Empty on a closed or silent connection.
std::pair<std::string, std::string> read_answer(int fd) {
  std::string got;
  char buf[65536];
  size_t head_end = std::string::npos, length = 0;
  while (true) {
    if (head_end == std::string::npos && (head_end = got.find("\r\n\r\n")) != std::string::npos) {
      const size_t at = got.find("Content-Length: ");
      if (at == std::string::npos || at > head_end) return {};
      length = std::stoull(got.substr(at + 16));
      head_end += 4;
    }
    if (head_end != std::string::npos && got.size() >= head_end + length) break;
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) return {};
    got.append(buf, size_t(n));
  }
  return {got.substr(0, head_end), got.substr(head_end, length)};
}

// n bytes of a fixed pseudo-random sequence (a file no compression shrinks).
std::string random_bytes(size_t n, uint32_t seed) {
  std::string bytes(n, '\0');
  for (char& ch : bytes) ch = char((seed = seed * 1664525u + 1013904223u) >> 24);
  return bytes;
}

// Reads n answers from a raw connection that may bring several in one read
// (read_answer keeps none of the bytes past its answer). Stops early on a
// closed or silent connection.
std::vector<std::pair<std::string, std::string>> read_answers(int fd, int n) {
  std::vector<std::pair<std::string, std::string>> answers;
  std::string got;
  char buf[65536];
  while (int(answers.size()) < n) {
    const size_t head_end = got.find("\r\n\r\n");
    if (head_end != std::string::npos) {
      const size_t at = got.find("Content-Length: ");
      if (at == std::string::npos || at > head_end) return answers;
      const size_t length = std::stoull(got.substr(at + 16));
      if (got.size() >= head_end + 4 + length) {
        answers.emplace_back(got.substr(0, head_end + 4), got.substr(head_end + 4, length));
        got.erase(0, head_end + 4 + length);
        continue;
      }
    }
    const ssize_t r = ::recv(fd, buf, sizeof buf, 0);
    if (r <= 0) return answers;
    got.append(buf, size_t(r));
  }
  return answers;
}

// A large file is sent in slices from the open file, never read whole: it
// arrives byte for byte, with its headers, whole or by any range, and the
// connection serves the next request after it. Downloads stopped part way
// leave no descriptor behind (Pistache's serveFile kept one open each).
TEST_F(ServiceTest, FilesGoOutInSlicesRevalidateAndStoppedDownloadsCloseThem) {
  const std::string web = dir_ + "/web";
  fs::create_directories(web);
  const std::string big = random_bytes(5'000'000, 12345);
  ASSERT_TRUE(collido::write_file_atomic(web + "/big.bin", big));
  ASSERT_TRUE(collido::write_file_atomic(web + "/index.html", "<!doctype html><title>t</title>"));
  ASSERT_NO_FATAL_FAILURE(start_web_server(web));
  const std::string& base = web_base_;

  auto whole = http("GET", base + "/ui/big.bin");
  ASSERT_EQ(whole.status, 200);
  EXPECT_TRUE(whole.body == big) << whole.body.size() << " bytes";
  EXPECT_EQ(whole.headers["content-length"], std::to_string(big.size()));
  EXPECT_EQ(whole.headers["accept-ranges"], "bytes");
  EXPECT_EQ(whole.headers["x-content-type-options"], "nosniff");
  EXPECT_EQ(whole.headers["cache-control"], "no-cache");
  auto from = http("GET", base + "/ui/big.bin", "", {"Range: bytes=1000-"});
  EXPECT_EQ(from.status, 206);
  EXPECT_TRUE(from.body == big.substr(1000)) << from.body.size() << " bytes";
  EXPECT_EQ(from.headers["content-range"],
            "bytes 1000-" + std::to_string(big.size() - 1) + "/" + std::to_string(big.size()));
  auto empty_page = http("GET", base + "/");
  EXPECT_EQ(empty_page.status, 200);
  EXPECT_EQ(empty_page.headers["content-type"], "text/html; charset=utf-8");

  // Revalidated: 304 while the file is the same, the file again once replaced;
  // a range of another version of it is the whole new file.
  const std::string tag = whole.headers["etag"];
  ASSERT_FALSE(tag.empty());
  auto same = http("GET", base + "/ui/big.bin", "", {"If-None-Match: " + tag});
  EXPECT_EQ(same.status, 304);
  EXPECT_TRUE(same.body.empty());
  EXPECT_EQ(same.headers["etag"], tag);
  EXPECT_EQ(same.headers.count("content-length"), 0u);
  EXPECT_EQ(http("GET", base + "/ui/big.bin", "",
                 {"If-Modified-Since: " + whole.headers["last-modified"]})
                .status,
            304);
  EXPECT_EQ(http("GET", base + "/ui/big.bin", "", {"Range: bytes=0-9", "If-Range: " + tag}).status,
            206);
  std::string changed = big;
  changed[0] ^= 1;
  changed += "more";
  ASSERT_TRUE(collido::write_file_atomic(web + "/big.bin", changed));
  auto fresh = http("GET", base + "/ui/big.bin", "", {"If-None-Match: " + tag});
  EXPECT_EQ(fresh.status, 200);
  EXPECT_TRUE(fresh.body == changed);
  EXPECT_NE(fresh.headers["etag"], tag);
  auto stale_range =
      http("GET", base + "/ui/big.bin", "", {"Range: bytes=0-9", "If-Range: " + tag});
  EXPECT_EQ(stale_range.status, 200);
  EXPECT_TRUE(stale_range.body == changed);
  ASSERT_TRUE(collido::write_file_atomic(web + "/big.bin", big));
  // Two answers on one connection: the file, then the page.
  const int fd = connect_loopback(web_server_->port());
  ASSERT_GE(fd, 0);
  timeval tv{10, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  for (const std::string path : {"/ui/big.bin", "/"}) {
    const std::string req = "GET " + path + " HTTP/1.1\r\nHost: x\r\n\r\n";
    ASSERT_EQ(::send(fd, req.data(), req.size(), MSG_NOSIGNAL), ssize_t(req.size()));
    auto [head, body] = read_answer(fd);
    EXPECT_EQ(head.compare(0, 15, "HTTP/1.1 200 OK"), 0) << path << ": " << head;
    EXPECT_EQ(body.size(), path == "/" ? 31u : big.size()) << path;
  }
  ::close(fd);

  // Twenty downloads stopped after their first bytes.
  const size_t before = open_descriptors();
  for (int i = 0; i < 20; ++i) {
    const int d = connect_loopback(web_server_->port());
    ASSERT_GE(d, 0);
    const std::string req = "GET /ui/big.bin HTTP/1.1\r\nHost: x\r\n\r\n";
    ASSERT_EQ(::send(d, req.data(), req.size(), MSG_NOSIGNAL), ssize_t(req.size()));
    char buf[4096];
    ASSERT_GT(::recv(d, buf, sizeof buf, 0), 0);
    ::close(d);
  }
  size_t after = open_descriptors();
  for (int wait = 0; wait < 100 && after > before; ++wait) {  // the server sees the closes
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    after = open_descriptors();
  }
  EXPECT_LE(after, before) << "descriptors left open by stopped downloads";
  EXPECT_TRUE(http("GET", base + "/ui/big.bin").body == big);
}

// The UI's libraries go out gzipped to a browser that takes it, from the copy
// install-web.sh makes, unless the file changed after the copy was made.
TEST_F(ServiceTest, UiLibrariesGoOutGzippedWhereTheBrowserTakesIt) {
  const std::string web = dir_ + "/web";
  fs::create_directories(web);
  const std::string js = "export const x = 1;\n", gz = "not really gzip, but what the copy holds";
  ASSERT_TRUE(collido::write_file_atomic(web + "/lib.js", js));
  ASSERT_TRUE(collido::write_file_atomic(web + "/lib.js.gz", gz));
  fs::last_write_time(web + "/lib.js",
                      fs::last_write_time(web + "/lib.js.gz") - std::chrono::seconds(5));
  ASSERT_NO_FATAL_FAILURE(start_web_server(web));
  const std::string url = web_base_ + "/ui/lib.js";

  auto zipped = http("GET", url, "", {"Accept-Encoding: gzip, deflate, br"});
  EXPECT_EQ(zipped.status, 200);
  EXPECT_EQ(zipped.body, gz);
  EXPECT_EQ(zipped.headers["content-encoding"], "gzip");
  EXPECT_EQ(zipped.headers["content-type"], "text/javascript; charset=utf-8");
  EXPECT_EQ(zipped.headers["vary"], "Accept-Encoding");
  auto plain = http("GET", url);
  EXPECT_EQ(plain.body, js);
  EXPECT_EQ(plain.headers.count("content-encoding"), 0u);
  EXPECT_EQ(plain.headers["vary"], "Accept-Encoding");
  EXPECT_NE(plain.headers["etag"], zipped.headers["etag"]);  // two representations, two tags
  EXPECT_EQ(http("GET", url, "", {"Accept-Encoding: gzip;q=0"}).body, js);
  // Edited after its copy was made: the file itself.
  ASSERT_TRUE(collido::write_file_atomic(web + "/lib.js", js + "// edited\n"));
  fs::last_write_time(web + "/lib.js",
                      fs::last_write_time(web + "/lib.js.gz") + std::chrono::seconds(5));
  auto edited = http("GET", url, "", {"Accept-Encoding: gzip"});
  EXPECT_EQ(edited.body, js + "// edited\n");
  EXPECT_EQ(edited.headers.count("content-encoding"), 0u);
}

// A request that computes runs off its connection's reactor thread: here a
// parametric sphere of 1.3 million triangles, built to count them (about a
// second). On a server of one reactor thread another connection is answered
// meanwhile (before, it waited for the build), and with one work thread and
// no queue a second such request is answered 503 with Retry-After until the
// first is done.
TEST_F(ServiceTest, RequestsThatComputeLeaveTheReactorFreeAndABusyPoolSays503) {
  ServerOptions o;
  o.port = 0;
  o.threads = 1;
  o.work_threads = 1;
  o.max_waiting_work = 0;
  ASSERT_NO_FATAL_FAILURE(start_second_server(o));
  // Signed up on the first server (the two share the store).
  Client first = client();
  first.sign_up("builder");
  Client c(web_base_);
  c.token = first.token;
  const json big = {
      {"name", "big ball"}, {"kind", "parametric"}, {"spec", "sphere:r=10,subdivisions=8"}};
  std::atomic<int> order{0};
  std::atomic<int> build_ended{-1};
  HttpResponse built;
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  std::thread build([&] {
    do  // refused only while the prediction below holds the pool
      built = c.call("POST", "/api/v1/models", big.dump());
    while (built.status == 503 && std::chrono::steady_clock::now() < until);
    build_ended = order++;
  });
  // Until the build holds the pool's one thread, a prediction is answered.
  HttpResponse refused;
  while (std::chrono::steady_clock::now() < until) {
    refused = c.call("POST", "/api/v1/predict", tiny_job("wall1").dump());
    if (refused.status == 503 || build_ended >= 0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  const auto health = http("GET", web_base_ + "/api/v1/health");
  const int health_ended = order++;
  build.join();
  EXPECT_EQ(refused.status, 503) << refused.body;
  EXPECT_EQ(refused.headers["retry-after"], "1");
  EXPECT_NE(refused.body.find("busy"), std::string::npos) << refused.body;
  EXPECT_EQ(health.status, 200);
  EXPECT_LT(health_ended, build_ended.load()) << "the health check waited for the build";
  ASSERT_EQ(built.status, 201) << built.body;
  EXPECT_EQ(json::parse(built.body)["triangles"], 1310720);
  // The build's task freed its place before its answer went out
  // (RequestPool::answering), so the same request sent now is answered, at
  // the first try, though the thread may still be leaving that task. (The
  // window is too short for this to fail reliably without it; the unit test
  // RequestPool.ATaskThatIsAnsweringLeavesRoomForTheNext pins it.)
  for (int i = 0; i < 20; ++i) {
    const HttpResponse again = c.call("POST", "/api/v1/predict", tiny_job("wall1").dump());
    ASSERT_EQ(again.status, 200) << "request " << i << ": " << again.body;
  }
}

// A prediction's request as bytes on the wire (computed on the pool), and a
// health check's (answered on the reactor thread), for the pipelining tests.
std::string predict_request(const Client& c) {
  const std::string job = tiny_job("wall1", 400, 1.0).dump();
  return "POST /api/v1/predict HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " + c.token +
         "\r\nContent-Type: application/json\r\nContent-Length: " + std::to_string(job.size()) +
         "\r\n\r\n" + job;
}
const char* const kHealthRequest = "GET /api/v1/health HTTP/1.1\r\nHost: x\r\n\r\n";

// Answers go out in the order their requests came, to a client that
// pipelines them (HTTP/1.1): a prediction (computed on the pool) before a
// health check (answered on the reactor thread), and a file sent in slices
// before the request behind it. Before, the health check was answered first,
// and the request behind a large file between two of its slices.
TEST_F(ServiceTest, PipelinedRequestsAreAnsweredInOrder) {
  Client c = client();
  c.sign_up("piper");
  const std::string predict = predict_request(c), health = kHealthRequest;
  const auto send_all = [](int fd, const std::string& bytes) {
    timeval tv{20, 0};
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    return ::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL) == ssize_t(bytes.size());
  };
  int fd = connect_loopback(server_->port());
  ASSERT_GE(fd, 0);
  ASSERT_TRUE(send_all(fd, predict + health + predict + health + health));
  auto answers = read_answers(fd, 5);
  ASSERT_EQ(answers.size(), 5u);
  for (int k = 0; k < 5; ++k) {
    const auto& [head, body] = answers[size_t(k)];
    ASSERT_EQ(head.compare(0, 15, "HTTP/1.1 200 OK"), 0) << "answer " << k << ": " << head;
    const json j = json::parse(body, nullptr, false);
    if (k == 0 || k == 2)
      EXPECT_TRUE(j.contains("total_time_s")) << "answer " << k << ": " << body;
    else
      EXPECT_EQ(j.value("status", ""), "ok") << "answer " << k << ": " << body;
  }
  ::close(fd);

  const std::string web = dir_ + "/web";
  fs::create_directories(web);
  const std::string big = random_bytes(3'000'000, 777);
  ASSERT_TRUE(collido::write_file_atomic(web + "/big.bin", big));
  ASSERT_NO_FATAL_FAILURE(start_web_server(web));
  fd = connect_loopback(web_server_->port());
  ASSERT_GE(fd, 0);
  const std::string file = "GET /ui/big.bin HTTP/1.1\r\nHost: x\r\n\r\n";
  ASSERT_TRUE(send_all(fd, file + health + file + predict + health));
  answers = read_answers(fd, 5);
  ASSERT_EQ(answers.size(), 5u);
  for (int k = 0; k < 5; ++k) {
    const auto& [head, body] = answers[size_t(k)];
    ASSERT_EQ(head.compare(0, 15, "HTTP/1.1 200 OK"), 0) << "answer " << k << ": " << head;
    if (k == 0 || k == 2) {
      EXPECT_TRUE(body == big) << "answer " << k << ": " << body.size() << " bytes";
    } else {
      const json j = json::parse(body, nullptr, false);
      EXPECT_TRUE(j.contains(k == 3 ? "total_time_s" : "status")) << "answer " << k << ": " << body;
    }
  }
  ::close(fd);
}

// A request refused from its head (here 413: a body over the limit) answers
// in its turn: the requests before it on the connection get their whole
// answers first (one computing on the pool, a file going out in slices), then
// the refusal, then the server closes. The refusal went out at once, ahead of
// them, and the earlier requests that came in the same read were dropped.
TEST_F(ServiceTest, ARefusalPipelinedBehindOtherRequestsComesAfterTheirAnswers) {
  Client c = client();
  c.sign_up("piper");
  const std::string predict = predict_request(c), health = kHealthRequest;
  const std::string too_big =
      "POST /api/v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Length: 99999999999\r\n\r\n";
  const std::string web = dir_ + "/web";
  fs::create_directories(web);
  const std::string big = random_bytes(3'000'000, 778);
  ASSERT_TRUE(collido::write_file_atomic(web + "/big.bin", big));
  ASSERT_NO_FATAL_FAILURE(start_web_server(web));
  const std::string file = "GET /ui/big.bin HTTP/1.1\r\nHost: x\r\n\r\n";

  for (const std::string& first : {predict, file, health}) {
    const int fd = connect_loopback(web_server_->port());
    ASSERT_GE(fd, 0);
    timeval tv{20, 0};
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    const std::string bytes = first + health + too_big;
    ASSERT_EQ(::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL), ssize_t(bytes.size()));
    const auto answers = read_answers(fd, 3);
    ASSERT_EQ(answers.size(), 3u) << first.substr(0, 30);
    EXPECT_EQ(answers[0].first.compare(0, 15, "HTTP/1.1 200 OK"), 0) << answers[0].first;
    if (first == file)
      EXPECT_TRUE(answers[0].second == big) << answers[0].second.size() << " bytes";
    else
      EXPECT_TRUE(json::parse(answers[0].second, nullptr, false)
                      .contains(first == predict ? "total_time_s" : "status"))
          << answers[0].second;
    EXPECT_EQ(answers[1].first.compare(0, 15, "HTTP/1.1 200 OK"), 0) << answers[1].first;
    EXPECT_EQ(answers[2].first.compare(0, 12, "HTTP/1.1 413"), 0) << answers[2].first;
    char byte;
    EXPECT_EQ(::recv(fd, &byte, 1, 0), 0) << "the connection ends after the refusal";
    ::close(fd);
  }
}

// An upload that asks whether to send its body (Expect: 100-continue, as curl
// does past 1 MiB; it waited a second for an answer that never came) is told
// to go on at once, then answered; one over the limit is refused before its
// body is sent.
TEST_F(ServiceTest, AnUploadThatAsksToGoOnIsToldToOrRefusedBeforeItsBody) {
  Client c = client();
  c.sign_up("curly");
  json model = c.call_json("POST", "/api/v1/models", {{"name", "asks"}, {"kind", "stl"}}, 201);
  const std::string stl = "/api/v1/models/" + std::to_string(model["id"].get<int>()) + "/stl";
  const std::string body =
      "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
      "endloop\nendfacet\nendsolid t\n";
  const auto head = [&](size_t length) {
    return "PUT " + stl + " HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " + c.token +
           "\r\nContent-Type: model/stl\r\nExpect: 100-continue\r\nContent-Length: " +
           std::to_string(length) + "\r\n\r\n";
  };
  const auto open = [&] {
    const int fd = connect_loopback(server_->port());
    timeval tv{20, 0};
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    return fd;
  };
  const auto read_some = [](int fd) {
    char buf[4096];
    const ssize_t r = ::recv(fd, buf, sizeof buf, 0);
    return r > 0 ? std::string(buf, size_t(r)) : std::string();
  };
  int fd = open();
  ASSERT_GE(fd, 0);
  std::string h = head(body.size());
  ASSERT_EQ(::send(fd, h.data(), h.size(), MSG_NOSIGNAL), ssize_t(h.size()));
  EXPECT_EQ(read_some(fd), "HTTP/1.1 100 Continue\r\n\r\n");
  ASSERT_EQ(::send(fd, body.data(), body.size(), MSG_NOSIGNAL), ssize_t(body.size()));
  auto answers = read_answers(fd, 1);
  ASSERT_EQ(answers.size(), 1u);
  EXPECT_EQ(answers[0].first.compare(0, 15, "HTTP/1.1 200 OK"), 0) << answers[0].first;
  EXPECT_EQ(json::parse(answers[0].second, nullptr, false).value("triangles", 0), 1)
      << answers[0].second;
  ::close(fd);
  EXPECT_EQ(c.call("GET", stl).body, body);

  fd = open();
  ASSERT_GE(fd, 0);
  h = head(size_t(1) << 40);
  ASSERT_EQ(::send(fd, h.data(), h.size(), MSG_NOSIGNAL), ssize_t(h.size()));
  answers = read_answers(fd, 1);
  ASSERT_EQ(answers.size(), 1u);
  EXPECT_EQ(answers[0].first.compare(0, 12, "HTTP/1.1 413"), 0) << answers[0].first;
  ::close(fd);
}

// HEAD is GET without the body, files and JSON alike; a method the path does
// not take gets 405 with the ones it does.
TEST_F(ServiceTest, HeadAnswersLikeGetWithoutTheBodyAnd405SaysWhatIsAllowed) {
  const std::string web = dir_ + "/web";
  fs::create_directories(web);
  const std::string big(1'000'000, 'x');
  ASSERT_TRUE(collido::write_file_atomic(web + "/big.bin", big));
  ASSERT_NO_FATAL_FAILURE(start_web_server(web));
  const std::string& base = web_base_;
  auto head = http("HEAD", base + "/ui/big.bin");
  EXPECT_EQ(head.status, 200);
  EXPECT_EQ(head.headers["content-length"], std::to_string(big.size()));
  EXPECT_EQ(head.headers["accept-ranges"], "bytes");
  EXPECT_TRUE(head.body.empty());
  auto head_part = http("HEAD", base + "/ui/big.bin", "", {"Range: bytes=0-9"});
  EXPECT_EQ(head_part.status, 206);
  EXPECT_EQ(head_part.headers["content-length"], "10");
  auto head_json = http("HEAD", base + "/api/v1/health");
  EXPECT_EQ(head_json.status, 200);
  EXPECT_EQ(head_json.headers["content-length"],
            std::to_string(http("GET", base + "/api/v1/health").body.size()));
  EXPECT_TRUE(head_json.body.empty());
  // A method the path does not take: 405 with the ones it does.
  auto wrong = http("DELETE", base + "/api/v1/health");
  EXPECT_EQ(wrong.status, 405);
  EXPECT_EQ(wrong.headers["allow"], "GET, HEAD");
  EXPECT_EQ(http("PUT", base + "/api/v1/jobs").headers["allow"], "POST, GET, HEAD");

  // On one connection, the answer after a HEAD's starts where the head ends.
  const int fd = connect_loopback(web_server_->port());
  ASSERT_GE(fd, 0);
  timeval tv{10, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  const std::string head_req = "HEAD /ui/big.bin HTTP/1.1\r\nHost: x\r\n\r\n";
  ASSERT_EQ(::send(fd, head_req.data(), head_req.size(), MSG_NOSIGNAL), ssize_t(head_req.size()));
  std::string got;
  char buf[4096];
  while (got.find("\r\n\r\n") == std::string::npos) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    ASSERT_GT(n, 0) << got;
    got.append(buf, size_t(n));
  }
  EXPECT_EQ(got.size(), got.find("\r\n\r\n") + 4) << "bytes after a HEAD's head";
  const std::string get_req = "GET /api/v1/health HTTP/1.1\r\nHost: x\r\n\r\n";
  ASSERT_EQ(::send(fd, get_req.data(), get_req.size(), MSG_NOSIGNAL), ssize_t(get_req.size()));
  auto [next_head, next_body] = read_answer(fd);
  EXPECT_EQ(next_head.compare(0, 15, "HTTP/1.1 200 OK"), 0) << next_head;
  EXPECT_EQ(next_body.front(), '{') << next_body;
  ::close(fd);
}

// GET /jobs in pages: each full page names the next in a Link header, and
// the pages together are the whole list, newest first.
TEST_F(ServiceTest, TheJobListComesInPagesLinkedOneToTheNext) {
  Client c = client();
  c.sign_up("pages");
  const std::string first = c.call_json("POST", "/api/v1/jobs", tiny_job("wall1"), 202)["id"];
  ASSERT_EQ(c.wait_job(first)["state"], "done");
  for (int k = 0; k < 4; ++k)  // the same scene: reused at once, a row each
    c.call_json("POST", "/api/v1/jobs", tiny_job("wall1"), 200);
  const json all = c.call_json("GET", "/api/v1/jobs");
  ASSERT_EQ(all.size(), 5u);
  EXPECT_EQ(all.back()["id"], first);
  EXPECT_EQ(c.call("GET", "/api/v1/jobs").headers.count("link"), 0u);  // one page holds them

  json paged = json::array();
  std::string next = "/api/v1/jobs?limit=2";
  for (int page = 0; page < 5 && !next.empty(); ++page) {
    const HttpResponse r = c.call("GET", next);
    ASSERT_EQ(r.status, 200) << r.body;
    for (const json& j : json::parse(r.body)) paged.push_back(j["id"]);
    next.clear();
    if (r.headers.count("link")) {
      const std::string link = r.headers.at("link");
      ASSERT_EQ(link.front(), '<') << link;
      ASSERT_NE(link.find(">; rel=\"next\""), std::string::npos) << link;
      next = link.substr(1, link.find('>') - 1);
    }
  }
  json ids = json::array();
  for (const json& j : all) ids.push_back(j["id"]);
  EXPECT_EQ(paged, ids);
  EXPECT_TRUE(next.empty()) << "a last page that still links on: " << next;
  // A limit is held to 1..1000; a place that is not one is refused.
  EXPECT_EQ(c.call_json("GET", "/api/v1/jobs?limit=0").size(), 1u);
  EXPECT_EQ(c.call_json("GET", "/api/v1/jobs?limit=99999").size(), 5u);
  EXPECT_EQ(c.call("GET", "/api/v1/jobs?before=yesterday").status, 400);
}

// A job whose files would not fit on the results' disk is refused with the
// figures, at the prediction and at submission; a small one still runs.
TEST_F(ServiceTest, AJobWhoseFilesWouldNotFitOnTheDiskIsRefused) {
  server_.reset();
  svc_.reset();
  disk_free_ = 4 << 20;  // 4 MiB free
  start();
  Client c = client();
  c.sign_up("disk");
  json big = tiny_job("wall1", 40, 2.0);
  big["scene"]["fps"] = 25;
  big["render"]["width"] = 1280, big["render"]["height"] = 720;
  for (const char* route : {"/api/v1/predict", "/api/v1/jobs"}) {
    const HttpResponse r = c.call("POST", route, big.dump());
    EXPECT_EQ(r.status, 507) << route << ": " << r.body;
    EXPECT_NE(r.body.find("do not fit in the 4.0 MiB"), std::string::npos) << r.body;
    EXPECT_NE(r.body.find("fewer frames"), std::string::npos) << r.body;
  }
  const json small = c.call_json("POST", "/api/v1/predict", tiny_job("wall1"));
  EXPECT_LT(small["output_bytes"]["admitted_by"].get<double>(), 4 << 20) << small.dump();
  const std::string id = c.call_json("POST", "/api/v1/jobs", tiny_job("wall1"), 202)["id"];
  const json done = c.wait_job(id);
  ASSERT_EQ(done["state"], "done");
  // The estimate holds what the job wrote.
  uint64_t written = 0;
  for (const auto& e : fs::recursive_directory_iterator(svc_->store().job_by_id(id)->run_dir))
    if (e.is_regular_file()) written += e.file_size();
  EXPECT_GT(written, 0u);
  EXPECT_GE(small["output_bytes"]["estimate"].get<double>(), double(written));

  // Jobs waiting for a worker hold their share: with room for two and a half
  // jobs' files, two wait and the third is refused.
  server_.reset();
  svc_.reset();
  const double each = small["output_bytes"]["admitted_by"].get<double>();
  disk_free_ = uint64_t(2.5 * each);
  workers_ = 0;
  start();
  Client w = client();
  w.sign_up("waits");
  json fresh = tiny_job("wall1");
  fresh["fresh"] = true;  // not the finished one's result again
  w.call_json("POST", "/api/v1/jobs", fresh, 202);
  w.call_json("POST", "/api/v1/jobs", fresh, 202);
  const HttpResponse third = w.call("POST", "/api/v1/jobs", fresh.dump());
  EXPECT_EQ(third.status, 507) << third.body;
  EXPECT_NE(third.body.find("is for the queued jobs"), std::string::npos) << third.body;
}

TEST_F(ServiceTest, AdmissionQueueLimitAndCancel) {
  Client c = client();
  c.sign_up("busy");
  // A job that runs a while, cancelled while it runs.
  json long_job = tiny_job("wall1", 400, 20);
  json job = c.call_json("POST", "/api/v1/jobs", long_job, 202);
  const std::string id = job["id"];
  for (int i = 0; i < 300 && c.call_json("GET", "/api/v1/jobs/" + id)["state"] != "running"; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  // While it runs, the queue fills up to the limit (8) and no further.
  int queued = 0;
  for (int i = 0; i < 9; ++i) {
    json s = tiny_job("wall1", 20 + i, 0.2);
    auto r = c.call("POST", "/api/v1/jobs", s.dump());
    if (r.status == 202) ++queued;
    else
      EXPECT_EQ(r.status, 429) << r.body;
  }
  EXPECT_EQ(queued, 8);
  json cancelled = c.call_json("POST", "/api/v1/jobs/" + id + "/cancel", nullptr, 202);
  EXPECT_EQ(c.wait_job(id, 60)["state"], "cancelled");
  EXPECT_EQ(c.call("POST", "/api/v1/jobs/" + id + "/cancel").status, 409);
  for (const json& j : c.call_json("GET", "/api/v1/jobs"))
    if (j["state"] == "queued") c.call("POST", "/api/v1/jobs/" + j["id"].get<std::string>() + "/cancel");
  std::string metrics = c.call("GET", "/metrics").body;
  EXPECT_NE(metrics.find("collidoscope_jobs{state=\"cancelled\"}"), std::string::npos);
  EXPECT_NE(metrics.find("collidoscope_queue_length 0"), std::string::npos) << metrics;
}

// The New job page shows where the particles start: placed as the run places
// them, inside the vessel, a pour's released over time; a fill that cannot
// fit is refused before submission, saying how many fit.
TEST_F(ServiceTest, ShowsWhereTheParticlesStart) {
  Client c = client();
  c.sign_up("starter");
  json fill = tiny_job("cylinder:r=5,h=10,caps=bottom", 400, 0.3);
  fill["scene"]["placement"] = {{"kind", "fill"}};
  const json start = c.call_json("POST", "/api/v1/start-preview", fill);
  EXPECT_EQ(start["particles"], 400);
  ASSERT_EQ(start["shown"].size(), 400u);
  ASSERT_EQ(start["release_s"].size(), 400u);
  for (size_t i = 0; i < 400; ++i) {
    const json& p = start["shown"][i];
    ASSERT_EQ(p.size(), 4u);
    EXPECT_LT(std::hypot(p[0].get<double>(), p[1].get<double>()) + 0.5, 5.0) << p;
    EXPECT_GT(p[2].get<double>(), 0.5) << p;
    EXPECT_EQ(p[3], 0.5);
    EXPECT_EQ(start["release_s"][i], 0.0);
  }
  // More than are shown: every k-th, over the whole set.
  json many = fill;
  many["scene"]["particles"]["count"] = 4000;
  many["scene"]["particles"]["radius"] = 0.2;
  const json more = c.call_json("POST", "/api/v1/start-preview", many);
  EXPECT_EQ(more["particles"], 4000);
  EXPECT_EQ(more["shown"].size(), 2000u);  // every 2nd, at most 3,000
  // A pour releases over time.
  const json pour = c.call_json("POST", "/api/v1/start-preview", tiny_job("wall1", 300, 1.0));
  EXPECT_EQ(pour["particles"], 300);
  EXPECT_GT(pour["release_s"].back().get<double>(), 0.0);
  // Too many to fill: refused, with how many fit.
  json crowded = fill;
  crowded["scene"]["particles"]["count"] = 100000;
  const auto r = c.call("POST", "/api/v1/start-preview", crowded.dump());
  EXPECT_EQ(r.status, 400) << r.body;
  EXPECT_NE(r.body.find("holds only"), std::string::npos) << r.body;
  // More than a preview places: the count, none shown, and why.
  const json huge = c.call_json("POST", "/api/v1/start-preview", tiny_job("wall1", 200001, 1.0));
  EXPECT_EQ(huge["particles"], 200001);
  EXPECT_TRUE(huge["shown"].empty());
  EXPECT_EQ(huge.value("note", ""),
            "more than 200000 particles are not placed for a preview; the run places them")
      << huge;
  // Signed out: refused.
  Client anonymous = client();
  EXPECT_EQ(anonymous.call("POST", "/api/v1/start-preview", fill.dump()).status, 401);
}

TEST_F(ServiceTest, AJobThatCanNeverFitIsRefusedWithTheFigures) {
  server_.reset();
  svc_.reset();
  start(/*host_bytes=*/16 << 20);
  Client c = client();
  c.sign_up("big");
  auto r = c.call("POST", "/api/v1/jobs", tiny_job("wall1", 200000, 0.2).dump());
  EXPECT_EQ(r.status, 409) << r.body;
  EXPECT_NE(r.body.find("memory"), std::string::npos) << r.body;
  EXPECT_NE(r.body.find("iB"), std::string::npos) << r.body;  // the figures, in bytes units
  // The prediction answers as the submission would, so the form says so first.
  auto predicted = c.call("POST", "/api/v1/predict", tiny_job("wall1", 200000, 0.2).dump());
  EXPECT_EQ(predicted.status, r.status) << predicted.body;
  EXPECT_EQ(predicted.body, r.body);
  // Where its particles would start is shown all the same (the form's start view).
  EXPECT_EQ(c.call("POST", "/api/v1/predict", tiny_job("wall1", 300, 1.0).dump()).status, 409);
  const json start = c.call_json("POST", "/api/v1/start-preview", tiny_job("wall1", 300, 1.0));
  EXPECT_EQ(start.value("particles", 0), 300) << start.dump();
  EXPECT_FALSE(start.value("shown", json::array()).empty()) << start.dump();
  // Past what a preview places, the note does not promise a run that memory refuses.
  const json huge = c.call_json("POST", "/api/v1/start-preview", tiny_job("wall1", 200001, 1.0));
  EXPECT_TRUE(huge["shown"].empty()) << huge.dump();
  EXPECT_EQ(huge.value("note", ""), "more than 200000 particles are not placed for a preview")
      << huge.dump();
}

// A job the service was stopped on before its run began (while it prepared:
// no run folder yet) starts over at the next start, where resuming would
// fail with "no such run directory"; temporary files a cut write left go.
TEST_F(ServiceTest, AJobStoppedBeforeItsRunBeganStartsOverAtTheNextStart) {
  Client c = client();
  c.sign_up("eve");
  const std::string id = stopped_in_first_attempt(c, false);
  // A write the stop cut short left temporary files; the next start removes them.
  const fs::path job_folder = fs::path(dir_) / "jobs" / id;
  std::ofstream(job_folder / "spec.run.json.tmp-123-0") << "half";
  std::ofstream(fs::path(dir_) / "models" / "7.stl.tmp-123-1") << "half";
  start();
  EXPECT_FALSE(fs::exists(job_folder / "spec.run.json.tmp-123-0"));
  EXPECT_FALSE(fs::exists(fs::path(dir_) / "models" / "7.stl.tmp-123-1"));
  EXPECT_TRUE(fs::exists(job_folder / "spec.json"));
  Client back = client();
  back.token = back.call_json("POST", "/api/v1/sessions",
                              {{"name", "eve"}, {"password", "correct horse"}})["token"];
  const json again = back.wait_job(id);
  EXPECT_EQ(again["state"], "done") << again.dump();
}

// A job cancelled while it ran, whose service stopped before the job did,
// ends cancelled at the next start instead of running again (the request was
// kept only in memory before).
TEST_F(ServiceTest, ACancelAskedBeforeTheServiceStoppedIsKept) {
  Client c = client();
  c.sign_up("fay");
  const std::string id = stopped_in_first_attempt(c, true);
  start();
  Client back = client();
  back.token = back.call_json("POST", "/api/v1/sessions",
                              {{"name", "fay"}, {"password", "correct horse"}})["token"];
  const json j = back.call_json("GET", "/api/v1/jobs/" + id);
  EXPECT_EQ(j["state"], "cancelled") << j.dump();
  EXPECT_EQ(j["attempts"], 1);
}

TEST(OpenApi, DescribesEveryRouteAndNoOther) {
  const json doc = json::parse(openapi_document());
  ASSERT_EQ(doc["openapi"].get<std::string>().substr(0, 2), "3.");
  std::set<std::string> documented, routed;
  for (auto p = doc["paths"].begin(); p != doc["paths"].end(); ++p)
    for (auto m = p->begin(); m != p->end(); ++m) {
      std::string method = m.key();
      for (char& ch : method) ch = char(std::toupper((unsigned char)ch));
      documented.insert(method + " " + p.key());
    }
  for (const RouteInfo& r : route_table())
    routed.insert(r.method + " " + std::regex_replace(r.pattern, std::regex("\\{(\\w+)\\*\\}"), "{$1}"));
  EXPECT_EQ(documented, routed);
}

// The server as its own process, killed with SIGKILL while a job runs: it
// comes back with the job resumed and finished and the database intact.
// The server as its own process, stopped while a job runs: killed with
// SIGKILL, or by Ctrl-C at its terminal (SIGINT to its whole process group,
// which the job must not take for its own stop). It comes back with the job
// resumed and finished and the database intact.
void stopped_server_resumes_its_job(bool ctrl_c) {
  const std::string dir = temp_dir(ctrl_c ? "serve_ctrl_c" : "serve_kill");
  auto start = [&](const std::string& log) {
    const std::string out = dir + "/" + log;
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    std::vector<std::string> args = {COLLIDO_BINARY, "serve", "--port", "0", "--data", dir + "/var",
                                     "--job-threads", "1", "--web", ""};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    // In a process group of its own, as at a terminal (the test is not in it).
    posix_spawnattr_t attr;
    posix_spawnattr_init(&attr);
    posix_spawnattr_setpgroup(&attr, 0);
    posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETPGROUP);
    pid_t pid = 0;
    EXPECT_EQ(posix_spawn(&pid, COLLIDO_BINARY, &fa, &attr, argv.data(), environ), 0);
    posix_spawn_file_actions_destroy(&fa);
    posix_spawnattr_destroy(&attr);
    std::smatch m;
    for (int i = 0; i < 200; ++i) {
      const std::string text = read_file(out);
      if (std::regex_search(text, m, std::regex("serving on (http://127.0.0.1:[0-9]+)")))
        return std::make_pair(pid, m[1].str());
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ADD_FAILURE() << "the server did not start: " << read_file(out);
    return std::make_pair(pid, std::string());
  };
  auto [pid, base] = start("serve1.log");
  ASSERT_FALSE(base.empty());
  Client c(base);
  c.sign_up("kill");
  // Long enough that the first checkpoint (after a second of running, or
  // at the last frame) leaves seconds to run: at 4 s of scene time the job
  // once ran in under a second here, wrote its first checkpoint at its last
  // frame, and finished its video while Ctrl-C reached the server.
  json job = c.call_json("POST", "/api/v1/jobs", tiny_job("wall1", 1500, 16), 202);
  const std::string id = job["id"];
  // Killed once the job has written a checkpoint (about a second of running).
  const std::string checkpoint = dir + "/var/jobs/" + id + "/run/checkpoint.bin";
  for (int i = 0; i < 1200 && !fs::exists(checkpoint); ++i) {
    const json j = c.call_json("GET", "/api/v1/jobs/" + id);
    ASSERT_NE(j["state"], "done") << "the job ended before the kill; make it longer";
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_TRUE(fs::exists(checkpoint));
  if (ctrl_c)
    ::kill(-pid, SIGINT);
  else
    ::kill(pid, SIGKILL);
  ::waitpid(pid, nullptr, 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // its job-exec child dies with it
  auto [pid2, base2] = start("serve2.log");
  ASSERT_FALSE(base2.empty());
  Client c2(base2);
  c2.token = c.token;  // sessions live in the database
  json done = c2.wait_job(id, 240);
  EXPECT_EQ(done["state"], "done") << done.dump();
  EXPECT_EQ(done["attempts"], 2);
  // Resumed, not restarted: the manifest says from which frame.
  json manifest = c2.call_json("GET", "/api/v1/jobs/" + id + "/files/result.json");
  EXPECT_GT(manifest["resumed_from_frame"].get<int>(), 0) << manifest.dump();
  ::kill(pid2, SIGTERM);
  ::waitpid(pid2, nullptr, 0);
  // No half file behind a final name, and the database is sound.
  for (const auto& e : fs::recursive_directory_iterator(dir + "/var/jobs/" + id)) {
    EXPECT_FALSE(is_temp_name(e.path().filename().string())) << e.path();
  }
  for (const json& a : manifest["artifacts"]) {
    const std::string path = a["path"];
    if (path.back() == '/') continue;
    EXPECT_EQ(fs::file_size(dir + "/var/jobs/" + id + "/run/" + path), a["bytes"].get<uint64_t>());
  }
  auto store = open_sqlite_store(dir + "/var/collidoscope.db");
  ASSERT_TRUE(store);
  EXPECT_EQ(*(*store)->integrity_check(), "ok");
}

TEST(ServeProcess, KilledServerResumesItsJob) {
  stopped_server_resumes_its_job(false);
}
TEST(ServeProcess, CtrlCStopsTheServerAndItsJobResumes) {
  stopped_server_resumes_its_job(true);
}

}  // namespace
}  // namespace collido::service
