#include "gvm/evaluate.h"

#include <chrono>
#include <cmath>
#include <limits>

#include "gvm/rng.h"

namespace collido::gvm {

Expected<RowSplit> split_rows(const std::vector<RunRecord>& rows, double train_fraction,
                              uint64_t seed) {
  if (rows.size() < 4)
    return invalid_argument("need at least 4 rows to split, got " + std::to_string(rows.size()));
  if (!(train_fraction > 0.0 && train_fraction < 1.0))
    return invalid_argument("train fraction must be in (0, 1)");
  std::vector<size_t> idx(rows.size());
  for (size_t i = 0; i < idx.size(); ++i) idx[i] = i;
  Rng rng(seed);
  rng.shuffle(idx);
  const size_t n_train = static_cast<size_t>(std::llround(train_fraction * rows.size()));
  if (n_train < 2 || n_train >= rows.size())
    return invalid_argument("train fraction leaves too few rows on one side");
  RowSplit s;
  for (size_t i = 0; i < idx.size(); ++i)
    (i < n_train ? s.train : s.validation).push_back(rows[idx[i]]);
  return s;
}

ErrorRow mean_abs_percent_error(const std::vector<RunRecord>& rows,
                                const std::function<RunMeasure(const RunConfig&)>& predict) {
  ErrorRow e{};
  double sum[kOutputCount] = {}, abs_sum[kOutputCount] = {};
  for (const auto& r : rows) {
    double truth[kOutputCount], pred[kOutputCount];
    measure_to_array(r.measure, truth);
    measure_to_array(predict(r.config), pred);
    for (size_t k = 0; k < kOutputCount; ++k) {
      if (truth[k] == 0.0) continue;
      sum[k] += std::abs(pred[k] - truth[k]) / std::abs(truth[k]);
      abs_sum[k] += std::abs(pred[k] - truth[k]);
      ++e[k].rows;
    }
  }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (size_t k = 0; k < kOutputCount; ++k) {
    e[k].mape_percent = e[k].rows ? 100.0 * sum[k] / e[k].rows : nan;
    e[k].mean_abs = e[k].rows ? abs_sum[k] / e[k].rows : nan;
  }
  return e;
}

Expected<Comparison> train_and_compare(const std::vector<RunRecord>& rows,
                                       const CompareOptions& opt) {
  auto split = split_rows(rows, opt.train_fraction, opt.split_seed);
  if (!split) return split.status();
  Comparison c;
  c.split = std::move(*split);
  const auto& tr = c.split.train;
  const auto& va = c.split.validation;
  auto gvm = ResourcePredictor::train(tr, va, opt.gvm, &c.gvm_report);
  if (!gvm) return gvm.status();
  c.gvm = std::move(*gvm);
  auto score = [&](std::string name, double seconds, auto predict) {
    ModelScore s{std::move(name),
                 mean_abs_percent_error(tr, predict),
                 mean_abs_percent_error(va, predict),
                 seconds,
                 {}};
    s.validation_predictions.reserve(va.size());
    for (const auto& r : va) s.validation_predictions.push_back(predict(r.config));
    c.scores.push_back(std::move(s));
  };
  score("gvm", c.gvm_report.seconds, [&](const RunConfig& x) { return c.gvm.predict_measure(x); });

  using clock = std::chrono::steady_clock;
  auto since = [](clock::time_point t0) {
    return std::chrono::duration<double>(clock::now() - t0).count();
  };
  auto t0 = clock::now();
  auto lin = PaperLinearFit::fit(tr);
  if (!lin) return lin.status();
  score("paper-linear", since(t0), [&](const RunConfig& x) { return lin->predict(x); });

  t0 = clock::now();
  auto ls = LeastSquaresFit::fit(tr, c.gvm.features());
  if (!ls) return ls.status();
  score("least-squares", since(t0), [&](const RunConfig& x) { return ls->predict(x); });

  t0 = clock::now();
  auto mlp = MlpFit::fit(tr, c.gvm.features(), opt.mlp);
  if (!mlp) return mlp.status();
  score("mlp-backprop", since(t0), [&](const RunConfig& x) { return mlp->predict(x); });
  return c;
}

std::vector<RunRecord> synthetic_run_log(size_t rows, uint64_t seed) {
  Rng rng(seed);
  std::vector<RunRecord> out;
  for (size_t r = 0; r < rows; ++r) {
    RunRecord rec;
    RunConfig& c = rec.config;
    c.particles = std::llround(std::pow(10.0, rng.uniform(2.0, 6.0)));
    c.triangles_original = std::llround(std::pow(10.0, rng.uniform(2.0, 3.5)));
    c.method = kAllMethods[rng.below(4)];  // the brute-force reference is too slow to log
    // Division multiplies triangles by a factor set by mesh size over particle radius.
    const double split = std::pow(10.0, rng.uniform(0.0, 2.5));
    const double factor = c.method == Method::kGravity        ? split
                          : c.method == Method::kCircumcircle ? 0.45 * split
                          : c.method == Method::kMidpoint4    ? 1.3 * split
                                                              : 1.0;
    c.triangles =
        std::max<int64_t>(c.triangles_original, std::llround(c.triangles_original * factor));
    // Geometry of a wall of that size (this synthetic cost model does not use it).
    c.radius = 1.0;
    c.wall_area = 40.0 * static_cast<double>(c.triangles_original);
    c.wall_box_volume = 0.5 * std::pow(c.wall_area, 1.5);
    c.traversal = rng.below(2) ? Traversal::kParticle : Traversal::kWall;
    c.frames = std::llround(std::pow(10.0, rng.uniform(0.0, 2.5)));
    c.backend = rng.below(2) ? Backend::kCuda : Backend::kCpu;
    c.device = c.backend == Backend::kCuda ? "synthetic-gpu" : "synthetic-cpu";
    c.threads = c.backend == Backend::kCuda ? 1 : 16;
    const double P = static_cast<double>(c.particles), T = static_cast<double>(c.triangles);
    const bool gpu = c.backend == Backend::kCuda;
    // Per frame: sort/grid work linear in P and T, plus pair tests that grow with the
    // triangle density per cell; the wall traversal pays for load imbalance.
    const double pair = P * std::sqrt(T) * 2e-10 * (c.traversal == Traversal::kWall ? 1.6 : 1.0);
    double t = (gpu ? 0.02 : 1.0) * (3e-8 * P + 1e-8 * T + pair) + (gpu ? 2e-4 : 1e-5);
    if (c.method == Method::kBin) t *= 0.8;
    const double noise = std::pow(10.0, rng.uniform(-0.02, 0.02));
    RunMeasure& m = rec.measure;
    m.time_per_frame_s = t * noise;
    m.total_time_s = (0.05 + 2e-7 * T + (gpu ? 0.3 : 0.0)) + c.frames * m.time_per_frame_s;
    m.peak_host_bytes = (60e6 + 40.0 * P + 90.0 * T) * std::pow(10.0, rng.uniform(-0.01, 0.01));
    m.peak_device_bytes = gpu ? 300e6 + 36.0 * P + 64.0 * T : 0.0;
    m.gpu_load = gpu ? std::min(0.98, 0.95 * (1.0 - std::exp(-P / 2e5)) + 0.02) : 0.0;
    out.push_back(rec);
  }
  return out;
}

}  // namespace collido::gvm
