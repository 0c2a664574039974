// The accuracy axis: how a method's contact set differs from the exact
// reference, split into real errors and borderline pairs (exact distance
// within tolerance of the radius, where float rounding may decide either way).
#pragma once

#include "sim/detect.h"

namespace collido::sim {

struct ContactDiff {
  uint64_t missed = 0;      // in the reference, not in the method, and not borderline
  uint64_t invented = 0;    // in the method, not in the reference, and not borderline
  uint64_t borderline = 0;  // differences within tolerance of the radius
  double max_distance_error = 0;  // over pairs both report, world units
  bool exact() const { return missed == 0 && invented == 0; }
};

// Compares contact lists (sorted by particle, then triangle) with tolerance
// `tol` (world units; the contract uses 1e-5 r_max).
ContactDiff compare_contacts(const TriangleMesh& mesh, const Particles& p, const std::vector<Contact>& reference,
                             const std::vector<Contact>& got, double tol);

// Particles near a wall: a `near_fraction` of them centred within `band`
// (world units) of a random surface point, the rest uniform in the bounding box.
Particles particles_near_surface(const TriangleMesh& mesh, size_t n, double r_lo, double r_hi, double near_fraction,
                                 double band, uint64_t seed);

// Adversarial particles: each centred at r (1 + s) from a surface point, s
// uniform in [-rel, rel], so every one is within rel r of touching. A third
// sit off faces along the normal (either side), a third off edges and a third
// off vertices (random directions), where several triangles meet.
Particles particles_touching(const TriangleMesh& mesh, size_t n, double r_lo, double r_hi, double rel,
                             uint64_t seed);

}  // namespace collido::sim
