#include "sim/parallel.h"

#include <algorithm>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace collido::sim {
namespace {

// A pool of persistent workers: a frame of 10^6 particles is a few ms, so
// starting threads for every loop would cost more than the loop.
class Pool {
 public:
  explicit Pool(int threads) {
    for (int t = 1; t < threads; ++t) workers_.emplace_back([this] { worker(); });
    size_ = threads;
  }
  ~Pool() {
    {
      std::lock_guard<std::mutex> lk(m_);
      stop_ = true;
    }
    cv_.notify_all();
    for (auto& w : workers_) w.join();
  }
  int size() const { return size_; }

  void run(size_t n, size_t grain, const std::function<void(size_t, size_t)>& body) {
    // One loop at a time: callers on several threads (service workers) take turns.
    std::lock_guard<std::mutex> serial(run_mutex_);
    const size_t chunks_wanted = static_cast<size_t>(size_) * 8;
    grain = std::max(grain, (n + chunks_wanted - 1) / chunks_wanted);
    grain = std::max<size_t>(grain, 1);
    if (size_ == 1 || n <= grain) {
      body(0, n);
      return;
    }
    {
      std::lock_guard<std::mutex> lk(m_);
      body_ = &body;
      n_ = n;
      grain_ = grain;
      next_.store(0);
      active_ = static_cast<int>(workers_.size());
      ++generation_;
    }
    cv_.notify_all();
    drain();
    std::unique_lock<std::mutex> lk(m_);
    done_cv_.wait(lk, [this] { return active_ == 0; });
    body_ = nullptr;
  }

 private:
  void drain() {
    for (;;) {
      size_t begin = next_.fetch_add(grain_);
      if (begin >= n_) return;
      (*body_)(begin, std::min(n_, begin + grain_));
    }
  }
  void worker() {
    uint64_t seen = 0;
    for (;;) {
      {
        std::unique_lock<std::mutex> lk(m_);
        cv_.wait(lk, [&] { return stop_ || generation_ != seen; });
        if (stop_) return;
        seen = generation_;
      }
      drain();
      std::lock_guard<std::mutex> lk(m_);
      if (--active_ == 0) done_cv_.notify_one();
    }
  }

  std::vector<std::thread> workers_;
  int size_ = 1;
  std::mutex run_mutex_, m_;
  std::condition_variable cv_, done_cv_;
  bool stop_ = false;
  uint64_t generation_ = 0;
  int active_ = 0;
  const std::function<void(size_t, size_t)>* body_ = nullptr;
  size_t n_ = 0, grain_ = 1;
  std::atomic<size_t> next_{0};
};

std::mutex g_pool_mutex;
std::unique_ptr<Pool> g_pool;
int g_requested = 0;

Pool& pool() {
  std::lock_guard<std::mutex> lk(g_pool_mutex);
  int want = g_requested > 0 ? g_requested : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  if (!g_pool || g_pool->size() != want) {
    g_pool.reset();
    g_pool = std::make_unique<Pool>(want);
  }
  return *g_pool;
}

}  // namespace

void set_cpu_threads(int threads) {
  std::lock_guard<std::mutex> lk(g_pool_mutex);
  g_requested = std::max(0, threads);
}

int cpu_threads() { return pool().size(); }

namespace detail {
void run_chunks(size_t n, size_t grain, const std::function<void(size_t, size_t)>& body) {
  pool().run(n, grain, body);
}
}  // namespace detail

}  // namespace collido::sim
