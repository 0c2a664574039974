// `collidoscope run SCENE.json --out DIR`: a job (job/job.h) from the command
// line: flags into a job spec, the job's progress into a bar or plain lines.
// `collidoscope job-exec SPEC.json`: the same job in a child process, as the
// service and cluster nodes start it (job/child.h speaks its protocol).
#include <fcntl.h>
#include <unistd.h>

#include <sys/prctl.h>

#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "app/cli.h"
#include "app/commands.h"
#include "common/process_memory.h"
#include "job/child.h"
#include "job/job.h"
#include "job/run_dir.h"
#include "job/subprocess.h"

namespace collido::app {

namespace fs = std::filesystem;

namespace {

const std::vector<FlagSpec> kFlags = {
    {"out", true, "run directory (default results/<scene name>)"},
    {"force", false, "replace the run already in --out (else a non-empty --out is refused)"},
    {"resume", true, "continue the run in DIR from its last checkpoint (no scene argument)"},
    {"backend", true, "auto | cpu | cuda: overrides the scene's backend"},
    {"duration", true, "simulated seconds: overrides the scene's duration (a quick preview)"},
    {"threads", true, "CPU threads (default: the CPUs this process may use)"},
    {"vtp", false, "also write VTK PolyData frames (DIR/vtp/*.vtp, DIR/frames.pvd) for ParaView"},
    {"video", false, "render the frames into DIR/render when the run ends"},
    {"formats", true, "with --video: comma list of mp4, webm, gif (default mp4,webm,gif)"},
    {"width", true, "video width (default 1280)"},
    {"height", true, "video height (default 720)"},
    {"camera", true, "front | iso | top | orbit (default iso)"},
    {"checkpoint-every", true, "seconds of work between saved states (default 1; 0 = every frame)"},
    {"quiet", false, "no progress output"},
    {"help", false, "this help"},
};

// A progress bar on a terminal, a plain line every tenth of a stage otherwise.
class ProgressPrinter {
 public:
  explicit ProgressPrinter(bool quiet) : quiet_(quiet), tty_(stderr_is_terminal()) {}
  void operator()(const job::Progress& p) {
    if (quiet_ || p.stage == job::Stage::kPrepare || p.stage == job::Stage::kDone) return;
    const double share = p.total ? double(p.done) / double(p.total) : 1.0;
    const char* what = p.stage == job::Stage::kSimulate ? "frame" : "render";
    if (p.stage != stage_) stage_ = p.stage, last_tenth_ = -1;
    if (tty_) {
      const int width = 30, filled = int(share * width + 0.5);
      std::fprintf(stderr, "\r[%.*s%*s] %3.0f%% %s %llu/%llu t=%.3g s, %llu contacts, eta %.0f s   ",
                   filled, "##############################", width - filled, "", 100 * share, what,
                   (unsigned long long)p.done, (unsigned long long)p.total, p.sim_time,
                   (unsigned long long)p.contacts, p.eta_s > 0 ? p.eta_s : 0.0);
      if (p.done == p.total) std::fprintf(stderr, "\n");
    } else if (p.done == p.total || int(share * 10) > last_tenth_) {
      last_tenth_ = int(share * 10);
      std::fprintf(stderr, "run: %s %llu/%llu (%.0f%%), t = %.4g s, %llu steps so far, eta %.0f s\n",
                   what, (unsigned long long)p.done, (unsigned long long)p.total, 100 * share,
                   p.sim_time, (unsigned long long)p.steps, p.eta_s > 0 ? p.eta_s : 0.0);
    }
  }
  bool tty() const { return tty_ && !quiet_; }

 private:
  bool quiet_, tty_;
  job::Stage stage_ = job::Stage::kPrepare;
  int last_tenth_ = -1;
};

Expected<std::string> read_text(const std::string& path, size_t limit) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return not_found(path + ": cannot open");
  std::ostringstream text;
  text << in.rdbuf();
  if (text.str().size() > limit) return invalid_argument(path + ": larger than the limit");
  return text.str();
}

// Flags into the spec; "" when they are fine, else the usage message.
std::string apply_flags(const ParsedArgs& p, job::JobSpec* spec) {
  std::string err;
  if (p.has("backend")) spec->backend = p.get("backend");
  if (!spec->backend.empty() && spec->backend != "auto" && spec->backend != "cpu" &&
      spec->backend != "cuda")
    return "--backend must be auto, cpu or cuda";
  if (p.has("duration")) {
    spec->duration = p.get_double("duration", 0, &err);
    if (!err.empty()) return err;
    // 0 in a spec means "the scene's"; the job holds the rest to the scene's limits.
    if (!(spec->duration > 0)) return "--duration must be a positive number of seconds";
  }
  if (p.has("threads") && !p.get_int_in("threads", 0, 0, job::kMaxThreads, &spec->threads, &err))
    return err;
  if (p.has("checkpoint-every")) {
    spec->checkpoint_interval_s = p.get_double("checkpoint-every", 1, &err);
    if (!err.empty()) return err;
    // A finite number: job.json keeps it for --resume, and JSON has no infinity.
    if (!(spec->checkpoint_interval_s >= 0) || !std::isfinite(spec->checkpoint_interval_s))
      return "--checkpoint-every must be a number of seconds >= 0";
  }
  if (p.has("vtp")) spec->vtp = true;
  if (p.has("video")) {
#ifdef COLLIDO_HAVE_RENDER
    spec->render = true;
    job::RenderSettings& rs = spec->render_settings;
    if (!parse_video_list(p.get("formats", "mp4,webm,gif"), &rs, &err))
      return "--formats: " + err;
    if (!p.get_int_in("width", rs.width, job::kMinFrameSide, job::kMaxFrameSide, &rs.width, &err) ||
        !p.get_int_in("height", rs.height, job::kMinFrameSide, job::kMaxFrameSide, &rs.height, &err))
      return err;
    rs.camera = p.get("camera", rs.camera);
#else
    return "--video: this build has no renderer";
#endif
  }
  return "";
}

}  // namespace

int cmd_run(const Args& args) {
  std::string err;
  auto p = parse_args(args, kFlags, &err);
  if (!p) return usage_error("run", err);
  if (p->has("help")) {
    print_help(
        "usage: collidoscope run SCENE.json [--out DIR] [--force] [--video] [--vtp] [--backend "
        "auto|cpu|cuda]\n"
        "       collidoscope run --resume DIR\n\n"
        "Runs the scene's collision frames and writes DIR/wall.stl, DIR/frames/frame_NNNNNN.snap,\n"
        "DIR/stats.csv (one row per frame), DIR/scene.json (with defaults), DIR/checkpoint.bin and\n"
        "DIR/result.json (status, files, measured cost); --video adds DIR/render/ (poster, MP4,\n"
        "WebM, GIF). A killed run continues with --resume DIR. Exit code 2: bad input; 1: the\n"
        "run failed.",
        kFlags);
    return kExitOk;
  }
  job::JobSpec spec;
  if (p->has("resume")) {
    if (!p->positional().empty() || p->has("out") || p->has("force"))
      return usage_error("run", "--resume DIR takes no scene, --out or --force");
    const std::string dir = p->get("resume");
    auto text = read_text(dir + "/job.json", size_t(64) << 20);
    if (!text) return usage_error("run", "--resume: " + text.status().message());
    auto saved = job::spec_from_json(*text);
    if (!saved) return usage_error("run", dir + "/job.json: " + saved.status().message());
    spec = std::move(*saved);
    spec.out_dir = dir;
    spec.dir_policy = job::DirPolicy::kResume;
    if (p->has("threads") && !p->get_int_in("threads", 0, 0, job::kMaxThreads, &spec.threads, &err))
      return usage_error("run", err);
  } else {
    if (p->positional().size() != 1)
      return usage_error("run", "one scene file expected (see --help)");
    const std::string scene_path = p->positional()[0];
    auto text = read_text(scene_path, size_t(16) << 20);
    if (!text) return usage_error("run", text.status().message());
    spec.scene_json = *text;
    // Absolute: --resume may run from another working directory.
    spec.scene_dir = fs::absolute(fs::path(scene_path)).parent_path().string();
    spec.out_dir = p->get("out", "results/" + fs::path(scene_path).stem().string());
    spec.dir_policy = p->has("force") ? job::DirPolicy::kReplace : job::DirPolicy::kRefuse;
    if (std::string e = apply_flags(*p, &spec); !e.empty()) return usage_error("run", e);
  }
  const bool quiet = p->has("quiet");
  ProgressPrinter printer(quiet);
  job::Hooks hooks;
  hooks.progress = [&](const job::Progress& pr) { printer(pr); };
  hooks.note = [&](const std::string& line) {
    std::fprintf(stderr, "%scollidoscope run: note: %s\n", printer.tty() ? "\n" : "",
                 line.c_str());
  };
  const job::JobResult r = job::run_job(spec, hooks);
  if (!r.status) {
    std::fprintf(stderr, "%scollidoscope run: %s\n", printer.tty() ? "\n" : "",
                 r.status.message().c_str());
    return exit_code(r.status);
  }
  if (!quiet) {
    const sim::TimeStepInfo& ts = r.time_step;
    // A small CPU scene steps on fewer threads than its pool has (sim::DynamicsConfig).
    const std::string threads =
        std::to_string(r.threads) + (r.threads == 1 ? " thread" : " threads") +
        (r.backend == "cpu" && r.step_threads < r.threads
             ? "; the steps on " + std::to_string(r.step_threads) + ", as for any small scene"
             : "");
    std::fprintf(stderr,
                 "run: %llu particles, wall %llu triangles, on the %s (%s): %llu steps in "
                 "%.1f s (%.3g ms per step); results in %s\n"
                 "run: stiffness %.4g N/m, damping ratio %.3g, critical step %.3g s, %s step %.3g s\n",
                 (unsigned long long)r.particles, (unsigned long long)r.triangles,
                 r.backend.c_str(), threads.c_str(), (unsigned long long)r.cost.steps,
                 r.cost.simulate_s,
                 r.cost.steps ? 1e3 * r.cost.simulate_s / double(r.cost.steps) : 0.0,
                 r.out_dir.c_str(), ts.stiffness, ts.damping_ratio, ts.critical_step,
                 ts.explicit_step > 0 ? "fixed" : "automatic",
                 ts.explicit_step > 0 ? ts.explicit_step : ts.spring_step);
    for (const job::Artifact& a : r.artifacts)
      if (a.role == "video" || a.role == "gif" || a.role == "poster")
        std::fprintf(stderr, "  %-7s %s/%s (%s)\n", a.role.c_str(), r.out_dir.c_str(),
                     a.path.c_str(), human_bytes(double(a.bytes)).c_str());
  }
  return kExitOk;
}

// ---------------------------------------------------------------------------
// job-exec: one job in this process, reporting on a pipe.

namespace {

const std::vector<FlagSpec> kExecFlags = {
    {"progress-fd", true, "file descriptor for JSON progress lines (job/child.h)"},
    {"progress-file", true,
     "append the progress lines to this file instead (a cluster job: the service reads it)"},
    {"resume", false,
     "continue the run in the spec's directory when it holds one (a requeued or preempted "
     "cluster job); else start as the spec says"},
    {"threads", true, "CPU threads (overrides the spec)"},
    {"help", false, "this help"},
};

// SIGTERM turns into the job's cancellation flag: the job stops at its next
// frame, writes its result.json and exits 1.
std::atomic<bool> g_cancel{false};
extern "C" void on_terminate(int) { g_cancel.store(true); }

void write_all(int fd, const std::string& s) {
  if (fd < 0) return;
  for (size_t at = 0; at < s.size();) {
    const ssize_t w = ::write(fd, s.data() + at, s.size() - at);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return;  // the parent went away: the job still finishes its files
    at += size_t(w);
  }
}

}  // namespace

int cmd_job_exec(const Args& args) {
  std::string err;
  auto p = parse_args(args, kExecFlags, &err);
  if (!p) return usage_error("job-exec", err);
  if (p->has("help")) {
    print_help("usage: collidoscope job-exec SPEC.json [--progress-fd N | --progress-file PATH] "
               "[--resume]\n\n"
               "Runs one job from its spec (job/job.h; the service and cluster nodes start this).",
               kExecFlags);
    return kExitOk;
  }
  if (p->positional().size() != 1) return usage_error("job-exec", "one spec file expected");
  int fd = p->get_int32("progress-fd", -1, &err);
  if (!err.empty()) return usage_error("job-exec", err);
  const std::string progress_file = p->get("progress-file", "");
  if (fd >= 0 && !progress_file.empty())
    return usage_error("job-exec", "--progress-fd and --progress-file: choose one");
  // A job whose parent (a service worker) is gone must not run on beside the
  // one the restarted service resumes in the same directory: it dies with its
  // parent, leaving its last checkpoint; a parent that died before this call
  // (while the libraries loaded) is caught by its pid, which the parent gave.
  // Started by no one (a shell), no matter; on a cluster the scheduler owns
  // the process.
  if (fd >= 0 && progress_file.empty()) {
    const char* given = std::getenv(job::kParentPidVariable);
    const pid_t parent = given ? pid_t(std::atol(given)) : getppid();
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) return kExitFailure;  // the parent died before prctl
  }
  if (!progress_file.empty()) {
    // Appended: a requeued job's lines follow its first attempt's.
    fd = ::open(progress_file.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    if (fd < 0)
      return usage_error("job-exec", progress_file + ": " + std::strerror(errno));
  }
  auto report = [&](const Status& st) {
    write_all(fd, job::status_line(st));
    if (!st) std::fprintf(stderr, "collidoscope job-exec: %s\n", st.message().c_str());
    return exit_code(st);
  };
  auto text = read_text(p->positional()[0], size_t(64) << 20);
  if (!text) return report(text.status());
  auto spec = job::spec_from_json(*text);
  if (!spec) return report(Status(spec.status().code(), p->positional()[0] + ": " +
                                                            spec.status().message()));
  if (p->has("threads")) spec->threads = p->get_int32("threads", 0, &err);
  if (!err.empty()) return usage_error("job-exec", err);
  if (p->has("resume") && job::holds_a_run(spec->out_dir))
    spec->dir_policy = job::DirPolicy::kResume;
  // A viewer closing a pipe must not kill the job; SIGTERM asks it to stop.
  std::signal(SIGPIPE, SIG_IGN);
  std::signal(SIGTERM, on_terminate);
  job::Hooks hooks;
  hooks.cancel = &g_cancel;
  // Each report carries the job's peak memory so far: what a scheduler's kill
  // (time limit, out of memory) leaves the service to record.
  hooks.progress = [&](const job::Progress& pr) {
    write_all(fd, job::progress_line(pr, uint64_t(own_process_memory().peak_resident_bytes)));
  };
  hooks.note = [&](const std::string& line) { write_all(fd, job::note_line(line)); };
  const job::JobResult r = job::run_job(*spec, hooks);
  return report(r.status);
}

}  // namespace collido::app
