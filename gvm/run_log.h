// The log of real runs: one row per finished job, its inputs (what was asked) and its
// outputs (what it cost). The predictor trains on it; the service keeps the same
// columns in SQLite. Files are CSV with a header line (RFC 4180 quoting).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "gvm/status.h"

namespace collido::gvm {

// How triangles are prepared, as the engine names them (DESIGN.md "The engine").
enum class Method { kGravity, kCircumcircle, kMidpoint4, kBin, kReference };
enum class Traversal { kWall, kParticle };
enum class Backend { kCpu, kCuda };

inline constexpr Method kAllMethods[] = {Method::kGravity, Method::kCircumcircle,
                                         Method::kMidpoint4, Method::kBin, Method::kReference};

// Lower-case names used in CSV, JSON and on the command line ("gravity", "wall", "cpu").
const char* method_name(Method m);
const char* traversal_name(Traversal t);
const char* backend_name(Backend b);
std::optional<Method> parse_method(const std::string& s);
std::optional<Traversal> parse_traversal(const std::string& s);
std::optional<Backend> parse_backend(const std::string& s);

// What a run is asked to do: the predictor's inputs.
struct RunConfig {
  int64_t particles = 0;           // number of particles
  int64_t triangles = 0;           // triangles after division (= original for bin/reference)
  int64_t triangles_original = 0;  // triangles of the mesh as loaded
  // The wall and particle geometry behind per-frame cost, all known before a run from
  // the scene. The predictor uses them only as ratios (area / radius^2 and so on), so a
  // scene's unit of length does not matter.
  double radius = 1.0;           // largest particle radius, world units
  double wall_area = 1.0;        // total triangle area of the wall as loaded, units^2
  double wall_box_volume = 1.0;  // wall's bounding box grown by radius on every side, units^3
  Method method = Method::kBin;
  Traversal traversal = Traversal::kParticle;
  int64_t frames = 1;  // frames simulated
  Backend backend = Backend::kCpu;
  std::string device;   // "NVIDIA H100 80GB HBM3", "AMD EPYC 7763", ...
  int64_t threads = 1;  // CPU worker threads (for cuda runs: the host threads used)
};

// What a run cost: the predictor's outputs.
struct RunMeasure {
  double time_per_frame_s = 0.0;   // wall-clock seconds per frame (detection + dynamics)
  double total_time_s = 0.0;       // wall-clock seconds of the whole run, set-up included
  double peak_host_bytes = 0.0;    // peak resident host memory, bytes
  double peak_device_bytes = 0.0;  // peak device memory, bytes (0 on the CPU backend)
  double gpu_load = 0.0;           // mean GPU utilisation in [0, 1] (0 on the CPU backend)
};

struct RunRecord {
  RunConfig config;
  RunMeasure measure;
};

// The CSV columns in the order they are written.
const std::vector<std::string>& run_log_columns();

// Checks a configuration's values (counts >= 1, threads >= 0, geometry finite and > 0);
// names the bad field.
Status validate(const RunConfig& c);
// Checks measured values (finite, >= 0, gpu_load <= 1); names the bad field.
Status validate(const RunMeasure& m);

// Parses CSV text. Columns may come in any order and unknown columns are ignored (the
// service may add its own); every known column is required. Errors name the line
// (1-based, header = line 1) and the column (1-based and by name).
Expected<std::vector<RunRecord>> parse_run_log(const std::string& text);
// Writes CSV text with a header line; doubles with 17 significant digits (round trip).
std::string format_run_log(const std::vector<RunRecord>& rows);
// Its header line and one row's record, each without the line break: a record
// may span lines (a quoted device name with a line break), so a writer that
// adds columns adds them to the record, not to a line of the text.
std::string run_log_header();
std::string format_run_log_row(const RunRecord& r);

// Combines repeated measurements of one configuration (rows whose RunConfig is equal in
// every field, e.g. two sweeps with the same seed) into one row, as `calibrate` combines
// its repeats: other work on a machine only adds time, so the smallest time per frame
// and the fastest run's total time and GPU load are kept, and the largest memory (a
// peak). Rows keep the order of their configuration's first appearance.
std::vector<RunRecord> merge_repeats(const std::vector<RunRecord>& rows);

// File versions of the two above.
Expected<std::vector<RunRecord>> read_run_log(const std::string& path);
Status write_run_log(const std::string& path, const std::vector<RunRecord>& rows);

}  // namespace collido::gvm
