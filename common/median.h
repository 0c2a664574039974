// The median of a set of measures: the middle one, or the mean of the middle two.
// The calibration sweeps keep a frame's median time, the job log a job's repeats'
// median, and the service's pace the median of its newest jobs' ratios.
// Header-only, so every module can use it without linking anything.
#pragma once

#include <algorithm>
#include <vector>

namespace collido {

// v must not be empty.
inline double median_of(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace collido
