// The `gvm` and `predict` commands end to end: exit codes, files written, output.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>

#include "app/cli.h"
#include "app/commands.h"
#include "gvm/csv.h"
#include "gvm/evaluate.h"
#include "gvm/run_log.h"
#include "tests/scratch.h"

namespace collido::app {
namespace {

std::string tmp(const std::string& name) {
  return test::scratch_path("cmd_gvm_test_" + name);
}

std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Runs f with stdout captured; returns {exit code, stdout}.
template <class F>
std::pair<int, std::string> run(F f) {
  testing::internal::CaptureStdout();
  const int code = f();
  std::fflush(stdout);
  return {code, testing::internal::GetCapturedStdout()};
}

TEST(CmdGvm, BadArgumentsExitTwo) {
  EXPECT_EQ(run([] { return cmd_gvm({}); }).first, kExitUsage);
  EXPECT_EQ(cmd_gvm({"fit"}), kExitUsage);
  EXPECT_EQ(cmd_gvm({"train"}), kExitUsage);                     // no --logs
  EXPECT_EQ(cmd_gvm({"train", "--logs", "x.csv"}), kExitUsage);  // no --out
  EXPECT_EQ(cmd_gvm({"train", "--logs", "x", "--out", "y", "--hidden", "many"}), kExitUsage);
  EXPECT_EQ(cmd_gvm({"train", "--logs", "x", "--out", "y", "--epochs", "0"}), kExitUsage);
  EXPECT_EQ(cmd_gvm({"train", "--logs", "x", "--out", "y", "--delta", "2"}), kExitUsage);
  EXPECT_EQ(cmd_gvm({"train", "--logs", "x", "--out", "y", "--activation", "relu"}), kExitUsage);
  EXPECT_EQ(cmd_gvm({"train", "--logs", "x", "--out", "y", "--bogus"}), kExitUsage);
  EXPECT_EQ(cmd_gvm({"synth", "--rows", "10"}), kExitUsage);
  EXPECT_EQ(cmd_predict({}), kExitUsage);
  // A detection-frame config names its model: without --model it is a usage error.
  const std::string config = tmp("usage_config.json");
  std::ofstream(config) << R"({"particles": 1000, "triangles": 156, "method": "bin"})";
  EXPECT_EQ(cmd_predict({config}), kExitUsage);
  // Job-only flags make no sense for a detection config.
  EXPECT_EQ(cmd_predict({config, "--model", "m.json", "--duration", "2"}), kExitUsage);
  EXPECT_EQ(run([] { return cmd_gvm({"train", "--help"}); }).first, kExitOk);
  EXPECT_EQ(run([] { return cmd_predict({"--help"}); }).first, kExitOk);
}

// Missing files are bad input, exit 2 as for every command (README).
TEST(CmdGvm, MissingFilesExitTwo) {
  EXPECT_EQ(cmd_gvm({"train", "--logs", tmp("absent.csv"), "--out", tmp("m.json")}), kExitUsage);
  EXPECT_EQ(cmd_predict({tmp("absent.json"), "--model", tmp("absent-model.json")}), kExitUsage);
  EXPECT_EQ(cmd_predict({tmp("absent.json")}), kExitUsage);  // what it is cannot be read
}

// A device name with a line break is one quoted field over two lines: the
// predictions written beside each validation row stay on that row's record.
TEST(CmdGvm, PredictionsStayOnTheirRowWhereAFieldBreaksTheLine) {
  const std::string log = tmp("broken_names.csv"), model = tmp("broken_model.json"),
                    predictions = tmp("broken_predictions.csv");
  ASSERT_EQ(run([&] { return cmd_gvm({"synth", "--out", log, "--rows", "60"}); }).first, kExitOk);
  auto rows = gvm::read_run_log(log);
  ASSERT_TRUE(rows) << rows.status().message();
  for (size_t i = 0; i < rows->size(); i += 2) (*rows)[i].config.device = "card\nrevision \"b\"";
  ASSERT_TRUE(gvm::write_run_log(log, *rows));
  auto train = run([&] {
    return cmd_gvm({"train", "--logs", log, "--out", model, "--epochs", "10", "--mlp-epochs", "20",
                    "--predictions", predictions});
  });
  ASSERT_EQ(train.first, kExitOk) << train.second;
  auto records = gvm::split_csv(slurp(predictions));
  ASSERT_TRUE(records) << records.status().message();
  ASSERT_EQ(records->size(), 19u);  // the header and 30 % of 60 rows
  const size_t columns = (*records)[0].fields.size();
  for (const auto& r : *records) EXPECT_EQ(r.fields.size(), columns) << "line " << r.line;
  EXPECT_NE(slurp(predictions).find("card\nrevision"), std::string::npos);
}

TEST(CmdGvm, SynthTrainPredict) {
  const std::string log = tmp("runs.csv"), model = tmp("model.json"), curve = tmp("curve.csv"),
                    predictions = tmp("predictions.csv");
  auto synth = run([&] { return cmd_gvm({"synth", "--out", log, "--rows", "100"}); });
  ASSERT_EQ(synth.first, kExitOk) << synth.second;
  auto train = run([&] {
    return cmd_gvm({"train", "--logs", log, "--out", model, "--epochs", "40", "--mlp-epochs", "100",
                    "--curve", curve, "--predictions", predictions});
  });
  ASSERT_EQ(train.first, kExitOk) << train.second;
  for (const char* s : {"70 train, 30 validation", "validation MAPE", "gvm", "paper-linear",
                        "least-squares", "mlp-backprop", "prediction time", "trained in"})
    EXPECT_NE(train.second.find(s), std::string::npos) << s;
  const std::string c = slurp(curve);
  EXPECT_EQ(c.rfind("epoch,train_loss,validation_loss,acceptance\n", 0), 0u);
  EXPECT_EQ(std::count(c.begin(), c.end(), '\n'), 41);
  // The validation rows as run-log rows, then each model's prediction of each output.
  auto rows = gvm::read_run_log(predictions);
  ASSERT_TRUE(rows) << rows.status().message();
  EXPECT_EQ(rows->size(), 30u);
  const std::string p = slurp(predictions);
  const std::string header = p.substr(0, p.find('\n'));
  for (const char* col : {"gvm_time_per_frame_s", "mlp-backprop_peak_host_bytes",
                          "paper-linear_gpu_load", "least-squares_total_time_s"})
    EXPECT_NE(header.find(col), std::string::npos) << col;

  // Merging a log with itself changes nothing but the row count read.
  const std::string merged = tmp("merged.csv");
  auto merge = run([&] { return cmd_gvm({"merge", log, log, "--out", merged}); });
  ASSERT_EQ(merge.first, kExitOk) << merge.second;
  EXPECT_NE(merge.second.find("200 rows from 2 logs -> 100 configurations"), std::string::npos)
      << merge.second;
  EXPECT_EQ(slurp(merged), slurp(log));
  EXPECT_EQ(cmd_gvm({"merge", "--out", merged}), kExitUsage);  // no logs
  EXPECT_EQ(cmd_gvm({"merge", log, "--out", merged, "/nonexistent.csv"}), kExitUsage);

  const std::string config = tmp("config.json");
  std::ofstream(config) << R"({"particles": 1e9, "triangles": 5000, "method": "gravity",
                               "traversal": "particle", "frames": 10, "backend": "cuda",
                               "radius": 1, "wall_area": 4e4, "wall_box_volume": 1e6})";
  auto pred = run([&] { return cmd_predict({config, "--model", model}); });
  ASSERT_EQ(pred.first, kExitOk) << pred.second;
  EXPECT_NE(pred.second.find("time per frame"), std::string::npos);
  EXPECT_NE(pred.second.find("warning: particles = 1000000000 is above"), std::string::npos)
      << pred.second;
  auto js = run([&] { return cmd_predict({config, "--model", model, "--json"}); });
  ASSERT_EQ(js.first, kExitOk);
  EXPECT_NE(js.second.find("\"in_range\": false"), std::string::npos) << js.second;

  std::ofstream(config) << R"({"particles": 100, "method": "gravity"})";
  EXPECT_EQ(cmd_predict({config, "--model", model}), kExitUsage);  // lacks "triangles"

  // A scene file is a simulation, which the detection-frame model does not cost.
  std::ofstream(config) << R"({"wall": "wall1", "particles": {"count": 3000, "radius": 1}})";
  testing::internal::CaptureStderr();
  EXPECT_EQ(cmd_predict({config, "--model", model}), kExitUsage);
  EXPECT_NE(testing::internal::GetCapturedStderr().find("scene file"), std::string::npos);
}

}  // namespace
}  // namespace collido::app
