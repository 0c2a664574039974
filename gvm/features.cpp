#include "gvm/features.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

namespace collido::gvm {

namespace {
// Below a nanosecond a time is noise; the floor keeps log10 finite for a 0 in the log.
constexpr double kMinSeconds = 1e-9;
}  // namespace

const std::vector<std::string>& output_feature_names() {
  static const std::vector<std::string> names = {"log10_time_per_frame_s", "log10_total_time_s",
                                                 "log10_1p_peak_host_bytes",
                                                 "log10_1p_peak_device_bytes", "gpu_load"};
  return names;
}

const std::vector<std::string>& measure_names() {
  static const std::vector<std::string> names = {
      "time_per_frame_s", "total_time_s", "peak_host_bytes", "peak_device_bytes", "gpu_load"};
  return names;
}

bool output_uses_input(size_t output, size_t input) {
  const bool per_run = output == 1 || output == 4;  // total time, GPU load
  return input != FeatureSpace::kLogFrames || per_run;
}

void mask_inputs(size_t output, double* x, size_t n) {
  for (size_t i = 0; i < n; ++i)
    if (!output_uses_input(output, i)) x[i] = 0.0;
}

void measure_to_array(const RunMeasure& m, double* out) {
  out[0] = m.time_per_frame_s;
  out[1] = m.total_time_s;
  out[2] = m.peak_host_bytes;
  out[3] = m.peak_device_bytes;
  out[4] = m.gpu_load;
}

RunMeasure array_to_measure(const double* a) {
  return {a[0], a[1], a[2], a[3], a[4]};
}

void encode_outputs(const RunMeasure& m, Backend b, double* y) {
  y[0] = std::log10(std::max(m.time_per_frame_s, kMinSeconds));
  y[1] = std::log10(std::max(m.total_time_s, kMinSeconds));
  y[2] = std::log10(1.0 + std::max(m.peak_host_bytes, 0.0));
  y[3] = std::log10(1.0 + std::max(m.peak_device_bytes, 0.0));
  y[4] = m.gpu_load;
  if (b == Backend::kCpu) y[3] = y[4] = std::numeric_limits<double>::quiet_NaN();
}

RunMeasure decode_outputs(const double* y, Backend b) {
  RunMeasure m;
  m.time_per_frame_s = std::pow(10.0, y[0]);
  m.total_time_s = std::pow(10.0, y[1]);
  m.peak_host_bytes = std::max(0.0, std::pow(10.0, y[2]) - 1.0);
  m.peak_device_bytes = std::max(0.0, std::pow(10.0, y[3]) - 1.0);
  m.gpu_load = std::clamp(y[4], 0.0, 1.0);
  if (b == Backend::kCpu) m.peak_device_bytes = m.gpu_load = 0.0;
  return m;
}

FeatureSpace FeatureSpace::from_rows(const std::vector<RunRecord>& rows) {
  std::set<std::string> seen;
  for (const auto& r : rows) seen.insert(r.config.device);
  return with_devices(std::vector<std::string>(seen.begin(), seen.end()));
}

FeatureSpace FeatureSpace::with_devices(std::vector<std::string> devices) {
  FeatureSpace f;
  f.devices_ = std::move(devices);
  f.build_names();
  return f;
}

void FeatureSpace::build_names() {
  names_ = {"log10_particles",   "log10_triangles",           "log10_triangles_original",
            "log10_frames",      "log10_threads",             "log10_area_per_r2",
            "log10_box_per_r3",  "log10_near_wall_particles", "log10_triangles_per_r2"};
  for (Method m : kAllMethods) names_.push_back(std::string("method=") + method_name(m));
  names_.push_back("traversal=particle");
  names_.push_back("backend=cuda");
  for (const auto& d : devices_) names_.push_back("device=" + d);
}

bool FeatureSpace::knows_device(const std::string& d) const {
  return std::find(devices_.begin(), devices_.end(), d) != devices_.end();
}

void FeatureSpace::encode_inputs(const RunConfig& c, double* x) const {
  auto lg = [](int64_t v) { return std::log10(static_cast<double>(std::max<int64_t>(v, 1))); };
  x[kLogParticles] = lg(c.particles);
  x[kLogTriangles] = lg(c.triangles);
  x[kLogTrianglesOriginal] = lg(c.triangles_original);
  x[kLogFrames] = lg(c.frames);
  x[kLogThreads] = lg(c.threads);
  const double r2 = c.radius * c.radius;
  x[kLogAreaPerR2] = std::log10(c.wall_area / r2);
  x[kLogBoxPerR3] = std::log10(c.wall_box_volume / (r2 * c.radius));
  const double near = std::min(1.0, 2.0 * c.radius * c.wall_area / c.wall_box_volume);
  x[kLogNearWallParticles] = std::log10(std::max(1.0, static_cast<double>(c.particles) * near));
  x[kLogTrianglesPerR2] = std::log10(static_cast<double>(std::max<int64_t>(c.triangles, 1)) * r2 /
                                     c.wall_area);
  for (size_t m = 0; m < 5; ++m) x[kMethodFirst + m] = c.method == kAllMethods[m] ? 1.0 : 0.0;
  x[kTraversal] = c.traversal == Traversal::kParticle ? 1.0 : 0.0;
  x[kBackend] = c.backend == Backend::kCuda ? 1.0 : 0.0;
  for (size_t d = 0; d < devices_.size(); ++d)
    x[kDeviceFirst + d] = devices_[d] == c.device ? 1.0 : 0.0;
}

std::vector<double> FeatureSpace::encode_inputs(const RunConfig& c) const {
  std::vector<double> x(input_count());
  encode_inputs(c, x.data());
  return x;
}

}  // namespace collido::gvm
