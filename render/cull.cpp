#include "render/cull.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

namespace collido::render {
namespace {

// floor/ceil without the libm call the x86-64 baseline needs for them.
inline int floor_int(float x) {
  const int i = int(x);
  return i - (x < float(i));
}
inline int ceil_int(float x) {
  const int i = int(x);
  return i + (x > float(i));
}

constexpr int kTile = 8;  // pixels per side of the coarse depth tiles

}  // namespace

void cull_particles(const Snapshot& s, const CullView& v, CullScratch* sc,
                    std::vector<uint32_t>* visible) {
  const size_t n = s.particle_count();
  const float* m = v.view.m;
  const float* p = v.proj.m;
  const int w = v.width, h = v.height;
  visible->clear();

  // 1. Project every particle once; drop those behind the camera or entirely
  //    off screen. The rest get a 16-bit key from the depth of their nearest
  //    point: order only decides how early occluders are found (culling is
  //    conservative in any order), so a coarse key and one counting-sort pass
  //    are enough.
  sc->projected.resize(n);
  sc->keys.resize(n);
  size_t kept = 0;
  const float key_scale = 65535.f / std::max(v.far_plane - v.near_plane, 1e-6f);
  for (size_t i = 0; i < n; ++i) {
    const float x = s.positions[3 * i], y = s.positions[3 * i + 1], z = s.positions[3 * i + 2];
    const float r = s.radius[i];
    const float dist = -(m[2] * x + m[6] * y + m[10] * z + m[14]);
    if (!(dist + r > v.near_plane)) continue;  // also drops NaN positions
    const float ex = m[0] * x + m[4] * y + m[8] * z + m[12];
    const float ey = m[1] * x + m[5] * y + m[9] * z + m[13];
    const float inv = 1.f / std::max(dist, 1e-6f);
    const float px = (p[0] * ex * inv * 0.5f + 0.5f) * w;
    const float py = (p[5] * ey * inv * 0.5f + 0.5f) * h;
    const float rpx = r * v.point_scale * inv;
    const float half = 0.5f * std::min(2.f * rpx + 1.f, v.max_point) + 1.f;
    if (px + half < 0 || px - half > w || py + half < 0 || py - half > h) continue;
    sc->projected[kept] = {px, py, rpx, dist - r, dist + r, uint32_t(i)};
    const float k = (dist - r - v.near_plane) * key_scale;
    sc->keys[kept++] = uint16_t(std::clamp(k, 0.f, 65535.f));
  }
  sc->sorted.resize(kept);
  {
    std::vector<uint32_t>& count = sc->count;
    count.assign(65537, 0);
    for (size_t k = 0; k < kept; ++k) ++count[size_t(sc->keys[k]) + 1];
    for (size_t b = 0; b < 65536; ++b) count[b + 1] += count[b];
    for (size_t k = 0; k < kept; ++k) sc->sorted[count[sc->keys[k]]++] = sc->projected[k];
  }

  // 2. Nearest first: keep a particle if any pixel it would shade is not yet
  //    covered by something certainly nearer; then record the pixels it
  //    certainly covers. GL shades exactly the pixels whose centres lie within
  //    diameter/2 of the projected centre (the point shader discards the rest
  //    of the square), so both tests use that disc, widened or narrowed by
  //    a slack for rounding in the rasterizer's fixed-point setup, or for
  //    multisampling, where llvmpipe evaluates gl_PointCoord off the pixel
  //    centre.
  const float kSlack = v.slack;
  constexpr float kInf = std::numeric_limits<float>::infinity();
  sc->depth.assign(size_t(w) * h, kInf);
  float* depth = sc->depth.data();
  // Per 8x8 tile, the farthest depth in it: a particle whose disc lies in
  // tiles all nearer than its front is hidden without a per-pixel look.
  const int tw = (w + kTile - 1) / kTile, th = (h + kTile - 1) / kTile;
  sc->tile_max.assign(size_t(tw) * th, kInf);
  float* tile_max = sc->tile_max.data();
  visible->reserve(kept);
  for (const CullScratch::Projected& q : sc->sorted) {
    const float px = q.px, py = q.py, radius_px = q.radius_px, front = q.front;
    bool show = front <= v.near_plane;  // cut by the near plane: never judge
    // Row by row over the disc's span: the first pixel not yet certainly
    // covered in front of this particle makes it visible.
    const float outer = radius_px + kSlack, outer2 = outer * outer;
    const int y0 = std::max(0, (ceil_int(py - outer - 0.5f)));
    const int y1 = std::min(h - 1, (floor_int(py + outer - 0.5f)));
    if (!show && y0 <= y1) {
      const int bx0 = std::max(0, ceil_int(px - outer - 0.5f)) / kTile;
      const int bx1 = std::min(w - 1, floor_int(px + outer - 0.5f)) / kTile;
      bool hidden = bx0 <= bx1;
      for (int by = y0 / kTile; by <= y1 / kTile && hidden; ++by)
        for (int bx = bx0; bx <= bx1; ++bx) hidden &= tile_max[size_t(by) * tw + bx] < front;
      if (hidden) continue;
    }
    for (int yy = y0; yy <= y1 && !show; ++yy) {
      const float dy = yy + 0.5f - py;
      const float hw = std::sqrt(std::max(outer2 - dy * dy, 0.f));
      const int x0 = std::max(0, (ceil_int(px - hw - 0.5f)));
      const int x1 = std::min(w - 1, (floor_int(px + hw - 0.5f)));
      const float* row = depth + size_t(yy) * w;
      for (int xx = x0; xx <= x1; ++xx) show |= row[xx] >= front;
    }
    if (!show) continue;
    visible->push_back(q.index);
    if (front <= v.near_plane) continue;
    // The point square is clamped to the driver's largest point size; only
    // pixels inside both the square and the disc are certainly shaded.
    const float square = 0.5f * std::min(2.f * radius_px + 1.f, v.max_point) - kSlack;
    const float inner = std::min(radius_px - kSlack, square);
    if (inner < 0.5f) continue;
    const float far_side = q.back, inner2 = inner * inner;
    const int iy0 = std::max(0, (ceil_int(py - inner - 0.5f)));
    const int iy1 = std::min(h - 1, (floor_int(py + inner - 0.5f)));
    for (int yy = iy0; yy <= iy1; ++yy) {
      const float dy = yy + 0.5f - py;
      const float hw = std::sqrt(std::max(inner2 - dy * dy, 0.f));
      const int x0 = std::max(0, (ceil_int(px - hw - 0.5f)));
      const int x1 = std::min(w - 1, (floor_int(px + hw - 0.5f)));
      float* row = depth + size_t(yy) * w;
      for (int xx = x0; xx <= x1; ++xx) row[xx] = std::min(row[xx], far_side);
    }
    if (iy0 > iy1) continue;
    const int tx0 = std::max(0, ceil_int(px - inner - 0.5f)) / kTile;
    const int tx1 = std::min(w - 1, floor_int(px + inner - 0.5f)) / kTile;
    for (int by = iy0 / kTile; by <= iy1 / kTile; ++by)
      for (int bx = tx0; bx <= tx1; ++bx) {
        float mx = 0;
        const int ye = std::min(h, (by + 1) * kTile), xe = std::min(w, (bx + 1) * kTile);
        for (int yy = by * kTile; yy < ye; ++yy) {
          const float* row = depth + size_t(yy) * w;
          for (int xx = bx * kTile; xx < xe; ++xx) mx = std::max(mx, row[xx]);
        }
        tile_max[size_t(by) * tw + bx] = mx;
      }
  }
}

}  // namespace collido::render
