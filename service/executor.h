// Where the service's jobs run. The local executor (workers.h) runs each in a
// `collidoscope job-exec` child on this machine; the Slurm executor
// (slurm_executor.h) submits each to a cluster's scheduler, which runs the same
// command on a node. Both take queued jobs from the store, report progress and
// ends through JobService, and cancel what the user cancels.
#pragma once

#include <algorithm>
#include <string>

#include "job/job.h"
#include "service/store.h"

namespace collido::service {

// The whole job's progress (0..1) from one report: the simulation is most of
// it, rendering (when the job renders) the rest.
inline double job_fraction(const job::Progress& p, bool render) {
  const double f = p.total ? double(p.done) / double(p.total) : 0.0;
  double progress = 0;
  if (p.stage == job::Stage::kSimulate) progress = render ? 0.8 * f : f;
  if (p.stage == job::Stage::kRender) progress = 0.8 + 0.2 * f;
  if (p.stage == job::Stage::kDone) progress = 1;
  return std::clamp(progress, 0.0, 1.0);
}

class Executor {
 public:
  virtual ~Executor() = default;
  // A job was queued: look for work now rather than at the next poll.
  virtual void notify() = 0;
  // The user cancelled a running job: ask it to stop (it ends "cancelled").
  virtual void cancel(const Job& job) = 0;
  // Stops following jobs. Local children are killed and resumed at the next
  // start; cluster jobs run on, and the next start follows them again.
  virtual void stop() = 0;
  // Worker threads on this machine (0 for a cluster's executor).
  virtual int size() const = 0;
};

}  // namespace collido::service
