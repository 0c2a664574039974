#include "service/request_pool.h"

#include <algorithm>

namespace collido::service {

namespace {
// The pool whose task this thread runs, and whether that task said answering().
thread_local RequestPool* tl_pool = nullptr;
thread_local bool tl_answering = false;
}  // namespace

RequestPool::RequestPool(int threads, size_t max_waiting) : max_waiting_(max_waiting) {
  for (int i = 0; i < std::max(1, threads); ++i) threads_.emplace_back([this] { run(); });
}

RequestPool::~RequestPool() {
  stop();
}

bool RequestPool::submit(std::function<void()> task) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_) return false;
    // A task a free thread takes at once does not wait.
    const size_t idle = threads_.size() - running_;
    if (queue_.size() >= max_waiting_ + idle) return false;
    queue_.push_back(std::move(task));
  }
  wake_.notify_one();
  return true;
}

void RequestPool::stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_ && threads_.empty()) return;
    stopping_ = true;
  }
  wake_.notify_all();
  for (std::thread& t : threads_)
    if (t.joinable()) t.join();
  threads_.clear();
}

size_t RequestPool::pending() const {
  std::lock_guard<std::mutex> lock(mu_);
  return queue_.size() + running_;
}

void RequestPool::answering() {
  if (!tl_pool || tl_answering) return;
  tl_answering = true;
  std::lock_guard<std::mutex> lock(tl_pool->mu_);
  --tl_pool->running_;
}

void RequestPool::run() {
  tl_pool = this;
  for (;;) {
    std::function<void()> task;
    {
      std::unique_lock<std::mutex> lock(mu_);
      wake_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
      if (queue_.empty()) return;  // stopping, and nothing left to answer
      task = std::move(queue_.front());
      queue_.pop_front();
      ++running_;
    }
    tl_answering = false;
    task();
    if (tl_answering) continue;
    std::lock_guard<std::mutex> lock(mu_);
    --running_;
  }
}

}  // namespace collido::service
