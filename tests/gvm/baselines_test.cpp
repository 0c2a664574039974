// Baselines and the held-out comparison: each baseline recovers data of its own form,
// and the split and error measure behave.
#include "gvm/baselines.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "gvm/evaluate.h"

namespace collido::gvm {
namespace {

RunRecord row(int64_t particles, int64_t triangles, double tpf, Backend b = Backend::kCpu) {
  RunRecord r;
  r.config.particles = particles;
  r.config.triangles = triangles;
  r.config.triangles_original = triangles;
  r.config.method = Method::kCircumcircle;
  r.config.traversal = Traversal::kParticle;
  r.config.frames = 10;
  r.config.backend = b;
  r.config.device = "dev";
  r.config.threads = 4;
  r.measure.time_per_frame_s = tpf;
  r.measure.total_time_s = 10 * tpf;
  r.measure.peak_host_bytes = 1e6 + 100.0 * particles;
  r.measure.peak_device_bytes = b == Backend::kCuda ? 5e5 + 10.0 * triangles : 0.0;
  r.measure.gpu_load = b == Backend::kCuda ? 0.5 : 0.0;
  return r;
}

TEST(PaperLinearFit, RecoversAPerParticleCountLine) {
  // The paper's Eqs. 9-10: t5 = 2.477e-9 ntri + 0.2712 at 1e5 particles and
  // t6 = 2.078e-5 ntri + 1.8970 at 1e6 particles.
  std::vector<RunRecord> rows;
  for (int64_t t : {1000, 50000, 120000, 250000}) {
    rows.push_back(row(100000, t, 2.477e-9 * t + 0.2712));
    rows.push_back(row(1000000, t, 2.078e-5 * t + 1.8970));
  }
  auto fit = PaperLinearFit::fit(rows);
  ASSERT_TRUE(fit);
  EXPECT_EQ(fit->groups(), 2u);
  RunConfig c = rows[0].config;
  c.triangles = 200000;
  EXPECT_NEAR(fit->predict(c).time_per_frame_s, 2.477e-9 * 200000 + 0.2712, 1e-9);
  EXPECT_NEAR(fit->predict(c).total_time_s, 10 * (2.477e-9 * 200000 + 0.2712), 1e-8);
  c.particles = 1000000;
  EXPECT_NEAR(fit->predict(c).time_per_frame_s, 2.078e-5 * 200000 + 1.8970, 1e-7);
  c.particles = 800000;  // untrained count: the nearest in log10 (1e6) answers
  EXPECT_NEAR(fit->predict(c).time_per_frame_s, 2.078e-5 * 200000 + 1.8970, 1e-7);
  EXPECT_FALSE(PaperLinearFit::fit({}));
}

TEST(LeastSquaresFit, RecoversAPowerLaw) {
  // t = 1e-9 * P * T^0.5 is linear in the log features.
  std::vector<RunRecord> rows;
  for (int64_t p : {100, 1000, 10000, 100000})
    for (int64_t t : {200, 3000, 40000})
      rows.push_back(row(p, t, 1e-9 * p * std::sqrt(static_cast<double>(t))));
  auto fit = LeastSquaresFit::fit(rows, FeatureSpace::from_rows(rows));
  ASSERT_TRUE(fit) << fit.status().message();
  RunConfig c = rows[0].config;
  c.particles = 5000;
  c.triangles = 1000;
  c.triangles_original = 1000;
  EXPECT_NEAR(fit->predict(c).time_per_frame_s / (1e-9 * 5000 * std::sqrt(1000.0)), 1.0, 1e-6);
  EXPECT_EQ(fit->predict(c).peak_device_bytes, 0.0);  // CPU
}

TEST(MlpFit, LearnsASmoothLogLogRelation) {
  std::vector<RunRecord> rows;
  for (int64_t p : {100, 300, 1000, 3000, 10000, 30000, 100000})
    for (int64_t t : {200, 2000, 20000})
      rows.push_back(row(p, t, 1e-9 * p * std::sqrt(static_cast<double>(t)), Backend::kCuda));
  MlpOptions opt;
  opt.epochs = 2000;
  auto fit = MlpFit::fit(rows, FeatureSpace::from_rows(rows), opt);
  ASSERT_TRUE(fit);
  auto err = mean_abs_percent_error(rows, [&](const RunConfig& c) { return fit->predict(c); });
  EXPECT_LT(err[0].mape_percent, 15.0);
}

TEST(Evaluate, SplitIsSeventyThirtyDisjointAndSeeded) {
  auto rows = synthetic_run_log(100, 3);
  auto a = split_rows(rows, 0.7, 5), b = split_rows(rows, 0.7, 5), c = split_rows(rows, 0.7, 6);
  ASSERT_TRUE(a && b && c);
  EXPECT_EQ(a->train.size(), 70u);
  EXPECT_EQ(a->validation.size(), 30u);
  std::set<double> seen;
  for (const auto* side : {&a->train, &a->validation})
    for (const auto& r : *side) seen.insert(r.measure.total_time_s);
  EXPECT_EQ(seen.size(), 100u);
  for (size_t i = 0; i < 70; ++i)
    EXPECT_EQ(a->train[i].measure.total_time_s, b->train[i].measure.total_time_s);
  bool differs = false;
  for (size_t i = 0; i < 70; ++i)
    differs |= a->train[i].measure.total_time_s != c->train[i].measure.total_time_s;
  EXPECT_TRUE(differs);
  EXPECT_FALSE(split_rows(synthetic_run_log(3, 1), 0.7, 1));
  EXPECT_FALSE(split_rows(rows, 1.0, 1));
}

TEST(Evaluate, PercentErrorSkipsZeroTruth) {
  std::vector<RunRecord> rows = {row(10, 10, 1.0), row(10, 10, 2.0, Backend::kCuda)};
  auto err = mean_abs_percent_error(rows, [](const RunConfig& c) {
    RunMeasure m;
    m.time_per_frame_s = 1.5;
    m.gpu_load = c.backend == Backend::kCuda ? 0.25 : 0.0;
    return m;
  });
  EXPECT_DOUBLE_EQ(err[0].mape_percent, 100.0 * (0.5 / 1.0 + 0.5 / 2.0) / 2);
  EXPECT_EQ(err[0].rows, 2u);
  EXPECT_EQ(err[4].rows, 1u);  // the CPU row's GPU load is 0: no percentage
  EXPECT_DOUBLE_EQ(err[4].mape_percent, 50.0);
  EXPECT_DOUBLE_EQ(err[4].mean_abs, 0.25);
}

TEST(Evaluate, CompareScoresEveryModelOnTheSameSplit) {
  CompareOptions opt;
  opt.gvm.epochs = 100;
  opt.mlp.epochs = 300;
  auto cmp = train_and_compare(synthetic_run_log(100, 2), opt);
  ASSERT_TRUE(cmp) << cmp.status().message();
  ASSERT_EQ(cmp->scores.size(), 4u);
  EXPECT_EQ(cmp->scores[0].name, "gvm");
  EXPECT_EQ(cmp->split.train.size(), 70u);
  EXPECT_EQ(cmp->gvm_report.curve.size(), 100u);
  for (const auto& s : cmp->scores)
    for (size_t k = 0; k < 3; ++k) {  // time, total, host bytes: every row counts
      EXPECT_EQ(s.validation[k].rows, 30u) << s.name;
      EXPECT_TRUE(std::isfinite(s.validation[k].mape_percent)) << s.name;
    }
}

}  // namespace
}  // namespace collido::gvm
