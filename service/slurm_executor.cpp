#include "service/slurm_executor.h"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/atomic_file.h"
#include "job/child.h"
#include "job/subprocess.h"
#include "service/job_service.h"

namespace collido::service {

namespace fs = std::filesystem;

namespace {

constexpr const char* kNamePrefix = "collido-";
constexpr const char* kProgressFile = "progress.jsonl";

std::string trim(std::string s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.pop_back();
  size_t b = 0;
  while (b < s.size() && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  return s.substr(b);
}

// A word for sh, in single quotes.
std::string shell_quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

bool is_slurm_id(const std::string& s) {
  if (s.empty() || s.size() > 32) return false;
  for (char c : s)
    if (!std::isdigit(static_cast<unsigned char>(c)) && c != '_') return false;
  return true;
}

}  // namespace

SlurmPhase slurm_phase(const std::string& state_word) {
  // sacct writes "CANCELLED by 1000": the state is the first word.
  const std::string state = state_word.substr(0, state_word.find(' '));
  for (const char* s : {"PENDING", "CONFIGURING", "REQUEUED", "REQUEUE_HOLD", "REQUEUE_FED",
                        "SUSPENDED", "RESV_DEL_HOLD", "SPECIAL_EXIT", "STOPPED"})
    if (state == s) return SlurmPhase::kWaiting;
  for (const char* s : {"RUNNING", "COMPLETING", "STAGE_OUT", "SIGNALING", "RESIZING"})
    if (state == s) return SlurmPhase::kRunning;
  for (const char* s : {"COMPLETED", "FAILED", "CANCELLED", "TIMEOUT", "OUT_OF_MEMORY",
                        "NODE_FAIL", "PREEMPTED", "BOOT_FAIL", "DEADLINE", "REVOKED"})
    if (state == s) return SlurmPhase::kEnded;
  return SlurmPhase::kUnknown;
}

SlurmOutcome slurm_outcome(const SlurmJobState& s, const std::optional<Status>& job_status,
                           bool cancel_requested, int time_limit_min) {
  const std::string state = s.state.substr(0, s.state.find(' '));
  std::string slurm = "Slurm: " + (state.empty() ? std::string("unknown") : state);
  if (!s.reason.empty() && s.reason != "None") slurm += ", " + s.reason;
  if (!s.exit_code.empty() && s.exit_code != "0:0") slurm += ", exit " + s.exit_code;
  auto from_job = [&](const Status& st) -> SlurmOutcome {
    if (st) return {"done", ""};
    if (st.code() == ErrorCode::kCancelled) return {"cancelled", st.message()};
    return {"failed", st.message()};
  };
  if (cancel_requested && (state == "CANCELLED" || state.empty() || state == "COMPLETED" ||
                           state == "FAILED"))
    return {"cancelled", "cancelled"};
  if (state == "COMPLETED" || state == "FAILED") {
    if (job_status) {
      SlurmOutcome o = from_job(*job_status);
      if (o.state == "done" && state == "FAILED") o = {"failed", "the job process failed (" + slurm + ")"};
      return o;
    }
    return {"failed", "the job ended without reporting a status (" + slurm + "); see job.log"};
  }
  if (state == "CANCELLED")
    return {"cancelled", "cancelled on the cluster by the scheduler or an administrator (" + slurm + ")"};
  if (state == "TIMEOUT")
    return {"failed", "the scheduler ended the job at its time limit of " +
                          std::to_string(time_limit_min) + " min (" + slurm + ")"};
  if (state == "OUT_OF_MEMORY")
    return {"failed", "the scheduler ended the job: it used more memory than it asked for (" +
                          slurm + ")"};
  if (state == "NODE_FAIL") return {"failed", "the job's node failed (" + slurm + ")"};
  if (state == "PREEMPTED")
    return {"failed", "the job was preempted and not requeued (" + slurm + ")"};
  if (!state.empty()) return {"failed", "the scheduler ended the job (" + slurm + ")"};
  // The controller forgot the job and no accounting remembers it: what it wrote.
  if (job_status) return from_job(*job_status);
  return {"failed", "the scheduler no longer knows this job and it left no status; see job.log"};
}

std::vector<SqueueRow> parse_squeue(const std::string& text) {
  std::vector<SqueueRow> rows;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::stringstream ls(line);
    std::string field;
    while (std::getline(ls, field, '|')) f.push_back(trim(field));
    if (f.size() < 3 || !is_slurm_id(f[0])) continue;
    SqueueRow r;
    r.id = f[0];
    r.name = f[1];
    r.state.state = f[2];
    if (f.size() > 3) r.state.reason = f[3];
    rows.push_back(std::move(r));
  }
  return rows;
}

bool scheduler_unreachable(const job::CommandOutput& out) {
  if (out.timed_out || out.exit.signal != 0) return true;
  for (const char* transient : {"timed out", "Unable to contact", "Socket", "Connection refused",
                                "temporarily unable", "Resource temporarily unavailable"})
    if (out.err.find(transient) != std::string::npos) return true;
  return false;
}

SlurmRequest slurm_request(const SlurmConfig& c, const Job& j) {
  SlurmRequest r;
  double limit_s = c.default_time_limit_s;
  const json pred = json::parse(j.prediction_json, nullptr, false);
  if (pred.is_object() && pred.contains("total_time_s") && pred["total_time_s"].is_object()) {
    const json& t = pred["total_time_s"];
    const double high = t.value("high", t.value("value", -1.0));
    if (high > 0 && std::isfinite(high)) limit_s = high * c.time_factor + c.time_margin_s;
  }
  // Whole minutes, at least one and at most a year (in double first: a model
  // extrapolating far outside its training could overflow an int).
  r.time_limit_min = int(std::clamp(std::ceil(limit_s / 60.0), 1.0, 365.0 * 24 * 60));
  const double bytes = double(j.predicted_host_bytes) * c.mem_factor + double(c.mem_margin_bytes);
  r.mem_mib = std::max<uint64_t>(1, uint64_t(std::ceil(bytes / double(1 << 20))));
  return r;
}

Expected<std::unique_ptr<SlurmExecutor>> SlurmExecutor::start(JobService* service,
                                                               SlurmConfig config) {
  // The scheduler must answer before the service takes jobs for it.
  auto probe = job::run_command({"squeue", "--me", "--noheader", "--format=%i"},
                                config.command_timeout_s);
  if (!probe) return backend_error("the Slurm executor needs squeue: " + probe.status().message());
  if (!probe->ok())
    return backend_error("the Slurm controller does not answer (squeue " +
                         probe->describe_failure() + ")");
  std::unique_ptr<SlurmExecutor> e(new SlurmExecutor(service, std::move(config)));
  e->thread_ = std::thread([p = e.get()] { p->loop(); });
  return e;
}

SlurmExecutor::SlurmExecutor(JobService* service, SlurmConfig config)
    : service_(service), config_(std::move(config)) {}

SlurmExecutor::~SlurmExecutor() { stop(); }

void SlurmExecutor::notify() {
  std::lock_guard lock(mu_);
  woken_ = true;
  wake_.notify_all();
}

void SlurmExecutor::cancel(const Job& job) {
  std::lock_guard lock(mu_);
  cancel_requested_.insert(job.id);
  woken_ = true;
  wake_.notify_all();
}

void SlurmExecutor::stop() {
  {
    std::lock_guard lock(mu_);
    stopping_ = true;
    wake_.notify_all();
  }
  if (thread_.joinable()) thread_.join();
}

void SlurmExecutor::loop() {
  for (;;) {
    {
      std::lock_guard lock(mu_);
      if (stopping_) return;
    }
    recheck_soon_ = false;
    submit_queued();
    follow();
    std::unique_lock lock(mu_);
    wake_.wait_for(lock, std::chrono::duration<double>(recheck_soon_ ? std::min(0.5, config_.poll_s)
                                                                     : config_.poll_s),
                   [&] { return stopping_ || woken_; });
    woken_ = false;
  }
}

void SlurmExecutor::submit_queued() {
  // The scheduler admits by memory and time: every queued job goes to it now
  // (INT64_MAX: the store keeps sizes as signed 64-bit integers).
  for (;;) {
    {
      std::lock_guard lock(mu_);
      if (stopping_) return;
    }
    auto claimed = service_->store().claim_next_job(uint64_t(INT64_MAX), unix_now());
    if (!claimed || !*claimed) return;
    submit(**claimed);
  }
}

void SlurmExecutor::submit(const Job& j) {
  const fs::path dir = fs::absolute(service_->job_dir(j.id));
  auto spec = service_->write_run_spec(j, config_.cpus);
  if (!spec) {
    service_->job_finished(j, "failed", spec.status().message(), {}, 0);
    return;
  }
  // The batch script: the same command a local worker runs, on a node; every
  // path in it and in the spec is absolute (JobService::open).
  const std::string script_path = (dir / "slurm.sh").string();
  const std::string script =
      "#!/bin/sh\n"
      "# Collidoscope job " + j.id + ", submitted by the service's Slurm executor\n"
      "# (docs/deploy.md). A requeued or preempted run continues from the last\n"
      "# checkpoint of the one before (--resume).\n"
      "exec " + shell_quote(service_->config().job_executable) + " job-exec " +
      shell_quote((dir / "spec.run.json").string()) + " --resume --progress-file " +
      shell_quote((dir / kProgressFile).string()) + " --threads " + std::to_string(config_.cpus) +
      "\n";
  if (Status st = write_file_atomic(script_path, script); !st) {
    service_->job_finished(j, "failed", st.message(), {}, 0);
    return;
  }
  ::chmod(script_path.c_str(), 0755);
  const SlurmRequest req = slurm_request(config_, j);
  const json pred = json::parse(j.prediction_json, nullptr, false);
  const bool cuda = pred.is_object() && pred.value("backend", "") == "cuda";
  std::vector<std::string> args = {
      "sbatch", "--parsable", "--job-name=" + std::string(kNamePrefix) + j.id,
      "--chdir=" + dir.string(), "--output=" + (dir / "job.log").string(),
      "--open-mode=append", "--time=" + std::to_string(req.time_limit_min),
      "--mem=" + std::to_string(req.mem_mib), "--cpus-per-task=" + std::to_string(config_.cpus),
      config_.requeue ? "--requeue" : "--no-requeue"};
  if (!config_.partition.empty()) args.push_back("--partition=" + config_.partition);
  if (!config_.account.empty()) args.push_back("--account=" + config_.account);
  if (cuda && !config_.gres.empty()) args.push_back("--gres=" + config_.gres);
  args.insert(args.end(), config_.extra_args.begin(), config_.extra_args.end());
  args.push_back(script_path);
  auto out = job::run_command(args, config_.command_timeout_s);
  if (!out || !out->ok()) {
    const std::string why = out ? out->describe_failure() : out.status().message();
    // A controller that did not answer in time may still have queued it (sbatch
    // retries while the controller is busy, and a reply lost on the way back
    // leaves a job behind): the job stays claimed with no Slurm id, and follow()
    // takes it up by its name or submits it again after orphan_grace_s. Only a
    // refusal ends it.
    if (out && scheduler_unreachable(*out)) {
      std::fprintf(stderr,
                   "collidoscope serve: sbatch for job %s did not answer (%s); it is looked "
                   "for by name and submitted again if it is not there\n",
                   j.id.c_str(), why.c_str());
      return;
    }
    service_->job_finished(j, "failed", "the scheduler refused the job (sbatch " + why + ")", {}, 0);
    return;
  }
  // --parsable: "id" or "id;cluster".
  const std::string id = trim(out->out.substr(0, out->out.find(';')));
  if (!is_slurm_id(id)) {
    service_->job_finished(j, "failed", "sbatch answered no job id: '" + trim(out->out) + "'", {}, 0);
    return;
  }
  service_->store().set_job_executor_ref(j.id, id);
  service_->job_progress(j.id, "pending", 0);
}

void SlurmExecutor::read_progress(const Job& j) {
  Followed& f = followed_[j.id];
  std::ifstream in((fs::path(service_->job_dir(j.id)) / kProgressFile).string(), std::ios::binary);
  if (!in) return;
  in.seekg(std::streamoff(f.offset));
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  // Whole lines only: the job may be writing the next one now.
  const size_t end = text.rfind('\n');
  if (end == std::string::npos) return;
  f.offset += end + 1;
  std::istringstream lines(text.substr(0, end + 1));
  std::string line;
  while (std::getline(lines, line)) {
    const job::ReportLine r = job::parse_report_line(line);
    if (r.kind == job::ReportLine::Kind::kProgress) {
      f.last = r.progress;
      f.peak_host_bytes = std::max(f.peak_host_bytes, r.peak_host_bytes);
      f.status.reset();  // a run after a status line: the job was requeued
    } else if (r.kind == job::ReportLine::Kind::kStatus) {
      f.status = r.status;
    }
  }
}

SlurmJobState SlurmExecutor::ask_sacct(const std::string& id, bool* answered) {
  SlurmJobState s;
  auto out = job::run_command({"sacct", "--noheader", "--parsable2", "--allocations", "--jobs=" + id,
                               "--format=State,Reason,ExitCode"},
                              config_.command_timeout_s);
  *answered = !(out && !out->ok() && scheduler_unreachable(*out));
  if (!out || !out->ok()) return s;  // no accounting here: unknown
  std::istringstream in(out->out);
  std::string line;
  if (!std::getline(in, line)) return s;
  std::stringstream ls(line);
  std::getline(ls, s.state, '|');
  std::getline(ls, s.reason, '|');
  std::getline(ls, s.exit_code, '|');
  s.state = trim(s.state);
  return s;
}

void SlurmExecutor::follow() {
  auto running = service_->store().running_jobs();
  if (!running) return;
  // Forget jobs that ended (here or in another replica).
  std::set<std::string> running_ids;
  for (const Job& j : *running) running_ids.insert(j.id);
  for (auto it = followed_.begin(); it != followed_.end();)
    it = running_ids.count(it->first) ? std::next(it) : followed_.erase(it);
  {
    std::lock_guard lock(mu_);
    for (auto it = cancel_requested_.begin(); it != cancel_requested_.end();)
      it = running_ids.count(*it) ? std::next(it) : cancel_requested_.erase(it);
  }
  if (running->empty()) return;
  auto q = job::run_command({"squeue", "--me", "--noheader", "--states=all", "--format=%i|%j|%T|%r"},
                            config_.command_timeout_s);
  // The controller not answering (restarting, overloaded) ends nothing: look again later.
  if (!q || !q->ok()) {
    std::fprintf(stderr, "collidoscope serve: squeue did not answer (%s); trying again\n",
                 q ? q->describe_failure().c_str() : q.status().message().c_str());
    return;
  }
  std::map<std::string, SqueueRow> by_id, by_name;
  for (SqueueRow& r : parse_squeue(q->out)) {
    by_name[r.name] = r;
    by_id[r.id] = std::move(r);
  }
  std::set<std::string> cancels;
  {
    std::lock_guard lock(mu_);
    cancels = cancel_requested_;
  }
  for (Job j : *running) {
    if (j.executor_ref.empty()) {
      // Claimed, but no Slurm id recorded: being submitted (here, or by another
      // replica), or its service died between sbatch and the store.
      if (auto it = by_name.find(kNamePrefix + j.id); it != by_name.end()) {
        service_->store().set_job_executor_ref(j.id, it->second.id);
        j.executor_ref = it->second.id;
      } else if (cancels.count(j.id) || j.cancel_requested) {
        // Cancelled before the scheduler took it (its submission went
        // unanswered): nothing runs it, and none will (a late one by its name too).
        job::run_command({"scancel", "--name=" + std::string(kNamePrefix) + j.id},
                         config_.command_timeout_s);
        service_->job_finished(j, "cancelled", "cancelled before the scheduler ran it", {}, 0);
        continue;
      } else {
        // One replica submits it: the one whose claim moves its start.
        if (unix_now() - j.started_at > config_.orphan_grace_s) {
          auto mine = service_->store().claim_orphan(j.id, j.started_at, unix_now());
          if (mine && *mine) submit(j);
        }
        continue;
      }
    }
    Followed& f = followed_[j.id];
    read_progress(j);
    // Asked here, or kept in the store (asked of another replica, or before a restart).
    const bool cancel = cancels.count(j.id) > 0 || j.cancel_requested;
    if (cancel && !f.cancel_sent) {
      auto out = job::run_command({"scancel", j.executor_ref}, config_.command_timeout_s);
      f.cancel_sent = out && out->ok();
    }
    SlurmJobState st;
    if (auto it = by_id.find(j.executor_ref); it != by_id.end()) {
      st = it->second.state;
    } else {
      bool answered = true;
      st = ask_sacct(j.executor_ref, &answered);
      // Out of squeue, and accounting did not answer: not a sign that it ended
      // (unless the job said so itself, in its last status line).
      if (!answered && !f.status) continue;
    }
    const SlurmPhase phase = slurm_phase(st.state);
    if (phase == SlurmPhase::kEnded || (phase == SlurmPhase::kUnknown && st.state.empty())) {
      // A requeued job shows its first run's end (FAILED: job-exec stops on the
      // SIGTERM) for a moment before it is PENDING again: an end counts once a
      // later look, a second on, still says so.
      const double now = unix_now();
      if (f.ended_seen_at == 0 || now - f.ended_seen_at < 1.0) {
        if (f.ended_seen_at == 0) f.ended_seen_at = now;
        recheck_soon_ = true;  // look again in a moment rather than at the next poll
        continue;
      }
      end(j, st);  // with the lines read above: written before this look saw the end
      std::lock_guard lock(mu_);
      cancel_requested_.erase(j.id);
      continue;
    }
    f.ended_seen_at = 0;
    std::string stage;
    double progress = j.progress;
    if (phase == SlurmPhase::kWaiting) {
      stage = st.state == "REQUEUED" || f.last.elapsed_s > 0 ? "requeued" : "pending";
      // Why it waits, where the scheduler says more than that it is next in
      // line: a limit it can never meet (PartitionTimeLimit, JobHeldAdmin)
      // would otherwise read as an ordinary wait for ever.
      const std::string& why = st.reason;
      if (!why.empty() && why != "None" && why != "Priority" && why != "Resources")
        stage += " (" + why + ")";
    } else {
      stage = f.last.elapsed_s > 0 || f.last.total ? job::to_string(f.last.stage) : "prepare";
      if (f.last.total || f.last.stage == job::Stage::kDone) {
        if (f.render < 0) {
          auto spec = service_->read_spec(j);
          f.render = spec && spec->render ? 1 : 0;
        }
        progress = job_fraction(f.last, f.render == 1);
      }
    }
    if (stage != f.stage || std::fabs(progress - f.progress) > 1e-4) {
      service_->job_progress(j.id, stage, progress);
      f.stage = stage;
      f.progress = progress;
    }
  }
}

void SlurmExecutor::end(const Job& j, const SlurmJobState& s) {
  Followed& f = followed_[j.id];
  const SlurmRequest req = slurm_request(config_, j);
  SlurmOutcome o = slurm_outcome(s, f.status, f.cancel_sent, req.time_limit_min);
  // Without cgroups Slurm's memory enforcement kills the step and calls the job
  // FAILED; its log says why, and a user should read it here.
  if (o.state == "failed" && !f.status) {
    std::ifstream log((fs::path(service_->job_dir(j.id)) / "job.log").string());
    std::string line;
    while (std::getline(log, line))
      if (line.find("exceeded memory limit") != std::string::npos) {
        o.error = "the scheduler killed the job: it used more than the " +
                  std::to_string(req.mem_mib) + " MiB it asked for; " + o.error;
        break;
      }
  }
  // What was measured of a run that failed: how far it got, in what time,
  // with what memory (the job's own reports), and why it ended.
  json partial = nullptr;
  if (o.state == "failed") {
    partial = {{"stage", job::to_string(f.last.stage)},
               {"frames_done", f.last.done},
               {"frames_total", f.last.total},
               {"elapsed_s", f.last.elapsed_s},
               {"steps", f.last.steps},
               {"sim_time", f.last.sim_time},
               {"peak_host_bytes", f.peak_host_bytes},
               {"scheduler", "slurm"},
               {"scheduler_job_id", j.executor_ref},
               {"scheduler_state", s.state},
               {"scheduler_reason", s.reason}};
  }
  service_->job_finished(j, o.state, o.error, service_->run_manifest(j), f.peak_host_bytes, partial);
  followed_.erase(j.id);
}

}  // namespace collido::service
