// The CPU thread pool: an object per owner, every index run once, sized from
// the CPUs this process may really use.
#include <gtest/gtest.h>
#include <sched.h>

#include <atomic>
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
