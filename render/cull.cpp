#include "render/cull.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

namespace collido::render {
namespace {

// LSD radix sort of (key, index) pairs by key, 11 bits per pass: a few ms for
// a million particles, where std::sort would take tens.
void radix_sort(std::vector<uint32_t>& keys, std::vector<uint32_t>& order,
                std::vector<uint32_t>& tmp_keys, std::vector<uint32_t>& tmp_order) {
  const size_t n = keys.size();
  tmp_keys.resize(n);
  tmp_order.resize(n);
  for (int shift = 0; shift < 32; shift += 11) {
    uint32_t count[2049] = {};
    for (size_t i = 0; i < n; ++i) ++count[((keys[i] >> shift) & 2047) + 1];
    for (int b = 0; b < 2048; ++b) count[b + 1] += count[b];
    for (size_t i = 0; i < n; ++i) {
      const uint32_t dst = count[(keys[i] >> shift) & 2047]++;
      tmp_keys[dst] = keys[i];
      tmp_order[dst] = order[i];
    }
    keys.swap(tmp_keys);
    order.swap(tmp_order);
  }
}

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

uint32_t float_key(float positive) {
  uint32_t k;
  std::memcpy(&k, &positive, 4);
  return k;  // non-negative IEEE floats order like their bit patterns
}

}  // namespace

void cull_particles(const Snapshot& s, const CullView& v, CullScratch* sc,
                    std::vector<uint32_t>* visible) {
  const size_t n = s.particle_count();
  const float* m = v.view.m;
  const float* p = v.proj.m;
  const int w = v.width, h = v.height;
  visible->clear();
  sc->keys.resize(n);
  sc->order.resize(n);
  size_t kept = 0;

  // 1. View depth of each particle's nearest point; drop those behind the
  //    camera or entirely off screen.
  for (size_t i = 0; i < n; ++i) {
    const float x = s.positions[3 * i], y = s.positions[3 * i + 1], z = s.positions[3 * i + 2];
    const float r = s.radius[i];
    const float dist = -(m[2] * x + m[6] * y + m[10] * z + m[14]);
    if (!(dist + r > v.near_plane)) continue;  // also drops NaN positions
    const float ex = m[0] * x + m[4] * y + m[8] * z + m[12];
    const float ey = m[1] * x + m[5] * y + m[9] * z + m[13];
    const float d = std::max(dist, 1e-6f);
    const float px = (p[0] * ex / d * 0.5f + 0.5f) * w;
    const float py = (p[5] * ey / d * 0.5f + 0.5f) * h;
    const float half = 0.5f * std::min(2.f * r * v.point_scale / d + 1.f, v.max_point) + 1.f;
    if (px + half < 0 || px - half > w || py + half < 0 || py - half > h) continue;
    sc->keys[kept] = float_key(std::max(dist - r, 0.f));
    sc->order[kept++] = uint32_t(i);
  }
  sc->keys.resize(kept);
  sc->order.resize(kept);
  radix_sort(sc->keys, sc->order, sc->tmp_keys, sc->tmp_order);

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
  visible->reserve(sc->order.size());
  for (uint32_t i : sc->order) {
    const float x = s.positions[3 * i], y = s.positions[3 * i + 1], z = s.positions[3 * i + 2];
    const float r = s.radius[i];
    const float dist = -(m[2] * x + m[6] * y + m[10] * z + m[14]);
    const float ex = m[0] * x + m[4] * y + m[8] * z + m[12];
    const float ey = m[1] * x + m[5] * y + m[9] * z + m[13];
    const float d = std::max(dist, 1e-6f);
    const float px = (p[0] * ex / d * 0.5f + 0.5f) * w;
    const float py = (p[5] * ey / d * 0.5f + 0.5f) * h;
    const float radius_px = r * v.point_scale / d;
    const float front = dist - r;
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
    visible->push_back(i);
    if (front <= v.near_plane) continue;
    // The point square is clamped to the driver's largest point size; only
    // pixels inside both the square and the disc are certainly shaded.
    const float square = 0.5f * std::min(2.f * radius_px + 1.f, v.max_point) - kSlack;
    const float inner = std::min(radius_px - kSlack, square);
    if (inner < 0.5f) continue;
    const float far_side = dist + r, inner2 = inner * inner;
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
