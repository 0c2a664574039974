#include "gvm/baselines.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "gvm/linalg.h"
#include "gvm/rng.h"

namespace collido::gvm {

namespace {

bool same_kind(const RunConfig& a, const RunConfig& b) {
  return a.method == b.method && a.traversal == b.traversal && a.backend == b.backend &&
         a.device == b.device && a.threads == b.threads;
}

inline double scale01(double v, double lo, double hi) {
  return hi > lo ? (v - lo) / (hi - lo) : 0.0;
}

void min_max(const Matrix& m, std::vector<double>* lo, std::vector<double>* hi) {
  lo->assign(m.cols(), std::numeric_limits<double>::infinity());
  hi->assign(m.cols(), -std::numeric_limits<double>::infinity());
  for (size_t r = 0; r < m.rows(); ++r)
    for (size_t c = 0; c < m.cols(); ++c) {
      if (std::isnan(m(r, c))) continue;  // a missing target
      (*lo)[c] = std::min((*lo)[c], m(r, c));
      (*hi)[c] = std::max((*hi)[c], m(r, c));
    }
  // A column with no value at all scales as a constant 0.
  for (size_t c = 0; c < m.cols(); ++c)
    if (!((*lo)[c] <= (*hi)[c])) (*lo)[c] = (*hi)[c] = 0.0;
}

void encode_rows(const std::vector<RunRecord>& rows, const FeatureSpace& f, Matrix* x, Matrix* y) {
  *x = Matrix(rows.size(), f.input_count());
  *y = Matrix(rows.size(), kOutputCount);
  for (size_t r = 0; r < rows.size(); ++r) {
    f.encode_inputs(rows[r].config, x->row(r));
    encode_outputs(rows[r].measure, rows[r].config.backend, y->row(r));
  }
}

}  // namespace

// ---- the paper's linear fit ------------------------------------------------------

Expected<PaperLinearFit> PaperLinearFit::fit(const std::vector<RunRecord>& rows) {
  if (rows.empty()) return invalid_argument("linear fit needs at least one row");
  PaperLinearFit out;
  std::vector<std::vector<const RunRecord*>> members;
  for (const auto& r : rows) {
    size_t g = 0;
    while (g < out.groups_.size() && !(out.groups_[g].key.particles == r.config.particles &&
                                       same_kind(out.groups_[g].key, r.config)))
      ++g;
    if (g == out.groups_.size()) {
      out.groups_.push_back(Group{r.config, {}, {}});
      members.emplace_back();
    }
    members[g].push_back(&r);
  }
  for (size_t g = 0; g < out.groups_.size(); ++g) {
    const auto& rs = members[g];
    const double n = static_cast<double>(rs.size());
    double mx = 0.0;
    for (auto* r : rs) mx += static_cast<double>(r->config.triangles) / n;
    double sxx = 0.0;
    for (auto* r : rs) sxx += std::pow(static_cast<double>(r->config.triangles) - mx, 2);
    for (int q = 0; q < 4; ++q) {
      auto val = [q](const RunRecord* r) {
        const RunMeasure& m = r->measure;
        return q == 0   ? m.time_per_frame_s
               : q == 1 ? m.peak_host_bytes
               : q == 2 ? m.peak_device_bytes
                        : m.gpu_load;
      };
      double my = 0.0;
      for (auto* r : rs) my += val(r) / n;
      double sxy = 0.0;
      for (auto* r : rs) sxy += (static_cast<double>(r->config.triangles) - mx) * (val(r) - my);
      // One triangle count in the group: a constant is all the data can say.
      const double a = sxx > 0.0 ? sxy / sxx : 0.0;
      out.groups_[g].a[q] = a;
      out.groups_[g].b[q] = my - a * mx;
    }
  }
  return out;
}

RunMeasure PaperLinearFit::predict(const RunConfig& c) const {
  const Group* best = nullptr;
  double best_d = std::numeric_limits<double>::infinity();
  for (int pass = 0; pass < 2 && !best; ++pass)
    for (const auto& g : groups_) {
      if (pass == 0 && !same_kind(g.key, c)) continue;
      const double d = std::abs(std::log10(static_cast<double>(g.key.particles)) -
                                std::log10(static_cast<double>(std::max<int64_t>(c.particles, 1))));
      if (d < best_d) {
        best_d = d;
        best = &g;
      }
    }
  RunMeasure m;
  if (!best) return m;
  const double t = static_cast<double>(c.triangles);
  double v[4];
  for (int q = 0; q < 4; ++q) v[q] = best->a[q] * t + best->b[q];
  m.time_per_frame_s = std::max(v[0], 1e-9);
  m.total_time_s = m.time_per_frame_s * static_cast<double>(c.frames);
  m.peak_host_bytes = std::max(v[1], 0.0);
  m.peak_device_bytes = std::max(v[2], 0.0);
  m.gpu_load = std::clamp(v[3], 0.0, 1.0);
  if (c.backend == Backend::kCpu) m.peak_device_bytes = m.gpu_load = 0.0;
  return m;
}

// ---- least squares -----------------------------------------------------------------

Expected<LinearRegression> LinearRegression::fit(const Matrix& x, const Matrix& y) {
  if (x.rows() == 0) return invalid_argument("least squares needs at least one row");
  if (y.rows() != x.rows()) return invalid_argument("least squares: x and y differ in rows");
  LinearRegression out;
  min_max(x, &out.lo_, &out.hi_);
  const size_t p = x.cols() + 1, K = y.cols();
  out.coef_ = Matrix(p, K);
  out.trained_.assign(K, false);
  std::vector<double> a(p);
  // One normal-equation system per output, over the rows where that output has a value.
  for (size_t k = 0; k < K; ++k) {
    std::vector<double> ata(p * p, 0.0), aty(p, 0.0);
    size_t used = 0;
    for (size_t r = 0; r < x.rows(); ++r) {
      if (std::isnan(y(r, k))) continue;
      ++used;
      for (size_t c = 0; c + 1 < p; ++c) a[c] = scale01(x(r, c), out.lo_[c], out.hi_[c]);
      a[p - 1] = 1.0;
      for (size_t i = 0; i < p; ++i) {
        for (size_t j = 0; j < p; ++j) ata[i * p + j] += a[i] * a[j];
        aty[i] += a[i] * y(r, k);
      }
    }
    if (used == 0) continue;  // never predicted
    // Constant columns are all zero after scaling, and one-hot blocks sum to the
    // intercept; a small ridge term makes both solvable without changing the fit.
    const double ridge = 1e-9 * static_cast<double>(used);
    for (size_t i = 0; i + 1 < p; ++i) ata[i * p + i] += ridge + (out.hi_[i] > out.lo_[i] ? 0 : 1);
    if (!cholesky_solve(ata, p, &aty)) return invalid_argument("least squares system is singular");
    for (size_t i = 0; i < p; ++i) out.coef_(i, k) = aty[i];
    out.trained_[k] = true;
  }
  return out;
}

void LinearRegression::predict(const double* x, double* y) const {
  const size_t p = lo_.size() + 1;
  for (size_t k = 0; k < coef_.cols(); ++k) {
    if (!trained_[k]) {
      y[k] = std::numeric_limits<double>::quiet_NaN();
      continue;
    }
    double s = coef_(p - 1, k);
    for (size_t i = 0; i + 1 < p; ++i) s += coef_(i, k) * scale01(x[i], lo_[i], hi_[i]);
    y[k] = s;
  }
}

Expected<LeastSquaresFit> LeastSquaresFit::fit(const std::vector<RunRecord>& rows,
                                               const FeatureSpace& features) {
  if (rows.empty()) return invalid_argument("least squares needs at least one row");
  Matrix x, y;
  encode_rows(rows, features, &x, &y);
  auto f = LinearRegression::fit(x, y);
  if (!f) return f.status();
  LeastSquaresFit out;
  out.features_ = features;
  out.fit_ = std::move(*f);
  return out;
}

RunMeasure LeastSquaresFit::predict(const RunConfig& c) const {
  std::vector<double> x = features_.encode_inputs(c);
  double y[kOutputCount];
  fit_.predict(x.data(), y);
  // An output never trained decodes to 0 (decode_outputs gives 0 where it is missing).
  for (double& v : y)
    if (std::isnan(v)) v = 0.0;
  return decode_outputs(y, c.backend);
}

// ---- back-propagation MLP ------------------------------------------------------------

Expected<MlpRegression> MlpRegression::fit(const Matrix& x, const Matrix& y,
                                           const MlpOptions& opt) {
  if (x.rows() == 0) return invalid_argument("MLP needs at least one row");
  if (y.rows() != x.rows()) return invalid_argument("MLP: x and y differ in rows");
  if (opt.hidden < 1 || opt.epochs < 0 || !(opt.learning_rate > 0.0))
    return invalid_argument("MLP options out of range");
  MlpRegression m;
  m.hidden_ = static_cast<size_t>(opt.hidden);
  min_max(x, &m.in_lo_, &m.in_hi_);
  min_max(y, &m.out_lo_, &m.out_hi_);
  const size_t N = x.rows(), I = x.cols(), H = m.hidden_, K = y.cols();
  Matrix xs(N, I), ys(N, K);
  for (size_t n = 0; n < N; ++n) {
    for (size_t i = 0; i < I; ++i) xs(n, i) = scale01(x(n, i), m.in_lo_[i], m.in_hi_[i]);
    for (size_t k = 0; k < K; ++k)
      ys(n, k) = std::isnan(y(n, k)) ? y(n, k) : scale01(y(n, k), m.out_lo_[k], m.out_hi_[k]);
  }
  // Loss = mean over outputs of each output's mean squared error over its present rows,
  // the same quantity the GVM minimises.
  std::vector<double> present(K, 0.0);
  for (size_t n = 0; n < N; ++n)
    for (size_t k = 0; k < K; ++k) present[k] += std::isnan(ys(n, k)) ? 0.0 : 1.0;
  Rng rng(opt.seed);
  // Glorot-style uniform start.
  const double r1 = 1.0 / std::sqrt(static_cast<double>(I)),
               r2 = 1.0 / std::sqrt(static_cast<double>(H));
  m.w1_.resize(H * I);
  for (auto& v : m.w1_) v = rng.uniform(-r1, r1);
  m.b1_.assign(H, 0.0);
  m.w2_.resize(K * H);
  for (auto& v : m.w2_) v = rng.uniform(-r2, r2);
  m.b2_.assign(K, 0.5);

  // Adam over one flat parameter vector view: w1, b1, w2, b2.
  std::vector<double*> params;
  for (auto* vec : {&m.w1_, &m.b1_, &m.w2_, &m.b2_})
    for (auto& v : *vec) params.push_back(&v);
  const size_t P = params.size();
  std::vector<double> grad(P), mom(P, 0.0), vel(P, 0.0), h(N * H), dh(H);
  const double b1 = 0.9, b2 = 0.999, eps = 1e-8;
  // Full-batch Adam at a fixed rate does not settle: the loss spikes now and then, and
  // where a run stops decides the model (on one real log, 300 / 3000 / 10000 epochs
  // gave 42 / 94 / 18 % time-per-frame error). So the rate decays on a cosine from
  // learning_rate to 1 % of it, and the parameters with the lowest training loss seen
  // are the ones kept (training rows only; the validation rows stay unseen).
  double best_loss = std::numeric_limits<double>::infinity();
  std::vector<double> best(P);
  for (int e = 1; e <= opt.epochs; ++e) {
    std::fill(grad.begin(), grad.end(), 0.0);
    double loss = 0.0;
    double* gw1 = grad.data();
    double* gb1 = gw1 + H * I;
    double* gw2 = gb1 + H;
    double* gb2 = gw2 + K * H;
    for (size_t n = 0; n < N; ++n) {
      hidden_sums(m.w1_.data(), m.b1_.data(), H, I, xs.row(n), &h[n * H]);
      for (size_t j = 0; j < H; ++j) h[n * H + j] = std::tanh(h[n * H + j]);
      std::fill(dh.begin(), dh.end(), 0.0);
      for (size_t k = 0; k < K; ++k) {
        if (std::isnan(ys(n, k))) continue;
        double o = m.b2_[k];
        for (size_t j = 0; j < H; ++j) o += m.w2_[k * H + j] * h[n * H + j];
        const double d = 2.0 * (o - ys(n, k)) / (present[k] * static_cast<double>(K));
        loss += (o - ys(n, k)) * (o - ys(n, k)) / (present[k] * static_cast<double>(K));
        gb2[k] += d;
        for (size_t j = 0; j < H; ++j) {
          gw2[k * H + j] += d * h[n * H + j];
          dh[j] += d * m.w2_[k * H + j];
        }
      }
      for (size_t j = 0; j < H; ++j) {
        const double dz = dh[j] * (1.0 - h[n * H + j] * h[n * H + j]);
        gb1[j] += dz;
        for (size_t i = 0; i < I; ++i) gw1[j * I + i] += dz * xs(n, i);
      }
    }
    if (loss < best_loss) {  // the loss of the parameters before this step
      best_loss = loss;
      for (size_t q = 0; q < P; ++q) best[q] = *params[q];
    }
    const double c1 = 1.0 - std::pow(b1, e), c2 = 1.0 - std::pow(b2, e);
    const double lr_min = 0.01 * opt.learning_rate;
    const double lr = lr_min + 0.5 * (opt.learning_rate - lr_min) *
                                   (1.0 + std::cos(M_PI * (e - 1) / std::max(1, opt.epochs)));
    for (size_t q = 0; q < P; ++q) {
      mom[q] = b1 * mom[q] + (1 - b1) * grad[q];
      vel[q] = b2 * vel[q] + (1 - b2) * grad[q] * grad[q];
      *params[q] -= lr * (mom[q] / c1) / (std::sqrt(vel[q] / c2) + eps);
    }
  }
  if (opt.epochs > 0)
    for (size_t q = 0; q < P; ++q) *params[q] = best[q];
  return m;
}

void MlpRegression::predict(const double* x, double* y) const {
  const size_t I = in_lo_.size(), H = hidden_, K = out_lo_.size();
  double hbuf[64];
  std::vector<double> big;
  double* h = hbuf;
  if (H > 64) {
    big.resize(H);
    h = big.data();
  }
  for (size_t j = 0; j < H; ++j) {
    double z = b1_[j];
    for (size_t i = 0; i < I; ++i) z += w1_[j * I + i] * scale01(x[i], in_lo_[i], in_hi_[i]);
    h[j] = std::tanh(z);
  }
  for (size_t k = 0; k < K; ++k) {
    double o = b2_[k];
    for (size_t j = 0; j < H; ++j) o += w2_[k * H + j] * h[j];
    y[k] = out_lo_[k] + o * (out_hi_[k] - out_lo_[k]);
  }
}

Expected<MlpFit> MlpFit::fit(const std::vector<RunRecord>& rows, const FeatureSpace& features,
                             const MlpOptions& opt) {
  if (rows.empty()) return invalid_argument("MLP needs at least one row");
  Matrix x, y;
  encode_rows(rows, features, &x, &y);
  auto f = MlpRegression::fit(x, y, opt);
  if (!f) return f.status();
  MlpFit m;
  m.features_ = features;
  m.fit_ = std::move(*f);
  return m;
}

RunMeasure MlpFit::predict(const RunConfig& c) const {
  std::vector<double> x = features_.encode_inputs(c);
  double y[kOutputCount];
  fit_.predict(x.data(), y);
  return decode_outputs(y, c.backend);
}

}  // namespace collido::gvm
