// The models the GVM is measured against, on the same split: the paper's linear fits of
// time in triangle count (Yong et al. 2018, Eqs. 9-10), ordinary least squares on the
// GVM's log features, and a small multilayer perceptron trained by back-propagation.
#pragma once

#include <cstdint>
#include <vector>

#include "gvm/features.h"
#include "gvm/matrix.h"
#include "gvm/run_log.h"
#include "gvm/status.h"

namespace collido::gvm {

// The paper's model: for a fixed particle count (and a fixed machine and method, as its
// experiments were), every cost is linear in the divided triangle count, t = a*ntri + b.
// One fit per group of equal (particles, method, traversal, backend, device, threads);
// total time = frames * predicted time per frame (the paper models no set-up time).
// A configuration whose group was not trained uses the group of the same kind with the
// nearest log10 particle count, then the nearest group of any kind.
class PaperLinearFit {
 public:
  PaperLinearFit() = default;
  static Expected<PaperLinearFit> fit(const std::vector<RunRecord>& rows);
  RunMeasure predict(const RunConfig& c) const;
  size_t groups() const { return groups_.size(); }

 private:
  struct Group {
    RunConfig key;      // triangles, frames ignored
    double a[4], b[4];  // time per frame, host bytes, device bytes, gpu load
  };
  std::vector<Group> groups_;
};

// Matrix-level fits, for predictors with features of their own (the job cost model
// in job/cost_model.h): inputs x and targets y in raw units (a NaN target is missing
// and left out of that output's fit); inputs are scaled to [0,1] inside.

// Ordinary least squares of each target column on the scaled inputs and an intercept,
// with a tiny ridge for one-hot collinearity and constant columns.
class LinearRegression {
 public:
  LinearRegression() = default;
  static Expected<LinearRegression> fit(const Matrix& x, const Matrix& y);
  // y[outputs] for x[inputs]; an output with no value in training predicts NaN.
  void predict(const double* x, double* y) const;
  size_t inputs() const { return lo_.size(); }
  size_t outputs() const { return coef_.cols(); }

 private:
  std::vector<double> lo_, hi_;  // input scaling
  Matrix coef_;                  // (inputs + 1) x outputs, intercept last
  std::vector<bool> trained_;    // per output
};

struct MlpOptions;

// A one-hidden-layer tanh perceptron with linear outputs, trained by full-batch
// back-propagation (Adam, cosine-decayed rate, best training loss kept); inputs and
// targets scaled to [0,1] inside.
class MlpRegression {
 public:
  MlpRegression() = default;
  static Expected<MlpRegression> fit(const Matrix& x, const Matrix& y, const MlpOptions& options);
  void predict(const double* x, double* y) const;
  size_t inputs() const { return in_lo_.size(); }
  size_t outputs() const { return out_lo_.size(); }

 private:
  std::vector<double> in_lo_, in_hi_, out_lo_, out_hi_;
  size_t hidden_ = 0;
  std::vector<double> w1_, b1_, w2_, b2_;  // hidden x inputs, hidden, outputs x hidden, outputs
};

// Ordinary least squares from the GVM's input features (log10 counts, one-hot
// categories, scaled to [0,1], plus an intercept) to its transformed targets, i.e. a
// power law in every count. A tiny ridge term keeps one-hot collinearity solvable.
class LeastSquaresFit {
 public:
  LeastSquaresFit() = default;
  static Expected<LeastSquaresFit> fit(const std::vector<RunRecord>& rows,
                                       const FeatureSpace& features);
  RunMeasure predict(const RunConfig& c) const;

 private:
  FeatureSpace features_;
  LinearRegression fit_;
};

struct MlpOptions {
  int hidden = 16;    // tanh neurons in the one hidden layer
  int epochs = 10000;  // full-batch Adam steps (cosine-decayed rate)
  double learning_rate = 0.01;
  uint64_t seed = 1;
};

// A one-hidden-layer tanh perceptron with a linear output layer, trained by full-batch
// back-propagation (Adam) on the same scaled inputs and targets as the GVM.
class MlpFit {
 public:
  MlpFit() = default;
  static Expected<MlpFit> fit(const std::vector<RunRecord>& rows, const FeatureSpace& features,
                              const MlpOptions& options);
  RunMeasure predict(const RunConfig& c) const;

 private:
  FeatureSpace features_;
  MlpRegression fit_;
};

}  // namespace collido::gvm
