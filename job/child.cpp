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

std::string progress_line(const Progress& p, uint64_t peak_host_bytes) {
  json j = {{"stage", to_string(p.stage)}, {"done", p.done},         {"total", p.total},
            {"elapsed_s", p.elapsed_s},    {"eta_s", p.eta_s},       {"steps", p.steps},
            {"sim_time", p.sim_time},      {"contacts", p.contacts}};
  if (peak_host_bytes > 0) j["peak_host_bytes"] = peak_host_bytes;
  return j.dump() + "\n";
}
std::string note_line(const std::string& note) { return json{{"note", note}}.dump() + "\n"; }
std::string status_line(const Status& s) {
  return json{{"status", to_string(s.code())}, {"message", s.message()}}.dump() + "\n";
}

ReportLine parse_report_line(const std::string& line) {
  ReportLine out;
  const json j = json::parse(line, nullptr, false);
  if (!j.is_object()) return out;
  try {
    if (j.contains("note") && j["note"].is_string()) {
      out.kind = ReportLine::Kind::kNote;
      out.note = j["note"].get<std::string>();
    } else if (j.contains("status") && j["status"].is_string()) {
      out.kind = ReportLine::Kind::kStatus;
      out.status = Status(code_from_name(j["status"].get<std::string>()),
                          j.value("message", std::string()));
    } else if (j.contains("stage")) {
      Progress& pr = out.progress;
      pr.stage = stage_from_name(j.value("stage", std::string()));
      pr.done = j.value("done", uint64_t(0));
      pr.total = j.value("total", uint64_t(0));
      pr.elapsed_s = j.value("elapsed_s", 0.0);
      pr.eta_s = j.value("eta_s", -1.0);
      pr.steps = j.value("steps", uint64_t(0));
      pr.sim_time = j.value("sim_time", 0.0);
      pr.contacts = j.value("contacts", uint64_t(0));
      out.peak_host_bytes = j.value("peak_host_bytes", uint64_t(0));
      out.kind = ReportLine::Kind::kProgress;
    }
  } catch (const json::exception&) {
    out = ReportLine();  // a field of the wrong type: not a line of ours
  }
  return out;
}

Expected<std::unique_ptr<ChildJob>> ChildJob::start(const std::string& executable,
                                                    const std::string& spec_path,
                                                    const std::string& log_path,
                                                    const std::vector<std::string>& env_overrides) {
  auto process = Subprocess::start(
      {executable, "job-exec", spec_path, "--progress-fd", std::to_string(kProgressFd)},
      kProgressFd, log_path, env_overrides, /*own_group=*/true);
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
    ReportLine r = parse_report_line(line);
    switch (r.kind) {
      case ReportLine::Kind::kNote: out.notes.push_back(std::move(r.note)); break;
      case ReportLine::Kind::kStatus:
        out.status = r.status;
        have_status = true;
        break;
      case ReportLine::Kind::kProgress:
        if (on_progress) on_progress(r.progress);
        break;
      case ReportLine::Kind::kNone: break;
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
