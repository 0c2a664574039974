// The committed calibration logs (bench/data/) against the predictor's targets: trained
// with the default options and split, the GVM must miss time per frame by <= 15 % and
// peak memory by <= 5 % (validation MAPE) and miss both by less than every baseline.
// Training is seeded and deterministic, so this is the figure docs/benchmarks.md gives,
// re-measured by every build; a change to the trainer or the features that loses
// accuracy on real runs fails here.
#include <gtest/gtest.h>

#include <string>

#include "gvm/evaluate.h"

namespace collido::gvm {
namespace {

const std::string kData = COLLIDO_BENCH_DATA;

Comparison compare(const std::string& log) {
  auto rows = read_run_log(kData + "/" + log);
  EXPECT_TRUE(rows) << rows.status().message();
  if (!rows) return {};
  EXPECT_GE(rows->size(), 100u);  // the issue asks for at least 100 real configurations
  auto cmp = train_and_compare(*rows, CompareOptions{});
  EXPECT_TRUE(cmp) << cmp.status().message();
  return cmp ? std::move(*cmp) : Comparison{};
}

// Index of each output in ErrorRow (measure_names() order).
constexpr size_t kTimePerFrame = 0, kHostBytes = 2;

TEST(CalibrationLog, CpuLogMeetsTheTargets) {
  const Comparison c = compare("calibration_cpu.csv");
  ASSERT_EQ(c.scores.size(), 4u);
  const ModelScore& gvm = c.scores[0];
  ASSERT_EQ(gvm.name, "gvm");
  EXPECT_LE(gvm.validation[kTimePerFrame].mape_percent, 15.0);
  EXPECT_LE(gvm.validation[kHostBytes].mape_percent, 5.0);
  for (size_t m = 1; m < c.scores.size(); ++m)
    for (size_t k : {kTimePerFrame, kHostBytes})
      EXPECT_LT(gvm.validation[k].mape_percent, c.scores[m].validation[k].mape_percent)
          << "output " << measure_names()[k] << " against " << c.scores[m].name;
}

// The GPU log is measured on the H100 and trained anywhere. Its figures are in
// docs/benchmarks.md; here only that it trains and predicts every output it has.
TEST(CalibrationLog, GpuLogTrainsEveryOutput) {
  const Comparison c = compare("calibration_cuda.csv");
  ASSERT_EQ(c.scores.size(), 4u);
  for (size_t k = 0; k < kOutputCount; ++k) {
    EXPECT_GT(c.scores[0].validation[k].rows, 0u) << measure_names()[k];
    EXPECT_LT(c.scores[0].validation[k].mape_percent, 50.0) << measure_names()[k];
  }
}

}  // namespace
}  // namespace collido::gvm
