// The calibration sweep through the library (job/calibrate.h): every configuration in a
// `collidoscope calibrate-exec` child, rows in the run-log format, cancellation, and the
// child's answer. No wall-clock assertions: the machine running the tests is shared.
#include "job/calibrate.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "gvm/run_log.h"
#include "tests/scratch.h"

namespace collido::job {
namespace {

using json = nlohmann::json;

std::string tmp(const std::string& name) {
  return test::scratch_path("calibrate_test_" + name + ".csv");
}

CalibrateSpec quick_spec(const std::string& out, int64_t configs) {
  CalibrateSpec s = calibrate_defaults("cpu", /*quick=*/true);
  s.configs = configs;
  s.repeats = 1;
  s.threads = 1;
  s.seed = 3;
  s.out_path = out;
  s.executable = COLLIDO_BINARY;
  return s;
}

TEST(Calibrate, QuickSweepWritesRunLogRows) {
  const std::string out = tmp("quick");
  std::vector<CalibrateProgress> seen;
  std::vector<std::string> notes;
  CalibrateHooks hooks;
  hooks.progress = [&](const CalibrateProgress& p) { seen.push_back(p); };
  hooks.note = [&](const std::string& n) { notes.push_back(n); };
  const auto summary = calibrate(quick_spec(out, 2), hooks);
  ASSERT_TRUE(summary) << summary.status().message();
  EXPECT_EQ(summary->backend, "cpu");
  EXPECT_EQ(summary->configs, 2u);
  EXPECT_EQ(summary->measured, 2u);
  EXPECT_EQ(summary->failed, 0u);
  EXPECT_FALSE(notes.empty());  // the plan

  // Each run is reported as it starts and when it ends, in order.
  ASSERT_EQ(seen.size(), 4u);
  for (size_t i = 0; i < seen.size(); ++i) {
    const CalibrateProgress& p = seen[i];
    EXPECT_EQ(p.index, i / 2 + 1);
    EXPECT_EQ(p.count, 2u);
    EXPECT_EQ(p.pass, 1);
    EXPECT_EQ(p.finished, i % 2 == 1);
    EXPECT_FALSE(p.running.empty());
    if (p.finished) {
      EXPECT_TRUE(p.error.empty()) << p.error;
      EXPECT_EQ(p.rows, i / 2 + 1);
      EXPECT_GT(p.frame_s, 0.0);
      EXPECT_GT(p.peak_host_bytes, 0.0);
    }
  }

  auto rows = gvm::read_run_log(out);
  ASSERT_TRUE(rows) << rows.status().message();
  ASSERT_EQ(rows->size(), 2u);
  for (const auto& r : *rows) {
    EXPECT_TRUE(gvm::validate(r.config)) << gvm::validate(r.config).message();
    EXPECT_TRUE(gvm::validate(r.measure)) << gvm::validate(r.measure).message();
    EXPECT_EQ(r.config.backend, gvm::Backend::kCpu);
    EXPECT_EQ(r.config.threads, 1);
    EXPECT_GT(r.measure.time_per_frame_s, 0.0);
    EXPECT_GT(r.measure.total_time_s, 0.0);
    EXPECT_GT(r.measure.peak_host_bytes, 1e6);  // a process with the engine loaded
    EXPECT_EQ(r.measure.peak_device_bytes, 0.0);
  }
}

// The peak memory of a row is its run's own process's, not the caller's: Linux hands
// a spawned child the parent's peak in wait4(), so a caller holding much memory (a
// service worker) must not see it in every row.
TEST(Calibrate, PeakMemoryIsTheRunsOwn) {
  const size_t held = size_t(512) << 20;
  std::vector<char> ballast(held);
  std::memset(ballast.data(), 1, ballast.size());  // resident, not only reserved
  const std::string out = tmp("peak");
  const auto summary = calibrate(quick_spec(out, 1), {});
  ASSERT_TRUE(summary) << summary.status().message();
  auto rows = gvm::read_run_log(out);
  ASSERT_TRUE(rows) << rows.status().message();
  ASSERT_EQ(rows->size(), 1u);
  EXPECT_GT((*rows)[0].measure.peak_host_bytes, 1e6);
  // A quick configuration (<= 2000 particles) needs tens of MiB at most.
  EXPECT_LT((*rows)[0].measure.peak_host_bytes, double(held));
  EXPECT_EQ(ballast[held / 2], 1);
}

TEST(Calibrate, CancelledSweepStops) {
  const std::string out = tmp("cancel");
  std::atomic<bool> cancel{false};
  int started = 0;
  CalibrateHooks hooks;
  hooks.cancel = &cancel;
  // Cancel as the first run starts: its child is killed and no other starts.
  hooks.progress = [&](const CalibrateProgress& p) {
    if (!p.finished) ++started, cancel = true;
  };
  const auto summary = calibrate(quick_spec(out, 4), hooks);
  ASSERT_FALSE(summary);
  EXPECT_EQ(summary.status().code(), ErrorCode::kCancelled) << summary.status().message();
  EXPECT_EQ(started, 1);
  auto rows = gvm::read_run_log(out);  // the log stays readable: what was measured, here none
  ASSERT_TRUE(rows) << rows.status().message();
  EXPECT_TRUE(rows->empty());

  // Cancelled before it starts: the wall survey's child is stopped too.
  const auto before = calibrate(quick_spec(tmp("cancel_before"), 2), hooks);
  ASSERT_FALSE(before);
  EXPECT_EQ(before.status().code(), ErrorCode::kCancelled);
}

TEST(Calibrate, BadSpecsAreRefusedBeforeAnyRun) {
  CalibrateSpec s = quick_spec(tmp("bad"), 2);
  s.configs = 0;
  EXPECT_EQ(calibrate(s, {}).status().code(), ErrorCode::kInvalidArgument);
  s = quick_spec(tmp("bad"), 2);
  s.radius_lo_pct = 3, s.radius_hi_pct = 0.3;
  EXPECT_EQ(calibrate(s, {}).status().code(), ErrorCode::kInvalidArgument);
  s = quick_spec(tmp("bad"), 2);
  s.backend = "tpu";
  EXPECT_EQ(calibrate(s, {}).status().code(), ErrorCode::kInvalidArgument);
  s = quick_spec(tmp("bad"), 2);
  s.executable.clear();
  EXPECT_EQ(calibrate(s, {}).status().code(), ErrorCode::kInvalidArgument);
  // An executable that is not there: an error, not a crash or a hang.
  s = quick_spec(tmp("bad"), 2);
  s.executable = "/nonexistent/collidoscope";
  const auto r = calibrate(s, {});
  ASSERT_FALSE(r);
  EXPECT_EQ(r.status().code(), ErrorCode::kBackend) << r.status().message();
  // An output that cannot be written: before the first run.
  s = quick_spec("/nonexistent-dir/runs.csv", 2);
  EXPECT_EQ(calibrate(s, {}).status().code(), ErrorCode::kIo);
}

// The child's side, in this process: one JSON line whatever the request.
TEST(Calibrate, ExecAnswersOneJsonLine) {
  std::string line;
  Status s = calibrate_exec(R"({"task": "run", "wall": "wall1", "r_max": 0.8, "method": "bin",
                                "traversal": "particle", "particles": 200, "frames": 2,
                                "backend": "cpu", "threads": 1, "seed": 5})",
                            &line);
  ASSERT_TRUE(s) << s.message();
  ASSERT_FALSE(line.empty());
  EXPECT_EQ(line.back(), '\n');
  EXPECT_EQ(line.find('\n'), line.size() - 1);
  json j = json::parse(line);
  EXPECT_TRUE(j.at("ok").get<bool>());
  EXPECT_EQ(j.at("triangles_original").get<int64_t>(), 156);  // wall1 (paper §5.4)
  EXPECT_GT(j.at("frame_s").get<double>(), 0.0);
  EXPECT_GT(j.at("peak_host_bytes").get<double>(), 0.0);

  for (const char* bad : {"not json", "[1, 2]", R"({"task": "dance"})",
                          R"({"task": "run", "wall": "wall1"})",
                          R"({"task": "run", "wall": "no-such-wall", "r_max": 1, "method": "bin",
                              "traversal": "particle", "particles": 10, "frames": 1,
                              "backend": "cpu", "threads": 1, "seed": 1})"}) {
    s = calibrate_exec(bad, &line);
    EXPECT_FALSE(s) << bad;
    j = json::parse(line);
    EXPECT_FALSE(j.at("ok").get<bool>()) << bad;
    EXPECT_FALSE(j.at("error").get<std::string>().empty()) << bad;
  }
}

}  // namespace
}  // namespace collido::job
