#include "sim/pair_batch.h"

#include <algorithm>

#include "sim/dynamics.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define COLLIDO_PAIR_BATCH_AVX2 1
#endif

namespace collido::sim {

#if COLLIDO_PAIR_BATCH_AVX2

bool pair_batch_supported() { return __builtin_cpu_supports("avx2"); }

namespace {

// Four lanes of doubles and their comparison masks. Only this file's
// target("avx2") functions touch them; every helper is inlined into
// pair_batch_forces, so no other translation unit ever runs AVX2 code.
typedef double V __attribute__((vector_size(32)));
typedef long long M __attribute__((vector_size(32)));

#define COLLIDO_AVX2 __attribute__((target("avx2"), always_inline)) inline

struct V3 {
  V x, y, z;
};

COLLIDO_AVX2 V splat(double s) { return V{s, s, s, s}; }
COLLIDO_AVX2 V load(const double* c, size_t k) {
  V v;
  __builtin_memcpy(&v, c + k, sizeof v);
  return v;
}
COLLIDO_AVX2 void store(double* c, size_t k, V v) { __builtin_memcpy(c + k, &v, sizeof v); }
COLLIDO_AVX2 V vsqrt(V a) { return V(_mm256_sqrt_pd(__m256d(a))); }
COLLIDO_AVX2 V pick(M m, V a, V b) { return m ? a : b; }
COLLIDO_AVX2 V3 pick(M m, V3 a, V3 b) { return {m ? a.x : b.x, m ? a.y : b.y, m ? a.z : b.z}; }
// The operators of sim/hd.h's Vec3T, in their order of operations.
COLLIDO_AVX2 V3 add(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
COLLIDO_AVX2 V3 sub(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
COLLIDO_AVX2 V3 mul(V3 a, V s) { return {a.x * s, a.y * s, a.z * s}; }
COLLIDO_AVX2 V dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
COLLIDO_AVX2 V3 cross(V3 a, V3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
// Columns c, c + 1 and c + 2 (x, y and z).
COLLIDO_AVX2 V3 load3(const PairBatch& b, PairBatch::Column c, size_t k) {
  const double* p = b.col(c);
  return {load(p, k), load(p + b.stride, k), load(p + 2 * b.stride, k)};
}
COLLIDO_AVX2 void store3(PairBatch& b, PairBatch::Column c, size_t k, V3 v) {
  double* p = b.col(c);
  store(p, k, v.x), store(p + b.stride, k, v.y), store(p + 2 * b.stride, k, v.z);
}

// a[idx[0..3]].
COLLIDO_AVX2 V at4(const double* a, const uint32_t* idx) {
  return V{a[idx[0]], a[idx[1]], a[idx[2]], a[idx[3]]};
}
// Three doubles at a[idx[0..3]] as columns: x, y and z of four particles (a
// load that leaves out the fourth double, so that nothing past the array is read).
COLLIDO_AVX2 V3 rows3(const Vec3d* a, const uint32_t* idx) {
  const __m256i three = _mm256_setr_epi64x(-1, -1, -1, 0);
  const __m256d r0 = _mm256_maskload_pd(&a[idx[0]].x, three);
  const __m256d r1 = _mm256_maskload_pd(&a[idx[1]].x, three);
  const __m256d r2 = _mm256_maskload_pd(&a[idx[2]].x, three);
  const __m256d r3 = _mm256_maskload_pd(&a[idx[3]].x, three);
  const __m256d t0 = _mm256_unpacklo_pd(r0, r1), t1 = _mm256_unpackhi_pd(r0, r1);
  const __m256d t2 = _mm256_unpacklo_pd(r2, r3), t3 = _mm256_unpackhi_pd(r2, r3);
  return {V(_mm256_permute2f128_pd(t0, t2, 0x20)), V(_mm256_permute2f128_pd(t1, t3, 0x20)),
          V(_mm256_permute2f128_pd(t0, t2, 0x31))};
}

}  // namespace

__attribute__((target("avx2"))) void pair_batch_forces(const ContactLaw& law, bool rot,
                                                        double dt, PairBatch& b) {
  using C = PairBatch;
  if (b.size == 0) return;
  for (size_t k = b.size; k % 4; ++k) {  // the inputs of the last group's padding
    for (int c = C::kSx; c <= C::kSz; ++c) b.col(C::Column(c))[k] = b.col(C::Column(c))[b.size - 1];
    b.owner[k] = b.owner[b.size - 1], b.partner[k] = b.partner[b.size - 1];
  }
  const PairBatch::Sources& P = b.src;
  const bool friction = law.mu > 0, hertz = law.model == ContactModel::kHertzMindlin;
  const bool rolling = rot && law.mu_roll > 0;
  const V zero = splat(0), one = splat(1.0), minus_one = splat(-1.0);
  const V3 none{zero, zero, zero};
  const V k_lin = splat(law.k), kt_lin = splat(law.kt), two_zeta = splat(2.0 * law.zeta);
  const V two_e = splat(2.0 * law.e_star), eight_g = splat(8.0 * law.g_star);
  const V two_thirds = splat(2.0 / 3.0), eta = splat(law.eta);
  const V mu = splat(law.mu), mu_roll = splat(law.mu_roll), vdt = splat(dt);
  const V tiny = splat(1e-12), two_fifths = splat(0.4);
  for (size_t k = 0; k < b.size; k += 4) {
    // pair_contact: the normal, the surfaces' relative velocity, the reduced
    // mass and, for the laws that read it, the contact's radius.
    const uint32_t* owners = b.owner.data() + k;  // the group's four
    const uint32_t* partners = b.partner.data() + k;
    const V3 d = sub(rows3(P.x, owners), rows3(P.x, partners));
    const V dist2 = dot(d, d);
    const V r = at4(P.r, owners), rj = at4(P.r, partners);
    const V m = at4(P.m, owners), mj = at4(P.m, partners);
    const V rs = r + rj;
    const V dist = vsqrt(dist2);
    const V3 along = mul(d, one / dist);
    const V3 apart{zero, zero, one};  // i < j: pair_contact's +z
    const V3 n = pick(dist > tiny * rs, along, apart);
    const V3 wi = rot ? rows3(P.w, owners) : none, wj = rot ? rows3(P.w, partners) : none;
    V3 vrel = sub(rows3(P.v, owners), rows3(P.v, partners));
    if (friction) vrel = sub(vrel, add(cross(wi, mul(n, r)), cross(wj, mul(n, rj))));
    const V r_eff = hertz || rolling ? r * rj / rs : zero;
    const V m_eff = m * mj / (m + mj);
    const V overlap = rs - dist;
    // contact_force: the law's stiffnesses and damping.
    V kn, kt, gamma_n, gamma_t;
    if (hertz) {
      const V a = vsqrt(r_eff * overlap);
      const V sn = two_e * a, st = eight_g * a;
      kn = two_thirds * sn;
      kt = st;
      gamma_n = eta * vsqrt(m_eff * sn);
      gamma_t = eta * vsqrt(m_eff * st);
    } else {
      kn = k_lin;
      kt = kt_lin;
      gamma_n = gamma_t = two_zeta * vsqrt(m_eff * k_lin);
    }
    const V vn = dot(vrel, n);
    const V fn = kn * overlap - gamma_n * vn;
    V3 f = mul(n, fn);
    V3 torque = none, s = none;
    if (friction) {
      const V3 vt = sub(vrel, mul(n, vn));
      s = load3(b, C::kSx, k);
      const V len2 = dot(s, s);
      const V3 proj = sub(s, mul(n, dot(s, n)));
      const V proj2 = dot(proj, proj);
      const V3 kept = pick(proj2 > zero, mul(proj, vsqrt(len2 / proj2)), proj);
      s = pick(len2 > zero, kept, s);
      s = add(s, mul(vt, vdt));
      V3 ft = sub(mul(s, -kt), mul(vt, gamma_t));
      const V ft2 = dot(ft, ft), limit = mu * pick(fn > zero, fn, zero);
      const M sliding = ft2 > limit * limit;
      if (!_mm256_testz_si256(__m256i(sliding), __m256i(sliding))) {
        const V ftn = vsqrt(ft2);
        const V3 capped = pick(ftn > zero, mul(ft, limit / ftn), none);
        const V3 reset = pick(kt > zero, mul(add(capped, mul(vt, gamma_t)), minus_one / kt), none);
        ft = pick(sliding, capped, ft);
        s = pick(sliding, reset, s);
      }
      f = add(f, ft);
      torque = cross(mul(n, minus_one), ft);
    }
    store3(b, C::kFx, k, f);
    if (rot) store3(b, C::kTx, k, torque);
    if (friction) store3(b, C::kSxOut, k, s);
    if (rolling && dt > 0) {
      // rolling_torque: against the rolling spin, never more than stops it within the step.
      const V ii = two_fifths * m * r * r, ij = two_fifths * mj * rj * rj;
      const V i_eff = ii * ij / (ii + ij);
      const V3 w_rel = sub(wi, wj);
      const V3 w = sub(w_rel, mul(n, dot(w_rel, n)));
      const V wl = vsqrt(dot(w, w));
      const V most = mu_roll * fn * r_eff, stop = i_eff * wl / vdt;
      const V t = pick(stop < most, stop, most);
      const V3 roll = mul(w, -t / wl);
      store3(b, C::kRollX, k, pick(fn > zero, pick(wl > zero, roll, none), none));
    } else if (rolling) {
      store3(b, C::kRollX, k, none);
    }
  }
}

namespace {

// Particles i to i + 3 of a Vec3d array as three registers of its twelve
// doubles in a row (x0 y0 z0 x1 | y1 z1 x2 y2 | z2 x3 y3 z3), held in a V3 whose
// x, y and z are those registers, not components: add, sub and mul work on
// them alike, as a Vec3's components all get the same kick.
static_assert(sizeof(Vec3d) == 3 * sizeof(double), "a Vec3d array is its doubles in a row");
using Quad = V3;
COLLIDO_AVX2 Quad load_quad(const Vec3d* p, uint32_t i) {
  const double* d = &p[i].x;
  return {load(d, 0), load(d, 4), load(d, 8)};
}
COLLIDO_AVX2 void store_quad(Vec3d* p, uint32_t i, Quad q) {
  double* d = &p[i].x;
  store(d, 0, q.x), store(d, 4, q.y), store(d, 8, q.z);
}
// A vector's components laid out as a quad's.
COLLIDO_AVX2 Quad spread(Vec3d u) {
  return {V{u.x, u.y, u.z, u.x}, V{u.y, u.z, u.x, u.y}, V{u.z, u.x, u.y, u.z}};
}
// Every component within [lo, hi] (false for NaN).
COLLIDO_AVX2 bool within(Quad q, const Quad& lo, const Quad& hi) {
  const M in =
      (q.x >= lo.x) & (q.y >= lo.y) & (q.z >= lo.z) & (q.x <= hi.x) & (q.y <= hi.y) & (q.z <= hi.z);
  return _mm256_movemask_pd(__m256d(in)) == 0xf;
}

}  // namespace

__attribute__((target("avx2"))) uint32_t open_plain_groups(const OpenGroups& g, uint32_t i,
                                                           uint32_t end, double* most) {
  // A speed's components under 1e150 square and sum to a finite number, as
  // the scalar pass's check asks; faster ones (or none finite) go its way.
  const Quad big = spread(Vec3d{1e150, 1e150, 1e150});
  const Quad small = spread(Vec3d{-1e150, -1e150, -1e150});
  const Quad lo = spread(g.lo), hi = spread(g.hi);
  const Quad next_lo = spread(g.next_lo), next_hi = spread(g.next_hi);
  const V close_half = splat(g.close_half), half_dt = splat(g.half_dt), dt = splat(g.dt);
  const uint32_t four_active = uint32_t(kActive) * 0x01010101u;
  double m = *most;
  // A group that is not plain stops the loop before any of its stores, so
  // the scalar pass takes it from the start.
  for (; i + 4 <= end; i += 4) {
    uint32_t states;
    __builtin_memcpy(&states, g.state + i, 4);
    if (states != four_active) break;
    const Quad x = load_quad(g.x, i), acc = load_quad(g.acc, i);
    Quad v = load_quad(g.v, i), w{}, alpha{};
    if (g.rot) w = load_quad(g.w, i), alpha = load_quad(g.alpha, i);
    if (g.close) {  // close_particle: the closing kick, the checks
      v = add(v, mul(acc, close_half));
      if (g.rot) w = add(w, mul(alpha, close_half));
      if (!within(v, small, big) || !within(x, lo, hi)) break;
    }
    v = add(v, mul(acc, half_dt));
    const Quad moved = add(x, mul(v, dt));
    if (g.rot) w = add(w, mul(alpha, half_dt));
    if (!within(moved, next_lo, next_hi)) break;
    store_quad(g.v, i, v);
    store_quad(g.x, i, moved);
    if (g.rot) store_quad(g.w, i, w);
    if (g.disp) {
      const Quad d = sub(moved, load_quad(g.ref, i));
      double sq[12];
      store(sq, 0, d.x * d.x), store(sq, 4, d.y * d.y), store(sq, 8, d.z * d.z);
      for (int k = 0; k < 12; k += 3) m = std::max(m, sq[k] + sq[k + 1] + sq[k + 2]);
    }
  }
  *most = m;
  return i;
}

namespace {
// A vector of four particles' values spread over a quad's layout, each
// particle's value on its three components.
COLLIDO_AVX2 Quad spread_each(V a) {
  const __m256d v = __m256d(a);
  return {V(_mm256_permute4x64_pd(v, 0x40)), V(_mm256_permute4x64_pd(v, 0xA5)),
          V(_mm256_permute4x64_pd(v, 0xFE))};
}
COLLIDO_AVX2 Quad mul_each(Quad a, Quad s) {
  return {a.x * s.x, a.y * s.y, a.z * s.z};
}
}  // namespace

__attribute__((target("avx2"))) uint32_t accelerate_active_groups(const GroupSums& g, uint32_t i,
                                                                  uint32_t end) {
  const uint32_t four_active = uint32_t(kActive) * 0x01010101u;
  const V one = splat(1.0), two_fifths = splat(0.4);
  for (; i + 4 <= end; i += 4) {
    uint32_t states;
    __builtin_memcpy(&states, g.state + i, 4);
    if (states != four_active) break;
    const V m = load(g.m, i);
    store_quad(g.acc, i, mul_each(load_quad(g.acc, i), spread_each(one / m)));
    if (g.rot) {
      const V r = load(g.r, i);
      store_quad(g.alpha, i,
                 mul_each(load_quad(g.alpha, i), spread_each(one / (two_fifths * m * r * r))));
    }
  }
  return i;
}

#else

uint32_t accelerate_active_groups(const GroupSums&, uint32_t i, uint32_t) {
  return i;
}
bool pair_batch_supported() { return false; }
void pair_batch_forces(const ContactLaw&, bool, double, PairBatch&) {}
uint32_t open_plain_groups(const OpenGroups&, uint32_t i, uint32_t, double*) {
  return i;
}

#endif

}  // namespace collido::sim
