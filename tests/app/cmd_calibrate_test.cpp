// The calibrate command end to end: a tiny real sweep written as a run log, and its
// argument errors. No wall-clock assertions: the machine running the tests is shared.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "app/cli.h"
#include "app/commands.h"
#include "gvm/csv.h"
#include "gvm/run_log.h"
#include "job/job_log.h"
#include "tests/scratch.h"

namespace collido::app {
namespace {

// calibrate runs each configuration in `collidoscope calibrate-exec`; this test calls the
// command inside its own binary, so it names the real one.
[[maybe_unused]] const bool kExeSet = setenv("COLLIDOSCOPE_EXE", COLLIDO_BINARY, 1) == 0;

std::string tmp(const std::string& name) {
  return test::scratch_path("cmd_calibrate_test_" + name);
}

TEST(CmdCalibrate, BadArgumentsExitTwo) {
  const std::string out = tmp("unused.csv");
  EXPECT_EQ(cmd_calibrate({}), kExitUsage);  // no --out
  EXPECT_EQ(cmd_calibrate({"--out", out, "--backend", "tpu"}), kExitUsage);
  EXPECT_EQ(cmd_calibrate({"--out", out, "--configs", "0"}), kExitUsage);
  EXPECT_EQ(cmd_calibrate({"--out", out, "--configs", "many"}), kExitUsage);
  EXPECT_EQ(cmd_calibrate({"--out", out, "--threads", "-1"}), kExitUsage);
  EXPECT_EQ(cmd_calibrate({"--out", out, "--repeats", "0"}), kExitUsage);
  EXPECT_EQ(cmd_calibrate({"--out", out, "--seed", "x"}), kExitUsage);
  EXPECT_EQ(cmd_calibrate({"--out", out, "--budget", "-1"}), kExitUsage);
  EXPECT_EQ(cmd_calibrate({"--out", out, "--radius", "x"}), kExitUsage);
  EXPECT_EQ(cmd_calibrate({"--out", out, "--radius", "3:0.3"}), kExitUsage);
  EXPECT_EQ(cmd_calibrate({"--out", out, "--radius", "0.3:"}), kExitUsage);
  EXPECT_EQ(cmd_calibrate({"--out", out, "--radius", "0"}), kExitUsage);
  EXPECT_EQ(cmd_calibrate({"--out", out, "--bogus"}), kExitUsage);
  EXPECT_EQ(cmd_calibrate({"--out", out, "extra"}), kExitUsage);
  EXPECT_EQ(cmd_calibrate({"--out"}), kExitUsage);  // --out needs a value
  testing::internal::CaptureStdout();
  EXPECT_EQ(cmd_calibrate({"--help"}), kExitOk);
  testing::internal::GetCapturedStdout();
}

TEST(CmdCalibrate, UnwritableOutputExitsOne) {
  testing::internal::CaptureStderr();
  EXPECT_EQ(cmd_calibrate({"--out", "/nonexistent-dir/runs.csv", "--quick", "--backend", "cpu"}),
            kExitFailure);
  const std::string said = testing::internal::GetCapturedStderr();
  // The file and why it cannot be written.
  EXPECT_NE(said.find("/nonexistent-dir/runs.csv"), std::string::npos) << said;
  EXPECT_NE(said.find("No such file or directory"), std::string::npos) << said;
}

std::vector<gvm::RunRecord> quick_sweep(const std::string& path, const char* configs,
                                        const char* radius = "1") {
  testing::internal::CaptureStdout();
  const int code = cmd_calibrate({"--out", path, "--quick", "--backend", "cpu", "--configs", configs,
                                  "--seed", "7", "--radius", radius});
  testing::internal::GetCapturedStdout();
  EXPECT_EQ(code, kExitOk);
  auto rows = gvm::read_run_log(path);
  EXPECT_TRUE(rows) << rows.status().message();
  return rows ? *rows : std::vector<gvm::RunRecord>{};
}

TEST(CmdCalibrate, QuickSweepWritesARunLog) {
  const auto rows = quick_sweep(tmp("quick.csv"), "5");
  ASSERT_EQ(rows.size(), 5u);
  for (const auto& r : rows) {
    const auto& c = r.config;
    const auto& m = r.measure;
    EXPECT_TRUE(gvm::validate(c)) << gvm::validate(c).message();
    EXPECT_TRUE(gvm::validate(m)) << gvm::validate(m).message();
    EXPECT_EQ(c.backend, gvm::Backend::kCpu);
    EXPECT_FALSE(c.device.empty());
    EXPECT_GE(c.threads, 1);
    EXPECT_GE(c.particles, 100);
    EXPECT_LE(c.particles, 2000);
    EXPECT_LE(c.frames, 3);
    // Division only adds triangles; bin and the reference keep the originals.
    EXPECT_GE(c.triangles, c.triangles_original);
    if (c.method == gvm::Method::kBin || c.method == gvm::Method::kReference) {
      EXPECT_EQ(c.triangles, c.triangles_original);
    }
    // Geometry: r = 1 % of the wall's longest side L, box = the wall's box grown by r,
    // so (2r)^2 (L + 2r) <= box volume <= (L + 2r)^3.
    const double rad = c.radius, side = 102 * rad;
    EXPECT_GT(rad, 0.0);
    EXPECT_GT(c.wall_area, 0.0);
    EXPECT_LE(c.wall_box_volume, side * side * side * (1 + 1e-9));
    EXPECT_GE(c.wall_box_volume, 4 * rad * rad * side * (1 - 1e-9));
    EXPECT_GT(m.time_per_frame_s, 0.0);
    EXPECT_GT(m.total_time_s, 0.0);
    // Time per frame is the median of timed frames that total time does not hold (the
    // run's frames after the first, then extra ones), so no timing relation between the
    // two is exact on a loaded machine; only their presence is checked.
    EXPECT_GT(m.peak_host_bytes, 1e6);  // a process with the engine loaded is megabytes
    EXPECT_EQ(m.peak_device_bytes, 0.0);
    EXPECT_EQ(m.gpu_load, 0.0);
  }
}

// With --radius LO:HI the radius is drawn per configuration, not tied to the wall:
// rows of one wall see different radii, and so different geometry ratios.
TEST(CmdCalibrate, RadiusRangeVariesPerConfiguration) {
  const auto rows = quick_sweep(tmp("radius.csv"), "9", "0.3:3");
  ASSERT_EQ(rows.size(), 9u);
  std::map<int64_t, std::set<double>> radii;  // by wall (its original triangles)
  for (const auto& r : rows) {
    const auto& c = r.config;
    radii[c.triangles_original].insert(c.radius);
    // r = 0.3..3 % of the longest side L: r / 0.03 <= L <= r / 0.003.
    const double lo = c.radius / 0.03 + 2 * c.radius, hi = c.radius / 0.003 + 2 * c.radius;
    EXPECT_LE(c.wall_box_volume, hi * hi * hi * (1 + 1e-9));
    EXPECT_GE(c.wall_box_volume, 4 * c.radius * c.radius * lo * (1 - 1e-9));
  }
  size_t walls_with_two = 0;
  for (const auto& [wall, rs] : radii) walls_with_two += rs.size() >= 2;
  EXPECT_GE(walls_with_two, 1u);
}

TEST(CmdCalibrate, SameSeedSameConfigurations) {
  const auto a = quick_sweep(tmp("seed_a.csv"), "3");
  const auto b = quick_sweep(tmp("seed_b.csv"), "3");
  ASSERT_EQ(a.size(), 3u);
  ASSERT_EQ(b.size(), 3u);
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].config.particles, b[i].config.particles);
    EXPECT_EQ(a[i].config.triangles, b[i].config.triangles);
    EXPECT_EQ(a[i].config.method, b[i].config.method);
    EXPECT_EQ(a[i].config.traversal, b[i].config.traversal);
    EXPECT_EQ(a[i].config.frames, b[i].config.frames);
    EXPECT_EQ(a[i].config.radius, b[i].config.radius);
    EXPECT_EQ(a[i].config.wall_area, b[i].config.wall_area);
    EXPECT_EQ(a[i].config.wall_box_volume, b[i].config.wall_box_volume);
  }
}

// The job path of the commands: a quick job sweep (real jobs through job-exec) writes a
// job log; gvm train makes a job cost model of the committed CPU log; predict prices a
// scene file with it, as text and JSON, and says when the scene lies outside.
TEST(CmdCalibrate, JobSweepTrainAndPredictAScene) {
  const std::string log = tmp("jobs.csv"), model = tmp("job_model.json"), scene = tmp("scene.json"),
                    held_out = tmp("held_out.csv"), work = tmp("jobs_work");
  ASSERT_EQ(cmd_calibrate({"--jobs", "--quick", "--configs", "2", "--repeats", "1", "--no-render",
                           "--out", log, "--work", work}),
            kExitOk);
  auto rows = job::read_job_log(log);
  ASSERT_TRUE(rows) << rows.status().message();
  EXPECT_GE(rows->size(), 1u);
  EXPECT_FALSE(std::filesystem::exists(work)) << "the sweep's own work folder goes with it";

  testing::internal::CaptureStdout();
  const int trained = cmd_gvm({"train", "--logs", std::string(COLLIDO_SOURCE_DIR) +
                               "/bench/data/jobs_cpu.csv", "--out", model, "--epochs", "30",
                               "--hidden", "6", "--folds", "3", "--mlp-epochs", "50",
                               "--predictions", held_out});
  const std::string train_out = testing::internal::GetCapturedStdout();
  ASSERT_EQ(trained, kExitOk) << train_out;
  for (const char* s : {"job log", "validation MAPE", "paper-linear", "least-squares",
                        "mlp-backprop", "interval", "prediction time"})
    EXPECT_NE(train_out.find(s), std::string::npos) << s << "\n" << train_out;
  // The held-out jobs, each with the GVM's interval around its point: the job log's
  // rows (30 % of the log) then three columns a cost.
  auto held = job::read_job_log(held_out);
  ASSERT_TRUE(held) << held.status().message();
  auto all = job::read_job_log(std::string(COLLIDO_SOURCE_DIR) + "/bench/data/jobs_cpu.csv");
  ASSERT_TRUE(all);
  EXPECT_NEAR(double(held->size()), 0.3 * double(all->size()), 2.0);
  std::ifstream in(held_out);
  const std::string held_csv((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::istringstream lines(held_csv);
  std::string header, row;
  std::getline(lines, header);
  std::getline(lines, row);
  EXPECT_NE(header.find(",gvm_total_p10,gvm_total_p50,gvm_total_p90,"), std::string::npos) << header;
  EXPECT_NE(header.find("gvm_output_p90"), std::string::npos) << header;
  // The log's own CSV reader: a wall spec such as "box:x=20,y=20,z=20" is one quoted field.
  auto records = gvm::split_csv(held_csv);
  ASSERT_TRUE(records) << records.status().message();
  ASSERT_GE(records->size(), 2u);
  const std::vector<std::string>& head = (*records)[0].fields;
  const std::vector<std::string>& fields = (*records)[1].fields;
  EXPECT_EQ(fields.size(), head.size());
  for (const std::string cost : {"total", "output"}) {  // the output's are the last three columns
    auto at = [&](const std::string& quantile) {
      const size_t k = size_t(std::find(head.begin(), head.end(), "gvm_" + cost + "_" + quantile) - head.begin());
      return k < fields.size() ? std::stod(fields[k]) : -1.0;
    };
    const double p10 = at("p10"), p50 = at("p50"), p90 = at("p90");
    EXPECT_TRUE(p10 <= p50 && p50 <= p90 && p10 > 0) << cost << ": " << row;
  }
  // Options of the other kind of log are refused, and so are integers past
  // int's range (cast, 4294967297 hidden neurons were 1) or past int64's.
  EXPECT_EQ(cmd_gvm({"train", "--logs", std::string(COLLIDO_SOURCE_DIR) + "/bench/data/jobs_cpu.csv",
                     "--out", model, "--ensemble", "3"}),
            kExitUsage);
  for (const char* hidden : {"4294967297", "1e30", "inf"})
    EXPECT_EQ(
        cmd_gvm({"train", "--logs", std::string(COLLIDO_SOURCE_DIR) + "/bench/data/jobs_cpu.csv",
                 "--out", model, "--hidden", hidden}),
        kExitUsage)
        << hidden;

  // The model replayed on its log in the log's order, alone and at the machine's pace.
  const std::string jobs_log = std::string(COLLIDO_SOURCE_DIR) + "/bench/data/jobs_cpu.csv";
  testing::internal::CaptureStdout();
  ASSERT_EQ(cmd_gvm({"replay", jobs_log, "--model", model}), kExitOk);
  const std::string replay = testing::internal::GetCapturedStdout();
  for (const char* s : {" jobs priced; total time:", "model alone:", "scaled by the pace:", "MAPE"})
    EXPECT_NE(replay.find(s), std::string::npos) << s << "\n" << replay;
  EXPECT_EQ(cmd_gvm({"replay", jobs_log}), kExitUsage);                         // no --model
  EXPECT_EQ(cmd_gvm({"replay", "--model", model}), kExitUsage);                 // no log
  EXPECT_EQ(cmd_gvm({"replay", tmp("absent.csv"), "--model", model}),
            kExitUsage);  // missing: bad input
  EXPECT_EQ(cmd_gvm({"replay", jobs_log, "--model", tmp("absent.json")}), kExitUsage);
  EXPECT_EQ(cmd_gvm({"train", "--logs", tmp("absent.csv"), "--out", tmp("m.json")}), kExitUsage);
  EXPECT_EQ(cmd_predict({tmp("absent-scene.json"), "--model", model}), kExitUsage);

  std::ofstream(scene) << R"({"wall": "wall1", "particles": {"count": 500, "radius": 1},
                              "placement": {"kind": "pour", "rate": 500}, "duration": 1,
                              "fps": 10, "backend": "cpu"})";
  testing::internal::CaptureStdout();
  ASSERT_EQ(cmd_predict({scene, "--model", model}), kExitOk);
  const std::string text = testing::internal::GetCapturedStdout();
  for (const char* s : {"total", "per frame", "host", "p10", "p90"})
    EXPECT_NE(text.find(s), std::string::npos) << s << "\n" << text;

  testing::internal::CaptureStdout();
  ASSERT_EQ(cmd_predict({scene, "--model", model, "--json", "--particles-out-of-range-check"}),
            kExitUsage);  // unknown flag
  testing::internal::GetCapturedStdout();

  std::ofstream(scene) << R"({"wall": "wall1", "particles": {"count": 300000, "radius": 0.5},
                              "duration": 1, "fps": 10, "backend": "cpu"})";
  testing::internal::CaptureStdout();
  ASSERT_EQ(cmd_predict({scene, "--model", model, "--json"}), kExitOk);
  const std::string js = testing::internal::GetCapturedStdout();
  EXPECT_NE(js.find("\"outside_training\": true"), std::string::npos) << js;
  EXPECT_NE(js.find("\"p90\""), std::string::npos) << js;

  // A job model refuses a detection config, and a missing model says how to make one.
  std::ofstream(scene) << R"({"particles": 1000, "triangles": 156, "method": "bin"})";
  EXPECT_EQ(cmd_predict({scene, "--model", model}), kExitUsage);
}

}  // namespace
}  // namespace collido::app
