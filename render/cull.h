// Occlusion culling of particles on the CPU, before they reach GL. Exact
// sphere depth (gl_FragDepth) turns off llvmpipe's early depth test, so every
// fragment of every point is shaded; in a dense vessel most particles are
// hidden behind the outer layers (overdraw of 20-30 at 1e5 particles). This
// pass drops the particles that are certainly hidden, which removes both their
// per-point setup (single-threaded in llvmpipe) and their fragments, and leaves
// the image unchanged. Internal to render/.
#pragma once

#include <cstdint>
#include <vector>

#include "render/camera.h"
#include "render/snapshot.h"

namespace collido::render {

struct CullView {
  Mat4 view, proj;
  int width = 0, height = 0;  // pixels
  float point_scale = 0;      // pixels per world unit at eye distance 1 (as the shader)
  float max_point = 0;        // largest point size GL draws, pixels
  float near_plane = 0;       // world units
  float far_plane = 0;        // world units
  // Pixels by which the shaded disc may differ from the exact one: 0.05 for
  // single-sampled rendering, 0.75 with multisampling.
  float slack = 0.05f;
};

// Reused buffers, so culling allocates nothing per frame once warmed up.
struct CullScratch {
  std::vector<float> depth;     // per pixel: nearest occluder's farthest possible depth
  std::vector<float> tile_max;  // per 8x8 tile: the largest depth in it
  struct Projected {
    float px, py;       // centre in pixels
    float radius_px;    // radius in pixels
    float front, back;  // view depth of the nearest and farthest point, world units
    uint32_t index;     // particle index in the snapshot
  };
  std::vector<Projected> projected, sorted;
  std::vector<uint16_t> keys;
  std::vector<uint32_t> count;
};

// Writes to *visible the particles that may be visible, nearest first.
// Conservative: a particle is dropped only when every pixel its point covers
// already holds an occluding sphere whose farthest point (centre depth + radius)
// is nearer than the particle's nearest point (centre depth - radius).
void cull_particles(const Snapshot& s, const CullView& v, CullScratch* scratch,
                    std::vector<uint32_t>* visible);

}  // namespace collido::render
