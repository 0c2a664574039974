// What the wall's index will hold once a run prepares it (sim/wall_index.h),
// known before anything is allocated: the cost model prices a job's device
// memory with it. The bin method's stored (cell, triangle) pairs are a tenth
// of the cells its preparation visits on a typical wall, and that share
// depends on how the triangles lie against the grid, so they are counted
// with the preparation's own cell walk.
#pragma once

#include <cstdint>

#include "sim/detect.h"
#include "sim/mesh.h"

namespace collido::sim {

struct WallFootprint {
  uint64_t buckets = 0;    // the wall grid's table: cells when dense, a power of two when hashed
  double bin_entries = 0;  // bin: (cell, triangle) pairs stored (0 for the other methods)
  bool sampled = false;    // bin_entries estimated from a sample of the triangles
};

// The footprint of `mesh` prepared with `method` for particles up to r_max in
// cells of edge `cell`, as WallIndex::prepare would build it for `particles`.
// Bin entries are counted exactly while the walk visits at most visit_limit
// cells; beyond, every k-th triangle is walked and the count scaled by the
// visits (within 0.5 % on the 83,750-triangle counter mesh). With 1e6 a
// prediction's share stays under 50 ms there (34-47 ms for r of 0.5 to 5 mm on
// the quiet 2-core VM). The divided methods' grid, over their pieces' centres,
// is sized from the wall's box.
WallFootprint wall_footprint(const TriangleMesh& mesh, Method method, double r_max, double cell,
                             uint64_t max_dense_cells, uint64_t particles, double pieces,
                             double visit_limit = 1e6);

}  // namespace collido::sim
