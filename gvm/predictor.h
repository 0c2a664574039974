// The resource predictor the service and the command line use: GVMs over the run-log
// features, with the encoding they were trained with, so it answers for a RunConfig.
// Each output has machines of its own (options.ensemble of them, from different seeds,
// averaged): one hidden layer shared by all five costs fitted real calibration sweeps
// worse, and an average of a few seeds is steadier than one (docs/gvm.md).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "gvm/features.h"
#include "gvm/machine.h"
#include "gvm/run_log.h"
#include "gvm/status.h"

namespace collido::gvm {

struct Prediction {
  RunMeasure measure;
  // One line per input outside what the model was trained on, naming the feature
  // ("particles = 2000000 is above the trained range [100, 1000000]"). Empty = in range.
  std::vector<std::string> warnings;
  bool in_range() const { return warnings.empty(); }
};

class ResourcePredictor {
 public:
  ResourcePredictor() = default;

  // Trains the GVMs on train rows; validation rows only feed report->curve, which holds
  // per epoch the mean over outputs and machines. Machines train on several threads;
  // the result does not depend on how many.
  static Expected<ResourcePredictor> train(const std::vector<RunRecord>& train,
                                           const std::vector<RunRecord>& validation,
                                           const GvmOptions& options, TrainReport* report);

  // Predicted costs of one configuration and the range warnings. Errors: invalid config.
  Expected<Prediction> predict(const RunConfig& c) const;

  // Costs only, no checks or allocation beyond the feature vector: the hot path.
  RunMeasure predict_measure(const RunConfig& c) const;

  // The most common device and thread count among training rows of this backend, used
  // for configurations that do not say; nullopt when the backend was never trained.
  std::optional<RunConfig> usual_host(Backend b) const;

  // machines()[k]: the ensemble of output k (empty when no training row had a value).
  const std::vector<std::vector<Machine>>& machines() const { return machines_; }
  const FeatureSpace& features() const { return features_; }
  size_t training_rows() const { return training_rows_; }

  // JSON text (see docs/gvm.md); doubles read back bit-exactly.
  std::string to_json() const;
  static Expected<ResourcePredictor> from_json(const std::string& text);
  Status save(const std::string& path) const;
  static Expected<ResourcePredictor> load(const std::string& path);

 private:
  struct Usual {
    Backend backend;
    std::string device;
    int64_t threads;
  };
  FeatureSpace features_;
  std::vector<std::vector<Machine>> machines_;  // per output, the ensemble
  std::vector<Usual> usual_;
  size_t training_rows_ = 0;
  GvmOptions options_;
  double train_loss_ = 0.0, validation_loss_ = 0.0;
};

// Reads a run configuration from JSON text: {"particles", "triangles", "method",
// "traversal", "frames", "backend"} are required; "triangles_original" (default: the
// triangle count), "device" and "threads" (default: the model's usual host for that
// backend, when model is given) are optional; other keys are ignored so that a whole
// job configuration can be passed. Counts may be written 1e6. Errors name the key.
Expected<RunConfig> run_config_from_json(const std::string& text, const ResourcePredictor* model);

// {"time_per_frame_s", "total_time_s", "peak_host_bytes", "peak_device_bytes", "gpu_load",
//  "in_range", "warnings", "config"} as JSON text, for the command line and the service.
std::string prediction_to_json(const RunConfig& c, const Prediction& p);

}  // namespace collido::gvm
