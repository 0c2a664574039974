#include "gvm/machine.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <utility>

#include "gvm/json_io.h"
#include "gvm/linalg.h"
#include "gvm/rng.h"

namespace collido::gvm {

const char* activation_name(Activation a) {
  return a == Activation::kSoftsign ? "softsign" : a == Activation::kTanh ? "tanh" : "sigmoid";
}

std::optional<Activation> parse_activation(const std::string& name) {
  if (name == "softsign") return Activation::kSoftsign;
  if (name == "tanh") return Activation::kTanh;
  if (name == "sigmoid") return Activation::kSigmoid;
  return std::nullopt;
}

namespace {

// tanh through one exp: 1 - 2 / (1 + e^2z) is within 4e-16 of std::tanh (absolute) and
// about 3x faster with glibc, and the activation is most of a Monte Carlo proposal's cost.
inline double activate(Activation a, double z) {
  switch (a) {
    case Activation::kSoftsign:
      return z / (1.0 + std::fabs(z));
    case Activation::kTanh:
      return 1.0 - 2.0 / (1.0 + std::exp(2.0 * z));
    case Activation::kSigmoid:
      break;
  }
  return 1.0 / (1.0 + std::exp(-z));
}

// The training loop's row kernels are built twice, for AVX2 and for any x86-64, and the
// loader picks one (an ifunc): each lane does the same IEEE operations at either width
// (AVX2 brings no fused multiply-add), so both give the same bits.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define COLLIDO_ROW_KERNEL __attribute__((target_clones("avx2", "default")))
#else
#define COLLIDO_ROW_KERNEL
#endif

// o[n] = f(beta * z[n]) for n rows, the activation chosen once outside the loop, so
// that the loop runs in vectors (it is most of a Monte Carlo proposal's cost; with the
// choice per row it ran one row at a time). The same bits as activate() row by row.
COLLIDO_ROW_KERNEL void activate_rows(Activation a, double beta, const double* z, double* o,
                                      size_t n) {
  switch (a) {
    case Activation::kSoftsign:
      for (size_t r = 0; r < n; ++r) o[r] = activate(Activation::kSoftsign, beta * z[r]);
      return;
    case Activation::kTanh:
      for (size_t r = 0; r < n; ++r) o[r] = activate(Activation::kTanh, beta * z[r]);
      return;
    case Activation::kSigmoid:
      break;
  }
  for (size_t r = 0; r < n; ++r) o[r] = activate(Activation::kSigmoid, beta * z[r]);
}

// The sums an output's least-squares affine fit needs, over its rows: of u = m (s - shift),
// of u^2 and of s t, where s is the output sum with neuron j's outputs o_old replaced by
// o_new (when given) and m masks the rows without a target. Four partial sums, row n into
// lane n % 4, added in one fixed order at the end: a single running sum is a chain of
// dependent adds the compiler may not reorder, and this order gives the same bits on
// every machine and vector width.
struct FitSums {
  double su, suu, sst;
};
template <bool kNew>
COLLIDO_ROW_KERNEL FitSums fit_sums(const double* s, const double* o_new, const double* o_old,
                                    double vk, const double* mk, const double* tc, double shift,
                                    size_t rows) {
  using V4 = double __attribute__((vector_size(32)));
  V4 su = {0, 0, 0, 0}, suu = su, sst = su;
  const size_t whole = rows / 4 * 4;
  // Rows [n, n + 4) from memory; the last rows copied into lanes padded with zeros.
  double pad_s[4] = {0, 0, 0, 0}, pad_new[4] = {0, 0, 0, 0}, pad_old[4] = {0, 0, 0, 0},
         pad_m[4] = {0, 0, 0, 0}, pad_t[4] = {0, 0, 0, 0};
  for (size_t r = whole; r < rows; ++r) {
    pad_s[r - whole] = s[r], pad_m[r - whole] = mk[r], pad_t[r - whole] = tc[r];
    if (kNew) pad_new[r - whole] = o_new[r], pad_old[r - whole] = o_old[r];
  }
  for (size_t n = 0; n < rows; n += 4) {
    const bool last = n == whole;
    const auto at = [&](const double* a, const double* pad) { return last ? pad : a + n; };
    V4 vs, vm, vt;
    std::memcpy(&vs, at(s, pad_s), sizeof vs);
    std::memcpy(&vm, at(mk, pad_m), sizeof vm);
    std::memcpy(&vt, at(tc, pad_t), sizeof vt);
    if (kNew) {
      V4 vn, vo;
      std::memcpy(&vn, at(o_new, pad_new), sizeof vn);
      std::memcpy(&vo, at(o_old, pad_old), sizeof vo);
      vs = vs + vk * (vn - vo);
    }
    const V4 u = vm * (vs - shift);  // shifted by the last mean: no cancellation
    su += u;
    suu += u * u;
    sst += vs * vt;  // t is 0 where the target is missing
  }
  return {(su[0] + su[1]) + (su[2] + su[3]), (suu[0] + suu[1]) + (suu[2] + suu[3]),
          (sst[0] + sst[1]) + (sst[2] + sst[3])};
}

// z[n] = b + w[0] x[0][n] + w[1] x[1][n] + .. for n rows, added in that order (as
// predict() adds a row's inputs), four rows at a time held in a vector across the inputs.
COLLIDO_ROW_KERNEL void neuron_over_rows(double b, const double* w, const double* const* x,
                                         size_t inputs, double* z, size_t rows) {
  using V4 = double __attribute__((vector_size(32)));
  size_t n = 0;
  for (; n + 4 <= rows; n += 4) {
    V4 acc = {b, b, b, b};
    for (size_t i = 0; i < inputs; ++i) {
      V4 xi;
      std::memcpy(&xi, x[i] + n, sizeof xi);
      acc += w[i] * xi;
    }
    std::memcpy(z + n, &acc, sizeof acc);
  }
  for (; n < rows; ++n) {
    double acc = b;
    for (size_t i = 0; i < inputs; ++i) acc += w[i] * x[i][n];
    z[n] = acc;
  }
}

// z_new[n] = z[n] + d * x[n] (x null: z[n] + d), for n rows.
COLLIDO_ROW_KERNEL void moved_rows(const double* z, double d, const double* x, double* z_new,
                                   size_t rows) {
  if (x)
    for (size_t n = 0; n < rows; ++n) z_new[n] = z[n] + d * x[n];
  else
    for (size_t n = 0; n < rows; ++n) z_new[n] = z[n] + d;
}

// Inputs equal on every training row carry no information; they are scaled to 0 and
// their weights are never proposed, so they cannot drift and add noise to predictions.
inline double scale_input(const MachineParams& p, size_t i, double x) {
  const double range = p.in_max[i] - p.in_min[i];
  return range > 0.0 ? (x - p.in_min[i]) / range : 0.0;
}

bool all_finite(const Matrix& m) {
  for (size_t r = 0; r < m.rows(); ++r)
    for (size_t c = 0; c < m.cols(); ++c)
      if (!std::isfinite(m(r, c))) return false;
  return true;
}

// Targets may be NaN (missing) but never infinite.
bool no_infinity(const Matrix& m) {
  for (size_t r = 0; r < m.rows(); ++r)
    for (size_t c = 0; c < m.cols(); ++c)
      if (std::isinf(m(r, c))) return false;
  return true;
}

// The Monte Carlo trainer. It keeps, for the training rows, every hidden neuron's
// pre-activation z_j(n) = w_j . x_n + b_j and output o_j(n), and every output sum
// s_k(n), so that one proposal costs O(rows * outputs) instead of a full forward pass.
class Trainer {
 public:
  Trainer(MachineParams& p, const Matrix& x, const Matrix& y, const GvmOptions& opt)
      : p_(p), opt_(opt), n_(x.rows()), rng_(opt.seed), delta_(opt.delta) {
    // Column-major scaled inputs: a w move reads one input column.
    xs_.assign(p.inputs * n_, 0.0);
    for (size_t i = 0; i < p.inputs; ++i)
      for (size_t n = 0; n < n_; ++n) xs_[i * n_ + n] = scale_input(p, i, x(n, i));
    for (size_t i = 0; i < p.inputs; ++i)
      if (p.in_max[i] > p.in_min[i]) active_.push_back(i);
    for (size_t i : active_) x_active_.push_back(&xs_[i * n_]);
    z_new_.assign(n_, 0.0);  // a proposal's scratch, sized once
    o_new_.assign(n_, 0.0);
    // Centred scaled targets: the affine fit then needs only sum(s), sum(s^2), sum(s*t).
    // A NaN target means "no value for this output in this row" (a CPU run has no
    // device memory); such entries get weight 0 everywhere.
    tc_.assign(p.outputs * n_, 0.0);
    mask_.assign(p.outputs * n_, 0.0);
    count_.assign(p.outputs, 0.0);
    vtt_.assign(p.outputs, 0.0);
    tmean_.assign(p.outputs, 0.0);
    for (size_t k = 0; k < p.outputs; ++k) {
      const double range = p.out_max[k] - p.out_min[k];
      double sum = 0.0;
      std::vector<double> t(n_, 0.0);
      for (size_t n = 0; n < n_; ++n) {
        if (std::isnan(y(n, k))) continue;
        mask_[k * n_ + n] = 1.0;
        count_[k] += 1.0;
        t[n] = range > 0.0 ? (y(n, k) - p.out_min[k]) / range : 0.0;
        sum += t[n];
      }
      tmean_[k] = count_[k] > 0.0 ? sum / count_[k] : 0.0;
      for (size_t n = 0; n < n_; ++n) {
        if (mask_[k * n_ + n] == 0.0) continue;
        tc_[k * n_ + n] = t[n] - tmean_[k];
        vtt_[k] += tc_[k * n_ + n] * tc_[k * n_ + n];
      }
    }
  }

  // Near a minimum most full-size steps overshoot and are refused; shrinking the step
  // when few are kept (and growing it back when many are) keeps the search moving.
  void end_epoch(double acceptance) {
    if (!opt_.adaptive_delta) return;
    if (acceptance < 0.1)
      delta_ = std::max(delta_ * 0.8, opt_.delta * 0.01);
    else if (acceptance > 0.2)
      delta_ = std::min(delta_ * 1.25, opt_.delta);
  }

  size_t parameter_count() const { return p_.hidden * (active_.size() + 2); }

  // Random start inside the ranges. Signs v: per output, a seeded random half of the
  // neurons get +1 and the other half -1 (see docs/gvm.md for why).
  void initialize() {
    const size_t H = p_.hidden;
    p_.v.assign(p_.outputs * H, 1);
    for (size_t k = 0; k < p_.outputs; ++k) {
      std::vector<int> signs(H);
      for (size_t j = 0; j < H; ++j) signs[j] = j < H / 2 ? 1 : -1;
      if (H % 2 == 1) signs[H - 1] = rng_.below(2) ? 1 : -1;
      rng_.shuffle(signs);
      std::copy(signs.begin(), signs.end(), p_.v.begin() + k * H);
    }
    p_.w.assign(H * p_.inputs, 0.0);
    p_.b.assign(H, 0.0);
    p_.beta.assign(H, 0.0);
    for (size_t j = 0; j < H; ++j) {
      // Weights start at w_max / sqrt(inputs) so that w.x varies about as much with 13
      // inputs as with 1: a neuron does not start as a sharp step along a random
      // direction, which Monte Carlo acceptance would then keep (on 5 synthetic run logs
      // the mean held-out loss fell from 0.025 to 0.015 against a full-range start).
      const double w0 =
          p_.w_max / std::sqrt(static_cast<double>(std::max<size_t>(active_.size(), 1)));
      // The neuron's surface w.x + b = 0 starts through a random point of the unit cube,
      // so no neuron starts saturated over all the data.
      double wx = 0.0;
      for (size_t i : active_) {
        p_.w[j * p_.inputs + i] = rng_.uniform(-w0, w0);
        wx += p_.w[j * p_.inputs + i] * rng_.uniform01();
      }
      p_.b[j] = std::clamp(-wx, -p_.b_max, p_.b_max);
      p_.beta[j] = rng_.uniform(-p_.beta_max, p_.beta_max);
    }
    recompute_all();
  }

  // Rebuilds every cache from the parameters. Called once per epoch too, which wipes
  // the rounding drift of many incremental updates.
  void recompute_all() {
    const size_t H = p_.hidden;
    z_.assign(H * n_, 0.0);
    o_.assign(H * n_, 0.0);
    s_.assign(p_.outputs * n_, 0.0);
    for (size_t j = 0; j < H; ++j) {
      double* z = &z_[j * n_];
      w_active_.clear();
      for (size_t i : active_) w_active_.push_back(p_.w[j * p_.inputs + i]);
      neuron_over_rows(p_.b[j], w_active_.data(), x_active_.data(), active_.size(), z, n_);
      activate_rows(p_.activation, p_.beta[j], z, &o_[j * n_], n_);
      for (size_t k = 0; k < p_.outputs; ++k) {
        const double vk = p_.v[k * H + j];
        for (size_t n = 0; n < n_; ++n) s_[k * n_ + n] += vk * o_[j * n_ + n];
      }
    }
    shift_.assign(p_.outputs, 0.0);
    for (size_t k = 0; k < p_.outputs; ++k) {
      double sum = 0.0;
      for (size_t n = 0; n < n_; ++n) sum += mask_[k * n_ + n] * s_[k * n_ + n];
      shift_[k] = count_[k] > 0.0 ? sum / count_[k] : 0.0;
    }
    loss_ = evaluate(nullptr, 0, nullptr);
  }

  // Training loss with neuron j's outputs replaced by o_new (or the current state when
  // o_new is null), each output mapped by its own least-squares affine map: the mean
  // over outputs of each output's mean squared error. Fills ac (a, c per output) if given.
  double evaluate(const double* o_new, size_t j, std::vector<std::pair<double, double>>* ac) {
    const size_t H = p_.hidden;
    double loss = 0.0;
    size_t used = 0;
    for (size_t k = 0; k < p_.outputs; ++k) {
      if (count_[k] == 0.0) {
        if (ac) (*ac)[k] = {0.0, 0.0};
        continue;
      }
      ++used;
      const double* s = &s_[k * n_];
      const double* tc = &tc_[k * n_];
      const double* mk = &mask_[k * n_];
      const double vk = p_.v[k * H + j];
      const double* o_old = &o_[j * n_];
      const double shift = shift_[k];
      const FitSums f = o_new ? fit_sums<true>(s, o_new, o_old, vk, mk, tc, shift, n_)
                              : fit_sums<false>(s, o_new, o_old, vk, mk, tc, shift, n_);
      const double su = f.su, suu = f.suu, sst = f.sst;
      const double nk = count_[k];
      const double vss = suu - su * su / nk;
      double c = 0.0, sse = vtt_[k];
      if (vss > 1e-14 * nk) {
        c = sst / vss;
        sse = std::max(0.0, vtt_[k] - c * sst);
      }
      if (ac) (*ac)[k] = {tmean_[k] - c * (shift + su / nk), c};
      loss += sse / nk;
    }
    return used ? loss / static_cast<double>(used) : 0.0;
  }

  // One Monte Carlo proposal; returns true when it was kept.
  bool step() {
    const size_t H = p_.hidden, na = active_.size();
    const size_t idx = rng_.below(H * (na + 2));
    const size_t j = idx / (na + 2), r = idx % (na + 2);
    const double u = rng_.uniform(-1.0, 1.0);
    double* z = &z_[j * n_];
    const double* z_moved = z_new_.data();  // the neuron's sums after the move
    double* target;
    double old_value, new_value;
    if (r < na) {  // a weight w_ji
      const size_t i = active_[r];
      target = &p_.w[j * p_.inputs + i];
      old_value = *target;
      new_value = std::clamp(old_value + delta_ * p_.w_max * u, -p_.w_max, p_.w_max);
      const double dw = new_value - old_value;
      moved_rows(z, dw, &xs_[i * n_], z_new_.data(), n_);
    } else if (r == na) {  // the bias b_j
      target = &p_.b[j];
      old_value = *target;
      new_value = std::clamp(old_value + delta_ * p_.w_max * u, -p_.b_max, p_.b_max);
      moved_rows(z, new_value - old_value, nullptr, z_new_.data(), n_);
    } else {  // the gain beta_j
      target = &p_.beta[j];
      old_value = *target;
      new_value = std::clamp(old_value + delta_ * p_.beta_max * u, -p_.beta_max, p_.beta_max);
      z_moved = z;  // a gain moves no sums
    }
    const double beta = r == na + 1 ? new_value : p_.beta[j];
    activate_rows(p_.activation, beta, z_moved, o_new_.data(), n_);
    const double new_loss = evaluate(o_new_.data(), j, nullptr);
    if (!(new_loss <= loss_)) return false;  // undo: nothing was written yet
    *target = new_value;
    for (size_t k = 0; k < p_.outputs; ++k) {
      const double vk = p_.v[k * H + j];
      double* s = &s_[k * n_];
      for (size_t n = 0; n < n_; ++n) s[n] += vk * (o_new_[n] - o_[j * n_ + n]);
    }
    if (z_moved != z) std::copy(z_new_.begin(), z_new_.end(), z);
    std::copy(o_new_.begin(), o_new_.end(), o_.begin() + j * n_);
    loss_ = new_loss;
    return true;
  }

  // Writes the least-squares affine output map of the current state into the params.
  void store_output_map() {
    std::vector<std::pair<double, double>> ac(p_.outputs);
    evaluate(nullptr, 0, &ac);
    p_.out_a.resize(p_.outputs);
    p_.out_c.resize(p_.outputs);
    for (size_t k = 0; k < p_.outputs; ++k) {
      p_.out_a[k] = ac[k].first;
      p_.out_c[k] = ac[k].second;
    }
  }

  double loss() const { return loss_; }

 private:
  MachineParams& p_;
  const GvmOptions& opt_;
  size_t n_;
  Rng rng_;
  std::vector<size_t> active_;
  std::vector<double> xs_, tc_, mask_, count_, vtt_, tmean_, shift_;
  std::vector<double> z_, o_, s_, z_new_, o_new_;
  std::vector<const double*> x_active_;  // the active inputs' columns of xs_
  std::vector<double> w_active_;         // one neuron's weights on them
  double loss_ = 0.0;
  double delta_;  // current step, opt_.delta / 100 .. opt_.delta
};

}  // namespace

Expected<Machine> Machine::train(const Matrix& x, const Matrix& y, const Matrix& val_x,
                                 const Matrix& val_y, const GvmOptions& opt, TrainReport* report,
                                 std::vector<std::string> input_names,
                                 std::vector<std::string> output_names) {
  const auto t0 = std::chrono::steady_clock::now();
  if (x.rows() < 2) return invalid_argument("GVM training needs at least 2 rows");
  if (y.rows() != x.rows()) return invalid_argument("GVM inputs and targets differ in rows");
  if (x.cols() == 0 || y.cols() == 0) return invalid_argument("GVM needs inputs and outputs");
  if (val_x.rows() != val_y.rows() ||
      (val_x.rows() > 0 && (val_x.cols() != x.cols() || val_y.cols() != y.cols())))
    return invalid_argument("GVM validation rows do not match the training shape");
  if (!all_finite(x) || !all_finite(val_x))
    return invalid_argument("GVM inputs contain NaN or infinity");
  if (!no_infinity(y) || !no_infinity(val_y))
    return invalid_argument("GVM targets contain infinity");
  if (opt.hidden < 1 || opt.hidden > 4096) return invalid_argument("hidden must be in 1..4096");
  if (opt.epochs < 0) return invalid_argument("epochs must be >= 0");
  if (!(opt.delta > 0.0 && opt.delta <= 1.0)) return invalid_argument("delta must be in (0, 1]");
  if (!(opt.w_max > 0.0) || !(opt.beta_max > 0.0))
    return invalid_argument("w_max and beta_max must be > 0");
  if (!input_names.empty() && input_names.size() != x.cols())
    return invalid_argument("one input name per column expected");
  if (!output_names.empty() && output_names.size() != y.cols())
    return invalid_argument("one output name per column expected");

  MachineParams p;
  p.activation = opt.activation;
  p.inputs = x.cols();
  p.outputs = y.cols();
  p.hidden = static_cast<size_t>(opt.hidden);
  for (size_t i = 0; i < p.inputs; ++i)
    p.input_names.push_back(input_names.empty() ? "x" + std::to_string(i) : input_names[i]);
  for (size_t k = 0; k < p.outputs; ++k)
    p.output_names.push_back(output_names.empty() ? "y" + std::to_string(k) : output_names[k]);
  p.in_min.assign(p.inputs, std::numeric_limits<double>::infinity());
  p.in_max.assign(p.inputs, -std::numeric_limits<double>::infinity());
  p.out_min.assign(p.outputs, std::numeric_limits<double>::infinity());
  p.out_max.assign(p.outputs, -std::numeric_limits<double>::infinity());
  for (size_t n = 0; n < x.rows(); ++n) {
    for (size_t i = 0; i < p.inputs; ++i) {
      p.in_min[i] = std::min(p.in_min[i], x(n, i));
      p.in_max[i] = std::max(p.in_max[i], x(n, i));
    }
    for (size_t k = 0; k < p.outputs; ++k) {
      if (std::isnan(y(n, k))) continue;
      p.out_min[k] = std::min(p.out_min[k], y(n, k));
      p.out_max[k] = std::max(p.out_max[k], y(n, k));
    }
  }
  // An output with no value in any row (device memory in a CPU-only log) is the
  // constant 0 and stays out of the loss.
  for (size_t k = 0; k < p.outputs; ++k)
    if (!(p.out_min[k] <= p.out_max[k])) p.out_min[k] = p.out_max[k] = 0.0;
  size_t active = 0;
  for (size_t i = 0; i < p.inputs; ++i) active += p.in_max[i] > p.in_min[i];
  p.w_max = opt.w_max;
  p.beta_max = opt.beta_max;
  // w.x ranges over [-w_max * active, w_max * active] on the unit cube; b must be able to
  // move a neuron's surface anywhere in it.
  p.b_max = opt.w_max * static_cast<double>(std::max<size_t>(active, 1));

  Trainer trainer(p, x, y, opt);
  trainer.initialize();
  TrainReport local;
  TrainReport& rep = report ? *report : local;
  rep = TrainReport{};
  const int64_t per_epoch = static_cast<int64_t>(trainer.parameter_count());
  for (int e = 1; e <= opt.epochs; ++e) {
    int64_t kept = 0;
    for (int64_t q = 0; q < per_epoch; ++q) kept += trainer.step();
    // The reported loss is the incrementally maintained one (a test compares it with a
    // full forward pass); the rebuild then drops the rounding drift of the updates.
    const double train_loss = trainer.loss();
    trainer.recompute_all();
    trainer.end_epoch(per_epoch ? static_cast<double>(kept) / per_epoch : 0.0);
    rep.proposals += per_epoch;
    rep.accepted += kept;
    trainer.store_output_map();
    Machine m(p);
    const double val =
        val_x.rows() > 0 ? m.loss(val_x, val_y) : std::numeric_limits<double>::quiet_NaN();
    rep.curve.push_back(
        {e, train_loss, val, per_epoch ? static_cast<double>(kept) / per_epoch : 0.0});
  }
  trainer.store_output_map();
  rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return Machine(std::move(p));
}

Expected<Machine> Machine::from_params(MachineParams p) {
  const size_t I = p.inputs, K = p.outputs, H = p.hidden;
  if (I == 0 || K == 0 || H == 0) return invalid_argument("GVM with no inputs, outputs or neurons");
  if (p.input_names.size() != I || p.in_min.size() != I || p.in_max.size() != I ||
      p.output_names.size() != K || p.out_min.size() != K || p.out_max.size() != K ||
      p.out_a.size() != K || p.out_c.size() != K || p.w.size() != H * I || p.b.size() != H ||
      p.beta.size() != H || p.v.size() != K * H)
    return invalid_argument("GVM parameter arrays have the wrong sizes");
  for (int s : p.v)
    if (s != 1 && s != -1) return invalid_argument("GVM output weights must be -1 or +1");
  auto finite = [](const std::vector<double>& a) {
    return std::all_of(a.begin(), a.end(), [](double d) { return std::isfinite(d); });
  };
  if (!finite(p.in_min) || !finite(p.in_max) || !finite(p.out_min) || !finite(p.out_max) ||
      !finite(p.out_a) || !finite(p.out_c) || !finite(p.w) || !finite(p.b) || !finite(p.beta))
    return invalid_argument("GVM parameters contain NaN or infinity");
  for (double w : p.w)
    if (std::abs(w) > p.w_max) return invalid_argument("GVM weight outside [-w_max, w_max]");
  for (double b : p.b)
    if (std::abs(b) > p.b_max) return invalid_argument("GVM bias outside [-b_max, b_max]");
  for (double be : p.beta)
    if (std::abs(be) > p.beta_max)
      return invalid_argument("GVM gain outside [-beta_max, beta_max]");
  for (size_t i = 0; i < I; ++i)
    if (p.in_min[i] > p.in_max[i]) return invalid_argument("GVM input range min > max");
  for (size_t k = 0; k < K; ++k)
    if (p.out_min[k] > p.out_max[k]) return invalid_argument("GVM output range min > max");
  return Machine(std::move(p));
}

void Machine::predict(const double* x, double* y) const {
  const size_t I = p_.inputs, K = p_.outputs, H = p_.hidden;
  // The scaled inputs, then the neurons' sums.
  double small[128];
  std::vector<double> large;
  double* xs = small;
  if (I + H > 128) {
    large.resize(I + H);
    xs = large.data();
  }
  double* z = xs + I;
  // Scale each input once, not once per neuron: the divisions dominated a prediction.
  for (size_t i = 0; i < I; ++i) xs[i] = scale_input(p_, i, x[i]);  // constant inputs: 0
  for (size_t k = 0; k < K; ++k) y[k] = 0.0;
  hidden_sums(p_.w.data(), p_.b.data(), H, I, xs, z);
  for (size_t j = 0; j < H; ++j) {
    const double o = activate(p_.activation, p_.beta[j] * z[j]);
    for (size_t k = 0; k < K; ++k) y[k] += p_.v[k * H + j] * o;
  }
  for (size_t k = 0; k < K; ++k) {
    const double scaled = p_.out_a[k] + p_.out_c[k] * y[k];
    y[k] = p_.out_min[k] + scaled * (p_.out_max[k] - p_.out_min[k]);
  }
}

std::vector<double> Machine::predict(const std::vector<double>& x) const {
  std::vector<double> y(p_.outputs);
  predict(x.data(), y.data());
  return y;
}

double Machine::loss(const Matrix& x, const Matrix& y) const {
  std::vector<double> out(p_.outputs), sum(p_.outputs, 0.0), count(p_.outputs, 0.0);
  for (size_t n = 0; n < x.rows(); ++n) {
    predict(x.row(n), out.data());
    for (size_t k = 0; k < p_.outputs; ++k) {
      if (std::isnan(y(n, k))) continue;
      const double range = p_.out_max[k] - p_.out_min[k];
      // Constant outputs are scaled by 1 so their errors still count.
      const double e = (out[k] - y(n, k)) / (range > 0.0 ? range : 1.0);
      sum[k] += e * e;
      count[k] += 1.0;
    }
  }
  double total = 0.0;
  size_t used = 0;
  for (size_t k = 0; k < p_.outputs; ++k)
    if (count[k] > 0.0) {
      total += sum[k] / count[k];
      ++used;
    }
  return used ? total / static_cast<double>(used) : std::numeric_limits<double>::quiet_NaN();
}

std::vector<RangeIssue> Machine::check_range(const double* x) const {
  std::vector<RangeIssue> issues;
  for (size_t i = 0; i < p_.inputs; ++i)
    if (!(x[i] >= p_.in_min[i] && x[i] <= p_.in_max[i]))
      issues.push_back({i, p_.input_names[i], x[i], p_.in_min[i], p_.in_max[i]});
  return issues;
}

std::string Machine::to_json() const {
  // Names come from user data; invalid UTF-8 is replaced rather than thrown about.
  return machine_to_json(p_).dump(1, ' ', false, nlohmann::json::error_handler_t::replace);
}

Expected<Machine> Machine::from_json(const std::string& text) {
  nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) return parse_error("GVM model is not valid JSON");
  auto params = machine_from_json(j);
  if (!params) return params.status();
  return from_params(std::move(*params));
}

}  // namespace collido::gvm
