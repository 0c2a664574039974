// Held-out evaluation: the 70/30 split of the paper (§5.8), the error measure, and one
// call that trains the GVM and every baseline on the same split and scores them.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "gvm/baselines.h"
#include "gvm/predictor.h"

namespace collido::gvm {

struct RowSplit {
  std::vector<RunRecord> train, validation;
};

// Seeded shuffle, then the first round(train_fraction * n) rows train.
// Errors: fewer than 4 rows, or a fraction that leaves a side with < 1 row (train < 2).
Expected<RowSplit> split_rows(const std::vector<RunRecord>& rows, double train_fraction,
                              uint64_t seed);

// Mean absolute percentage error of one output over the rows whose true value is not 0
// (a CPU run's device bytes and GPU load are 0, where a percentage means nothing).
struct OutputError {
  double mape_percent = 0.0;  // NaN when no row counted
  double mean_abs = 0.0;      // mean |predicted - true| over the same rows, raw units
  size_t rows = 0;
};
using ErrorRow = std::array<OutputError, kOutputCount>;

// MAPE per output (measure_names() order) of a predictor over rows.
ErrorRow mean_abs_percent_error(const std::vector<RunRecord>& rows,
                                const std::function<RunMeasure(const RunConfig&)>& predict);

struct ModelScore {
  std::string name;
  ErrorRow train, validation;
  double fit_seconds = 0.0;
  std::vector<RunMeasure> validation_predictions;  // one per RowSplit::validation row
};

struct CompareOptions {
  GvmOptions gvm;
  MlpOptions mlp;
  uint64_t split_seed = 1;
  double train_fraction = 0.7;
};

struct Comparison {
  RowSplit split;
  ResourcePredictor gvm;
  TrainReport gvm_report;
  std::vector<ModelScore> scores;  // gvm, paper-linear, least-squares, mlp-backprop
};

// Splits rows, trains the GVM and the three baselines on the same training rows and
// scores all of them on both sides.
Expected<Comparison> train_and_compare(const std::vector<RunRecord>& rows,
                                       const CompareOptions& options);

// A made-up cost model for trying the predictor before real logs exist. It is not a
// measurement of the engine and must not be quoted as one. Deterministic in seed.
std::vector<RunRecord> synthetic_run_log(size_t rows, uint64_t seed);

}  // namespace collido::gvm
