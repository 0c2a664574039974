#include "sim/parallel.h"

#include <sched.h>

#include <algorithm>
#include <atomic>
#include <chrono>
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
//
// A dynamics step is several loops of a few hundred microseconds each, back
// to back. Two things made a second thread useless there (a 6,000-particle
// pour: 22.0 s on one thread, 22.6 s on two): a worker slept on a condition
// variable between loops, and waking it took about as long as the loop; and
// the caller waited for every worker to check in, even one still waking after
// the caller had done all the work itself. So a worker now spins a short while
// for the next loop before it sleeps, and a loop ends when its indices are
// done, whoever ran them.
//
// Claims go through one 64-bit ticket, the loop's generation over the next
// free index. A claim is a compare-and-swap of the ticket the claimer read,
// so a thread that read a loop's fields and then lost the race to that loop's
// end claims nothing: the caller closes the ticket (index past any count)
// before it writes the next loop's fields, and a generation comes back only
// after 2^32 loops.
struct ThreadPool::Impl {
  static constexpr uint64_t kClosed = 0xFFFFFFFFu;
  // How long an idle worker looks for the next loop before it sleeps, and the
  // caller for the workers' last chunks before it blocks. Short: with another
  // process on the machine, spinning takes the time the others need (a
  // 25,000-particle fill beside a busy loop on the 2-core VM: 6.4-6.8 s with
  // the old sleeping pool, 7.6-8.0 s spinning 200 µs, 6.2-6.8 s spinning 20
  // µs), and 20 µs catches the next pass of a dynamics step as well as 200 did.
  static constexpr auto kSpin = std::chrono::microseconds(20);

  explicit Impl(int threads) : size(threads) {
    for (int t = 1; t < threads; ++t) workers.emplace_back([this] { worker(); });
  }
  ~Impl() {
    {
      std::lock_guard<std::mutex> lk(m);
      stop.store(true);
    }
    cv.notify_all();
    for (auto& w : workers) w.join();
  }

  // exact: chunks of exactly grain_in (run_items); else at least grain_in,
  // and at most n / (8 threads) so that a light loop's claims stay few.
  void run(size_t n, size_t grain_in, const std::function<void(size_t, size_t)>& fn,
           bool exact = false) {
    std::lock_guard<std::mutex> serial(run_mutex);
    const size_t chunks_wanted = static_cast<size_t>(size) * 8;
    size_t g = exact ? grain_in : std::max(grain_in, (n + chunks_wanted - 1) / chunks_wanted);
    g = std::max<size_t>(g, 1);
    if (size == 1 || n <= g) {
      fn(0, n);
      return;
    }
    // Indices live in the ticket's low 32 bits: a longer loop runs in parts.
    constexpr size_t kPart = size_t(1) << 31;
    if (n <= kPart) return run_part(n, g, fn);
    for (size_t base = 0; base < n; base += kPart) {
      const std::function<void(size_t, size_t)> part = [&](size_t b, size_t e) {
        fn(base + b, base + e);
      };
      run_part(std::min(kPart, n - base), g, part);
    }
  }

  // One loop of n <= 2^31 indices on every thread.
  void run_part(size_t n, size_t g, const std::function<void(size_t, size_t)>& fn) {
    body.store(&fn, std::memory_order_relaxed);
    count.store(n, std::memory_order_relaxed);
    grain.store(g, std::memory_order_relaxed);
    finished.store(0, std::memory_order_relaxed);
    const uint64_t gen = ++generation;
    ticket.store(gen << 32);  // publishes the fields above (seq_cst)
    if (sleepers.load() > 0) {
      std::lock_guard<std::mutex> lk(m);
      cv.notify_all();
    }
    work(gen);
    // The rest is in workers' hands: wait for it, briefly spinning first.
    const auto until = std::chrono::steady_clock::now() + kSpin;
    while (finished.load(std::memory_order_acquire) != n) {
      if (std::chrono::steady_clock::now() > until) {
        std::unique_lock<std::mutex> lk(m);
        done_cv.wait(lk, [&] { return finished.load(std::memory_order_acquire) == n; });
        break;
      }
      cpu_relax();
    }
    ticket.store((gen << 32) | kClosed);  // no late claim reaches the next loop's fields
  }

  // Claims and runs chunks of loop `gen` until none is left (or the loop is over).
  void work(uint64_t gen) {
    uint64_t t = ticket.load();
    for (;;) {
      if ((t >> 32) != gen) return;
      const size_t idx = t & kClosed, n = count.load(std::memory_order_relaxed);
      if (idx >= n) return;
      const size_t end = std::min(n, idx + grain.load(std::memory_order_relaxed));
      const auto* fn = body.load(std::memory_order_relaxed);
      if (!ticket.compare_exchange_weak(t, (gen << 32) | end)) continue;  // t reloaded
      // Claimed: loop `gen` cannot end before this chunk is counted, so its fields hold.
      (*fn)(idx, end);
      if (finished.fetch_add(end - idx, std::memory_order_acq_rel) + (end - idx) == n) {
        std::lock_guard<std::mutex> lk(m);
        done_cv.notify_one();
      }
      t = ticket.load();
    }
  }

  void worker() {
    uint64_t seen = 0;
    for (;;) {
      const auto until = std::chrono::steady_clock::now() + kSpin;
      uint64_t gen = ticket.load() >> 32;
      for (int spins = 0; gen == seen && !stop.load(std::memory_order_relaxed); ++spins) {
        if ((spins & 63) == 63 && std::chrono::steady_clock::now() > until) {
          std::unique_lock<std::mutex> lk(m);
          ++sleepers;
          cv.wait(lk, [&] { return stop.load() || (ticket.load() >> 32) != seen; });
          --sleepers;
        }
        cpu_relax();
        gen = ticket.load() >> 32;
      }
      if (stop.load()) return;
      seen = gen;
      work(gen);
    }
  }

  static void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    asm volatile("yield");
#endif
  }

  const int size;
  std::vector<std::thread> workers;
  std::mutex run_mutex, m;
  std::condition_variable cv, done_cv;
  std::atomic<bool> stop{false};
  std::atomic<int> sleepers{0};
  uint32_t generation = 0;  // the caller's count of loops, wrapping (under run_mutex)
  std::atomic<uint64_t> ticket{0};
  std::atomic<const std::function<void(size_t, size_t)>*> body{nullptr};
  std::atomic<size_t> count{0}, grain{1}, finished{0};
};

ThreadPool::ThreadPool(int threads)
    : impl_(std::make_unique<Impl>(threads > 0 ? threads : usable_cpus())) {}
ThreadPool::~ThreadPool() = default;
int ThreadPool::size() const { return impl_->size; }
void ThreadPool::run_chunks(size_t n, size_t grain,
                            const std::function<void(size_t, size_t)>& body) {
  impl_->run(n, grain, body);
}

void ThreadPool::run_items(size_t n, const std::function<void(size_t)>& body) {
  impl_->run(
      n, 1,
      [&body](size_t begin, size_t end) {
        for (size_t i = begin; i < end; ++i) body(i);
      },
      true);
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
