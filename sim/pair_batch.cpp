#include "sim/pair_batch.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define COLLIDO_PAIR_BATCH_AVX2 1
#endif

namespace collido::sim {

#if COLLIDO_PAIR_BATCH_AVX2

bool linear_pair_batch_supported() { return __builtin_cpu_supports("avx2"); }

namespace {

// Four lanes of doubles and their comparison masks. Only this file's
// target("avx2") functions touch them; every helper is inlined into
// linear_pair_batch, so no other translation unit ever runs AVX2 code.
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
COLLIDO_AVX2 V3 load3(const LinearPairBatch& b, LinearPairBatch::Column c, size_t k) {
  const double* p = b.col(c);
  return {load(p, k), load(p + b.stride, k), load(p + 2 * b.stride, k)};
}
COLLIDO_AVX2 void store3(LinearPairBatch& b, LinearPairBatch::Column c, size_t k, V3 v) {
  double* p = b.col(c);
  store(p, k, v.x), store(p + b.stride, k, v.y), store(p + 2 * b.stride, k, v.z);
}

}  // namespace

__attribute__((target("avx2"))) void linear_pair_batch(const ContactLaw& law, bool rot,
                                                        double dt, LinearPairBatch& b) {
  using C = LinearPairBatch;
  if (b.size == 0) return;
  for (size_t k = b.size; k % 4; ++k)
    for (int c = 0; c < C::kColumns; ++c) b.col(C::Column(c))[k] = b.col(C::Column(c))[b.size - 1];
  const bool friction = law.mu > 0;
  const V zero = splat(0), one = splat(1.0);
  const V k_n = splat(law.k), two_zeta = splat(2.0 * law.zeta);
  const V mu = splat(law.mu), vdt = splat(dt), minus_one = splat(-1.0);
  const V minus_kt = splat(-law.kt), minus_inv_kt = splat(-1.0 / law.kt);
  const V tiny = splat(1e-12);
  for (size_t k = 0; k < b.size; k += 4) {
    // pair_contact: the normal, the surfaces' relative velocity, the reduced mass.
    const V3 d = load3(b, C::kDx, k);
    const V dist2 = load(b.col(C::kDist2), k);
    const V r = load(b.col(C::kRi), k), rj = load(b.col(C::kRj), k);
    const V m = load(b.col(C::kMi), k), mj = load(b.col(C::kMj), k);
    const V rs = r + rj;
    const V dist = vsqrt(dist2);
    const V3 along = mul(d, one / dist);
    const V3 apart{zero, zero, load(b.col(C::kCoincidentSign), k)};
    const V3 n = pick(dist > tiny * rs, along, apart);
    V3 vrel = sub(load3(b, C::kVix, k), load3(b, C::kVjx, k));
    if (friction)
      vrel = sub(vrel, add(cross(load3(b, C::kWix, k), mul(n, r)),
                           cross(load3(b, C::kWjx, k), mul(n, rj))));
    const V m_eff = m * mj / (m + mj);
    const V overlap = rs - dist;
    // contact_force, the linear law.
    const V gamma = two_zeta * vsqrt(m_eff * k_n);
    const V vn = dot(vrel, n);
    const V fn = k_n * overlap - gamma * vn;
    V3 f = mul(n, fn);
    V3 torque{zero, zero, zero};
    V3 s{zero, zero, zero};
    if (friction) {
      const V3 vt = sub(vrel, mul(n, vn));
      s = load3(b, C::kSx, k);
      const V len2 = dot(s, s);
      const V3 proj = sub(s, mul(n, dot(s, n)));
      const V proj2 = dot(proj, proj);
      const V3 kept = pick(proj2 > zero, mul(proj, vsqrt(len2 / proj2)), proj);
      s = pick(len2 > zero, kept, s);
      s = add(s, mul(vt, vdt));
      V3 ft = sub(mul(s, minus_kt), mul(vt, gamma));
      const V ft2 = dot(ft, ft), limit = mu * pick(fn > zero, fn, zero);
      const M sliding = ft2 > limit * limit;
      if (!_mm256_testz_si256(__m256i(sliding), __m256i(sliding))) {
        const V ftn = vsqrt(ft2);
        const V3 capped = pick(ftn > zero, mul(ft, limit / ftn), V3{zero, zero, zero});
        const V3 reset = law.kt > 0 ? mul(add(capped, mul(vt, gamma)), minus_inv_kt)
                                    : V3{zero, zero, zero};
        ft = pick(sliding, capped, ft);
        s = pick(sliding, reset, s);
      }
      f = add(f, ft);
      torque = cross(mul(n, minus_one), ft);
    }
    store3(b, C::kFx, k, f);
    if (rot) store3(b, C::kTx, k, torque);
    if (friction) store3(b, C::kSxOut, k, s);
  }
}

#else

bool linear_pair_batch_supported() { return false; }
void linear_pair_batch(const ContactLaw&, bool, double, LinearPairBatch&) {}

#endif

}  // namespace collido::sim
