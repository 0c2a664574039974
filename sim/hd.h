// Host/device annotations and small vector math shared by the CPU and CUDA backends.
// Per-element math is written once, marked COLLIDO_HD, and compiled for both.
#pragma once

#include <cmath>
#include <cstdint>

#if defined(__CUDACC__)
#define COLLIDO_HD __host__ __device__
#define COLLIDO_FORCEINLINE __forceinline__
#else
#define COLLIDO_HD
#define COLLIDO_FORCEINLINE inline __attribute__((always_inline))
#endif

namespace collido::sim {

template <class T>
struct Vec3T {
  T x, y, z;
};
using Vec3f = Vec3T<float>;
using Vec3d = Vec3T<double>;

template <class T>
COLLIDO_HD COLLIDO_FORCEINLINE Vec3T<T> operator+(Vec3T<T> a, Vec3T<T> b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z};
}
template <class T>
COLLIDO_HD COLLIDO_FORCEINLINE Vec3T<T> operator-(Vec3T<T> a, Vec3T<T> b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
template <class T>
COLLIDO_HD COLLIDO_FORCEINLINE Vec3T<T> operator*(Vec3T<T> a, T s) {
  return {a.x * s, a.y * s, a.z * s};
}
template <class T>
COLLIDO_HD COLLIDO_FORCEINLINE Vec3T<T> operator*(T s, Vec3T<T> a) {
  return {a.x * s, a.y * s, a.z * s};
}
template <class T>
COLLIDO_HD COLLIDO_FORCEINLINE T dot(Vec3T<T> a, Vec3T<T> b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
template <class T>
COLLIDO_HD COLLIDO_FORCEINLINE Vec3T<T> cross(Vec3T<T> a, Vec3T<T> b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <class T>
COLLIDO_HD COLLIDO_FORCEINLINE T norm2(Vec3T<T> a) {
  return dot(a, a);
}
// Scalar helpers that pick the float or double routine on both host and device.
COLLIDO_HD COLLIDO_FORCEINLINE float hd_sqrt(float v) { return sqrtf(v); }
COLLIDO_HD COLLIDO_FORCEINLINE double hd_sqrt(double v) { return sqrt(v); }
template <class T>
COLLIDO_HD COLLIDO_FORCEINLINE T hd_min(T a, T b) { return b < a ? b : a; }
template <class T>
COLLIDO_HD COLLIDO_FORCEINLINE T hd_max(T a, T b) { return a < b ? b : a; }
template <class T>
COLLIDO_HD COLLIDO_FORCEINLINE T hd_abs(T a) { return a < T(0) ? -a : a; }

COLLIDO_HD COLLIDO_FORCEINLINE uint32_t hd_popcount(uint32_t bits) {
#if defined(__CUDA_ARCH__)
  return uint32_t(__popc(bits));
#else
  // Bit arithmetic: without -mpopcnt, __builtin_popcount is a call into
  // libgcc, made for each particle's top cell in the octree.
  bits = bits - ((bits >> 1) & 0x55555555u);
  bits = (bits & 0x33333333u) + ((bits >> 2) & 0x33333333u);
  return (((bits + (bits >> 4)) & 0x0F0F0F0Fu) * 0x01010101u) >> 24;
#endif
}

// False for NaN and infinities (x - x is 0 only for finite x); works the same in device code.
COLLIDO_HD COLLIDO_FORCEINLINE bool hd_finite(double v) { return v - v == 0.0; }

template <class T>
COLLIDO_HD COLLIDO_FORCEINLINE T length(Vec3T<T> a) {
  return hd_sqrt(dot(a, a));
}
template <class To, class From>
COLLIDO_HD COLLIDO_FORCEINLINE Vec3T<To> cast3(Vec3T<From> a) {
  return {static_cast<To>(a.x), static_cast<To>(a.y), static_cast<To>(a.z)};
}

// The threads that share one item of parallel_for_lanes: `size` consecutive
// lanes of a warp on the GPU (mask: theirs), or one thread (size 1, the default). Each lane
// works on a share of the item and the group combines the shares. The sums
// run as a butterfly, so every lane gets the same bits; with one lane they
// return their argument, so a one-thread loop's arithmetic is unchanged.
struct LaneGroup {
  uint32_t lane = 0, size = 1, mask = 1;
  template <class T>  // double or uint32_t
  COLLIDO_HD COLLIDO_FORCEINLINE T sum(T v) const {
#if defined(__CUDA_ARCH__)
    for (uint32_t o = size >> 1; o > 0; o >>= 1) v += __shfl_xor_sync(mask, v, o);
#endif
    return v;
  }
  COLLIDO_HD COLLIDO_FORCEINLINE Vec3d sum(Vec3d v) const { return {sum(v.x), sum(v.y), sum(v.z)}; }
  COLLIDO_HD COLLIDO_FORCEINLINE double max(double v) const {
#if defined(__CUDA_ARCH__)
    for (uint32_t o = size >> 1; o > 0; o >>= 1) v = fmax(v, __shfl_xor_sync(mask, v, o));
#endif
    return v;
  }
  // The lowest set bit's number (bits != 0).
  COLLIDO_HD static COLLIDO_FORCEINLINE uint32_t lowest(uint32_t bits) {
#if defined(__CUDA_ARCH__)
    return uint32_t(__ffs(int(bits)) - 1);
#else
    return uint32_t(__builtin_ctz(bits));
#endif
  }
  // The lanes with b set, as bits by lane number.
  COLLIDO_HD COLLIDO_FORCEINLINE uint32_t bits(bool b) const {
#if defined(__CUDA_ARCH__)
    if (size > 1) return (__ballot_sync(mask, b) & mask) >> ((threadIdx.x & 31u) & ~(size - 1u));
#endif
    return b ? 1u : 0u;
  }
  // Lane `lane`'s v, on every lane.
  template <class T>  // double or uint32_t
  COLLIDO_HD COLLIDO_FORCEINLINE T from(uint32_t lane, T v) const {
#if defined(__CUDA_ARCH__)
    if (size > 1) return __shfl_sync(mask, v, lane, size);
#endif
    (void)lane;
    return v;
  }
  COLLIDO_HD COLLIDO_FORCEINLINE Vec3d from(uint32_t lane, Vec3d v) const {
    return {from(lane, v.x), from(lane, v.y), from(lane, v.z)};
  }
  // The sum of v over the lanes up to and including this one.
  COLLIDO_HD COLLIDO_FORCEINLINE uint32_t scan(uint32_t v) const {
#if defined(__CUDA_ARCH__)
    for (uint32_t o = 1; o < size; o <<= 1) {
      const uint32_t u = __shfl_up_sync(mask, v, o, size);
      if (lane >= o) v += u;
    }
#endif
    return v;
  }
  // How many lanes before this one have b set, and how many in all.
  COLLIDO_HD COLLIDO_FORCEINLINE uint32_t count_before(bool b) const {
#if defined(__CUDA_ARCH__)
    if (size > 1) return __popc(__ballot_sync(mask, b) & mask & ((1u << (threadIdx.x & 31)) - 1u));
#endif
    (void)b;
    return 0;
  }
  COLLIDO_HD COLLIDO_FORCEINLINE uint32_t count(bool b) const {
#if defined(__CUDA_ARCH__)
    if (size > 1) return __popc(__ballot_sync(mask, b) & mask);
#endif
    return b ? 1u : 0u;
  }
};

}  // namespace collido::sim
