// What the renderer draws: one frame of particles and the wall, in plain arrays.
// The engine's own snapshot (sim/snapshot.h) is converted into this by the caller,
// so the renderer never depends on the engine.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace collido::render {

// Axis-aligned box in world units (float, relative to the caller's render origin).
struct Bounds {
  float lo[3] = {0, 0, 0};
  float hi[3] = {0, 0, 0};
  bool empty() const { return !(lo[0] <= hi[0] && lo[1] <= hi[1] && lo[2] <= hi[2]); }
};

// The wall as an indexed triangle mesh. Kept apart from the particles so a
// caller can keep one copy for a whole run; the renderer uploads it only when
// its contents change.
struct WallMesh {
  std::vector<float> vertices;    // x, y, z per vertex (world units)
  std::vector<uint32_t> indices;  // 3 vertex indices per triangle
  size_t triangle_count() const { return indices.size() / 3; }
};

struct Snapshot {
  // Particles, one entry per particle (positions interleaved x, y, z).
  std::vector<float> positions;  // 3 per particle, world units
  std::vector<float> radius;     // world units
  std::vector<float> scalar;     // value coloured by (speed, world units per second)
  std::vector<uint8_t> contact;  // 1 when the particle touches the wall this frame

  WallMesh wall;
  // Where the wall is drawn: a rigid motion applied to its vertices, column-major
  // (as GL takes it), the identity for a still wall. A moving wall changes only
  // this from frame to frame, so its mesh is uploaded and smoothed once.
  float wall_model[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  // A part of the wall that moves while `wall` stands still (empty: none), with
  // its own model matrix: both meshes upload once, only the matrix changes.
  WallMesh part;
  float part_model[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};

  // The region the camera frames. Keep it constant over a run (the wall's box)
  // so the camera does not jump from frame to frame.
  Bounds bounds;

  double time = 0;     // simulated time, seconds
  uint64_t frame = 0;  // frame index in the run
  // Particles in the whole run when only a subset is drawn; 0 means "all drawn".
  uint64_t total_particles = 0;

  size_t particle_count() const { return radius.size(); }
};

// Checks that the arrays agree in length and the indices lie inside the mesh;
// returns an empty string when the snapshot is usable, else what is wrong.
std::string validate_snapshot(const Snapshot& snap);

// Box around the wall vertices and the particles (with their radii).
Bounds compute_bounds(const Snapshot& snap);

}  // namespace collido::render
