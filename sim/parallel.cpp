#include "sim/parallel.h"

#include <sched.h>

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <fstream>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace collido::sim {

// Persistent workers: a frame of 10^6 particles is a few ms, so starting
// threads for every loop would cost more than the loop.
struct ThreadPool::Impl {
  explicit Impl(int threads) : size(threads) {
    for (int t = 1; t < threads; ++t) workers.emplace_back([this] { worker(); });
  }
  ~Impl() {
    {
      std::lock_guard<std::mutex> lk(m);
      stop = true;
    }
    cv.notify_all();
    for (auto& w : workers) w.join();
  }

  void run(size_t n, size_t grain_in, const std::function<void(size_t, size_t)>& fn) {
    std::lock_guard<std::mutex> serial(run_mutex);
    const size_t chunks_wanted = static_cast<size_t>(size) * 8;
    size_t g = std::max(grain_in, (n + chunks_wanted - 1) / chunks_wanted);
    g = std::max<size_t>(g, 1);
    if (size == 1 || n <= g) {
      fn(0, n);
      return;
    }
    {
      std::lock_guard<std::mutex> lk(m);
      body = &fn;
      count = n;
      grain = g;
      next.store(0);
      active = static_cast<int>(workers.size());
      ++generation;
    }
    cv.notify_all();
    drain();
    std::unique_lock<std::mutex> lk(m);
    done_cv.wait(lk, [this] { return active == 0; });
    body = nullptr;
  }

  void drain() {
    for (;;) {
      const size_t begin = next.fetch_add(grain);
      if (begin >= count) return;
      (*body)(begin, std::min(count, begin + grain));
    }
  }
  void worker() {
    uint64_t seen = 0;
    for (;;) {
      {
        std::unique_lock<std::mutex> lk(m);
        cv.wait(lk, [&] { return stop || generation != seen; });
        if (stop) return;
        seen = generation;
      }
      drain();
      std::lock_guard<std::mutex> lk(m);
      if (--active == 0) done_cv.notify_one();
    }
  }

  const int size;
  std::vector<std::thread> workers;
  std::mutex run_mutex, m;
  std::condition_variable cv, done_cv;
  bool stop = false;
  uint64_t generation = 0;
  int active = 0;
  const std::function<void(size_t, size_t)>* body = nullptr;
  size_t count = 0, grain = 1;
  std::atomic<size_t> next{0};
};

ThreadPool::ThreadPool(int threads)
    : impl_(std::make_unique<Impl>(threads > 0 ? threads : usable_cpus())) {}
ThreadPool::~ThreadPool() = default;
int ThreadPool::size() const { return impl_->size; }
void ThreadPool::run_chunks(size_t n, size_t grain,
                            const std::function<void(size_t, size_t)>& body) {
  impl_->run(n, grain, body);
}

namespace {

// The CPU quota of this process's cgroup in CPUs (v2 "cpu.max", else v1
// "cpu.cfs_quota_us"/"cpu.cfs_period_us"); 0 when none is set or readable.
double cgroup_cpu_quota() {
  std::ifstream self("/proc/self/cgroup");
  std::string line, v2_path;
  while (std::getline(self, line))
    if (line.rfind("0::", 0) == 0) v2_path = line.substr(3);
  for (const std::string& dir : {"/sys/fs/cgroup" + v2_path, std::string("/sys/fs/cgroup")}) {
    std::ifstream f(dir + "/cpu.max");
    std::string quota;
    double period = 0;
    if (f >> quota >> period && quota != "max" && period > 0) {
      const double q = std::atof(quota.c_str());
      if (q > 0) return q / period;
    }
  }
  std::ifstream q1("/sys/fs/cgroup/cpu/cpu.cfs_quota_us"), p1("/sys/fs/cgroup/cpu/cpu.cfs_period_us");
  double q = 0, p = 0;
  if (q1 >> q && p1 >> p && q > 0 && p > 0) return q / p;
  return 0;
}

}  // namespace

int usable_cpus() {
  int n = 0;
  cpu_set_t set;
  if (sched_getaffinity(0, sizeof set, &set) == 0) n = CPU_COUNT(&set);
  if (n <= 0) n = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const double quota = cgroup_cpu_quota();
  if (quota > 0) n = std::min(n, std::max(1, static_cast<int>(std::ceil(quota - 1e-9))));
  return std::max(1, n);
}

ThreadPool& default_pool() {
  static ThreadPool pool(usable_cpus());
  return pool;
}

}  // namespace collido::sim
