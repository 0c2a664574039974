// The CPU side of the engine's one-source loops: a thread pool and
// parallel_for. Loop bodies are the same COLLIDO_HD lambdas the GPU runs.
//
// A pool is an object its owner holds (a job, a benchmark, a test); the engine
// reads it from its config (DetectConfig::pool, DynamicsConfig::pool). Callers
// that bring none share default_pool(), which is sized once and never resized,
// so no caller can change the threads of another one's running loop.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>

namespace collido::sim {

class ThreadPool {
 public:
  // `threads` workers in all, the calling thread included; <= 0 = usable_cpus().
  explicit ThreadPool(int threads = 0);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int size() const;
  // Runs body(begin, end) over chunks of [0, n) on the pool; returns when all
  // are done. Loops from several caller threads take turns.
  void run_chunks(size_t n, size_t grain, const std::function<void(size_t, size_t)>& body);
  // Runs body(i) for each i in [0, n), one index a claim: for a few heavy
  // items of uneven cost (run_chunks would hand out n / (8 threads) at a
  // time, and the octree's costly top cells lie side by side: its counter
  // mesh built in 1.1 s on 16 threads, no faster than on 2).
  void run_items(size_t n, const std::function<void(size_t)>& body);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// CPUs this process may really use: its affinity mask (taskset, a Slurm step,
// a container's cpuset), capped by a cgroup CPU quota where one is set. At least 1.
int usable_cpus();

// The pool shared by callers that bring none: usable_cpus() threads, made at first use.
ThreadPool& default_pool();

// Indices a chunk holds at least: a loop no longer than this runs on the
// calling thread alone. Light loops (a few ns an index: kicks, copies) and
// heavy ones (contact forces, list builds: up to about a microsecond an index).
inline constexpr size_t kLightGrain = 1024;
inline constexpr size_t kHeavyGrain = 64;

// Calls f(i) for every i in [0, n) on the pool's threads, in dynamically balanced chunks.
template <class F>
void cpu_parallel_for(ThreadPool& pool, size_t n, F&& f, size_t grain = kLightGrain) {
  if (n == 0) return;
  pool.run_chunks(n, grain, [&f](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) f(static_cast<uint32_t>(i));
  });
}

// Host-side atomic add used by loop bodies on the CPU backend.
inline uint32_t host_atomic_add(uint32_t* p, uint32_t v) {
  return __atomic_fetch_add(p, v, __ATOMIC_RELAXED);
}

}  // namespace collido::sim
