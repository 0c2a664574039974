// Wall-clock seconds for stage timings and progress estimates. Header-only.
#pragma once

#include <chrono>

namespace collido {

using SteadyClock = std::chrono::steady_clock;

// Seconds from t0 to now on the steady clock.
inline double seconds_since(SteadyClock::time_point t0) {
  return std::chrono::duration<double>(SteadyClock::now() - t0).count();
}

}  // namespace collido
