// Per-contact math of the dynamics, written once for both backends: the
// closest point on a prepared triangle, the choice of one contact per touched
// wall feature, and the spring-dashpot force with optional Coulomb friction.
#pragma once

#include <cmath>
#include <cstdint>

#include "sim/grid.h"
#include "sim/hd.h"
#include "sim/narrow_phase.h"

namespace collido::sim {

// Closest point on a 2D segment (s, e) to (u, v); writes the point, returns the squared distance.
COLLIDO_HD COLLIDO_FORCEINLINE double segment_closest_2d(double u, double v, double su, double sv,
                                                         double eu, double ev, double& qu,
                                                         double& qv) {
  const double du = eu - su, dv = ev - sv;
  const double len2 = du * du + dv * dv;
  double t = len2 > 0 ? ((u - su) * du + (v - sv) * dv) / len2 : 0;
  t = t < 0 ? 0 : (t > 1 ? 1 : t);
  qu = su + t * du, qv = sv + t * dv;
  const double x = u - qu, y = v - qv;
  return x * x + y * y;
}

// Whether a point at in-plane coordinates (u, v) lies farther from triangle
// t's box of corners in its plane than `left`, what reach2 leaves after the
// point's height (the squared distance is at least h^2 plus that), by a margin
// of 1e-6 reach2 far above the rounding of either: so beyond sqrt(reach2) of t,
// by a test cheaper than the closest point. A divided wall's lookup visits
// cells of pieces and a bin cell may list long slivers, most of them out of
// reach: the test spares each the edge tests and their divisions (a fill of
// wall1 by the gravity method took 7.7 ms a step on the CPU without it;
// docs/benchmarks.md).
COLLIDO_HD COLLIDO_FORCEINLINE bool out_of_reach(double u, double v, double left,
                                                 const PlanarTriangleD& t, double reach2) {
  const double u_lo = t.c1 < 0 ? t.c1 : 0, u_hi = t.c1 > t.b1 ? t.c1 : t.b1;
  const double du = u < u_lo ? u_lo - u : (u > u_hi ? u - u_hi : 0);
  const double dv = v < 0 ? -v : (v > t.c2 ? v - t.c2 : 0);
  return !(du * du + dv * dv < left + 1e-6 * reach2);
}

// Squared distance from p to the triangle (prepared in double: a float
// closest point would carry the coordinates' rounding, about 1e-7 of them,
// into the push's direction, a sideways force that walks a resting particle
// across a floor), the closest point *q, p's signed height *h over the plane,
// and *aside, the squared distance in the plane from p's foot to the face (0
// inside it: then the push is along +-n exactly). *aside is its own figure, not
// the total less h^2, which would carry h^2's rounding (1e-17 of it, more where
// nvcc fuses the multiply and add) into the test of a centre over an edge.
// Where p lies beyond sqrt(reach2) by its height, then by out_of_reach, it
// returns reach2 and leaves *q, *h and *aside as they were: the height first,
// before the in-plane coordinates, since it alone culls most candidates (a
// wall1 fill by the gravity method 0.85 -> 0.73 ms a step).
COLLIDO_HD COLLIDO_FORCEINLINE double closest_point_planar(Vec3d p, const PlanarTriangleD& t,
                                                           double reach2, Vec3d* q, double* h,
                                                           double* aside) {
  const Vec3d ap = p - t.a;
  const double hh = dot(ap, t.n), left = reach2 - hh * hh;
  if (!(left > 0)) return reach2;  // the plane alone (exact): most culled candidates, cheapest
  const Vec3d e2 = cross(t.n, t.e1);
  const double u = dot(ap, t.e1), v = dot(ap, e2);
  if (out_of_reach(u, v, left, t, reach2)) return reach2;
  double qu = u, qv = v, d = 0;
  const bool inside =
      t.c2 > 0 && v >= 0 && (t.c1 - t.b1) * v - t.c2 * (u - t.b1) >= 0 && t.c2 * u - t.c1 * v >= 0;
  if (!inside) {
    double au, av, bu, bv, cu, cv;
    const double d0 = segment_closest_2d(u, v, 0, 0, t.b1, 0, au, av);
    const double d1 = segment_closest_2d(u, v, t.b1, 0, t.c1, t.c2, bu, bv);
    const double d2 = segment_closest_2d(u, v, t.c1, t.c2, 0, 0, cu, cv);
    d = d0, qu = au, qv = av;
    if (d1 < d) d = d1, qu = bu, qv = bv;
    if (d2 < d) d = d2, qu = cu, qv = cv;
  }
  *q = t.a + t.e1 * qu + e2 * qv;
  *h = hh;
  *aside = d;
  return d + hh * hh;
}

// One wall contact of a particle: the closest point q on the wall, the unit
// normal n from q towards the centre, and the centre's distance.
struct WallContact {
  Vec3d q, n;
  double dist;
  uint32_t triangle;  // original (mesh) index, the friction history key
};

// The wall contacts of one particle, one per touched feature. A candidate
// whose closest point lies on or behind the tangent plane of another contact
// (the plane through that contact's point, normal n) is the same support seen
// again: the shared vertex of six floor triangles, the shared edge of two, the
// neighbour of the face the sphere sits on, a piece of the same divided
// triangle. Such points are always farther from the centre than the contact
// that shadows them, so keeping the unshadowed ones keeps the deepest of each
// support, in any order of arrival. Concave corners (floor meets side) give
// points in front of each other's planes and keep both contacts.
template <int K>
struct WallContactSet {
  WallContact c[K];
  int n = 0;
  uint32_t dropped = 0;  // unshadowed contacts beyond K (deepest kept)

  COLLIDO_HD COLLIDO_FORCEINLINE void offer(const WallContact& w, double tol) {
    for (int k = 0; k < n; ++k)
      if (dot(w.q - c[k].q, c[k].n) <= tol) return;  // behind an existing contact's plane
    int m = 0;
    for (int k = 0; k < n; ++k)
      if (!(dot(c[k].q - w.q, w.n) <= tol))
        c[m++] = c[k];  // keep those the new one does not shadow
    n = m;
    if (n < K) {
      c[n++] = w;
      return;
    }
    // Full: replace the shallowest if the new one is deeper.
    int s = 0;
    for (int k = 1; k < n; ++k)
      if (c[k].dist > c[s].dist) s = k;
    ++dropped;
    if (w.dist < c[s].dist) c[s] = w;
  }
};

// The normal force law of a contact.
enum class ContactModel : uint32_t {
  kLinear = 0,        // linear spring-dashpot: F = k d - gamma v_n, gamma from the restitution
  kHertzMindlin = 1,  // Hertz normal, Mindlin tangential, damping that keeps the restitution
};

// Constants of one kind of contact (particle-particle, or particle-wall).
struct ContactLaw {
  ContactModel model = ContactModel::kLinear;
  // Linear: the normal stiffness (N/m) and the damping ratio; gamma = 2 zeta sqrt(m_eff k).
  // The tangential spring is 2/7 k with the same damping.
  double k = 0;
  double zeta = 0;
  double kt = 0;
  // Hertz-Mindlin: the effective Young's and shear moduli of the pair (Pa) and the
  // damping factor eta: gamma = eta sqrt(m_eff S) with S the contact's current
  // stiffness (S_n = 2 E* sqrt(R* d) normal, S_t = 8 G* sqrt(R* d) tangential).
  // eta is solved from the restitution once (hertz_damping_factor), so the
  // restitution is the requested one at every impact speed.
  double e_star = 0;
  double g_star = 0;
  double eta = 0;
  double mu = 0;       // Coulomb coefficient (0: no friction)
  double mu_roll = 0;  // rolling resistance (constant torque mu_roll F_n R*; 0: none)
};

// Tangential spring state of one contact, kept between steps.
struct FrictionSlot {
  uint32_t key;  // partner: particle index, or kWallKeyBit | original triangle
  float sx, sy, sz;
};
inline constexpr uint32_t kWallKeyBit = 0x80000000u;
inline constexpr uint32_t kNoKey = 0xFFFFFFFFu;

// Result of one contact on the particle it belongs to.
struct ContactForce {
  Vec3d f;         // force on the particle, N
  Vec3d torque;    // about its centre, N m
  double elastic;  // J stored in the normal and tangential springs
  double fn;       // N, the normal force (negative while the dashpot pulls)
};

// Force of one contact on particle i. n: unit normal towards i; overlap > 0;
// vrel: velocity of i's surface point relative to the partner's at the contact
// (translation and rotation); m_eff: reduced mass; r_eff: the contact's
// effective radius (r_i r_j / (r_i + r_j), or r_i on a wall; Hertz only);
// lever: distance from i's centre to the contact point. *spring is the
// tangential spring (in: last step's, out: this step's); dt is the step.
COLLIDO_HD COLLIDO_FORCEINLINE ContactForce contact_force(const ContactLaw& law, Vec3d n,
                                                          double overlap, Vec3d vrel, double m_eff,
                                                          double r_eff, double lever,
                                                          Vec3d* spring, double dt) {
  ContactForce out;
  double kn, kt, gamma_n, gamma_t;
  if (law.model == ContactModel::kHertzMindlin) {
    // Stiffness grows with the contact's radius sqrt(R* d); the elastic force is
    // 4/3 E* sqrt(R*) d^3/2, its energy 8/15 E* sqrt(R*) d^5/2.
    const double a = hd_sqrt(r_eff * overlap);
    const double sn = 2.0 * law.e_star * a, st = 8.0 * law.g_star * a;
    kn = 2.0 / 3.0 * sn;
    kt = st;
    gamma_n = law.eta * hd_sqrt(m_eff * sn);
    gamma_t = law.eta * hd_sqrt(m_eff * st);
    out.elastic = 0.4 * kn * overlap * overlap;
  } else {
    kn = law.k;
    kt = law.kt;
    gamma_n = gamma_t = 2.0 * law.zeta * hd_sqrt(m_eff * law.k);
    out.elastic = 0.5 * law.k * overlap * overlap;
  }
  const double vn = dot(vrel, n);
  // Not clamped at zero: the dashpot may pull briefly as a pair separates.
  // That keeps the restitution exactly the one the damping was derived
  // from (clamping ends the contact early and gives e = 0.4 for a nominal 0.3).
  const double fn = kn * overlap - gamma_n * vn;
  out.f = n * fn;
  out.fn = fn;
  out.torque = Vec3d{0, 0, 0};
  if (law.mu > 0) {
    const Vec3d vt = vrel - n * vn;
    // Carry the spring into the current tangent plane, keeping its length
    // (one square root: the ratio of the squared lengths).
    Vec3d s = *spring;
    const double len2 = dot(s, s);
    if (len2 > 0) {
      s = s - n * dot(s, n);
      const double proj2 = dot(s, s);
      if (proj2 > 0) s = s * hd_sqrt(len2 / proj2);
    }
    s = s + vt * dt;
    Vec3d ft = s * (-kt) - vt * gamma_t;
    const double ft2 = dot(ft, ft), limit = law.mu * (fn > 0 ? fn : 0);
    if (ft2 > limit * limit) {
      // Sliding: cap at the Coulomb limit, and reset the spring to what that
      // force implies (the square root only here: most contacts stick).
      const double ftn = hd_sqrt(ft2);
      ft = ftn > 0 ? ft * (limit / ftn) : Vec3d{0, 0, 0};
      s = kt > 0 ? (ft + vt * gamma_t) * (-1.0 / kt) : Vec3d{0, 0, 0};
    }
    *spring = s;
    out.f = out.f + ft;
    out.torque = cross(n * (-lever), ft);
    out.elastic += 0.5 * kt * dot(s, s);
  }
  return out;
}

// Rolling resistance of one contact (the constant directional torque model,
// "CDT" in the DEM codes): mu_roll F_n R* against the relative rolling spin
// (the twist about the normal is left free), never more than the torque that
// would stop that spin within the step (i_eff: the pair's reduced moment of
// inertia), so a resting ball does not rock to and fro. w_rel: i's spin
// minus its partner's. Zero on the measuring pass (dt = 0).
COLLIDO_HD COLLIDO_FORCEINLINE Vec3d rolling_torque(const ContactLaw& law, Vec3d n, double fn,
                                                    Vec3d w_rel, double r_eff, double i_eff,
                                                    double dt) {
  if (!(law.mu_roll > 0) || !(dt > 0) || !(fn > 0)) return Vec3d{0, 0, 0};
  const Vec3d w = w_rel - n * dot(w_rel, n);
  const double wl = length(w);
  if (!(wl > 0)) return Vec3d{0, 0, 0};
  const double t = hd_min(law.mu_roll * fn * r_eff, i_eff * wl / dt);
  return w * (-t / wl);
}

}  // namespace collido::sim
