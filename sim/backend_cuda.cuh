// CUDA backend shared by the engine's pipelines (detection, dynamics): device
// buffers that grow but never shrink, a generic kernel for parallel_for, and CUB
// for scan, radix sort, segmented sort and reductions. No geometry lives here.
// Include only from .cu files.
#pragma once

#include <cuda_runtime.h>

#include <thrust/iterator/counting_iterator.h>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_reduce.cuh>
#include <cub/device/device_scan.cuh>
#include <cub/device/device_segmented_sort.cuh>
#include <cub/device/device_select.cuh>
#include <string>
#include <vector>

#include "sim/hd.h"
#include "sim/parallel.h"
#include "sim/status.h"

namespace collido::sim {

namespace cuda_detail {

struct MinOp {
  __device__ float operator()(float a, float b) const { return b < a ? b : a; }
};
// Sums 32-bit counts in 64 bits.
struct Plus64 {
  __host__ __device__ uint64_t operator()(uint64_t a, uint64_t b) const { return a + b; }
};

// Every loop kernel returns at once, all its threads alike, while the halt
// word it is given (when it is given one) is set: a dynamics step launched
// ahead of the host's look at the lists' check then does nothing (see
// CudaBackend::parallel_max_halting).
__device__ __forceinline__ bool halted(const unsigned long long* halt) {
  return halt && *halt;
}

template <class F>
__global__ void for_each_kernel(uint32_t n, F f, const unsigned long long* halt) {
  if (halted(halt)) return;
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) f(i);
}

// What the last block of a max pass decides: whether the largest value passed
// `limit`; then *halt = mark. count: the blocks done so far. The pass's
// largest value and count are left at 0 for the next pass (no memset to
// launch before it).
struct MaxDecision {
  unsigned int* count = nullptr;  // nullptr: nothing to decide
  unsigned long long* halt = nullptr;
  double limit = 0;
  unsigned long long mark = 0;
};

// f(i) for every i, and the largest value any returned (values >= 0, whose
// bits order as the numbers do) into *out: a warp's and then the block's
// largest, one atomic per block; with a decision, the last block to finish
// takes the whole pass's largest (and zeroes *out) and compares it with the limit.
template <class F>
__global__ void for_each_max_kernel(uint32_t n, F f, unsigned long long* out,
                                    const unsigned long long* halt, MaxDecision decide) {
  if (halted(halt)) return;
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  double v = i < n ? f(i) : 0.0;
  for (int o = 16; o > 0; o >>= 1) v = fmax(v, __shfl_down_sync(0xffffffffu, v, o));
  __shared__ double warp_max[32];
  if ((threadIdx.x & 31) == 0) warp_max[threadIdx.x >> 5] = v;
  __syncthreads();
  if (threadIdx.x != 0) return;
  double m = 0;
  for (uint32_t w = 0; w < (blockDim.x + 31) / 32; ++w) m = fmax(m, warp_max[w]);
  atomicMax(out, static_cast<unsigned long long>(__double_as_longlong(m)));
  if (!decide.count) return;
  __threadfence();  // this block's largest is seen by whichever block ends last
  if (atomicAdd(decide.count, 1u) != gridDim.x - 1) return;
  *decide.count = 0;
  const double largest = __longlong_as_double(static_cast<long long>(atomicExch(out, 0ull)));
  if (largest > decide.limit) *decide.halt = decide.mark;
}

// The same with at least two 256-thread blocks per SM: caps a heavy loop body
// at 128 registers so it keeps a quarter of the SM's threads in flight to hide
// its gathers (uncapped, the pair forces took 132 and ran one block per SM).
template <class F>
__global__ void __launch_bounds__(256, 2)
    for_each_kernel_heavy(uint32_t n, F f, const unsigned long long* halt) {
  if (halted(halt)) return;
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) f(i);
}

// The same capped at 80 registers (three 256-thread blocks an SM), for the
// tree walk: uncapped it took 112, which left 14 % of the SM's warps to hide
// its node fetches.
template <class F>
__global__ void __launch_bounds__(256, 3)
    for_each_kernel_walk(uint32_t n, F f, const unsigned long long* halt) {
  if (halted(halt)) return;
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) f(i);
}

// f(i, group) for every i < n, `size` consecutive lanes an item (a power of
// two up to 32, so a group never spans two warps); a group leaves together.
template <class F>
__device__ __forceinline__ void run_lanes(uint32_t n, uint32_t size, F& f) {
  const uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
  const uint32_t i = t / size;
  if (i >= n) return;
  LaneGroup g;
  g.lane = t & (size - 1);
  g.size = size;
  const uint32_t ones = size == 32 ? 0xffffffffu : (1u << size) - 1u;
  g.mask = ones << ((threadIdx.x & 31u) & ~(size - 1u));
  f(i, g);
}
template <class F>
__global__ void __launch_bounds__(256, 2)
    for_each_lanes_kernel(uint32_t n, uint32_t size, F f, const unsigned long long* halt) {
  if (!halted(halt)) run_lanes(n, size, f);
}

// The same with four 256-thread blocks an SM (64 registers at most), for a
// loop body that waits on its loads more than it computes and needs a few
// registers more than 64: the octree's test stage (sim/detect_pipeline.h).
template <class F>
__global__ void __launch_bounds__(256, 4)
    for_each_lanes_kernel_light(uint32_t n, uint32_t size, F f, const unsigned long long* halt) {
  if (!halted(halt)) run_lanes(n, size, f);
}

// Up to kMaxColumns columns of doubles reduced in one launch (see
// CudaBackend::reduce_columns).
inline constexpr int kMaxColumns = 32;
struct Columns {
  const double* col[kMaxColumns];
  unsigned long long max_mask;  // bit c: column c's largest value, else its sum
};

// Block (x, c): column c's values at x, x + stride, ... (stride: the grid's
// threads along x) summed, or their largest taken, in a fixed order, then the
// block's in a fixed tree: partials[c * gridDim.x + x]. The same bits every run.
static __global__ void __launch_bounds__(256)
    column_partials_kernel(Columns cols, uint32_t n, double* partials) {
  const uint32_t c = blockIdx.y;
  const bool largest = (cols.max_mask >> c) & 1ull;
  const double* d = cols.col[c];
  double v = largest ? -INFINITY : 0.0;
  for (uint32_t i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x)
    v = largest ? fmax(v, d[i]) : v + d[i];
  __shared__ double part[256];
  part[threadIdx.x] = v;
  __syncthreads();
  for (uint32_t h = blockDim.x / 2; h > 0; h >>= 1) {
    if (threadIdx.x < h)
      part[threadIdx.x] = largest ? fmax(part[threadIdx.x], part[threadIdx.x + h])
                                  : part[threadIdx.x] + part[threadIdx.x + h];
    __syncthreads();
  }
  if (threadIdx.x == 0) partials[size_t(c) * gridDim.x + blockIdx.x] = part[0];
}

}  // namespace cuda_detail

class CudaBackend {
 public:
  // A per-particle walk reads its particle through the sorted index: other
  // warps hide the scattered read, and a reordered copy would cost 16 bytes
  // of device memory a particle (sim/detect_pipeline.h, bvh).
  static constexpr bool kWalksReadReorderedCopy = false;
  // Pair forces from a neighbour list are evaluated by both particles: records
  // between two passes cost the GPU more memory traffic than the arithmetic
  // saves (H200, 10^6 particles with friction: 0.74 against 0.54 ms a step).
  static constexpr bool kPairForcesOncePerPair = false;
  static constexpr bool kPairRecordsInBatches = false;  // a CPU's vectors (sim/pair_batch.h)
  // Device memory that grows but never shrinks, so frames reuse it.
  template <class T>
  class Buffer {
   public:
    Buffer() = default;
    Buffer(const Buffer&) = delete;
    Buffer& operator=(const Buffer&) = delete;
    ~Buffer() { release(); }
    T* data() const { return ptr_; }
    size_t size() const { return size_; }

   private:
    friend class CudaBackend;
    void release() {
      if (ptr_) host_ ? cudaFreeHost(ptr_) : cudaFree(ptr_);
      ptr_ = nullptr;
    }
    T* ptr_ = nullptr;
    size_t size_ = 0, capacity_ = 0;
    bool host_ = false;  // pinned host memory the device reads (resize_host_visible)
  };

  static constexpr bool kHostThreads = false;
  // Work can be launched ahead of a decision the device takes itself
  // (parallel_max_halting): the host need not wait for the number.
  static constexpr bool kRunsAhead = true;
  void set_pool(ThreadPool*) {}  // the GPU needs no host threads
  int threads() const { return 0; }

  ~CudaBackend() {
    if (temp_) cudaFree(temp_);
  }

  template <class T>
  void resize(Buffer<T>& b, size_t n) {
    allocate(b, n, false);
  }
  // A buffer in pinned host memory that kernels read across the bus (mapped,
  // one address for both under unified addressing): for data the device
  // reads rarely, such as the double copy of the particles whose pairs fall
  // in float's band (a few in 10^3), which would otherwise hold 32 bytes of
  // device memory a particle. Not counted in bytes_held(); the host writes it
  // directly (host_pointer) between frames.
  template <class T>
  void resize_host_visible(Buffer<T>& b, size_t n) {
    allocate(b, n, true);
  }
  // Where the host may write b directly: host-visible buffers only.
  template <class T>
  T* host_pointer(Buffer<T>& b) const {
    return b.host_ ? b.ptr_ : nullptr;
  }
  uint64_t bytes_held() const { return bytes_ + temp_bytes_; }

  template <class F>
  void parallel_for(size_t n, F f) {
    launch(cuda_detail::for_each_kernel<F>, n, f);
  }
  // parallel_for for loop bodies with many live values (the force kernels).
  template <class F>
  void parallel_for_heavy(size_t n, F f) {
    launch(cuda_detail::for_each_kernel_heavy<F>, n, f);
  }
  // parallel_for for a tree walk (a loop of dependent node fetches).
  template <class F>
  void parallel_for_walk(size_t n, F f) {
    launch(cuda_detail::for_each_kernel_walk<F>, n, f);
  }
  // Lanes an item for parallel_for_lanes (n items of about `work` pieces
  // each), `asked` when not 0. A thread walking a particle's list alone is one
  // dependent load and contact after another, and with a few thousand
  // particles nothing hides that latency; lanes beyond the work only add
  // their sums. H200, `bench run --pairs on` (about 6 candidates a
  // particle), us a step with 1 / 2 / 4 / 8 lanes: 3,000 particles 47.4 /
  // 48.3 / 43.1 / 40.4; 10,000 49.5 / 50.3 / 46.3 / 48.8; 20,000 50.2 / 51.5
  // / 54.6 / 56.6. So 8 lanes up to 64 particles an SM, 4 up to 128, with
  // the candidates to share; never 2.
  uint32_t lanes_for(size_t n, double work, uint32_t asked) {
    if (asked > 0) return asked;
    const size_t sms = sm_count();
    if (work >= 6 && n <= sms * 64) return 8;
    if (work >= 3 && n <= sms * 128) return 4;
    return 1;
  }
  // f(i, group) for every i < n, `lanes` threads an item (one: the heavy kernel).
  template <class F>
  void parallel_for_lanes(size_t n, uint32_t lanes, F f) {
    if (lanes <= 1) {
      parallel_for_heavy(n, [=] __device__(uint32_t i) { f(i, LaneGroup{}); });
      return;
    }
    launch_lanes(cuda_detail::for_each_lanes_kernel<F>, n, lanes, f);
  }
  // The same with more threads in flight and fewer registers each (see
  // for_each_lanes_kernel_light); lanes a power of two from 2 to 32.
  template <class F>
  void parallel_for_lanes_light(size_t n, uint32_t lanes, F f) {
    launch_lanes(cuda_detail::for_each_lanes_kernel_light<F>, n, lanes, f);
  }
  // How many items of `lanes` threads a loop that strides over a count
  // known only on the device should launch: as many as the SMs hold at once.
  uint32_t strided_items(size_t n, uint32_t lanes) {
    return static_cast<uint32_t>(std::min<size_t>(n, size_t(sm_count()) * (2048 / lanes)));
  }
  template <class T>
  void fill(T* p, size_t n, T v) {
    // In parts a launch can index (the statistics of 2^28 particles are 17 x 2^28 values).
    constexpr size_t kPart = size_t(1) << 31;
    for (size_t at = 0; at < n; at += kPart) {
      T* q = p + at;
      parallel_for(std::min(kPart, n - at), [=] __device__(uint32_t i) { q[i] = v; });
    }
  }
  void copy(void* dst, const void* src, size_t bytes) {
    check(cudaMemcpyAsync(dst, src, bytes, cudaMemcpyDeviceToDevice), "cudaMemcpy D2D");
  }
  void to_device(void* dst, const void* src, size_t bytes) {
    check(cudaMemcpy(dst, src, bytes, cudaMemcpyHostToDevice), "cudaMemcpy H2D");
  }
  void to_host(void* dst, const void* src, size_t bytes) {
    check(cudaMemcpy(dst, src, bytes, cudaMemcpyDeviceToHost), "cudaMemcpy D2H");
  }
  void sync() { check(cudaDeviceSynchronize(), "kernel"); }
  Status status() const { return ok_ ? Status::ok() : Status(ErrorCode::kBackend, error_); }

  uint64_t exclusive_scan(uint32_t* d, size_t n) {
    if (n == 0) return 0;
    // The total in 64 bits, before the scan: the 32-bit prefixes wrap past
    // 2^32, and a total read from the last of them wrapped with them, so a
    // caller's limit (a bin's 2^31 entries) was passed where the CPU's held.
    resize(scalar_, 1);
    uint64_t* total = reinterpret_cast<uint64_t*>(scalar_.data());
    if (!cub_call("reduce", [&](void* t, size_t& bytes) {
          return cub::DeviceReduce::Reduce(t, bytes, d, total, static_cast<int>(n),
                                           cuda_detail::Plus64{}, uint64_t(0));
        }))
      return 0;
    uint64_t sum = 0;
    to_host(&sum, total, sizeof sum);
    // In place: CUB's scans take the same sequence in and out.
    if (!cub_call("scan", [&](void* t, size_t& bytes) {
          return cub::DeviceScan::ExclusiveSum(t, bytes, d, d, static_cast<int>(n));
        }))
      return 0;
    return sum;
  }

  // In-place exclusive prefix sum that stays on the device (no total read
  // back, so nothing waits): for counts whose sum fits 32 bits.
  void exclusive_scan_on_device(uint32_t* d, size_t n) {
    if (n == 0) return;
    cub_call("scan", [&](void* t, size_t& bytes) {
      return cub::DeviceScan::ExclusiveSum(t, bytes, d, d, static_cast<int>(n));
    });
  }

  // Sum and maximum of n doubles (0 when n == 0); one small read-back each.
  double reduce_sum(const double* d, size_t n) {
    if (n == 0) return 0;
    resize(scalar_, 1);
    if (!cub_call("reduce", [&](void* t, size_t& bytes) {
          return cub::DeviceReduce::Sum(t, bytes, d, scalar_.data(), static_cast<int>(n));
        }))
      return 0;
    double v = 0;
    to_host(&v, scalar_.data(), sizeof v);
    return v;
  }
  // Sums (or, for the columns of max_mask, largest values) of the first n
  // doubles of each column, 0 when n == 0: one launch and one read-back for
  // them all, where a reduction each cost a round trip to the device (18 for
  // a frame's statistics: 0.2-0.3 ms a frame on the H200).
  void reduce_columns(const double* const* columns, size_t count, size_t n,
                      unsigned long long max_mask, double* out) {
    std::fill(out, out + count, 0.0);
    if (n == 0 || count == 0 || !ok_) return;
    if (count > size_t(cuda_detail::kMaxColumns) || n > UINT32_MAX) {
      // The statistics are 18 columns over a particle count that launch() indexes.
      ok_ = false;
      error_ = "a reduction of " + std::to_string(count) + " columns of " + std::to_string(n) +
               " is more than one launch takes";
      return;
    }
    cuda_detail::Columns cols{};
    for (size_t c = 0; c < count; ++c) cols.col[c] = columns[c];
    cols.max_mask = max_mask;
    constexpr uint32_t kBlock = 256;
    const uint32_t blocks = uint32_t(std::min<size_t>((n + kBlock - 1) / kBlock, 4 * sm_count()));
    resize(partials_, count * blocks);
    if (!ok_) return;
    cuda_detail::column_partials_kernel<<<dim3(blocks, uint32_t(count)), kBlock>>>(
        cols, uint32_t(n), partials_.data());
    if (!check(cudaGetLastError(), "kernel launch")) return;
    std::vector<double> host(count * blocks);
    to_host(host.data(), partials_.data(), host.size() * sizeof(double));
    if (!ok_) return;
    for (size_t c = 0; c < count; ++c) {
      const bool largest = (max_mask >> c) & 1ull;
      double v = largest ? -INFINITY : 0.0;
      for (uint32_t b = 0; b < blocks; ++b)
        v = largest ? std::max(v, host[c * blocks + b]) : v + host[c * blocks + b];
      out[c] = v;
    }
  }
  // Runs f(i) for every i < n and returns the largest value it returned (0
  // when n == 0); f returns doubles >= 0. One pass, no reduction of its own.
  template <class F>
  double parallel_max(size_t n, F f) {
    if (n == 0 || !ok_) return 0;
    resize(max_bits_, 1);
    check(cudaMemsetAsync(max_bits_.data(), 0, sizeof(unsigned long long)), "memset");
    launch_max(n, f, max_bits_.data(), {});
    unsigned long long bits = 0;
    to_host(&bits, max_bits_.data(), sizeof bits);
    return bits_as_double(bits);
  }
  // parallel_max that leaves the decision on the device: when the largest
  // value passes `limit`, the halt word is set to `mark` (non-zero), and every
  // loop launched after it returns at once until halt() reads and clears it.
  // A window of work can so be launched ahead of a check that may void it
  // (the dynamics' lists), with no wait for the device each time.
  template <class F>
  void parallel_max_halting(size_t n, F f, double limit, unsigned long long mark) {
    if (n == 0 || !ok_) return;
    if (halt_.size() == 0) {
      // The word, the count of blocks done, the pass's largest value, and a
      // reduction's result read back with the word (halt_and_max).
      resize(halt_, 4);
      if (!ok_ ||
          !check(cudaMemsetAsync(halt_.data(), 0, 4 * sizeof(unsigned long long)), "memset"))
        return;
    }
    cuda_detail::MaxDecision d;
    d.count = reinterpret_cast<unsigned int*>(halt_.data() + 1);
    d.halt = halt_.data();
    d.limit = limit;
    d.mark = mark;
    launch_max(n, f, halt_.data() + 2, d);
  }
  // The halt word (0 when nothing halted), read once the work launched before
  // has run, and cleared.
  unsigned long long halt() {
    double none;
    return halt_and_max(nullptr, 0, &none);
  }
  // halt() and reduce_max(d, n) in one wait for the device: the largest of
  // d[0, n) is reduced beside the halt word and both come back in one copy.
  // When the word is set, the work it voided may have left d stale: the
  // value is then the caller's to throw away.
  unsigned long long halt_and_max(const double* d, size_t n, double* largest) {
    *largest = 0;
    if (halt_.size() == 0) {
      *largest = reduce_max(d, n);
      return 0;
    }
    if (!ok_) return 0;
    double* slot = reinterpret_cast<double*>(halt_.data() + 3);
    if (n > 0 && !cub_call("reduce", [&](void* t, size_t& bytes) {
          return cub::DeviceReduce::Max(t, bytes, d, slot, static_cast<int>(n));
        }))
      return 0;
    unsigned long long words[4] = {};
    to_host(words, halt_.data(), sizeof words);
    if (!ok_) return 0;
    if (words[0]) check(cudaMemsetAsync(halt_.data(), 0, sizeof words[0]), "memset");
    if (n > 0) *largest = bits_as_double(words[3]);
    return words[0];
  }
  double reduce_max(const double* d, size_t n) {
    if (n == 0) return 0;
    resize(scalar_, 1);
    if (!cub_call("reduce", [&](void* t, size_t& bytes) {
          return cub::DeviceReduce::Max(t, bytes, d, scalar_.data(), static_cast<int>(n));
        }))
      return 0;
    double v = 0;
    to_host(&v, scalar_.data(), sizeof v);
    return v;
  }

  // The indices i < n where keep(i), in order, into out; their count into
  // *count, which stays on the device (one pass, CUB's decoupled look-back).
  template <class F>
  void select_indices(size_t n, F keep, uint32_t* out, uint32_t* count) {
    if (n == 0) {
      fill(count, 1, 0u);
      return;
    }
    cub_call("select", [&](void* t, size_t& bytes) {
      return cub::DeviceSelect::If(t, bytes, thrust::counting_iterator<uint32_t>(0), out, count,
                                   static_cast<int>(n), keep);
    });
  }

  // Radix sort of (key, value) pairs over the low key_bits bits of the keys.
  void sort_pairs(const uint32_t* kin, const uint32_t* vin, uint32_t* kout, uint32_t* vout, size_t n,
                  int key_bits = 32) {
    if (n == 0) return;
    cub_call("sort", [&](void* t, size_t& bytes) {
      return cub::DeviceRadixSort::SortPairs(t, bytes, kin, kout, vin, vout, static_cast<int>(n), 0, key_bits);
    });
  }

  uint32_t dedup_min(uint64_t* key, float* dist, size_t n, uint64_t* kout, float* dout) {
    if (n == 0) return 0;
    if (!cub_call("sort", [&](void* t, size_t& bytes) {
          return cub::DeviceRadixSort::SortPairs(t, bytes, key, kout, dist, dout, static_cast<int>(n));
        }))
      return 0;
    resize(runs_, 1);
    if (!cub_call("reduce_by_key", [&](void* t, size_t& bytes) {
          return cub::DeviceReduce::ReduceByKey(t, bytes, kout, key, dout, dist, runs_.data(), cuda_detail::MinOp(),
                                                static_cast<int>(n));
        }))
      return 0;
    uint32_t runs = 0;
    to_host(&runs, runs_.data(), sizeof runs);
    copy(kout, key, runs * sizeof(uint64_t));
    copy(dout, dist, runs * sizeof(float));
    return runs;
  }

  void sort_segments(uint32_t* tri, uint64_t* cell, const uint32_t* start, uint32_t buckets, uint64_t total) {
    if (total == 0) return;
    resize(seg_tri_, total);
    resize(seg_cell_, total);
    if (!cub_call("segmented sort", [&](void* t, size_t& bytes) {
          return cub::DeviceSegmentedSort::SortPairs(t, bytes, tri, seg_tri_.data(), cell, seg_cell_.data(),
                                                     static_cast<int>(total), static_cast<int>(buckets), start,
                                                     start + 1);
        }))
      return;
    copy(tri, seg_tri_.data(), total * sizeof(uint32_t));
    copy(cell, seg_cell_.data(), total * sizeof(uint64_t));
  }

 private:
  // n items of `lanes` threads each, in 256-thread blocks, for either lanes kernel.
  template <class F>
  void launch_lanes(void (*kernel)(uint32_t, uint32_t, F, const unsigned long long*), size_t n,
                    uint32_t lanes, F f) {
    if (n == 0 || !ok_) return;
    const uint32_t blocks = static_cast<uint32_t>((n * lanes + 255) / 256);
    kernel<<<blocks, 256>>>(static_cast<uint32_t>(n), lanes, f, halt_word());
    check(cudaGetLastError(), "kernel launch");
  }
  // One thread per index in 256-thread blocks, for either loop kernel.
  template <class F>
  void launch(void (*kernel)(uint32_t, F, const unsigned long long*), size_t n, F f) {
    if (n == 0 || !ok_) return;
    if (n > UINT32_MAX) {  // a 32-bit index would wrap: an error, not a loop over part of it
      ok_ = false;
      error_ = "a loop over " + std::to_string(n) + " elements is more than one launch indexes";
      return;
    }
    constexpr uint32_t kBlock = 256;
    const uint32_t blocks = static_cast<uint32_t>((n + kBlock - 1) / kBlock);
    kernel<<<blocks, kBlock>>>(static_cast<uint32_t>(n), f, halt_word());
    check(cudaGetLastError(), "kernel launch");
  }
  // The max pass both parallel_max calls launch: the largest f(i) into *out
  // (which starts at 0), and the decision when there is one.
  template <class F>
  void launch_max(size_t n, F f, unsigned long long* out, cuda_detail::MaxDecision decide) {
    constexpr uint32_t kBlock = 256;
    const uint32_t blocks = static_cast<uint32_t>((n + kBlock - 1) / kBlock);
    cuda_detail::for_each_max_kernel<<<blocks, kBlock>>>(static_cast<uint32_t>(n), f, out,
                                                         halt_word(), decide);
    check(cudaGetLastError(), "kernel launch");
  }
  // The halt word loops read: none until a halting pass has been asked for.
  const unsigned long long* halt_word() const { return halt_.size() ? halt_.data() : nullptr; }

  // The device's SMs, read once.
  uint32_t sm_count() {
    if (sms_ == 0) {
      int device = 0, count = 0;
      if (cudaGetDevice(&device) != cudaSuccess ||
          cudaDeviceGetAttribute(&count, cudaDevAttrMultiProcessorCount, device) != cudaSuccess)
        count = 1;
      sms_ = count > 0 ? uint32_t(count) : 1u;
    }
    return sms_;
  }

  // b holding n elements, in device memory or (host) pinned host memory; it
  // grows but never shrinks, so frames reuse it.
  template <class T>
  void allocate(Buffer<T>& b, size_t n, bool host) {
    if (n <= b.capacity_ && b.host_ == host) {
      b.size_ = n;
      return;
    }
    if (b.ptr_ && !b.host_) bytes_ -= b.capacity_ * sizeof(T);
    b.release();
    b.size_ = b.capacity_ = 0;
    b.host_ = host;
    if (n == 0) return;
    void* p = nullptr;
    const bool ok = host ? check(cudaHostAlloc(&p, n * sizeof(T), cudaHostAllocMapped), "cudaHostAlloc")
                         : check(cudaMalloc(&p, n * sizeof(T)), "cudaMalloc");
    if (!ok) return;
    b.ptr_ = static_cast<T*>(p);
    b.size_ = b.capacity_ = n;
    if (!host) bytes_ += n * sizeof(T);
  }

  // One CUB call the CUB way: a size query (call with null scratch), the
  // scratch, the call. Nothing runs once an error is recorded: after a failed
  // allocation the buffers are null, and a CUB kernel writing there would
  // poison the process's CUDA context for every other detector and job (the
  // caller should see the first error, "out of memory"). Returns whether it ran.
  template <class Call>
  bool cub_call(const char* what, Call call) {
    if (!ok_) return false;
    size_t bytes = 0;
    call(nullptr, bytes);
    void* t = temp(bytes);
    return ok_ && check(call(t, bytes), what);
  }

  bool check(cudaError_t e, const char* what) {
    if (e == cudaSuccess) return true;
    if (ok_) error_ = std::string("CUDA ") + what + ": " + cudaGetErrorString(e);
    ok_ = false;
    return false;
  }
  static double bits_as_double(unsigned long long bits) {
    double v = 0;
    std::memcpy(&v, &bits, sizeof v);
    return v;
  }

  // CUB's scratch space, grown on demand and kept for later frames.
  void* temp(size_t bytes) {
    if (bytes > temp_bytes_) {
      if (temp_) cudaFree(temp_);
      temp_ = nullptr;
      temp_bytes_ = 0;
      if (check(cudaMalloc(&temp_, bytes), "cudaMalloc (scratch)")) temp_bytes_ = bytes;
    }
    return temp_;
  }

  bool ok_ = true;
  std::string error_;
  uint64_t bytes_ = 0;
  void* temp_ = nullptr;
  size_t temp_bytes_ = 0;
  Buffer<uint32_t> runs_, seg_tri_;
  Buffer<uint64_t> seg_cell_;
  Buffer<double> scalar_, partials_;
  Buffer<unsigned long long> max_bits_;  // parallel_max's result, as the bits of a double
  // parallel_max_halting's word, block count and largest value, and halt_and_max's result.
  Buffer<unsigned long long> halt_;
  uint32_t sms_ = 0;                      // the device's SMs (sm_count)
};

}  // namespace collido::sim
