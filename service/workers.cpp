#include "service/workers.h"

#include <signal.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/atomic_file.h"
#include "job/child.h"
#include "service/job_service.h"

namespace collido::service {

namespace fs = std::filesystem;

uint64_t available_memory_bytes() {
  std::ifstream in("/proc/meminfo");
  std::string key;
  uint64_t value = 0;
  std::string unit;
  while (in >> key >> value) {
    std::getline(in, unit);
    if (key == "MemAvailable:") return value * 1024;
  }
  return 0;
}

std::vector<std::string> visible_gpus() {
  std::vector<std::string> out;
  if (const char* list = std::getenv("CUDA_VISIBLE_DEVICES")) {
    std::stringstream in(list);
    std::string item;
    while (std::getline(in, item, ','))
      if (!item.empty() && item != "-1") out.push_back(item);
    return out;
  }
  std::error_code ec;
  for (const auto& e : fs::directory_iterator("/dev", ec)) {
    const std::string name = e.path().filename().string();
    if (name.size() > 6 && name.compare(0, 6, "nvidia") == 0 &&
        std::all_of(name.begin() + 6, name.end(), [](unsigned char c) { return std::isdigit(c); }))
      out.push_back(name.substr(6));
  }
  std::sort(out.begin(), out.end(), [](const std::string& a, const std::string& b) {
    return std::stoi(a) < std::stoi(b);
  });
  return out;
}

WorkerPool::WorkerPool(JobService* service, int workers, std::vector<std::string> gpus)
    : service_(service), gpus_(std::move(gpus)) {
  for (int i = 0; i < workers; ++i) threads_.emplace_back([this, i] { loop(i); });
}

WorkerPool::~WorkerPool() { stop(); }

void WorkerPool::notify() {
  std::lock_guard lock(mu_);
  ++pending_wakeups_;
  wake_.notify_one();
}

void WorkerPool::cancel(const Job& job) { service_->cancel_flag(job.id)->store(true); }

void WorkerPool::stop() {
  {
    std::lock_guard lock(mu_);
    if (stopping_ && threads_.empty()) return;
    stopping_ = true;
    for (pid_t pid : children_) ::kill(pid, SIGKILL);
    wake_.notify_all();
  }
  for (auto& t : threads_)
    if (t.joinable()) t.join();
  threads_.clear();
}

uint64_t WorkerPool::free_bytes_for_jobs() {
  // What the configured share of the machine leaves after the jobs running now,
  // and no more than the kernel says is free.
  const uint64_t total = service_->memory_for_jobs();
  const uint64_t left = total > running_bytes_ ? total - running_bytes_ : 0;
  const uint64_t avail = available_memory_bytes();
  return avail ? std::min(left, avail) : left;
}

void WorkerPool::loop(int worker) {
  for (;;) {
    std::optional<Job> job;
    {
      std::unique_lock lock(mu_);
      if (stopping_) return;
      auto claimed = service_->store().claim_next_job(free_bytes_for_jobs(), unix_now());
      if (claimed && *claimed) {
        job = std::move(**claimed);
        running_bytes_ += job->predicted_host_bytes;
      } else {
        // Nothing that fits now: sleep until a submission, or look again in a
        // second (memory frees up, a job ends in another worker).
        wake_.wait_for(lock, std::chrono::seconds(1),
                       [&] { return stopping_ || pending_wakeups_ > 0; });
        if (pending_wakeups_ > 0) --pending_wakeups_;
        continue;
      }
    }
    run_one(*job, worker);
    {
      std::lock_guard lock(mu_);
      running_bytes_ -= std::min(running_bytes_, job->predicted_host_bytes);
    }
    wake_.notify_all();
  }
}

void WorkerPool::run_one(const Job& j, int worker) {
  const std::string dir = service_->job_dir(j.id);
  // The spec as submitted; a job started before (the server stopped under it)
  // continues from its checkpoint.
  auto spec = service_->write_run_spec(j);
  if (!spec) {
    service_->job_finished(j, "failed", spec.status().message(), {}, 0);
    return;
  }
  const std::string run_spec = (fs::path(dir) / "spec.run.json").string();
  service_->job_started(j);
  std::vector<std::string> env;
  if (size_t(worker) < gpus_.size()) env.push_back("CUDA_VISIBLE_DEVICES=" + gpus_[worker]);
  auto child = job::ChildJob::start(service_->config().job_executable, run_spec,
                                    (fs::path(dir) / "job.log").string(), env);
  if (!child) {
    service_->job_finished(j, "failed", "could not start the job: " + child.status().message(), {},
                           0);
    return;
  }
  {
    std::lock_guard lock(mu_);
    if (stopping_) ::kill((*child)->pid(), SIGKILL);
    children_.insert((*child)->pid());
  }
  const bool render = spec->render;
  auto last_write = std::chrono::steady_clock::now() - std::chrono::seconds(1);
  std::string last_stage;
  auto cancel = service_->cancel_flag(j.id);
  job::ChildResult result = (*child)->wait(
      [&](const job::Progress& p) {
        const double progress = job_fraction(p, render);
        const std::string stage = job::to_string(p.stage);
        const auto now = std::chrono::steady_clock::now();
        // At most a few writes a second, and every change of stage.
        if (stage != last_stage || now - last_write > std::chrono::milliseconds(250)) {
          service_->job_progress(j.id, stage, progress);
          last_write = now;
          last_stage = stage;
        }
      },
      cancel.get());
  bool stopping;
  {
    std::lock_guard lock(mu_);
    children_.erase((*child)->pid());
    stopping = stopping_;
  }
  if (stopping && result.signal == SIGKILL) return;  // left running: resumed at the next start
  const json manifest = service_->run_manifest(j);
  std::string state = "failed", error;
  if (result.status) {
    state = "done";
  } else if (result.status.code() == ErrorCode::kCancelled || cancel->load()) {
    state = "cancelled";
    error = result.status.message();
  } else {
    error = result.status.message();
    if (result.signal) error += " (the job process ended by signal " + std::to_string(result.signal) + ")";
  }
  service_->job_finished(j, state, error, manifest, result.peak_host_bytes);
}

}  // namespace collido::service
