// The general vector machine (Zhao 2016, arXiv:1602.03950) as a regression model:
// three layers, hidden neuron j gives o_j = f(beta_j * (w_j . x + b_j)), output k is
// s_k = sum_j v_kj o_j with fixed v_kj in {-1, +1}, and every parameter stays in a
// fixed range. Training is Monte Carlo: change one parameter at a time and keep the
// change if the training loss did not rise. See docs/gvm.md for the choices made.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "gvm/matrix.h"
#include "gvm/status.h"

namespace collido::gvm {

enum class Activation { kSoftsign, kTanh, kSigmoid };

// "softsign", "tanh" or "sigmoid".
const char* activation_name(Activation a);
std::optional<Activation> parse_activation(const std::string& name);

struct GvmOptions {
  int hidden = 16;    // hidden neurons
  int epochs = 2000;  // one epoch = one proposal per trainable parameter
  uint64_t seed = 1;  // everything random (signs, start, proposals) derives from it
  // Proposal half-width in units of each parameter's scale: w_max for w and b, beta_max
  // for beta. A move is theta + delta * scale * U(-1, 1), clamped to the range.
  double delta = 0.1;
  // Between epochs the step shrinks x0.8 after an epoch that kept < 10% of proposals
  // and grows x1.25 (up to delta) after one that kept > 20%; floor delta / 100.
  bool adaptive_delta = true;
  // softsign z / (1 + |z|): no exp, so a proposal costs less than half of tanh's, and on
  // the calibration sweeps it fit time per frame and memory better (total time a little
  // worse) at the same number of proposals (docs/gvm.md "Activation").
  Activation activation = Activation::kSoftsign;
  double w_max = 1.0;  // w in [-w_max, w_max]
  // beta in [-beta_max, beta_max]. It bounds how sharp a neuron can be, Zhao's margin
  // knob. 3 gave the lowest held-out error on real calibration sweeps (run costs bend
  // from a fixed floor to growth in the counts within half a decade; 1 cannot follow
  // that and 10 overfits); one input carrying a full period of sin(x) needs about 5
  // (docs/gvm.md).
  double beta_max = 3.0;
  // ResourcePredictor only (Machine::train ignores it): machines trained per output,
  // each from its own seed, whose predictions are averaged.
  int ensemble = 3;
};

struct EpochLoss {
  int epoch;               // 1-based
  double train_loss;       // mean squared error in the scaled [0,1] output space
  double validation_loss;  // same on the validation rows (NaN when there are none)
  double acceptance;       // fraction of this epoch's proposals that were kept
};

struct TrainReport {
  std::vector<EpochLoss> curve;  // one entry per epoch
  double seconds = 0.0;          // wall-clock training time
  int64_t proposals = 0;
  int64_t accepted = 0;
};

// An input value outside the range seen in training (raw, unscaled units).
struct RangeIssue {
  size_t input;
  std::string name;
  double value, min, max;
};

// Everything a trained machine is; kept public so it can be saved and inspected.
struct MachineParams {
  Activation activation = Activation::kSoftsign;
  size_t inputs = 0, outputs = 0, hidden = 0;
  std::vector<std::string> input_names, output_names;
  std::vector<double> in_min, in_max;    // per input, raw units, over the training rows
  std::vector<double> out_min, out_max;  // per output, raw units, over the training rows
  // Affine output map: scaled output = out_a + out_c * s_k, fitted by least squares on
  // the training rows (a sum of +-1-weighted outputs in [-1,1] has no natural scale).
  std::vector<double> out_a, out_c;
  std::vector<double> w;     // hidden x inputs, row-major
  std::vector<double> b;     // hidden
  std::vector<double> beta;  // hidden
  std::vector<int> v;        // outputs x hidden, each -1 or +1
  double w_max = 1.0, b_max = 1.0, beta_max = 1.0;
};

class Machine {
 public:
  Machine() = default;

  // Trains on rows of x (inputs) and y (targets), both in raw units; the scaling is
  // fitted on these rows. A NaN target means that output has no value in that row (it
  // is left out of the loss and the fits). val_x/val_y (may have 0 rows) only feed the
  // reported curve; an output with no value in any row predicts 0. Errors: empty data,
  // mismatched shapes, NaN/inf inputs, infinite targets, bad options.
  static Expected<Machine> train(const Matrix& x, const Matrix& y, const Matrix& val_x,
                                 const Matrix& val_y, const GvmOptions& options,
                                 TrainReport* report, std::vector<std::string> input_names = {},
                                 std::vector<std::string> output_names = {});

  // Builds a machine from saved parameters, checking their shapes and ranges.
  static Expected<Machine> from_params(MachineParams params);

  // Predicts raw-unit outputs y[outputs()] for raw-unit inputs x[inputs()]. No allocation
  // up to 64 inputs.
  void predict(const double* x, double* y) const;
  std::vector<double> predict(const std::vector<double>& x) const;

  // Mean squared error in the scaled [0,1] output space: per output over the rows where
  // y is not NaN, then averaged over outputs. The training loss is the same quantity.
  double loss(const Matrix& x, const Matrix& y) const;

  // Inputs outside [min, max] of the training rows; empty when x is inside.
  std::vector<RangeIssue> check_range(const double* x) const;

  const MachineParams& params() const { return p_; }
  size_t inputs() const { return p_.inputs; }
  size_t outputs() const { return p_.outputs; }

  // JSON text of params(); doubles are written so that they read back bit-exactly.
  std::string to_json() const;
  static Expected<Machine> from_json(const std::string& text);

 private:
  explicit Machine(MachineParams p) : p_(std::move(p)) {}
  MachineParams p_;
};

}  // namespace collido::gvm
