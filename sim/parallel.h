// The CPU side of the engine's one-source loops: a persistent thread pool and
// parallel_for. Loop bodies are the same COLLIDO_HD lambdas the GPU runs.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>

namespace collido::sim {

// Threads used by CPU loops; 0 = all hardware threads. Takes effect at the next loop.
void set_cpu_threads(int threads);
int cpu_threads();

namespace detail {
// Runs body(begin, end) over chunks of [0, n) on the pool; returns when all are done.
void run_chunks(size_t n, size_t grain, const std::function<void(size_t, size_t)>& body);
}  // namespace detail

// Calls f(i) for every i in [0, n) on all pool threads, in dynamically balanced chunks.
template <class F>
void cpu_parallel_for(size_t n, F&& f, size_t grain = 4096) {
  if (n == 0) return;
  detail::run_chunks(n, grain, [&f](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) f(static_cast<uint32_t>(i));
  });
}

// Host-side atomic add used by loop bodies on the CPU backend.
inline uint32_t host_atomic_add(uint32_t* p, uint32_t v) {
  return __atomic_fetch_add(p, v, __ATOMIC_RELAXED);
}

}  // namespace collido::sim
