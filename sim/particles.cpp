#include "sim/particles.h"

#include <cmath>
#include <cstdlib>
#include <fstream>

#include "common/atomic_file.h"

namespace collido::sim {

Particles random_particles(size_t n, const Bounds3d& box, double r_min, double r_max, uint64_t seed) {
  Particles p;
  p.resize(n);
  SplitMix64 rng(seed);
  for (size_t i = 0; i < n; ++i) {
    p.x[i] = rng.uniform(box.lo.x, box.hi.x);
    p.y[i] = rng.uniform(box.lo.y, box.hi.y);
    p.z[i] = rng.uniform(box.lo.z, box.hi.z);
    p.r[i] = r_min == r_max ? r_min : rng.uniform(r_min, r_max);
  }
  return p;
}

Expected<Particles> load_particles_csv(const std::string& path) {
  std::ifstream in(path);
  if (!in) return open_failure(path, path + ": cannot open for reading");
  Particles p;
  std::string line;
  size_t lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.find_first_not_of(" \t") == std::string::npos || line[0] == '#') continue;
    double v[4];
    const char* s = line.c_str();
    bool ok = true;
    for (int k = 0; k < 4 && ok; ++k) {
      char* end = nullptr;
      v[k] = std::strtod(s, &end);
      if (end == s) ok = false;
      s = end;
      while (*s == ' ' || *s == '\t') ++s;
      if (k < 3) {
        if (*s != ',') ok = false;
        ++s;
      }
    }
    if (ok && *s != '\0') ok = false;
    if (!ok) {
      if (lineno == 1 && p.size() == 0) continue;  // a header such as "x,y,z,r"
      return parse_error(path + ": line " + std::to_string(lineno) + ": expected 4 numbers x,y,z,r");
    }
    if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]) || !std::isfinite(v[3]))
      return parse_error(path + ": line " + std::to_string(lineno) + ": non-finite value");
    if (!(v[3] > 0))
      return parse_error(path + ": line " + std::to_string(lineno) + ": radius must be > 0");
    p.x.push_back(v[0]), p.y.push_back(v[1]), p.z.push_back(v[2]), p.r.push_back(v[3]);
  }
  if (p.size() == 0) return parse_error(path + ": no particles");
  return p;
}

double max_radius(const Particles& p) {
  double m = 0;
  for (double r : p.r) m = std::max(m, r);
  return m;
}

}  // namespace collido::sim
