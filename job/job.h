// One job, end to end: a scene document in; the wall, placement, simulation
// frames, snapshots, per-frame statistics, optional ParaView frames, the
// rendered PNGs, poster, MP4, WebM and GIF, and a result.json manifest out.
// The command line (`collidoscope run`), `collidoscope job-exec` (a job in a
// child process, what the service and a cluster node start) and tests all run
// a job through run_job(). It reports progress through a callback, polls a
// cancellation flag every frame, never prints, exits or throws, and writes
// every file under a temporary name renamed into place, so no file under its
// final name is ever half-written. State is saved at frame boundaries, so a
// killed job resumes where it stopped (JobSpec::dir_policy = kResume).
//
// The entry header of the job module: free of CUDA, Pistache, SQLite, GL and
// FFmpeg types.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "common/status.h"
#include "job/render_run.h"
#include "sim/dynamics.h"

namespace collido::job {

// What to do with an output directory that already holds files.
enum class DirPolicy {
  kRefuse,   // an error names the directory (the default: nothing is lost)
  kReplace,  // the old run's files are removed first (only from a directory that holds a run)
  kResume,   // continue the run saved there from its last checkpoint
};
const char* to_string(DirPolicy p);
bool parse_dir_policy(const std::string& s, DirPolicy* out);

// Limits checked before anything large is allocated; a scene beyond them is
// refused with the figures (kResourceExhausted).
struct Budget {
  uint64_t host_bytes = 0;  // estimated peak host memory; 0 = the memory this machine has
  // (triangle, grid cell) pairs the bin preparation may visit: about 11 s on
  // one thread here (measured: 2.7e8 pairs, wall1 at radius 0.05, took 14.8 s;
  // 4.9e7 took 2.7 s), where a radius of 1e-4 of wall1's size asks for 2.2e10.
  double wall_cells = 2e8;
  double pieces = 5e7;  // wall triangles after division
};

// A job's render defaults: the scene's frame rate (fps 0) and a GIF loop too.
inline RenderSettings job_render_defaults() {
  RenderSettings r;
  r.fps = 0;
  r.gif = true;
  return r;
}

// More CPU threads than any machine here has: a larger count is a mistake.
inline constexpr int kMaxThreads = 4096;

struct JobSpec {
  std::string scene_json;  // the scene document (scene/scene.h)
  // Folder that relative wall files of the scene are found in ("" = the current one).
  std::string scene_dir;
  std::string out_dir;  // the run directory
  DirPolicy dir_policy = DirPolicy::kRefuse;
  int threads = 0;            // CPU threads of this job's pool, 0..kMaxThreads; 0 = the CPUs it may use
  std::string backend;        // "" = the scene's; else auto | cpu | cuda
  double duration = 0;        // > 0: simulated seconds instead of the scene's (a preview)
  bool vtp = false;           // also ParaView frames (vtp/*.vtp, frames.pvd)
  bool render = false;        // render the frames when the run ends
  RenderSettings render_settings = job_render_defaults();  // fps 0 = the scene's frame rate
  // Save the state after a frame once this much wall time has passed since the
  // last save (the last frame is always saved); 0 = after every frame.
  double checkpoint_interval_s = 1.0;
  Budget budget;
};

enum class Stage { kPrepare, kSimulate, kRender, kDone };
const char* to_string(Stage s);

struct Progress {
  Stage stage = Stage::kPrepare;
  uint64_t done = 0, total = 0;  // frames of this stage
  double elapsed_s = 0;          // wall time since the job started
  double eta_s = -1;             // estimated seconds left in the whole job; < 0 = unknown
  uint64_t steps = 0;            // simulation steps so far
  double sim_time = 0;           // simulated seconds so far
  uint64_t contacts = 0;         // wall + particle contacts in the last frame
};

struct Hooks {
  std::function<void(const Progress&)> progress;  // called at least once per frame
  std::function<void(const std::string&)> note;   // warnings and choices made, one line each
  const std::atomic<bool>* cancel = nullptr;       // polled at least once per frame
};

// One file of the results, relative to the run directory.
struct Artifact {
  std::string path;
  uint64_t bytes = 0;
  std::string mime;
  std::string role;  // "video", "gif", "poster", "stats", "scene", "wall", "snapshots", ...
  uint64_t count = 1;  // files: a folder of frames ("frames/") is one artifact
};

// What the job cost, measured.
struct Cost {
  double total_s = 0, prepare_s = 0, simulate_s = 0, render_s = 0;
  uint64_t frames = 0, steps = 0;
  uint64_t peak_host_bytes = 0;    // this process's peak resident set
  uint64_t peak_device_bytes = 0;  // held by the engine's backend (0 on the CPU)
  double gpu_busy_fraction = 0;    // share of the simulation's wall time on the GPU (0 on the CPU)
  // What the steps did (each frame's end counts weighted by its steps; the frames this
  // process ran): what a job's time turns on besides its sizes, kept for the cost model.
  double active_steps = 0, wall_contact_steps = 0, pair_contact_steps = 0;
  // The neighbour lists' builds (each a pass over the particles and the wall's
  // candidates), which particles that move far between steps make often.
  double list_builds = 0;
};

struct JobResult {
  Status status;
  std::string out_dir;
  std::vector<Artifact> artifacts;
  std::vector<std::string> notes;
  Cost cost;
  std::string backend;  // "cpu" or "cuda", as run
  int threads = 0;       // the job's pool
  int step_threads = 0;  // those the steps ran on (1 for a small CPU scene, 0 on the GPU)
  uint64_t particles = 0, triangles = 0;
  uint64_t escaped = 0, invalid = 0;  // at the last frame
  // Frames whose steps showed a failing setting (sim::frame_warnings).
  uint64_t blow_up_frames = 0, tunnel_risk_frames = 0;
  sim::TimeStepInfo time_step;
  // The wall representation as run, and why: "method" / "grid_length" "auto" record the candidates' times.
  std::string method;
  double grid_length = 0;  // m, the wall grid's cell edge as run
  std::string choice;      // the automatic choice's reason (empty when the scene fixed both)
  uint64_t resumed_from_frame = 0;  // > 0 when the job continued a checkpoint
};

// Runs the job; every failure is in result.status (also for a cancelled job,
// kCancelled). result.json in the run directory says the same.
JobResult run_job(const JobSpec& spec, const Hooks& hooks);

// The spec as the JSON document `collidoscope job-exec SPEC.json` reads, and back.
std::string spec_to_json(const JobSpec& spec);
Expected<JobSpec> spec_from_json(const std::string& text);

}  // namespace collido::job
