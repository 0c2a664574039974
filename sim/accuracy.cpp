#include "sim/accuracy.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "sim/narrow_phase.h"
#include "sim/particles.h"

namespace collido::sim {

ContactDiff compare_contacts(const TriangleMesh& mesh, const Particles& p, const std::vector<Contact>& reference,
                             const std::vector<Contact>& got, double tol) {
  std::unordered_map<uint32_t, size_t> by_id;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) by_id[mesh.source_ids[t]] = t;
  auto exact = [&](const Contact& c) {
    const size_t t = by_id.at(c.triangle);
    return std::sqrt(point_triangle_dist2(Vec3d{p.x[c.particle], p.y[c.particle], p.z[c.particle]},
                                          mesh.corner(t, 0), mesh.corner(t, 1), mesh.corner(t, 2)));
  };
  auto less = [](const Contact& a, const Contact& b) {
    return a.particle != b.particle ? a.particle < b.particle : a.triangle < b.triangle;
  };
  ContactDiff d;
  size_t i = 0, j = 0;
  while (i < reference.size() || j < got.size()) {
    if (j == got.size() || (i < reference.size() && less(reference[i], got[j]))) {
      const Contact& c = reference[i++];
      (std::fabs(c.distance - p.r[c.particle]) <= tol ? d.borderline : d.missed)++;
    } else if (i == reference.size() || less(got[j], reference[i])) {
      const Contact& c = got[j++];
      (std::fabs(exact(c) - p.r[c.particle]) <= tol ? d.borderline : d.invented)++;
    } else {
      d.max_distance_error = std::max(d.max_distance_error, std::fabs(reference[i].distance - got[j].distance));
      ++i, ++j;
    }
  }
  return d;
}

Particles particles_near_surface(const TriangleMesh& mesh, size_t n, double r_lo, double r_hi, double near_fraction,
                                 double band, uint64_t seed) {
  SplitMix64 rng(seed);
  const Bounds3d box = mesh_bounds(mesh);
  // Pick surface points by area so a dense patch of small triangles is not favoured.
  std::vector<double> cdf(mesh.triangles.size());
  double total = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    cdf[t] = total += triangle_area(mesh.corner(t, 0), mesh.corner(t, 1), mesh.corner(t, 2));
  Particles p;
  p.resize(n);
  const size_t near = static_cast<size_t>(near_fraction * static_cast<double>(n));
  for (size_t i = 0; i < n; ++i) {
    Vec3d c;
    if (i < near) {
      const size_t t = std::lower_bound(cdf.begin(), cdf.end(), rng.uniform() * total) - cdf.begin();
      double u = rng.uniform(), v = rng.uniform();
      if (u + v > 1) u = 1 - u, v = 1 - v;
      const Vec3d a = mesh.corner(t, 0), b = mesh.corner(t, 1), e = mesh.corner(t, 2);
      Vec3d dir{rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)};
      dir = dir * (1.0 / std::max(1e-12, length(dir)));
      c = a + (b - a) * u + (e - a) * v + dir * rng.uniform(0, band);
    } else {
      c = {rng.uniform(box.lo.x, box.hi.x), rng.uniform(box.lo.y, box.hi.y), rng.uniform(box.lo.z, box.hi.z)};
    }
    p.x[i] = c.x, p.y[i] = c.y, p.z[i] = c.z;
    p.r[i] = r_lo == r_hi ? r_lo : rng.uniform(r_lo, r_hi);
  }
  return p;
}

Particles particles_touching(const TriangleMesh& mesh, size_t n, double r_lo, double r_hi, double rel,
                             uint64_t seed) {
  SplitMix64 rng(seed);
  Particles p;
  p.resize(n);
  const size_t m = mesh.triangles.size();
  for (size_t i = 0; i < n && m; ++i) {
    const size_t t = rng.next() % m;
    const Vec3d a = mesh.corner(t, 0), b = mesh.corner(t, 1), c = mesh.corner(t, 2);
    const double r = r_lo == r_hi ? r_lo : rng.uniform(r_lo, r_hi);
    const double s = rng.uniform(-rel, rel);
    Vec3d on, dir;
    Vec3d random{rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)};
    random = random * (1.0 / std::max(1e-12, length(random)));
    switch (i % 3) {
      case 0: {  // off the face, along its normal
        double u = rng.uniform(), v = rng.uniform();
        if (u + v > 1) u = 1 - u, v = 1 - v;
        on = a + (b - a) * u + (c - a) * v;
        const Vec3d nrm = cross(b - a, c - a);
        const double len = length(nrm);
        dir = len > 0 ? nrm * ((rng.next() & 1 ? 1.0 : -1.0) / len) : random;
        break;
      }
      case 1: {  // off an edge
        const int k = static_cast<int>(rng.next() % 3);
        const Vec3d e0 = mesh.corner(t, k), e1 = mesh.corner(t, (k + 1) % 3);
        on = e0 + (e1 - e0) * rng.uniform();
        const Vec3d e = e1 - e0;
        const double e2 = dot(e, e);
        dir = e2 > 0 ? random - e * (dot(random, e) / e2) : random;  // perpendicular to the edge
        dir = dir * (1.0 / std::max(1e-12, length(dir)));
        break;
      }
      default:  // off a vertex
        on = mesh.corner(t, static_cast<int>(rng.next() % 3));
        dir = random;
    }
    const Vec3d centre = on + dir * (r * (1 + s));
    p.x[i] = centre.x, p.y[i] = centre.y, p.z[i] = centre.z, p.r[i] = r;
  }
  return p;
}

}  // namespace collido::sim
