// The CPU thread pool: an object per owner, every index run once, sized from
// the CPUs this process may really use.
#include <gtest/gtest.h>
#include <sched.h>

#include <atomic>
#include <chrono>
#include <thread>
#include <vector>

#include "sim/parallel.h"

namespace collido::sim {
namespace {

TEST(ThreadPool, RunsEveryIndexOnce) {
  for (int threads : {1, 3}) {
    ThreadPool pool(threads);
    EXPECT_EQ(pool.size(), threads);
    std::vector<std::atomic<int>> hits(100003);
    cpu_parallel_for(pool, hits.size(), [&](uint32_t i) { hits[i]++; }, 7);
    for (const auto& h : hits) ASSERT_EQ(h.load(), 1);
  }
}

// Loops back to back, as a dynamics step issues them: of every length around
// the grains (none, one index, a chunk, a few), some with one slow index that
// keeps a chunk claimed while the caller has run out of work, some after the
// workers have gone to sleep. Every index runs once per loop, and a loop
// returns only when all of its indices are done.
TEST(ThreadPool, BackToBackLoopsRunEveryIndexOnce) {
  for (int threads : {2, 4}) {
    ThreadPool pool(threads);
    std::vector<std::atomic<int>> hits(5000);
    for (int round = 0; round < 400; ++round) {
      const size_t n = std::vector<size_t>{0, 1, 63, 64, 65, 700, 1024, 1025, 4999}[round % 9];
      const size_t grain = round % 2 ? kHeavyGrain : kLightGrain;
      const size_t slow = round % 5 == 0 && n ? n - 1 : n;  // this index sleeps
      if (round % 97 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(2));
      cpu_parallel_for(
          pool, n,
          [&](uint32_t i) {
            if (i == slow) std::this_thread::sleep_for(std::chrono::microseconds(300));
            hits[i]++;
          },
          grain);
      for (size_t i = 0; i < hits.size(); ++i)
        ASSERT_EQ(hits[i].exchange(0), i < n ? 1 : 0) << "round " << round << " index " << i;
    }
  }
}

// run_items hands out one index a claim, where run_chunks would give a loop
// of 64 on two threads chunks of four: items 0 and 1 each wait (up to 5 s)
// for the other to start, which they can only do on two threads at once.
TEST(ThreadPool, RunItemsHandsOutOneItemAClaim) {
  ThreadPool pool(2);
  std::vector<std::atomic<int>> hits(64);
  std::atomic<int> started{0};
  std::atomic<bool> met{true};
  pool.run_items(hits.size(), [&](size_t i) {
    if (i < 2) {
      ++started;
      const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
      while (started.load() < 2 && std::chrono::steady_clock::now() < until)
        std::this_thread::yield();
      if (started.load() < 2) met = false;
    }
    hits[i]++;
  });
  EXPECT_TRUE(met.load()) << "items 0 and 1 ran one after the other";
  for (const auto& h : hits) ASSERT_EQ(h.load(), 1);
}

// A pool made and dropped at once, its workers still starting or spinning.
TEST(ThreadPool, StopsWhileItsWorkersWait) {
  for (int k = 0; k < 50; ++k) {
    ThreadPool pool(3);
    std::atomic<uint64_t> sum{0};
    if (k % 2) cpu_parallel_for(pool, 3000, [&](uint32_t i) { sum += i; }, kHeavyGrain);
    EXPECT_EQ(sum.load(), k % 2 ? 2999ull * 3000 / 2 : 0);
  }
}

TEST(ThreadPool, TwoPoolsRunAtOnceWithoutSharingThreads) {
  ThreadPool a(2), b(1);
  std::atomic<uint64_t> sum_a{0}, sum_b{0};
  std::thread ta([&] { cpu_parallel_for(a, 200000, [&](uint32_t i) { sum_a += i; }); });
  std::thread tb([&] { cpu_parallel_for(b, 100000, [&](uint32_t i) { sum_b += i; }); });
  ta.join();
  tb.join();
  EXPECT_EQ(sum_a.load(), 199999ull * 200000 / 2);
  EXPECT_EQ(sum_b.load(), 99999ull * 100000 / 2);
}

// A process pinned to one CPU (taskset, a Slurm step, a container) gets a
// pool of one, whatever the machine's core count.
TEST(ThreadPool, UsableCpusFollowTheAffinityMask) {
  EXPECT_GE(usable_cpus(), 1);
  int seen = 0;
  std::thread pinned([&] {
    cpu_set_t one;
    CPU_ZERO(&one);
    CPU_SET(sched_getcpu(), &one);
    if (sched_setaffinity(0, sizeof one, &one) != 0) return;
    seen = usable_cpus();
    ThreadPool pool;
    EXPECT_EQ(pool.size(), 1);
  });
  pinned.join();
  EXPECT_EQ(seen, 1);
}

}  // namespace
}  // namespace collido::sim
