// The job sweep: a seeded set of real jobs (walls, particle counts and sizes,
// placements, particle contacts, friction, duration and frame rate, rendering) run
// on this machine, each through `collidoscope job-exec` in a process of its own as the
// service runs them, one job-log row each (job/job_log.h). `collidoscope calibrate
// --jobs`, a service worker and a cluster node all run it through calibrate_jobs().
//
// Every job's inputs come from assess_job() and the time-step plan before it runs;
// its cost from the result.json the job writes: wall time per stage, the job
// process's own peak resident set (VmHWM, common/process_memory.h), the engine's
// device memory and GPU share, and the bytes of every file it left.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>

#include "common/status.h"
#include "job/calibrate.h"

namespace collido::job {

struct JobSweepSpec {
  std::string backend = "cpu";  // cpu | cuda (cuda fails when no GPU is usable)
  int64_t configs = 300;        // jobs in the sweep, 1..100000
  uint64_t seed = 1;            // fixes every drawn job
  bool quick = false;           // tiny jobs (tests): two small walls, <= 300 particles
  int threads = 1;              // CPU threads of every job, 0..4096 (0 = all it may use)
  int repeats = 3;              // passes over the sweep, 1..100
  double budget_s = 0;          // seconds; no job starts after this (0 = no limit)
  bool render = true;           // draw rendered jobs too (the executable needs a renderer)
  // Share of the jobs with gravity drawn long enough for their particles to land
  // (1.5 to 3 falls across the wall's height), fewer particles keeping them within
  // ten times the usual work: the settled piles a user's job of seconds spends most
  // of its steps in. Drawn from a stream of its own, so 0 reproduces the sweeps before it.
  double settled_share = 0;
  // Each job's bound on particle-steps drawn log-uniformly between the usual bound and
  // this many times it (1: the usual bound for every job). At one bound, every job of
  // many particles is trimmed to the same particle-steps, and a model cannot tell a
  // cost a particle-step from a cost a particle; drawn, the work of a job varies as a
  // user's does. From a stream of its own, so 1 reproduces the sweeps before it.
  double work_spread = 1;
  // Folder of STL walls the sweep may draw (teapot, 3ds Max export, sphere with a
  // hole from tests/data/meshes); "" or missing = parametric walls only.
  std::string mesh_dir;
  std::string out_path;    // job log CSV, rewritten (whole, renamed into place) after every job
  std::string work_dir;    // where run directories are made; tidied when the sweep ends
  std::string executable;  // the `collidoscope` binary each job is started from
};

// Checks a spec's values; kInvalidArgument names the field.
Status validate(const JobSweepSpec& spec);

// The sweep's walls, for the docs and the unseen-scene check: parametric specs and,
// when mesh_dir has them, these STL files.
const std::vector<std::string>& job_sweep_shapes();
const std::vector<std::string>& job_sweep_meshes();

// Runs the sweep; progress through hooks (CalibrateProgress: total_s, frame_s the
// time per frame, peak_host_bytes, device_bytes). Jobs that fail are counted in the
// summary and left out of the log; the status is an error when the spec is invalid,
// the log cannot be written, cuda was asked for and no GPU is usable, no job was
// measured, or the sweep was cancelled.
Expected<CalibrateSummary> calibrate_jobs(const JobSweepSpec& spec, const CalibrateHooks& hooks);

}  // namespace collido::job
