// Where a run's particles start: filling a region inside the vessel without
// overlaps, or released over time from an inlet (a pour, or a jet with a velocity).
#pragma once

#include <cstdint>
#include <string>

#include "sim/dynamics.h"
#include "sim/mesh.h"

namespace collido::sim {

struct ParticleSpec {
  uint64_t count = 1000;
  double r_min = 0.5, r_max = 0.5;  // m; equal for one size, else uniform in [r_min, r_max]
};

enum class PlacementKind {
  kFill,  // a jittered lattice in a region, inside a closed wall, clear of it
  kPour,  // layers released from a disc inlet, falling with gravity
  kJet,   // layers released from a disc inlet with the given velocity
};
const char* to_string(PlacementKind k);
bool parse_placement_kind(const std::string& s, PlacementKind* out);

struct PlacementSpec {
  PlacementKind kind = PlacementKind::kFill;
  // fill: the region (m); when unset, the wall's box.
  bool has_region = false;
  Vec3d region_lo{0, 0, 0}, region_hi{0, 0, 0};
  // pour and jet: the inlet disc's centre and radius (m), its rate (particles/s,
  // 0 = as fast as layers can leave without overlapping). When the centre is
  // unset, the inlet sits under the top of the wall's box, centred.
  bool has_inlet = false;
  Vec3d inlet{0, 0, 0};
  double inlet_radius = 0;  // 0 = a third of the box's smaller horizontal side
  double rate = 0;
  // Initial velocity (m/s): every particle's for fill and jet; for a pour the
  // inlet speed (0 = 1 m/s along gravity).
  Vec3d velocity{0, 0, 0};
};

// Builds the particle set. Fill refuses a region that cannot hold the count
// (the message says how many fit); inlets refuse a disc too small for one particle.
// pool: where a fill in an open wall looks at its places (a winding number or
// rays each); null: this thread. The set is the same either way.
Expected<ParticleSet> place_particles(const TriangleMesh& wall, const ParticleSpec& particles,
                                      const PlacementSpec& placement, Vec3d gravity, uint64_t seed,
                                      ThreadPool* pool = nullptr);

// A fill's lattice: sites 2.1 r_max apart, the first 1.1 r_max in from the region's
// faces (on a floor at the region's bottom the first layer is then clear of it).
// The sites along one side of length `side` (0 where none fits): a fill searches
// whole layers of them, from the bottom up.
double fill_sites_along(double side, double r_max);

// When a placement's particles take part, known before placing them: a fill
// places all at once; an inlet (pour, jet) releases `slots` particles every
// `period` seconds, each slot at its own phase, until the last at about last_release.
struct ReleasePlan {
  uint64_t slots = 0;       // inlet slots (0 for a fill)
  double period = 0;        // s between two releases of one slot
  double last_release = 0;  // s: when the last particle leaves (0 for a fill)
  double speed = 0;         // m/s: the initial speed of every particle
  // s: when the first particles released reach the wall, falling straight down
  // from the inlet's slots (a pour, or a jet along gravity) to the first
  // triangle under them; -1 where not known (a fill, a jet across gravity, no
  // gravity, or nothing under the inlet). A duration shorter than this shows
  // particles that never touch anything.
  double first_contact = -1;
  // Mean share of the particles released over a run of `duration` seconds (1 for a fill).
  double mean_active(double duration) const;
};
// The plan of a placement against a wall (its slots are place_particles');
// the same errors as place_particles gives for the inlet.
Expected<ReleasePlan> plan_release(const TriangleMesh& wall, const ParticleSpec& particles,
                                   const PlacementSpec& placement, Vec3d gravity);

}  // namespace collido::sim
