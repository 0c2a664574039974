// Particle sets for detection: reproducible random scenes and CSV input.
#pragma once

#include <cstdint>
#include <string>

#include "sim/detect.h"
#include "sim/mesh.h"

namespace collido::sim {

// A small, fast, portable generator (SplitMix64): the same seed gives the same
// scene on every compiler, which std::uniform_real_distribution does not promise.
struct SplitMix64 {
  uint64_t state;
  explicit SplitMix64(uint64_t seed) : state(seed) {}
  uint64_t next() {
    uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [0, 1), 53 random bits.
  double uniform() { return static_cast<double>(next() >> 11) * (1.0 / 9007199254740992.0); }
  double uniform(double a, double b) { return a + (b - a) * uniform(); }
};

// n particles uniform in `box` with radii uniform in [r_min, r_max] (world units).
Particles random_particles(size_t n, const Bounds3d& box, double r_min, double r_max, uint64_t seed);

// Reads x,y,z,r rows (a header line is allowed); errors name the file and line.
Expected<Particles> load_particles_csv(const std::string& path);

// Largest radius in the set (0 when empty).
double max_radius(const Particles& p);

}  // namespace collido::sim
