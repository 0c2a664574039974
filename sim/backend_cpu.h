// CPU backend of the detection pipeline: host memory, the thread pool's
// parallel_for, and serial scan/sort where those are cheap next to the traversal.
#pragma once

#include <algorithm>
#include <cstring>
#include <mutex>
#include <numeric>
#include <vector>

#include "sim/hd.h"
#include "sim/parallel.h"
#include "sim/status.h"

namespace collido::sim {

class CpuBackend {
 public:
  // A per-particle walk reads a copy of the particles reordered by the sort:
  // a thread stalls on the scattered read where a copying loop overlaps many
  // (20 % of a frame on the counter mesh, sim/detect_pipeline.h, bvh).
  static constexpr bool kWalksReadReorderedCopy = true;
  // Pair forces from a neighbour list are evaluated once per pair and gathered
  // (sim/dynamics_pipeline.h): the contact arithmetic is most of a step here.
  static constexpr bool kPairForcesOncePerPair = true;
  // And, under the linear law, four at a time (sim/pair_batch.h).
  static constexpr bool kPairRecordsInBatches = true;
  // Its loops run on host threads (a pool), which a small scene may leave idle.
  static constexpr bool kHostThreads = true;
  static constexpr bool kRunsAhead = false;  // parallel_max answers at once
  // The pool that runs this backend's loops (nullptr: default_pool()).
  void set_pool(ThreadPool* pool) { pool_ = pool ? pool : &default_pool(); }
  int threads() const { return pool_->size(); }

  template <class T>
  using Buffer = std::vector<T>;

  template <class T>
  void resize(std::vector<T>& b, size_t n) {
    bytes_ += (int64_t(n) - int64_t(b.size())) * int64_t(sizeof(T));
    b.resize(n);
  }
  uint64_t bytes_held() const { return static_cast<uint64_t>(std::max<int64_t>(bytes_, 0)); }
  // Memory both sides read: all of it here.
  template <class T>
  void resize_host_visible(std::vector<T>& b, size_t n) {
    resize(b, n);
  }
  template <class T>
  T* host_pointer(std::vector<T>& b) const {
    return b.data();
  }

  template <class F>
  void parallel_for(size_t n, F f) {
    cpu_parallel_for(*pool_, n, f);
  }
  // Loop bodies with many live values: the GPU caps their registers; threads here.
  template <class F>
  void parallel_for_heavy(size_t n, F f) {
    cpu_parallel_for(*pool_, n, f, kHeavyGrain);
  }
  // body(begin, end) over chunks of [0, n) of at least `grain` indices.
  template <class F>
  void parallel_chunks(size_t n, size_t grain, F body) {
    if (n) pool_->run_chunks(n, grain, body);
  }
  // A tree walk: the GPU caps its registers; threads here.
  template <class F>
  void parallel_for_walk(size_t n, F f) {
    cpu_parallel_for(*pool_, n, f);
  }
  // f(i, group) for every i < n, one thread an item (see LaneGroup).
  uint32_t lanes_for(size_t, double, uint32_t) const { return 1; }
  template <class F>
  void parallel_for_lanes(size_t n, uint32_t, F f) {
    cpu_parallel_for(*pool_, n, [&f](uint32_t i) { f(i, LaneGroup{}); }, kHeavyGrain);
  }
  template <class F>
  void parallel_for_lanes_light(size_t n, uint32_t lanes, F f) {
    parallel_for_lanes(n, lanes, f);
  }
  // Items for a loop that strides over a count the device holds: one each here.
  uint32_t strided_items(size_t n, uint32_t) const { return static_cast<uint32_t>(n); }
  // Runs f(i) for every i < n and returns the largest value it returned (0
  // when n == 0); f returns doubles >= 0.
  template <class F>
  double parallel_max(size_t n, F f) {
    return parallel_max_chunks(n, [&f](size_t begin, size_t end) {
      double local = 0;
      for (size_t i = begin; i < end; ++i) local = std::max(local, f(static_cast<uint32_t>(i)));
      return local;
    });
  }
  // The largest of body(begin, end) over chunks of [0, n) (0 when n == 0);
  // body returns doubles >= 0.
  template <class F>
  double parallel_max_chunks(size_t n, F body) {
    if (n == 0) return 0;
    std::mutex m;
    double best = 0;
    pool_->run_chunks(n, kLightGrain, [&](size_t begin, size_t end) {
      const double local = body(begin, end);
      std::lock_guard<std::mutex> lock(m);
      best = std::max(best, local);
    });
    return best;
  }
  template <class T>
  void fill(T* p, size_t n, T v) {
    std::fill(p, p + n, v);
  }
  void copy(void* dst, const void* src, size_t bytes) { std::memcpy(dst, src, bytes); }
  void to_device(void* dst, const void* src, size_t bytes) { std::memcpy(dst, src, bytes); }
  void to_host(void* dst, const void* src, size_t bytes) { std::memcpy(dst, src, bytes); }
  void sync() {}
  Status status() const { return Status::ok(); }

  // In-place exclusive prefix sum; returns the total.
  uint64_t exclusive_scan(uint32_t* d, size_t n) {
    uint64_t sum = 0;
    for (size_t i = 0; i < n; ++i) {
      const uint32_t v = d[i];
      d[i] = static_cast<uint32_t>(sum);
      sum += v;
    }
    return sum;
  }

  void exclusive_scan_on_device(uint32_t* d, size_t n) { exclusive_scan(d, n); }

  // The indices i < n where keep(i), in order, into out; their count into *count.
  template <class F>
  void select_indices(size_t n, F keep, uint32_t* out, uint32_t* count) {
    uint32_t m = 0;
    for (size_t i = 0; i < n; ++i)
      if (keep(static_cast<uint32_t>(i))) out[m++] = static_cast<uint32_t>(i);
    *count = m;
  }

  // Sum and maximum of n doubles (0 when n == 0); per-frame statistics and the time step.
  double reduce_sum(const double* d, size_t n) { return std::accumulate(d, d + n, 0.0); }
  double reduce_max(const double* d, size_t n) { return n ? *std::max_element(d, d + n) : 0.0; }
  // Each column's reduce_sum, or reduce_max for the columns of max_mask.
  void reduce_columns(const double* const* columns, size_t count, size_t n,
                      unsigned long long max_mask, double* out) {
    for (size_t c = 0; c < count; ++c)
      out[c] = (max_mask >> c) & 1ull ? reduce_max(columns[c], n) : reduce_sum(columns[c], n);
  }

  // Stable LSD radix sort of (key, value) pairs into kout/vout, 8 bits a pass;
  // passes whose byte is the same for every key are skipped (so key_bits, the
  // bits the keys use, needs no special handling here).
  void sort_pairs(const uint32_t* kin, const uint32_t* vin, uint32_t* kout, uint32_t* vout, size_t n,
                  int key_bits = 32) {
    (void)key_bits;
    tk_.resize(n);
    tv_.resize(n);
    std::memcpy(kout, kin, n * sizeof(uint32_t));
    std::memcpy(vout, vin, n * sizeof(uint32_t));
    uint32_t *ks = kout, *vs = vout, *kd = tk_.data(), *vd = tv_.data();
    for (int shift = 0; shift < 32; shift += 8) {
      size_t hist[257] = {0};
      for (size_t i = 0; i < n; ++i) ++hist[((ks[i] >> shift) & 0xFF) + 1];
      if (n && hist[((ks[0] >> shift) & 0xFF) + 1] == n) continue;
      for (int b = 0; b < 256; ++b) hist[b + 1] += hist[b];
      for (size_t i = 0; i < n; ++i) {
        const size_t slot = hist[(ks[i] >> shift) & 0xFF]++;
        kd[slot] = ks[i];
        vd[slot] = vs[i];
      }
      std::swap(ks, kd);
      std::swap(vs, vd);
    }
    if (ks != kout) {
      std::memcpy(kout, ks, n * sizeof(uint32_t));
      std::memcpy(vout, vs, n * sizeof(uint32_t));
    }
  }

  // Sorts (key, distance) pairs by key and keeps one pair per key with the
  // smallest distance, written to kout/dout; returns how many remain.
  uint32_t dedup_min(const uint64_t* key, const float* dist, size_t n, uint64_t* kout, float* dout) {
    order_.resize(n);
    std::iota(order_.begin(), order_.end(), 0u);
    std::sort(order_.begin(), order_.end(), [&](uint32_t a, uint32_t b) {
      return key[a] != key[b] ? key[a] < key[b] : dist[a] < dist[b];
    });
    uint32_t m = 0;
    for (size_t i = 0; i < n; ++i) {
      const uint32_t s = order_[i];
      if (m && kout[m - 1] == key[s]) continue;  // sorted by distance within a key: first is smallest
      kout[m] = key[s];
      dout[m] = dist[s];
      ++m;
    }
    return m;
  }

  // Sorts each bucket's (triangle, cell) entries by triangle so runs repeat exactly.
  void sort_segments(uint32_t* tri, uint64_t* cell, const uint32_t* start, uint32_t buckets, uint64_t) {
    cpu_parallel_for(*pool_, buckets, [&](uint32_t b) {
      const uint32_t s = start[b], e = start[b + 1];
      if (e - s < 2) return;
      std::vector<std::pair<uint32_t, uint64_t>> v(e - s);
      for (uint32_t k = s; k < e; ++k) v[k - s] = {tri[k], cell[k]};
      std::sort(v.begin(), v.end());
      for (uint32_t k = s; k < e; ++k) tri[k] = v[k - s].first, cell[k] = v[k - s].second;
    }, 1024);
  }

 private:
  ThreadPool* pool_ = &default_pool();
  int64_t bytes_ = 0;
  std::vector<uint32_t> tk_, tv_, order_;
};

}  // namespace collido::sim
