// Threads for the requests that compute (a sign-in's Argon2id hash, an STL
// upload's parse, a parametric model's mesh, a prediction, a submission), so
// that the reactor thread which owns a connection never waits on one: Pistache
// runs a handler on the reactor thread of its connection, and every other
// connection of that thread waits until it returns (a parametric sphere of
// 1.3 million triangles took 0.5-1.3 s to build there, a sign-in 0.16 s).
#pragma once

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace collido::service {

class RequestPool {
 public:
  // threads >= 1; at most max_waiting tasks wait for a thread (beyond those a
  // free thread takes at once).
  RequestPool(int threads, size_t max_waiting);
  ~RequestPool();  // stop()
  RequestPool(const RequestPool&) = delete;
  RequestPool& operator=(const RequestPool&) = delete;

  // Queues the task; false (the task dropped) when max_waiting tasks would
  // wait or the pool has stopped: the caller answers 503 itself.
  bool submit(std::function<void()> task);
  // Called by a task on its pool thread once only its answer is left to
  // send: its thread counts as free from here on. A client that sends its
  // next request as the answer arrives then finds room (with no queue it was
  // refused while the thread was still leaving the task). Does nothing off a
  // pool thread or when called twice.
  static void answering();
  // Runs what is queued, then joins the threads; later submits are refused.
  void stop();
  // Tasks queued or running (those answering() not counted).
  size_t pending() const;

 private:
  void run();

  const size_t max_waiting_;
  mutable std::mutex mu_;
  std::condition_variable wake_;
  std::deque<std::function<void()>> queue_;
  size_t running_ = 0;
  bool stopping_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace collido::service
