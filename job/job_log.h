// The job log: one row per finished job, what it was asked to do (every input known
// before it runs, from the scene through assess_job()) and what it cost. The job cost
// model (job/cost_model.h) trains on it; `collidoscope calibrate --jobs` writes it.
// Files are CSV with a header line, as the detection run log (gvm/run_log.h), whose
// columns differ: the header says which kind a log is (log_kind).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/status.h"

namespace collido::job {

struct JobAssessment;

// What a job was asked to do: the cost model's inputs. Lengths in metres.
struct JobInputs {
  std::string wall;             // the wall spec or file name (a label; not an input of the model)
  uint64_t particles = 0;
  uint64_t triangles = 0;       // of the wall as loaded
  double pieces = 0;            // triangles after division, estimated (= triangles for bin)
  double wall_cells = 0;        // (triangle, cell) pairs the bin preparation visits (0 if divided)
  // The wall index's footprint (sim/wall_footprint.h): the (cell, triangle) pairs
  // the bin method stores, and the wall grid's buckets. NaN: a log written before
  // they were recorded (the cost model then falls back to wall_cells and the box).
  double bin_entries = __builtin_nan(""), wall_buckets = __builtin_nan("");
  double wall_area = 0;         // m^2
  double box[3] = {0, 0, 0};    // m: the wall's bounding-box sides
  double r_min = 0, r_max = 0;  // m
  std::string method = "bin";   // bin, bvh, gravity, circumcircle, midpoint4
  std::string placement = "fill";  // fill, pour, jet
  double release_s = 0;            // s: when an inlet releases its last particle (0 for fill)
  bool particle_contacts = false;
  double friction = 0;           // Coulomb coefficient
  // Of the particle-wall contact (the wall's material where the scene sets one). How
  // long landed particles bounce before they rest on the wall follows from it (a
  // settled fill's cost 6x apart between 0.3 and 0.9); recorded, not yet read by the
  // cost model (docs/gvm.md, "Restitution"). NaN: a log written before it was recorded.
  double restitution = __builtin_nan("");
  double gravity = 9.81;         // |g|, m/s^2
  // m/s: the particles' speed as they start (sim::ReleasePlan::speed: an inlet's or a
  // fill's velocity); how soon the neighbour lists are built again follows from it.
  // NaN: a log written before it was recorded (stop 62).
  double start_speed = __builtin_nan("");
  // 1 where the wall is open (an edge not shared by exactly two triangles of opposite
  // turns, sim::is_closed_manifold), else 0: a fill tells an open wall's sites in and
  // out by winding numbers over every triangle, and an inlet's places too, where a
  // closed wall's need a few rays a group. NaN: a log written before it was recorded
  // (stop 63).
  double wall_open = __builtin_nan("");
  double duration = 0;           // simulated seconds
  double fps = 0;                // frames per simulated second
  uint64_t frames = 0;           // written after the initial one
  double step_s = 0;             // the planned step (sim::plan_steps)
  uint64_t steps_per_frame = 0;  // planned
  uint64_t steps = 0;            // planned, over every frame
  int render_width = 0, render_height = 0;  // pixels; 0 x 0 = no rendering
  std::string formats = "none";  // videos asked for, '+'-joined: "mp4+webm+gif", or "none"
  std::string backend = "cpu";   // cpu, cuda: as the job runs
  std::string device;            // the CPU's or GPU's name
  int threads = 1;               // CPU threads of the job's pool

  bool renders() const { return render_width > 0 && render_height > 0; }
  bool has_format(const std::string& f) const;
};

// What a job cost, measured (result.json's cost, the artifacts' sizes).
struct JobMeasure {
  double total_s = 0;          // wall seconds, start to result.json
  double prepare_s = 0;        // scene, wall, placement, engine set-up, first files
  double simulate_s = 0;       // every frame: steps, snapshots, statistics, checkpoints
  double render_s = 0;         // PNGs, poster and videos (0 without rendering)
  double per_frame_s = 0;      // (simulate_s + render_s) / frames written (the initial one too)
  double peak_host_bytes = 0;  // the job process's own peak resident set (VmHWM)
  double peak_device_bytes = 0;  // held by the engine on the GPU (0 on the CPU)
  double gpu_load = 0;           // share of the job's wall time inside the GPU engine (0 on the CPU)
  double output_bytes = 0;       // every file of the run directory
  uint64_t steps_taken = 0;      // measured: the plan's check, not a model output
  double load_avg = 0;           // the machine's 1-minute load when the job started (a note)
  // What the steps did, measured (result.json's cost; notes, not model outputs): the
  // sums over frames of the active particles, wall contacts and particle pairs in
  // contact at each frame's end times its steps. NaN where a log predates them.
  double active_steps = kNotRecorded, wall_contact_steps = kNotRecorded,
         pair_contact_steps = kNotRecorded;
  double list_builds = kNotRecorded;  // the neighbour lists' builds (NaN before stop 61)
  static constexpr double kNotRecorded = __builtin_nan("");
  // Each run's total time and time per frame where the row merges repeats of one job
  // (merge_job_repeats; the row's own times are their medians), in run order; empty
  // where the row is one run. A user's job is one run, so the cost model sets its
  // interval by these (docs/gvm.md, "Intervals for one run").
  std::vector<double> total_s_runs, per_frame_s_runs;
};

struct JobRecord {
  JobInputs inputs;
  JobMeasure measure;
};

// The inputs of an assessed job run on `backend` ("cpu" or "cuda") by `device` with
// `threads` CPU threads (0 = what the job's pool would take: this machine's CPUs).
JobInputs job_inputs(const JobAssessment& a, const std::string& backend,
                     const std::string& device, int threads);

// A finished job's measure from its manifest (the run directory's result.json text):
// times per stage, peaks, GPU share of the whole job, steps taken, and the bytes of
// every artifact. *backend (when given) is the backend the job ran on. A run resumed
// from a checkpoint has no measure (its times are its last attempt's alone).
Expected<JobMeasure> job_measure_from_manifest(const std::string& result_json,
                                               std::string* backend = nullptr);

// The CSV columns in the order they are written: every one is required on reading
// but the optional ones (the measured notes added since the first logs), which are
// read when present and written empty when not recorded.
const std::vector<std::string>& job_log_columns();
const std::vector<std::string>& job_log_optional_columns();

// Checks the values (counts, finite sizes, known names); names the bad field.
Status validate(const JobInputs& in);
Status validate(const JobMeasure& m);

// Parses CSV text: columns in any order, unknown ones ignored, every listed one
// required. Errors name the line and the column.
Expected<std::vector<JobRecord>> parse_job_log(const std::string& text);
// CSV text with a header line; doubles with 17 significant digits (round trip).
std::string format_job_log(const std::vector<JobRecord>& rows);
// Its header line and one row's record, each without the line break: a record
// may span lines (a quoted field with a line break), so a writer that adds
// columns adds them to the record, not to a line of the text.
std::string job_log_header();
std::string format_job_log_row(const JobRecord& r);
Expected<std::vector<JobRecord>> read_job_log(const std::string& path);
Status write_job_log(const std::string& path, const std::vector<JobRecord>& rows);

// Combines repeated runs of one job (rows whose inputs are equal in every column):
// the median of their times (total, each stage's, per frame; the middle one, or the
// mean of the middle two, each time on its own, so the stages of a merged row add up
// to its total only nearly) and of their GPU loads, and the largest memory and output
// (peaks); the first run's other notes. First-appearance order. The merged row keeps
// every run's total and time per frame (JobMeasure::total_s_runs; a row that merged
// runs before gives each of its own, and the median is over all of them). The
// median, not the fastest run: on the 2-vCPU VM a run's pace moves both ways around
// its usual value, and the fastest of a few runs is one end of that scatter
// (docs/gvm.md, "The logs": a model held out on the same 846 jobs scored 17.1 %
// against the fastest of two runs, 17.5 against the fastest of four, 14.2 against
// the median of four).
std::vector<JobRecord> merge_job_repeats(const std::vector<JobRecord>& rows);

// Which kind of log a CSV text is, from its header line: detection frames
// (gvm/run_log.h), jobs (this file), or neither.
enum class LogKind { kDetection, kJob, kUnknown };
LogKind log_kind(const std::string& csv_text);
const char* to_string(LogKind k);

}  // namespace collido::job
