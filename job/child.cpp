#include "job/child.h"

#include <signal.h>

#include <nlohmann/json.hpp>

namespace collido::job {

using json = nlohmann::json;

namespace {
constexpr int kProgressFd = 3;

ErrorCode code_from_name(const std::string& name) {
  for (ErrorCode c : {ErrorCode::kOk, ErrorCode::kInvalidArgument, ErrorCode::kNotFound,
                      ErrorCode::kIo, ErrorCode::kParse, ErrorCode::kResourceExhausted,
                      ErrorCode::kCancelled, ErrorCode::kBackend})
    if (name == to_string(c)) return c;
  return ErrorCode::kBackend;
}

Stage stage_from_name(const std::string& name) {
  for (Stage s : {Stage::kPrepare, Stage::kSimulate, Stage::kRender, Stage::kDone})
    if (name == to_string(s)) return s;
  return Stage::kPrepare;
}
}  // namespace

std::string progress_line(const Progress& p) {
  return json{{"stage", to_string(p.stage)}, {"done", p.done},         {"total", p.total},
              {"elapsed_s", p.elapsed_s},    {"eta_s", p.eta_s},       {"steps", p.steps},
              {"sim_time", p.sim_time},      {"contacts", p.contacts}}
             .dump() +
         "\n";
}
std::string note_line(const std::string& note) { return json{{"note", note}}.dump() + "\n"; }
std::string status_line(const Status& s) {
  return json{{"status", to_string(s.code())}, {"message", s.message()}}.dump() + "\n";
}

Expected<std::unique_ptr<ChildJob>> ChildJob::start(const std::string& executable,
                                                    const std::string& spec_path,
                                                    const std::string& log_path,
                                                    const std::vector<std::string>& env_overrides) {
  auto process = Subprocess::start(
      {executable, "job-exec", spec_path, "--progress-fd", std::to_string(kProgressFd)},
      kProgressFd, log_path, env_overrides);
  if (!process) return process.status();
  return std::unique_ptr<ChildJob>(new ChildJob(std::move(*process)));
}

ChildJob::~ChildJob() = default;  // Subprocess kills and reaps a child still running

void ChildJob::request_cancel() { process_->send_signal(SIGTERM); }

ChildResult ChildJob::wait(const std::function<void(const Progress&)>& on_progress,
                           const std::atomic<bool>* cancel) {
  ChildResult out;
  bool have_status = false;
  auto on_line = [&](const std::string& line) {
    const json j = json::parse(line, nullptr, false);
    if (!j.is_object()) return;  // not ours: ignore rather than trust
    if (j.contains("note") && j["note"].is_string()) {
      out.notes.push_back(j["note"].get<std::string>());
    } else if (j.contains("status") && j["status"].is_string()) {
      const std::string msg = j.value("message", std::string());
      out.status = Status(code_from_name(j["status"].get<std::string>()), msg);
      have_status = true;
    } else if (j.contains("stage") && on_progress) {
      Progress pr;
      pr.stage = stage_from_name(j.value("stage", std::string()));
      pr.done = j.value("done", uint64_t(0));
      pr.total = j.value("total", uint64_t(0));
      pr.elapsed_s = j.value("elapsed_s", 0.0);
      pr.eta_s = j.value("eta_s", -1.0);
      pr.steps = j.value("steps", uint64_t(0));
      pr.sim_time = j.value("sim_time", 0.0);
      pr.contacts = j.value("contacts", uint64_t(0));
      on_progress(pr);
    }
  };
  const ExitInfo e = process_->wait(on_line, cancel, SIGTERM);
  out.peak_host_bytes = e.peak_host_bytes;
  out.exit_code = e.exit_code;
  out.signal = e.signal;
  if (!have_status) {
    if (out.signal)
      out.status = backend_error("the job process was " + describe(e));
    else
      out.status = backend_error("the job process ended (" + describe(e) + ") without a status");
  }
  return out;
}

}  // namespace collido::job
