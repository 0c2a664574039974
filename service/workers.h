// The workers that run queued jobs, apart from Pistache's request threads:
// each takes the oldest queued job whose predicted memory fits what is free,
// runs it in a `collidoscope job-exec` child, writes its progress to the store
// while it runs and its result, cost and log row when it ends.
#pragma once

#include <sys/types.h>

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "service/executor.h"
#include "service/store.h"

namespace collido::service {

class JobService;

// Memory free for new work now (MemAvailable), bytes; 0 when unknown.
uint64_t available_memory_bytes();

// The GPUs a job may be given, as CUDA_VISIBLE_DEVICES names them: that
// variable's list when it is set, else the /dev/nvidiaN device nodes. Read
// without loading CUDA into the server.
std::vector<std::string> visible_gpus();

class WorkerPool final : public Executor {
 public:
  // `workers` threads; worker i runs its jobs on gpus[i] (CUDA_VISIBLE_DEVICES
  // of its children) when there is one, else as the server's environment says.
  WorkerPool(JobService* service, int workers, std::vector<std::string> gpus = {});
  ~WorkerPool() override;
  // A job was queued: wake a waiting worker.
  void notify() override;
  // Sets the job's cancellation flag, which its worker passes to the child.
  void cancel(const Job& job) override;
  // Stops every worker. A job running now is killed, not ended: it stays
  // "running" in the store, and the next start queues it again to resume from
  // its checkpoint (what a crash would leave, on purpose).
  void stop() override;
  int size() const override { return int(threads_.size()); }

 private:
  void loop(int worker);
  void run_one(const Job& job, int worker);
  uint64_t free_bytes_for_jobs();

  JobService* service_;
  std::vector<std::string> gpus_;
  std::vector<std::thread> threads_;
  std::mutex mu_;
  std::condition_variable wake_;
  bool stopping_ = false;
  uint64_t pending_wakeups_ = 0;
  std::set<pid_t> children_;     // running job-exec children, to kill on stop
  uint64_t running_bytes_ = 0;   // predicted memory of the jobs running now
};

}  // namespace collido::service
