// Uniform grid over the engine's local frame (paper 3.4-3.5). Cells are
// numbered by Eq. 7, hash = z * sizeY * sizeX + y * sizeX + x. When the dense
// table would be too large for the domain (sparse or huge scenes), cells map
// into a power-of-two hashed table instead and lookups filter by the full cell number.
#pragma once

#include <cstdint>

#include "sim/hd.h"

namespace collido::sim {

inline constexpr uint32_t kInvalidBucket = 0xFFFFFFFFu;

// Particles as the paper packs them: x, y, z, r in 16 bytes (one vector load on the GPU).
struct alignas(16) PackedParticle {
  float x, y, z, r;
};

struct TriangleF {
  Vec3f a, b, c;
};

struct GridSpec {
  Vec3f origin{0, 0, 0};  // corner of cell (0, 0, 0), local frame
  float cell = 1, inv_cell = 1;
  int nx = 1, ny = 1, nz = 1;
  uint32_t buckets = 1;  // table size: nx * ny * nz when dense, a power of two when hashed
  uint32_t hashed = 0;

  // Cell coordinates of p; false when p lies outside the grid (or is not finite).
  COLLIDO_HD COLLIDO_FORCEINLINE bool cell_of(Vec3f p, int& x, int& y, int& z) const {
    const float fx = (p.x - origin.x) * inv_cell, fy = (p.y - origin.y) * inv_cell,
                fz = (p.z - origin.z) * inv_cell;
    if (!(fx >= 0.f && fy >= 0.f && fz >= 0.f)) return false;
    if (!(fx < float(nx) && fy < float(ny) && fz < float(nz))) return false;
    // Rounding can put a point a hair below the upper face into cell n; clamp it back.
    x = int(fx) < nx ? int(fx) : nx - 1;
    y = int(fy) < ny ? int(fy) : ny - 1;
    z = int(fz) < nz ? int(fz) : nz - 1;
    return true;
  }
  COLLIDO_HD COLLIDO_FORCEINLINE bool inside(int x, int y, int z) const {
    return x >= 0 && y >= 0 && z >= 0 && x < nx && y < ny && z < nz;
  }
  // Eq. 7, in 64 bits so huge domains do not wrap.
  COLLIDO_HD COLLIDO_FORCEINLINE uint64_t linear(int x, int y, int z) const {
    return (uint64_t(z) * uint64_t(ny) + uint64_t(y)) * uint64_t(nx) + uint64_t(x);
  }
  COLLIDO_HD COLLIDO_FORCEINLINE void unlinear(uint64_t l, int& x, int& y, int& z) const {
    x = int(l % uint64_t(nx));
    l /= uint64_t(nx);
    y = int(l % uint64_t(ny));
    z = int(l / uint64_t(ny));
  }
  // Calls f(cell number, bucket) for each cell within `reach` cells of (cx, cy, cz) inside the grid.
  template <class F>
  COLLIDO_HD COLLIDO_FORCEINLINE void for_each_neighbour(int cx, int cy, int cz, int reach, F&& f) const {
    for (int z = cz - reach; z <= cz + reach; ++z)
      for (int y = cy - reach; y <= cy + reach; ++y)
        for (int x = cx - reach; x <= cx + reach; ++x) {
          if (!inside(x, y, z)) continue;
          const uint64_t l = linear(x, y, z);
          f(l, bucket(l));
        }
  }
  // True when p lies in cell l: a hashed bucket holds several cells, so lookups filter with it.
  COLLIDO_HD COLLIDO_FORCEINLINE bool holds(Vec3f p, uint64_t l) const {
    int x = 0, y = 0, z = 0;
    return cell_of(p, x, y, z) && linear(x, y, z) == l;
  }
  COLLIDO_HD COLLIDO_FORCEINLINE uint32_t bucket(uint64_t l) const {
    if (!hashed) return uint32_t(l);
    l ^= l >> 33;  // murmur finaliser: neighbouring cells land far apart
    l *= 0xff51afd7ed558ccdull;
    l ^= l >> 33;
    return uint32_t(l) & (buckets - 1);
  }
};

COLLIDO_HD COLLIDO_FORCEINLINE Vec3f position(const PackedParticle& p) { return {p.x, p.y, p.z}; }

// Atomic add on memory the loop bodies share, for either backend.
COLLIDO_HD COLLIDO_FORCEINLINE uint32_t atomic_add_u32(uint32_t* p, uint32_t v) {
#if defined(__CUDA_ARCH__)
  return atomicAdd(p, v);
#else
  return __atomic_fetch_add(p, v, __ATOMIC_RELAXED);
#endif
}

}  // namespace collido::sim
