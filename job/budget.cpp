#include "job/budget.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "sim/divide.h"
#include "sim/wall_footprint.h"

namespace collido::job {
namespace {

// Host bytes per particle: the input set and its download copy (2 x 64), the
// engine's arrays (positions, velocities, accelerations, radius, mass,
// release, speed, states: about 110), the statistics scratch (16 x 8), a
// snapshot (29) and, with friction, spins and two generations of springs.
// With particle contacts: the particle grid and the neighbour list's own
// arrays (about 130), and some 12 neighbours a particle in a dense pile, each
// listed with its place (8), the 6 of larger index with the record of their
// force on the CPU (1 + 24, 24 more for the torque with friction, 24 for
// rolling resistance). Measured (bench run, a lattice of 6 neighbours, CPU):
// 506 bytes of engine arrays without friction, 1026 with; this gives 614 and 1190.
// A still wall's lists (with particle contacts or without): a start and a count,
// and a few triangles a particle near the wall (8 of 4 bytes, room for a
// quarter more); without particle contacts the positions they were built at too.
double bytes_per_particle(const sim::DynamicsConfig& c) {
  double b = 2 * 64 + 110 + 128 + 29;
  const bool friction = c.material.friction > 0;
  if (friction) b += 48 + 2 * 16 * 4 + (c.particle_contacts ? 2 * 16 * 8 : 0);
  if (c.particle_contacts)
    b += 130 + 12 * 8 + 6 * (25 + (friction ? 24 : 0) + (c.material.rolling_friction > 0 ? 24 : 0));
  if ((c.particle_contacts || sim::wall_lists_without_pairs(c)) && !c.wall_motion.moving())
    b += 8 + 8 * 4 * 1.25 + (c.particle_contacts ? 0 : 24);
  return b;
}

std::string figure(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

}  // namespace

uint64_t machine_memory_bytes() {
  const long pages = sysconf(_SC_PHYS_PAGES), size = sysconf(_SC_PAGE_SIZE);
  return pages > 0 && size > 0 ? uint64_t(pages) * uint64_t(size) : (uint64_t(8) << 30);
}

WorkEstimate estimate_work(const sim::TriangleMesh& wall, const sim::DynamicsConfig& config,
                           uint64_t particles, double r_max) {
  WorkEstimate e;
  const double cell = config.grid_length > 0 ? config.grid_length : 2 * r_max;
  if (config.method == sim::Method::kBvh) {
    // The tree holds each triangle once, and fewer nodes than triangles: no grid.
    e.pieces = double(wall.triangles.size());
  } else if (config.method == sim::Method::kBin) {
    // The bin preparation visits every cell of each triangle's box grown by r_max.
    const double grow = r_max + cell;
    for (size_t t = 0; t < wall.triangles.size(); ++t) {
      double cells = 1;
      for (int axis = 0; axis < 3; ++axis) {
        double lo = 1e300, hi = -1e300;
        for (int k = 0; k < 3; ++k) {
          const sim::Vec3d p = wall.corner(t, k);
          const double v = axis == 0 ? p.x : axis == 1 ? p.y : p.z;
          lo = std::min(lo, v), hi = std::max(hi, v);
        }
        cells *= std::floor((hi - lo + 2 * grow) / cell) + 2;
      }
      e.wall_cells += cells;
    }
    e.pieces = double(wall.triangles.size());
  } else {
    // Four-way splitting's count is a product per triangle. Bisection (gravity,
    // circumcircle) stops each piece as soon as it fits, 6 to 14 times fewer on
    // the calibration walls: counted exactly by walking the bisections (about
    // 45 ns a piece on the 2-core VM, so at most 0.1 s) up to kCountedPieces.
    // Beyond, twice four-way's count bounds it from above (a box's faces give
    // 0.5 to 1 times it, equilateral triangles 1 to 1.5 times: a sixth of it,
    // which stood here, priced a wall at a sixth to a ninth of its pieces, and
    // admitted runs that then ran out of memory). The grid over piece centres
    // costs work in proportion to the pieces, not cells.
    constexpr double kCountedPieces = 2e6;
    const double m4 = sim::midpoint4_piece_count(wall, r_max);
    const sim::DivisionMethod how = sim::division_of(config.method);
    e.pieces = how == sim::DivisionMethod::kMidpoint4 ? m4
               : m4 / 6 <= kCountedPieces             ? sim::division_piece_count(wall, how, r_max)
                                                      : 2 * m4;
  }
  const sim::WallFootprint f = sim::wall_footprint(wall, config.method, r_max, cell,
                                                   config.max_dense_cells, particles, e.pieces);
  e.bin_entries = f.bin_entries;
  e.wall_buckets = double(f.buckets);
  // A piece's bytes at the preparation's peak, when the divided mesh, its
  // float and double triangles, the keys and the sorted copies are all alive:
  // 606 B measured (wall1 at r = 0.2, gravity, 8.9e6 pieces: 5.42 GB resident,
  // `run` on the CPU); 160 B, what stays afterwards, priced it at a quarter.
  constexpr double kPieceBytes = 640;
  e.host_bytes = double(particles) * bytes_per_particle(config) + e.pieces * kPieceBytes +
                 std::min(e.wall_cells, 1e12) * 12 + 64.0 * (1 << 20);
  return e;
}

Status check_budget(const WorkEstimate& e, const Budget& budget) {
  if (!(e.pieces <= budget.pieces))
    return resource_exhausted("dividing the wall would make about " + figure(e.pieces) +
                              " triangles, over the limit of " + figure(budget.pieces) +
                              ": use the bin method (no division) or larger particles");
  if (!(e.wall_cells <= budget.wall_cells))
    return resource_exhausted(
        "the wall would be prepared over " + figure(e.wall_cells) + " (triangle, cell) pairs, over "
        "the limit of " + figure(budget.wall_cells) +
        ": the grid cells are tiny next to the wall; use larger particles or a larger grid_length");
  const double limit = budget.host_bytes ? double(budget.host_bytes) : double(machine_memory_bytes());
  if (!(e.host_bytes <= limit))
    return resource_exhausted("the run needs about " + figure(e.host_bytes / double(1 << 30)) +
                              " GiB of memory (" + figure(e.pieces) + " wall triangles after division), "
                              "more than the " + figure(limit / double(1 << 30)) +
                              " GiB it may use; use fewer particles or the bin method");
  return Status::ok();
}

}  // namespace collido::job
