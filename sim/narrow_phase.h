// Exact per-element geometry shared by every backend: closest point on a
// triangle (Ericson, Real-Time Collision Detection, 5.1.5) made robust for
// slivers and zero-length edges, and the triangle/box overlap test
// (Akenine-Moller's separating axes) used by the `bin` method.
#pragma once

#include "sim/hd.h"

namespace collido::sim {

// Closest point to p on segment [a, b]; a zero-length segment gives a.
template <class T>
COLLIDO_HD COLLIDO_FORCEINLINE Vec3T<T> closest_on_segment(Vec3T<T> p, Vec3T<T> a, Vec3T<T> b) {
  Vec3T<T> ab = b - a;
  T len2 = dot(ab, ab);
  if (!(len2 > T(0))) return a;
  T t = dot(p - a, ab) / len2;
  t = t < T(0) ? T(0) : (t > T(1) ? T(1) : t);
  return a + ab * t;
}

// Squared distance from p to triangle (a, b, c). Works in coordinates relative
// to a so float keeps its precision for small triangles far from the origin.
// Degenerate triangles (zero area, repeated corners) fall back to their edges.
template <class T>
COLLIDO_HD COLLIDO_FORCEINLINE T point_triangle_dist2(Vec3T<T> p, Vec3T<T> a, Vec3T<T> b,
                                                      Vec3T<T> c) {
  const Vec3T<T> ab = b - a, ac = c - a, ap = p - a;
  const T d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= T(0) && d2 <= T(0)) return dot(ap, ap);  // vertex region A
  const Vec3T<T> bp = ap - ab;
  const T d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= T(0) && d4 <= d3) return dot(bp, bp);  // vertex region B
  const Vec3T<T> cp = ap - ac;
  const T d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= T(0) && d5 <= d6) return dot(cp, cp);  // vertex region C

  const T vc = d1 * d4 - d3 * d2;
  const T vb = d5 * d2 - d1 * d6;
  const T va = d3 * d6 - d5 * d4;
  const Vec3T<T> n = cross(ab, ac);
  const T n2 = dot(n, n);
  // A triangle whose area is lost in rounding has no interior worth the name:
  // the minimum over its three edges is exact and never divides by zero.
  const T emax = hd_max(hd_max(dot(ab, ab), dot(ac, ac)), dot(ac - ab, ac - ab));
  const T eps = sizeof(T) == 4 ? T(1e-10) : T(1e-24);
  if (!(n2 > eps * emax * emax)) {
    Vec3T<T> q0 = closest_on_segment(p, a, b) - p;
    Vec3T<T> q1 = closest_on_segment(p, b, c) - p;
    Vec3T<T> q2 = closest_on_segment(p, c, a) - p;
    return hd_min(hd_min(dot(q0, q0), dot(q1, q1)), dot(q2, q2));
  }
  if (vc <= T(0) && d1 >= T(0) && d3 <= T(0)) {  // edge region AB
    const T v = d1 / (d1 - d3);
    const Vec3T<T> q = ap - ab * v;
    return dot(q, q);
  }
  if (vb <= T(0) && d2 >= T(0) && d6 <= T(0)) {  // edge region AC
    const T w = d2 / (d2 - d6);
    const Vec3T<T> q = ap - ac * w;
    return dot(q, q);
  }
  if (va <= T(0) && (d4 - d3) >= T(0) && (d5 - d6) >= T(0)) {  // edge region BC
    const T w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    const Vec3T<T> q = bp - (ac - ab) * w;
    return dot(q, q);
  }
  // Face region: the distance to the plane, which is better conditioned than
  // reconstructing the point from barycentric coordinates.
  const T h = dot(ap, n);
  return h * h / n2;
}

// Closest point on triangle (a, b, c) to p, for callers that need the point
// itself (contact normals). Same regions and fallbacks as the distance above.
template <class T>
COLLIDO_HD inline Vec3T<T> closest_point_on_triangle(Vec3T<T> p, Vec3T<T> a, Vec3T<T> b,
                                                     Vec3T<T> c) {
  const Vec3T<T> ab = b - a, ac = c - a, ap = p - a;
  const T d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= T(0) && d2 <= T(0)) return a;
  const Vec3T<T> bp = ap - ab;
  const T d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= T(0) && d4 <= d3) return b;
  const Vec3T<T> cp = ap - ac;
  const T d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= T(0) && d5 <= d6) return c;
  const T vc = d1 * d4 - d3 * d2, vb = d5 * d2 - d1 * d6, va = d3 * d6 - d5 * d4;
  const Vec3T<T> n = cross(ab, ac);
  const T n2 = dot(n, n);
  const T emax = hd_max(hd_max(dot(ab, ab), dot(ac, ac)), dot(ac - ab, ac - ab));
  const T eps = sizeof(T) == 4 ? T(1e-10) : T(1e-24);
  if (!(n2 > eps * emax * emax)) {
    Vec3T<T> q0 = closest_on_segment(p, a, b), q1 = closest_on_segment(p, b, c),
             q2 = closest_on_segment(p, c, a);
    T e0 = norm2(q0 - p), e1 = norm2(q1 - p), e2 = norm2(q2 - p);
    return e0 <= e1 && e0 <= e2 ? q0 : (e1 <= e2 ? q1 : q2);
  }
  if (vc <= T(0) && d1 >= T(0) && d3 <= T(0)) return a + ab * (d1 / (d1 - d3));
  if (vb <= T(0) && d2 >= T(0) && d6 <= T(0)) return a + ac * (d2 / (d2 - d6));
  if (va <= T(0) && (d4 - d3) >= T(0) && (d5 - d6) >= T(0))
    return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  return p - n * (dot(ap, n) / n2);
}

namespace detail {
template <class T>
COLLIDO_HD COLLIDO_FORCEINLINE bool axis_separates(Vec3T<T> axis, Vec3T<T> v0, Vec3T<T> v1,
                                                   Vec3T<T> v2, Vec3T<T> h) {
  const T p0 = dot(axis, v0), p1 = dot(axis, v1), p2 = dot(axis, v2);
  const T r = h.x * hd_abs(axis.x) + h.y * hd_abs(axis.y) + h.z * hd_abs(axis.z);
  const T lo = hd_min(p0, hd_min(p1, p2)), hi = hd_max(p0, hd_max(p1, p2));
  return lo > r || hi < -r;
}
}  // namespace detail

// True when triangle (a, b, c) intersects the axis-aligned box with the given
// centre and half-extents (closed sets: touching counts). Thirteen axes: the
// box normals, the triangle normal and the nine edge cross products.
template <class T>
COLLIDO_HD inline bool triangle_box_overlap(Vec3T<T> a, Vec3T<T> b, Vec3T<T> c, Vec3T<T> centre,
                                            Vec3T<T> half) {
  const Vec3T<T> v0 = a - centre, v1 = b - centre, v2 = c - centre;
  // Box face normals: compare the triangle's extent with the box's.
  if (hd_min(v0.x, hd_min(v1.x, v2.x)) > half.x || hd_max(v0.x, hd_max(v1.x, v2.x)) < -half.x)
    return false;
  if (hd_min(v0.y, hd_min(v1.y, v2.y)) > half.y || hd_max(v0.y, hd_max(v1.y, v2.y)) < -half.y)
    return false;
  if (hd_min(v0.z, hd_min(v1.z, v2.z)) > half.z || hd_max(v0.z, hd_max(v1.z, v2.z)) < -half.z)
    return false;
  const Vec3T<T> e0 = v1 - v0, e1 = v2 - v1, e2 = v0 - v2;
  // Triangle plane.
  const Vec3T<T> n = cross(e0, e1);
  if (detail::axis_separates(n, v0, v1, v2, half)) return false;
  // Edge x box-axis cross products.
  const Vec3T<T> ex{1, 0, 0}, ey{0, 1, 0}, ez{0, 0, 1};
  const Vec3T<T> edges[3] = {e0, e1, e2};
  for (int i = 0; i < 3; ++i) {
    if (detail::axis_separates(cross(ex, edges[i]), v0, v1, v2, half)) return false;
    if (detail::axis_separates(cross(ey, edges[i]), v0, v1, v2, half)) return false;
    if (detail::axis_separates(cross(ez, edges[i]), v0, v1, v2, half)) return false;
  }
  return true;
}

}  // namespace collido::sim

namespace collido::sim {

// A triangle prepared for distance queries: corner a, a unit edge direction
// e1 (along ab), the unit normal n, and the 2D coordinates of b and c in the
// (e1, n x e1) frame. The frame is computed in double, so a float query only
// projects onto unit vectors and tests 2D edges, which keeps slivers (needles
// 10^4 times longer than wide) accurate to float rounding of the coordinates
// instead of failing in the cancellations of the 3D formulas. Detection uses
// the float form; contact forces the double one (sim/contact_force.h).
// 16-byte aligned (48 bytes in float): the GPU reads it as three vector loads.
template <class T>
struct alignas(16) PlanarTriangleT {
  Vec3T<T> a, e1, n;
  T b1, c1, c2;  // b = (b1, 0), c = (c1, c2) with c2 >= 0; c2 == 0: degenerate (a segment)
};
using PlanarTriangle = PlanarTriangleT<float>;
using PlanarTriangleD = PlanarTriangleT<double>;

// Builds the frame in double for the triangle (a, b, c) shifted by -origin, stored as T.
template <class T = float>
inline PlanarTriangleT<T> make_planar(Vec3d a, Vec3d b, Vec3d c, Vec3d origin) {
  a = a - origin, b = b - origin, c = c - origin;
  // Put the longest edge first so e1 is well defined whenever any edge is.
  const double lab = norm2(b - a), lbc = norm2(c - b), lca = norm2(a - c);
  if (lbc >= lab && lbc >= lca) {
    Vec3d t = a;
    a = b, b = c, c = t;
  } else if (lca >= lab && lca >= lbc) {
    Vec3d t = a;
    a = c, c = b, b = t;
  }
  PlanarTriangleT<T> out;
  const Vec3d ab = b - a, ac = c - a;
  const double len = length(ab);
  const Vec3d e1 = len > 0 ? ab * (1.0 / len) : Vec3d{1, 0, 0};
  Vec3d n = cross(ab, ac);
  const double nl = length(n);
  double c2 = 0;
  if (nl > 1e-300 && nl > 1e-14 * len * len) {
    n = n * (1.0 / nl);
    c2 = dot(ac, cross(n, e1));
  } else {
    // Degenerate: any unit vector perpendicular to e1 serves as a normal.
    Vec3d t = std::fabs(e1.x) < 0.9 ? Vec3d{1, 0, 0} : Vec3d{0, 1, 0};
    n = cross(e1, t);
    n = n * (1.0 / length(n));
  }
  out.a = cast3<T>(a);
  out.e1 = cast3<T>(e1);
  out.n = cast3<T>(n);
  out.b1 = static_cast<T>(len);
  out.c1 = static_cast<T>(dot(ac, e1));
  out.c2 = static_cast<T>(c2 > 0 ? c2 : 0);
  return out;
}

// Squared distance from p to a 2D segment (s, e), the point given as (u, v).
COLLIDO_HD COLLIDO_FORCEINLINE float segment_dist2_2d(float u, float v, float su, float sv,
                                                      float eu, float ev) {
  const float du = eu - su, dv = ev - sv;
  const float len2 = du * du + dv * dv;
  float t = len2 > 0.f ? ((u - su) * du + (v - sv) * dv) / len2 : 0.f;
  t = t < 0.f ? 0.f : (t > 1.f ? 1.f : t);
  const float x = u - (su + t * du), y = v - (sv + t * dv);
  return x * x + y * y;
}

// Squared distance from p (same local frame) to the prepared triangle. With
// `below`, a point whose distance to the triangle's plane alone reaches it
// returns that (a lower bound of the distance, >= below) without the edge
// tests: a caller asking "closer than sqrt(below)?" gets the same answer for
// less work, and the distance itself wherever it is below.
COLLIDO_HD COLLIDO_FORCEINLINE float point_triangle_dist2(Vec3f p, const PlanarTriangle& t,
                                                          float below = INFINITY) {
  const Vec3f ap = p - t.a;
  const float h = dot(ap, t.n);
  if (h * h >= below) return h * h;
  const Vec3f e2 = cross(t.n, t.e1);
  const float u = dot(ap, t.e1), v = dot(ap, e2);
  // Inside when left of all three counter-clockwise edges (a->b is the u axis).
  if (t.c2 > 0.f && v >= 0.f && (t.c1 - t.b1) * v - t.c2 * (u - t.b1) >= 0.f &&
      t.c2 * u - t.c1 * v >= 0.f)
    return h * h;
  const float d = hd_min(segment_dist2_2d(u, v, 0.f, 0.f, t.b1, 0.f),
                         hd_min(segment_dist2_2d(u, v, t.b1, 0.f, t.c1, t.c2),
                                segment_dist2_2d(u, v, t.c1, t.c2, 0.f, 0.f)));
  return d + h * h;
}

}  // namespace collido::sim
