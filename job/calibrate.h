// Calibration: a seeded sweep of real, small detection configurations run on this
// machine with the backend at hand, one row each in the run-log format the predictor
// trains on and the service stores (gvm/run_log.h). `collidoscope calibrate`, a
// service worker and a cluster node all run it through calibrate().
//
// Every configuration runs in a process of its own, `collidoscope calibrate-exec
// REQUEST --result-fd 3`, started with posix_spawn (job/subprocess.h; never fork()
// from a threaded process, and CUDA does not survive a fork), so that its peak memory
// is its own and a configuration that crashes or exhausts memory costs one row, not
// the sweep. The child sends its measurements as one JSON line. The wall survey and
// the GPU probe run in children too: the caller never holds a wall, an engine thread
// pool or a CUDA context for the sweep.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>

#include "common/status.h"

namespace collido::job {

struct CalibrateSpec {
  std::string backend = "auto";  // cpu | cuda | auto (cuda when a GPU is usable)
  int64_t configs = 300;         // configurations in the sweep, 1..100000
  uint64_t seed = 1;             // fixes the sweep and every configuration's particles
  bool quick = false;            // tiny sweep (small walls, <= 2000 particles, <= 3 frames)
  int threads = 0;               // CPU threads of every run, 0..4096; 0 = all a run may use
  int repeats = 3;               // passes over the sweep, 1..100
  double budget_s = 0;           // seconds; no run starts after this (0 = no limit)
  // Largest particle radius, % of the wall's longest side, 0.01 <= lo <= hi <= 50;
  // lo < hi draws one per configuration, log-uniform.
  double radius_lo_pct = 1, radius_hi_pct = 1;
  std::string out_path;    // run-log CSV, rewritten (whole, renamed into place) after every run
  std::string executable;  // the `collidoscope` binary each run is started from
};

// The spec `collidoscope calibrate` starts from: on cuda 200 configurations, 2 repeats
// and a 330 s budget (a GPU machine's call is limited), on cpu 300 and 3 repeats;
// 6 configurations and no budget with quick.
CalibrateSpec calibrate_defaults(const std::string& backend, bool quick);

// Checks a spec's values; kInvalidArgument names the field.
Status validate(const CalibrateSpec& spec);

// One run of the sweep: reported as it starts and again when it ends.
struct CalibrateProgress {
  int pass = 0, passes = 0;     // 1-based pass over the sweep (a repeat), of passes
  size_t index = 0, count = 0;  // 1-based configuration, of count
  std::string backend;          // "cpu" or "cuda": the sweep's
  std::string running;          // "bin/particle wall1 r=0.5, 1000 particles x 3 frames"
  bool finished = false;        // false: about to start; true: it ended
  std::string error;            // finished: why it failed ("" = it measured)
  // Finished and measured: this run's figures.
  int64_t triangles = 0;         // after division
  double frame_s = 0;            // steady seconds per frame
  double total_s = 0;            // seconds, set-up and the run's frames
  double peak_host_bytes = 0;    // the run's own process
  double device_bytes = 0;       // held by the detector after preparation (0 on cpu)
  size_t rows = 0;               // rows in the log now
};

struct CalibrateHooks {
  std::function<void(const CalibrateProgress&)> progress;  // twice per run
  std::function<void(const std::string&)> note;  // the plan, choices made, one line each
  // Polled between runs and every 100 ms during one (the run is then killed).
  const std::atomic<bool>* cancel = nullptr;
};

struct CalibrateSummary {
  std::string backend;  // "cpu" or "cuda", as run
  std::string device;   // the name the sweep's rows carry (the reference's: the CPU's)
  size_t configs = 0, measured = 0, failed = 0;  // measured rows are in the log
  int repeats = 0;
  bool out_of_budget = false;  // budget_s ran out before every pass ended
  double took_s = 0;           // seconds from the survey to the last run
};

// Runs the sweep, rewriting spec.out_path after every run so an interrupted sweep
// keeps what it measured. Configurations that fail are counted in the summary (and
// left out of the log); the status is an error when the spec is invalid, the log
// cannot be written, cuda was asked for and no GPU is usable, the wall survey fails,
// no configuration was measured, or the sweep was cancelled (kCancelled).
Expected<CalibrateSummary> calibrate(const CalibrateSpec& spec, const CalibrateHooks& hooks);

// This machine's CPU model name (/proc/cpuinfo), "cpu" where it cannot be read.
std::string cpu_model_name();

// The name of the GPU a `collidoscope calibrate-exec` child finds, asked in that
// child so the caller never holds a CUDA context; kBackend when none is usable.
Expected<std::string> probe_gpu(const std::string& executable,
                                const std::atomic<bool>* cancel = nullptr);

// What `collidoscope calibrate-exec REQUEST --result-fd N` runs in the child: one
// request of a sweep (the GPU probe, the wall survey or one configuration), given as
// the JSON calibrate() writes. *result_line is always set: one JSON line (newline
// included) for the parent, with the child's own peak resident bytes.
Status calibrate_exec(const std::string& request_json, std::string* result_line);

}  // namespace collido::job
