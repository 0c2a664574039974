// The job cost model: what a job the user submits will cost before it runs (total
// time, time per frame, peak host and device memory, GPU load, output bytes), each
// with a 10-90 % interval, and whether the job lies outside what the model was
// trained on. The service prices every submission with it (admission control trusts
// the memory figure); `collidoscope predict SCENE.json` prints it.
//
// The model is the paper's general vector machine (gvm/machine.h, Monte Carlo
// trained): for each cost an ensemble of GVMs over a job's features (job_features),
// each member trained with one fold of the training rows held out. The held-out
// fold's errors calibrate the interval (split-conformal quantiles of the out-of-fold
// residuals), so the interval is measured on runs the member never saw; docs/gvm.md
// ("Job cost model") gives the choices and their figures.
#pragma once

#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

#include "common/status.h"
#include "gvm/machine.h"
#include "job/job_log.h"

namespace collido::job {

struct JobAssessment;

// A predicted cost: p50 the point prediction, [p10, p90] the interval that held
// 80 % of the held-out fold's runs in training.
struct CostInterval {
  double p10 = 0, p50 = 0, p90 = 0;
};

struct JobCostPrediction {
  CostInterval total_s;            // s, the whole job
  CostInterval per_frame_s;        // s per frame written (simulation and rendering)
  CostInterval peak_host_bytes;    // the job process's peak resident set
  CostInterval peak_device_bytes;  // 0 on the CPU
  CostInterval gpu_load;           // share of the job's wall time in the GPU engine; 0 on the CPU
  CostInterval output_bytes;       // every file the job leaves
  bool outside_training = false;
  // "" when inside; else why, for people ("particles = 200000 is above the trained
  // range [40, 20000]; method 'midpoint4' is not in the training data").
  std::string outside_reason;
  std::vector<std::string> outside_reasons;  // the same, one per line
  std::string backend;                       // "cpu" or "cuda": the backend priced
  std::string device;                        // the device the model was trained on
  int threads = 0;                           // CPU threads priced
  // What drives the cost, from the time-step plan and the scene.
  uint64_t steps = 0, steps_per_frame = 0;
  double particle_steps = 0;  // released particles x steps
  double pair_contacts = 0;   // touching pairs expected, averaged over the run (0 without particle contacts)
  double list_builds = 0;     // the neighbour lists' builds expected over the run (0: no lists)
  double pixel_frames = 0;    // rendered pixels x frames (0 without rendering)
};

// {"backend", "device", "threads", "total_s": {"p10", "p50", "p90"}, ... each cost,
//  "outside_training", "outside_reason", "outside_reasons", "drivers": {...}}
nlohmann::json to_json(const JobCostPrediction& p);
// The prediction's drivers alone (to_json's "drivers"): what its costs follow from.
nlohmann::json drivers_to_json(const JobCostPrediction& p);

// ---- Features ------------------------------------------------------------------

// The model's inputs: logs of counts (costs grow as powers of them) and flags. See
// job_feature_names() for the order; devices one-hot after the fixed block.
inline constexpr size_t kJobFixedFeatures = 29;
const std::vector<std::string>& job_feature_names();  // the fixed block
// Writes kJobFixedFeatures + devices.size() values into x.
void job_features(const JobInputs& in, const std::vector<std::string>& devices, double* x);

// What drives a job's cost, estimated from its inputs (also features, in log form).
struct CostDrivers {
  double mean_active = 1;     // share of the particles released, averaged over the run
  double particle_steps = 0;  // particles x mean_active x steps
  double landed = 0;          // share of the particles resting, averaged over the run (gravity)
  double pair_contacts = 0;   // expected touching pairs, averaged over the run (particle contacts on)
  double near_wall = 0;       // particles within a radius of the wall, if spread evenly
  double near_wall_share = 0;  // share of the released particles near the wall: spread evenly, or landed
  double packing = 0;         // particles' volume over the wall's box volume
  double pixel_frames = 0;    // rendered pixels x frames written
  double snapshot_bytes = 0;  // the frames' snapshots, about 29 bytes a released particle
  double list_builds = 0;     // the neighbour lists' builds expected over the run (0: no lists)
  double pooled_steps = 0;    // steps that hand their passes to the pool (steps_released_beyond)
};
CostDrivers cost_drivers(const JobInputs& in);
// The share of the particles an inlet has released, averaged over a run of `duration`
// s when it releases at a steady rate until release_s (1 for a fill: release_s 0).
double mean_released_share(double release_s, double duration);
// The share of a job's particles that have landed, averaged over its run: each lands a
// free fall after its release (from half the wall's height in a fill, from an inlet
// over its top otherwise); 0 without gravity or before the first lands.
double landed_share(const JobInputs& in);
// The neighbour lists' builds expected over a job's run (expected_list_builds in
// job/cost_model.cpp says how); 0 where the engine keeps no lists.
double expected_list_builds(const JobInputs& in);
// The steps of a job's run during which its inlet has released more than `grain`
// particles (all of them for a fill of more): a pool's pass over fewer runs on the
// calling thread (sim::ThreadPool::run_chunks), so only these steps pay the pool's
// hand-offs.
double steps_released_beyond(const JobInputs& in, double grain);

// ---- Outputs -------------------------------------------------------------------

inline constexpr size_t kJobOutputs = 6;
// "total_s", "per_frame_s", "peak_host_bytes", "peak_device_bytes", "gpu_load", "output_bytes"
const std::vector<std::string>& job_output_names();
// The measure's six costs in that order.
void job_measure_to_array(const JobMeasure& m, double* out);
// Model space: log10 of times and bytes (device bytes log10(1 + b)), GPU load as is;
// a CPU job's device bytes and GPU load are missing (NaN), predicted as exactly 0.
double encode_cost(size_t output, double value, bool cuda);
double decode_cost(size_t output, double y, bool cuda);
// Whether output k reads feature i: the memory peaks do not depend on how many steps
// a job takes, so their machines never see the step counts.
bool job_output_uses_feature(size_t output, size_t feature);

// ---- The model -------------------------------------------------------------------

struct JobCostOptions {
  gvm::GvmOptions gvm;  // per machine (ensemble is ignored: folds set the members)
  int folds = 5;        // members per cost, each trained with one fold held out (2..20)
  double coverage = 0.8;  // of the [p10, p90] interval: its quantiles are (1 -+ coverage) / 2
  JobCostOptions() {
    gvm.hidden = 12;
    gvm.epochs = 800;  // 1000 rows train in under 10 s on 2 cores; 1500 scored the same
  }
};

struct JobTrainReport {
  double seconds = 0;
  std::vector<gvm::EpochLoss> curve;  // mean over every machine, per epoch
  int64_t proposals = 0, accepted = 0;
};

class JobCostModel {
 public:
  JobCostModel() = default;

  // Trains on a job log's rows (any mix of backends and devices). Errors: fewer rows
  // than folds x 2, invalid rows, bad options.
  static Expected<JobCostModel> train(const std::vector<JobRecord>& rows,
                                      const JobCostOptions& options, JobTrainReport* report);

  // The model file: JSON with kind "collidoscope-job-cost-model". A detection-frame
  // model (kind "collidoscope-resource-predictor") is refused with a message that says so.
  static Expected<JobCostModel> load(const std::string& path);
  static Expected<JobCostModel> from_json(const std::string& text);
  std::string to_json() const;
  Status save(const std::string& path) const;

  // The cost of an assessed job run on `backend` ("cpu" or "cuda") with `threads` CPU
  // threads (0 = what the training jobs of that backend used), on the device the model
  // was trained on. kInvalidArgument when the model has no jobs of that backend.
  Expected<JobCostPrediction> predict(const JobAssessment& a, const std::string& backend,
                                      int threads = 0) const;
  // The same for a job log row's inputs (their device and threads as given).
  Expected<JobCostPrediction> predict(const JobInputs& in) const;
  // Point predictions only, no checks (evaluation and benchmarks): out[kJobOutputs].
  void predict_point(const JobInputs& in, double* out) const;
  // The same from the members' priors alone, without their GVMs' corrections (0 for a
  // cost without a prior): what the sums of the cost drivers say.
  void prior_point(const JobInputs& in, double* out) const;

  const std::vector<std::string>& backends() const { return backends_; }
  const std::vector<std::string>& devices() const { return devices_; }
  bool trained_for(const std::string& backend) const;
  size_t training_rows() const { return rows_; }
  // Output k's interval quantiles of the out-of-fold residuals (model space).
  double residual_lo(size_t k) const { return q_lo_[k]; }
  double residual_hi(size_t k) const { return q_hi_[k]; }
  double gvm_weight(size_t k) const { return gvm_weight_[k]; }
  double point_offset(size_t k) const { return point_offset_[k]; }
  // What training showed, kept in the file for people (the service's admin page):
  // the loss per epoch (mean over every machine, at most kKeptEpochs of them, evenly
  // spaced), and each training row's cost k measured against its out-of-fold
  // prediction (the member that never saw it): {measured, predicted} pairs.
  static constexpr size_t kKeptEpochs = 300;
  const std::vector<gvm::EpochLoss>& curve() const { return curve_; }
  const std::vector<std::pair<double, double>>& held_out(size_t k) const { return held_out_[k]; }
  // The above with the training settings and intervals, as JSON.
  nlohmann::json summary() const;

 private:
  struct Usual {
    std::string backend, device;
    int threads;
  };
  // A member's prior (a cost as the sum of what drives it; cost_model.cpp): its
  // weights, and a floor below which no prediction of the prior goes.
  struct Prior {
    std::vector<double> w;
    double floor = 0;
  };
  // A prior at a job's n terms (prior_terms in cost_model.cpp), in model space
  // (encode_cost); 0 where k has none.
  static double prior_value(size_t k, const Prior& p, const double* terms, size_t n, bool cuda);
  // Member m of output k at a job's prior terms and features: its prior plus its GVM.
  double member_point(size_t k, size_t m, const double* terms, size_t n, bool cuda,
                      const double* x) const;
  // Model space; x null: the members' priors alone (NaN where k has none).
  void point(const JobInputs& in, const double* x, double* y) const;
  // Costs from model space (0 where y is NaN).
  static void decode_point(const JobInputs& in, const double* y, double* out);
  std::vector<std::string> check_range(const JobInputs& in, const double* x) const;

  std::vector<std::string> backends_, devices_;
  std::vector<Usual> usual_;
  std::vector<double> x_min_, x_max_;                 // per feature, training rows
  std::vector<std::vector<gvm::Machine>> members_;   // per output
  std::vector<std::vector<Prior>> priors_;           // per output, one per member
  double q_lo_[kJobOutputs] = {}, q_hi_[kJobOutputs] = {};
  // The share of each member's GVM correction added to its prior (times: chosen on
  // the out-of-fold errors in training; else 1).
  double gvm_weight_[kJobOutputs] = {1, 1, 1, 1, 1, 1};
  // Added to every member's point (model space): memory's is raised so few jobs
  // exceed it by more than 5 % (chosen in training); 0 for the other costs.
  double point_offset_[kJobOutputs] = {};
  double coverage_ = 0.8;
  size_t rows_ = 0;
  JobCostOptions options_;
  std::vector<std::string> formats_seen_, methods_seen_, placements_seen_;
  std::vector<gvm::EpochLoss> curve_;
  std::vector<std::pair<double, double>> held_out_[kJobOutputs];
};

// ---- Evaluation against the baselines ----------------------------------------------

struct JobErrors {
  double mape[kJobOutputs] = {};   // % over rows whose true value is not 0 (NaN when none)
  size_t rows[kJobOutputs] = {};
  double host_under5 = 0;          // share of rows whose host peak is under-predicted by > 5 %
  double device_under5 = 0;        // the same for device memory (cuda rows)
  // Share inside [p10, p90] (GVM only; NaN else): of the rows, and for the times of
  // rows that keep their runs (JobMeasure::total_s_runs), of each run.
  double coverage[kJobOutputs] = {};
};

struct JobModelScore {
  std::string name;  // gvm, paper-linear, least-squares, mlp-backprop
  JobErrors validation, train;
  double fit_seconds = 0;
};

struct JobComparison {
  std::vector<JobRecord> train, validation;
  JobCostModel model;
  JobTrainReport report;
  std::vector<JobModelScore> scores;
};

// The 70/30 split of split_seed, the GVM model and the three baselines (the paper's
// per-particle-count linear fit in triangles, least squares and a back-propagation
// MLP on the same features and targets) trained on the same rows, all scored.
Expected<JobComparison> compare_job_models(const std::vector<JobRecord>& rows,
                                           const JobCostOptions& options, uint64_t split_seed,
                                           int mlp_epochs = 10000);

// ---- The machine's pace ------------------------------------------------------------

// How fast the machine runs now against what a model prices: the median of measured
// over predicted total time of its most recent jobs, where more of them ran slower
// (or faster) than priced than chance would put on one side; 1 otherwise. A shared
// machine's speed moves (the 2-vCPU development VM ran the same 280 jobs 17 % slower
// a session after the log's sweep; docs/gvm.md), which a model trained on earlier
// runs cannot see; the service scales its time prices by the pace of the jobs it ran
// last.
struct Pace {
  double factor = 1;  // measured over predicted total time, in [kPaceFastest, kPaceSlowest]
  size_t jobs = 0;    // the jobs it stands on (0: too few, factor 1)
};
inline constexpr size_t kPaceWindow = 25;  // the most recent jobs it reads (10: noisier)
inline constexpr size_t kPaceLeast = 6;    // with fewer, no pace (5 all one way is chance at 5 %)
inline constexpr double kPaceTail = 0.025;  // the sign test's level a side (5 % in all)
// A few odd jobs must not halve or double every price: the factor stays within these.
inline constexpr double kPaceFastest = 0.5, kPaceSlowest = 2.0;
// From the ratios measured / predicted of the most recent jobs, newest first (the
// first kPaceWindow count).
Pace pace_of(const std::vector<double>& ratios);
// The model's pace on finished jobs, newest first: the first kPaceWindow it can
// price count (one it cannot, a zero or non-finite ratio, is skipped).
Pace pace_of(const JobCostModel& model, const std::vector<JobRecord>& newest_first);
// A time interval scaled by the pace.
CostInterval paced(const CostInterval& t, const Pace& pace);

// A model on a job log replayed in the log's order, as the service meets jobs: each
// job's total time priced by the model alone, and scaled by the pace of the jobs
// before it (`gvm replay`).
struct PaceReplay {
  size_t jobs = 0;               // priced
  double mape = 0, paced_mape = 0;    // total time, %
  double holds = 0, paced_holds = 0;  // share of jobs inside the 10-90 % interval
  double last_factor = 1;        // the pace after the last job
};
PaceReplay replay_with_pace(const JobCostModel& model, const std::vector<JobRecord>& in_run_order);

}  // namespace collido::job
