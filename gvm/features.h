// The predictor's numbers: how a run configuration becomes the GVM's input vector and
// how measured costs become its targets (and back). Counts enter as log10 because run
// costs span decades and grow roughly as powers of them; categories enter one-hot.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "gvm/run_log.h"

namespace collido::gvm {

// Targets, in order: log10 time per frame, log10 total time, log10(1 + peak host bytes),
// log10(1 + peak device bytes), GPU load. The +1 keeps the CPU backend's 0 device bytes
// finite; GPU load is already a fraction.
inline constexpr size_t kOutputCount = 5;
const std::vector<std::string>& output_feature_names();
// Plain names of the measured quantities ("time_per_frame_s", ...), same order.
const std::vector<std::string>& measure_names();

// RunMeasure fields in output order, raw units.
void measure_to_array(const RunMeasure& m, double* out);
RunMeasure array_to_measure(const double* a);

// Transformed targets y[kOutputCount] of a measure, and back (clamped to valid values).
// A CPU run has no device: its device bytes and GPU load are NaN (missing) targets on
// the way in and exactly 0 on the way out, so no model spends capacity learning a 0.
void encode_outputs(const RunMeasure& m, Backend b, double* y);
RunMeasure decode_outputs(const double* y, Backend b);

// Whether output k reads input i of FeatureSpace's layout. Time per frame is the steady
// cost of one frame and the memory peaks are reached in the first frame, so none of the
// three depends on how many frames a run has: their machines never see the frame count
// (an input a target does not depend on only lets a model fit noise along it). Total
// time and GPU load (busy time over total time) do.
bool output_uses_input(size_t output, size_t input);
// Zeroes, in x[0..n), the inputs output k does not read. Applied to the training rows
// only: an input constant there is frozen in training, and the trained machine scales it
// to 0 at prediction whatever its value, so predictions need no mask.
void mask_inputs(size_t output, double* x, size_t n);

class FeatureSpace {
 public:
  FeatureSpace() = default;
  // The device vocabulary (one-hot columns) is the set of devices in these rows, sorted.
  static FeatureSpace from_rows(const std::vector<RunRecord>& rows);
  static FeatureSpace with_devices(std::vector<std::string> devices);

  // Input vector layout: log10 particles, log10 triangles, log10 triangles_original,
  // log10 frames, log10 max(threads, 1), the geometry block (below), one-hot method (5),
  // traversal == particle, backend == cuda, one-hot device (vocabulary order).
  // Geometry, dimensionless so that a scene's unit of length does not matter (r = radius,
  // A = wall_area, V = wall_box_volume): log10 A / r^2 (the wall's size in grid cells of
  // its surface), log10 V / r^3 (cells of the domain box), log10 of the particles near
  // the wall, max(1, particles * min(1, 2 r A / V)) (uniformly placed particles within
  // r of the surface: the ones that meet triangles), log10 triangles * r^2 / A
  // (triangles per r^2 of surface: the length of a cell's triangle list).
  size_t input_count() const { return names_.size(); }
  const std::vector<std::string>& input_names() const { return names_; }
  const std::vector<std::string>& devices() const { return devices_; }
  bool knows_device(const std::string& d) const;

  // Writes input_count() values into x.
  void encode_inputs(const RunConfig& c, double* x) const;
  std::vector<double> encode_inputs(const RunConfig& c) const;

  // Indices of the named blocks, for messages about a feature.
  static constexpr size_t kLogParticles = 0, kLogTriangles = 1, kLogTrianglesOriginal = 2,
                          kLogFrames = 3, kLogThreads = 4, kLogAreaPerR2 = 5, kLogBoxPerR3 = 6,
                          kLogNearWallParticles = 7, kLogTrianglesPerR2 = 8, kMethodFirst = 9,
                          kTraversal = 14, kBackend = 15, kDeviceFirst = 16;

 private:
  void build_names();
  std::vector<std::string> devices_;
  std::vector<std::string> names_;
};

}  // namespace collido::gvm
