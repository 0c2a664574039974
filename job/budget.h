// Work and memory of a run estimated from the scene and its wall before
// anything large is allocated, so a scene that would stall a worker for
// minutes or exhaust its memory is refused at once with the figures.
#pragma once

#include <cstdint>
#include <string>

#include "common/status.h"
#include "job/job.h"
#include "sim/dynamics.h"
#include "sim/mesh.h"

namespace collido::job {

struct WorkEstimate {
  double wall_cells = 0;     // (triangle, cell) pairs the bin preparation visits
  double pieces = 0;         // triangles after division (= original for bin)
  double bin_entries = 0;    // bin: (cell, triangle) pairs the index stores (sim/wall_footprint.h)
  double wall_buckets = 0;   // the wall grid's table (0 for the tree)
  double host_bytes = 0;     // peak host memory of the engine and its outputs
};

// The estimate for `particles` particles of radius up to r_max against `wall`.
WorkEstimate estimate_work(const sim::TriangleMesh& wall, const sim::DynamicsConfig& config,
                           uint64_t particles, double r_max);

// kResourceExhausted, with the figures and what to change, when the estimate
// exceeds the budget (a budget.host_bytes of 0 means this machine's memory).
Status check_budget(const WorkEstimate& e, const Budget& budget);

// Physical memory of this machine, bytes.
uint64_t machine_memory_bytes();

}  // namespace collido::job
