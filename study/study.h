// The study: speed against accuracy for every detection setting, and where
// the dynamics break (docs/study.md). `collidoscope study` runs it and
// bench/study_charts.py draws it. Rows are measured, never modelled.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "sim/detect.h"
#include "sim/status.h"

namespace collido::sim {
class ThreadPool;
}

namespace collido::study {

struct StudyOptions {
  bool quick = false;                    // the matrix that runs in minutes on 2 cores
  sim::Backend backend = sim::Backend::kCpu;
  std::string mesh_dir = "tests/data/meshes";  // third-party meshes (all .stl files in it)
  std::vector<std::string> scenes;       // detection scenes to run (names); empty = all
  size_t max_particles = 0;              // largest particle count (0 = 10^5 on the CPU, 10^6 on the GPU)
  sim::ThreadPool* pool = nullptr;       // CPU threads; nullptr = default pool
  std::function<void(const std::string&)> progress;  // one line per finished group
};

// One detection setting on one scene: speed, memory and accuracy against the reference.
struct DetectRow {
  std::string backend, scene, placement;  // placement: uniform | near (within 1e-4 r of touching)
  size_t triangles = 0, particles = 0;
  std::string method, traversal, precision;  // precision: exact | float | double (reference)
  double grid_factor = 0, grid_length = 0;  // grid length / r_max, and in world units
  size_t triangles_used = 0;
  double prepare_ms = 0, extra_bytes_per_particle = 0;
  // The setting is timed in two passes (sim::fastest_frames_ms: the fastest
  // of at least sim::kAutoMinFrames frames), in the same rounds as the other
  // settings of its batch (all of them on the CPU, one method and traversal
  // on the GPU): frame_ms is the faster pass, frame_ms_other_pass the slower
  // (what a repeat could give; the charts call one setting faster than
  // another only beyond it).
  double frame_ms = 0, frame_ms_other_pass = 0;
  // The automatic choice's own time for this setting where it was one of its
  // candidates (0: not one), measured apart from the study's two passes.
  double frame_ms_choice = 0;
  uint64_t contacts = 0, missed = 0, invented = 0, band_pairs = 0;
  double max_distance_error = 0;  // over shared pairs, in r_max
  std::string verdict;            // exact | loses_contacts | invents_contacts | failed
  bool is_auto = false;           // what method/grid_length auto picks for this scene
  std::string note;               // failed: why; the automatic choice: its reason (each candidate timed)
};

// One dynamics setting: errors against a 16x finer reference and analytic values.
struct DynamicsRow {
  std::string backend, scene, method;
  double dt_factor = 0, speed_factor = 0;  // step / automatic step; impact speed / the scene's
  bool particle_contacts = false;
  double dt = 0;
  uint64_t steps = 0;
  double trajectory_error = 0;   // largest end-position difference to the reference, radii
  double energy_drift = 0;       // (E_end - E_ref_end) / energy scale
  double restitution_error = -1; // relative, bounce scene (-1: not measured)
  double friction_error = -1;    // relative, bounce scene (-1: not measured)
  uint64_t escaped = 0, tunnelled = 0, invalid = 0;
  std::string warnings;          // what the engine reported (sim::frame_warnings), '; '-joined
  std::string verdict;           // stable | blows_up | tunnels | loses_contacts
};

Status run_detect_study(const StudyOptions& options, std::vector<DetectRow>* rows);
Status run_dynamics_study(const StudyOptions& options, std::vector<DynamicsRow>* rows);

// Writes DIR/study_detect.csv, DIR/study_dynamics.csv (RFC 4180 quoting;
// measurements with no value, such as a blown-up run's trajectory error, left
// empty) and DIR/study.json (both tables plus the machine, the same rows),
// each through a temporary name. A half given as null was not run: its table
// stays as it is, and so does its part of an existing study.json (`study
// --only dynamics` refreshes the dynamics without emptying the detection).
Status write_study(const std::string& dir, const std::vector<DetectRow>* detect,
                   const std::vector<DynamicsRow>* dynamics, const std::string& machine);

}  // namespace collido::study
