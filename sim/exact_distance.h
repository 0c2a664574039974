// The contact predicate every detection method answers to, and the float
// error band outside of which the fast float test may decide alone.
//
// A sphere (centre p, radius r) touches a triangle when exact_dist2(p, tri) <
// r * r, both evaluated in double in world coordinates. "Exact" here means one
// fixed sequence of correctly rounded IEEE operations: the CPU and the GPU
// compute the same bits, because the device path uses the _rn intrinsics,
// which nvcc never fuses into a multiply-add (a fused one rounds once where
// the host rounds twice, and a pair within an ulp of touching would flip).
// The reference detector and the filter of every float method call this one
// function, so "the reference's contact set" has no tolerance at all.
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>

#include "sim/hd.h"
#include "sim/mesh.h"
#include "sim/narrow_phase.h"

namespace collido::sim {

// A double whose arithmetic is never contracted into fused multiply-adds.
struct Rn {
  double v;
  Rn() = default;
  COLLIDO_HD constexpr Rn(double x) : v(x) {}  // NOLINT: implicit, like a double
};
#if defined(__CUDA_ARCH__)
COLLIDO_HD COLLIDO_FORCEINLINE Rn operator+(Rn a, Rn b) { return __dadd_rn(a.v, b.v); }
COLLIDO_HD COLLIDO_FORCEINLINE Rn operator-(Rn a, Rn b) { return __dsub_rn(a.v, b.v); }
COLLIDO_HD COLLIDO_FORCEINLINE Rn operator*(Rn a, Rn b) { return __dmul_rn(a.v, b.v); }
COLLIDO_HD COLLIDO_FORCEINLINE Rn operator/(Rn a, Rn b) { return __ddiv_rn(a.v, b.v); }
#else
// The host build never contracts (sim/CMakeLists.txt: -ffp-contract=off).
COLLIDO_HD COLLIDO_FORCEINLINE Rn operator+(Rn a, Rn b) { return a.v + b.v; }
COLLIDO_HD COLLIDO_FORCEINLINE Rn operator-(Rn a, Rn b) { return a.v - b.v; }
COLLIDO_HD COLLIDO_FORCEINLINE Rn operator*(Rn a, Rn b) { return a.v * b.v; }
COLLIDO_HD COLLIDO_FORCEINLINE Rn operator/(Rn a, Rn b) { return a.v / b.v; }
#endif
COLLIDO_HD COLLIDO_FORCEINLINE Rn operator-(Rn a) { return -a.v; }
COLLIDO_HD COLLIDO_FORCEINLINE bool operator<(Rn a, Rn b) { return a.v < b.v; }
COLLIDO_HD COLLIDO_FORCEINLINE bool operator>(Rn a, Rn b) { return a.v > b.v; }
COLLIDO_HD COLLIDO_FORCEINLINE bool operator<=(Rn a, Rn b) { return a.v <= b.v; }
COLLIDO_HD COLLIDO_FORCEINLINE bool operator>=(Rn a, Rn b) { return a.v >= b.v; }

// A triangle's corners in world coordinates, double: what the exact test reads.
struct TriangleD {
  Vec3d a, b, c;
};

// A particle in world coordinates, double (the filter's copy of a frame's input).
struct ParticleD {
  double x, y, z, r;
};

// Squared distance from p to triangle (a, b, c), bit for bit the same on both backends.
COLLIDO_HD inline double exact_dist2(Vec3d p, const TriangleD& t) {
  return point_triangle_dist2<Rn>(cast3<Rn>(p), cast3<Rn>(t.a), cast3<Rn>(t.b), cast3<Rn>(t.c)).v;
}

// True when the sphere touches the triangle: the contract's definition of a contact.
COLLIDO_HD COLLIDO_FORCEINLINE bool exact_touch(const ParticleD& q, const TriangleD& t,
                                                double* dist2) {
  *dist2 = exact_dist2(Vec3d{q.x, q.y, q.z}, t);
  return Rn(*dist2) < Rn(q.r) * Rn(q.r);
}

// Half-width of the float distance's error band, as a multiple of the unit
// roundoff times the magnitudes involved. The float path rounds the particle
// and the triangle's frame to float in the wall's local frame, then projects,
// tests 2D edges and squares: about 20 roundings of quantities no larger than
// L = |p|_1 + r + |a|_1 + longest edge, which in practice cancel to under one
// ulp of L (DetectTest.FloatErrorStaysInsideTheBand measures 0.9 ulp at worst
// on slivers, far from the origin, wall1 and a third-party mesh). 16 ulps
// keeps a margin of more than ten over that; the test fails below four.
inline constexpr float kFloatBandUlps = 16.f;

// The band for a particle at local position p (float) of radius r, against a
// wall whose triangles have |a|_1 + longest edge <= wall_scale (local frame).
COLLIDO_HD COLLIDO_FORCEINLINE float float_band(float px, float py, float pz, float r,
                                                float wall_scale) {
  return kFloatBandUlps * (FLT_EPSILON * 0.5f) *
         (hd_abs(px) + hd_abs(py) + hd_abs(pz) + r + wall_scale);
}

// The wall_scale of float_band for `mesh` in the local frame centred at
// `origin`: the largest |corner|_1 + longest edge over its triangles. A
// divided piece lies inside its original, so this bounds the pieces too.
inline float wall_band_scale(const TriangleMesh& mesh, Vec3d origin) {
  double scale = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    double corner = 0, edge = 0;
    for (int k = 0; k < 3; ++k) {
      const Vec3d v = mesh.corner(t, k) - origin;
      corner = std::max(corner, std::fabs(v.x) + std::fabs(v.y) + std::fabs(v.z));
      edge = std::max(edge, length(mesh.corner(t, (k + 1) % 3) - mesh.corner(t, k)));
    }
    scale = std::max(scale, corner + edge);
  }
  return static_cast<float>(scale * (1 + 1e-6));
}

}  // namespace collido::sim
