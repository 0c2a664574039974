// `collidoscope calibrate`: flags and printing around the calibration sweep of
// job/calibrate.h, which runs every configuration in a `collidoscope calibrate-exec`
// child of its own and writes one run-log row per configuration (gvm/run_log.h).
// `calibrate-exec` is that child: one request of a sweep, its answer as a JSON line.
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "app/cli.h"
#include "app/commands.h"

#ifdef COLLIDO_HAVE_RUN  // the sweep lives in the job library
#include "job/calibrate.h"
#include "job/calibrate_jobs.h"
#endif

namespace collido::app {

#ifdef COLLIDO_HAVE_RUN

namespace {

const std::vector<FlagSpec>& calibrate_flags() {
  static const std::vector<FlagSpec> specs = {
      {"out", true, "run log CSV to write (required; rewritten after every configuration)"},
      {"backend", true,
       "cpu | cuda | auto (default auto: cuda when a GPU is usable; with --jobs, cpu, and auto is "
       "cpu)"},
      {"configs", true,
       "number of configurations (default 300 on cpu, 200 on cuda, 6 with --quick; with --jobs "
       "300, 150 on cuda, 4 with --quick)"},
      {"seed", true, "seed of the sweep and of the particles (default 1)"},
      {"radius", true,
       "largest particle radius, % of the wall's longest side: P, or LO:HI for one drawn "
       "log-uniform per configuration (default 1)"},
      {"quick", false, "tiny sweep (small walls, <= 2000 particles, <= 3 frames) for tests"},
      {"threads", true,
       "CPU threads of every run (default 0 = all cores; 1 is steadier on "
       "a machine shared with other work)"},
      {"repeats", true,
       "runs per configuration; smallest times (with --jobs the median times), largest memory "
       "kept (default 3 on cpu, 2 on cuda)"},
      {"budget", true,
       "seconds; start no run after this, keep the rows measured by then (default 0 = none on "
       "cpu, 330 on cuda; with --jobs 480 on cuda)"},
      {"jobs", false,
       "sweep real jobs (job-exec children) into a job log instead of detection frames"},
      {"job-threads", true, "with --jobs: CPU threads of every job (default 1)"},
      {"settled", true,
       "with --jobs: share of jobs with gravity drawn long enough for their particles to land, "
       "fewer particles keeping them within ten times the usual work (default 0)"},
      {"work-spread", true,
       "with --jobs: each job's bound on particle-steps drawn log-uniformly between the usual "
       "bound and F times it, so the work of large jobs varies (default 1: the usual bound)"},
      {"meshes", true,
       "with --jobs: folder of the sweep's STL walls (default tests/data/meshes, if there)"},
      {"work", true,
       "with --jobs: folder for the jobs' run directories (default OUT.work; one the sweep makes "
       "goes when it ends)"},
      {"no-render", false, "with --jobs: no rendered jobs (a build without a renderer)"},
      {"help", false, "show this help"},
  };
  return specs;
}

// "P" or "LO:HI" percent into *lo, *hi; false when it is not two numbers.
bool parse_radius(const std::string& text, double* lo, double* hi) {
  const auto colon = text.find(':');
  char* end = nullptr;
  const std::string a = text.substr(0, colon);
  *lo = std::strtod(a.c_str(), &end);
  bool ok = !a.empty() && end && *end == 0;
  *hi = *lo;
  if (colon != std::string::npos) {
    const std::string b = text.substr(colon + 1);
    *hi = std::strtod(b.c_str(), &end);
    ok = ok && !b.empty() && end && *end == 0;
  }
  return ok;
}

// The collidoscope binary each configuration runs in: COLLIDOSCOPE_EXE when set (a
// test calls this command inside its own binary), else this very program. A program
// that is not collidoscope would run its own main() as the child, so it is refused.
bool collidoscope_executable(std::string* path, std::string* error) {
  if (const char* env = std::getenv("COLLIDOSCOPE_EXE"); env && *env) {
    *path = env;
    return true;
  }
  std::vector<char> buf(4096);
  const ssize_t n = readlink("/proc/self/exe", buf.data(), buf.size() - 1);
  if (n <= 0) {
    *error = "cannot find this program's path (/proc/self/exe); set COLLIDOSCOPE_EXE";
    return false;
  }
  *path = std::string(buf.data(), size_t(n));
  const std::string base = path->substr(path->rfind('/') + 1);
  if (base.rfind("collidoscope", 0) != 0) {
    *error = "each configuration runs in `collidoscope calibrate-exec`, and this program (" +
             *path + ") is not collidoscope; set COLLIDOSCOPE_EXE to its path";
    return false;
  }
  return true;
}

const std::vector<FlagSpec> kExecFlags = {
    {"result-fd", true, "file descriptor for the JSON result line (default: stdout)"},
    {"help", false, "this help"},
};

void write_all(int fd, const std::string& s) {
  for (size_t at = 0; at < s.size();) {
    const ssize_t w = ::write(fd, s.data() + at, s.size() - at);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return;  // the parent went away: nobody is left to tell
    at += size_t(w);
  }
}

// Prints one line per finished run or job.
void print_progress(const job::CalibrateProgress& p) {
  if (!p.finished) return;  // one line per run, once it has ended
  std::fprintf(stderr, "[%d/%d %3zu/%zu] %s: ", p.pass, p.passes, p.index, p.count,
               p.running.c_str());
  if (!p.error.empty()) {
    std::fprintf(stderr, "FAILED: %s\n", p.error.c_str());
    return;
  }
  std::fprintf(stderr, "%lld triangles, %.3f ms/frame, total %.3f s, host %s",
               static_cast<long long>(p.triangles), 1e3 * p.frame_s, p.total_s,
               human_bytes(p.peak_host_bytes).c_str());
  if (p.backend == "cuda") std::fprintf(stderr, ", device %s", human_bytes(p.device_bytes).c_str());
  std::fprintf(stderr, "\n");
}

bool is_dir(const std::string& p) {
  struct stat st;
  return ::stat(p.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
}

// `calibrate --jobs`: the job sweep of job/calibrate_jobs.h.
int calibrate_jobs(const ParsedArgs& parsed) {
  const char* cmd = "calibrate --jobs";
  std::string error;
  job::JobSweepSpec spec;
  spec.backend = parsed.get("backend", "cpu");
  if (spec.backend == "auto") spec.backend = "cpu";
  const bool cuda = spec.backend == "cuda";
  spec.quick = parsed.has("quick");
  spec.configs = parsed.get_int("configs", spec.quick ? 4 : cuda ? 150 : 300, &error);
  spec.seed = static_cast<uint64_t>(parsed.get_int("seed", 1, &error));
  spec.threads = parsed.get_int32("job-threads", 1, &error);
  spec.repeats = parsed.get_int32("repeats", cuda ? 2 : 3, &error);
  spec.budget_s = static_cast<double>(parsed.get_int("budget", cuda && !spec.quick ? 480 : 0, &error));
  if (!error.empty()) return usage_error(cmd, error);
  spec.render = !parsed.has("no-render");
  spec.settled_share = parsed.get_double("settled", 0.0, &error);
  spec.work_spread = parsed.get_double("work-spread", 1.0, &error);
  if (!error.empty()) return usage_error(cmd, error);
  spec.out_path = parsed.get("out");
  spec.work_dir = parsed.get("work", spec.out_path + ".work");
  spec.mesh_dir = parsed.get("meshes", is_dir("tests/data/meshes") ? "tests/data/meshes" : "");
  if (!collidoscope_executable(&spec.executable, &error)) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, error.c_str());
    return kExitFailure;
  }
  if (Status s = job::validate(spec); !s) return usage_error(cmd, s.message());
  // The renderer's rasterizer threads follow LP_NUM_THREADS, which each job-exec child
  // inherits: a one-thread job renders on one thread too (a sweep then keeps to one core).
  if (spec.threads > 0) setenv("LP_NUM_THREADS", std::to_string(spec.threads).c_str(), 1);
  job::CalibrateHooks hooks;
  hooks.note = [](const std::string& line) { std::fprintf(stderr, "calibrate: %s\n", line.c_str()); };
  hooks.progress = print_progress;
  const auto summary = job::calibrate_jobs(spec, hooks);
  if (!summary) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, summary.status().message().c_str());
    return exit_code(summary.status());
  }
  std::printf("%zu jobs (%zu failed) x %d repeats in %.1f s on %s: %s\n", summary->measured,
              summary->failed, summary->repeats, summary->took_s, summary->device.c_str(),
              spec.out_path.c_str());
  return kExitOk;
}

}  // namespace

int cmd_calibrate(const Args& args) {
  const char* cmd = "calibrate";
  std::string error;
  auto parsed = parse_args(args, calibrate_flags(), &error);
  if (!parsed) return usage_error(cmd, error);
  if (parsed->has("help")) {
    print_help(
        "usage: collidoscope calibrate --out RUNS.csv [--backend cpu|cuda|auto] [--configs N]\n"
        "                              [--seed S] [--quick] [--threads T] [--repeats R]\n"
        "                              [--budget SECONDS] [--radius P|LO:HI]\n"
        "       collidoscope calibrate --jobs --out JOBS.csv [--backend cpu|cuda] [--configs N]\n"
        "                              [--seed S] [--job-threads T] [--repeats R] [--budget S]\n"
        "                              [--meshes DIR] [--work DIR] [--no-render] [--quick]\n"
        "                              [--settled SHARE] [--work-spread F]\n\n"
        "Runs a seeded sweep of real configurations (walls, particle counts, methods,\n"
        "traversals, frames) on this machine, each in a process of its own, and writes one\n"
        "run-log row per configuration: time per frame (the steady cost: median of the\n"
        "frames after the first, timing extra frames where the run has too few), total\n"
        "time (set-up and the run's frames), peak host and device memory, GPU load.\n"
        "Repeats are whole passes over the sweep; with --budget, no run starts after that\n"
        "many seconds and the log keeps the configurations measured by then. Measure on an\n"
        "otherwise idle machine: other work slows runs unevenly (docs/gvm.md).\n"
        "`collidoscope gvm train --logs RUNS.csv` trains on the log.\n\n"
        "With --jobs: a seeded sweep of real jobs instead (walls, particle counts and radii,\n"
        "pour, jet and fill placements, particle contacts, friction, duration and frames,\n"
        "render sizes and formats), each through `collidoscope job-exec` as the service\n"
        "runs them, one job-log row each: the job's inputs and its cost (total and per-stage\n"
        "time, time per frame, peak host and device memory, GPU load, output bytes). Defaults:\n"
        "300 jobs x 3 repeats on cpu, 150 x 2 and a 480 s budget on cuda, one thread a job.\n"
        "Exit codes: 0 every configuration ran, 1 a run or the output failed, 2 bad arguments.",
        calibrate_flags());
    return kExitOk;
  }
  if (!parsed->positional().empty())
    return usage_error(cmd, "unexpected argument '" + parsed->positional()[0] + "'");
  if (!parsed->has("out")) return usage_error(cmd, "--out RUNS.csv is required");
  if (parsed->has("jobs")) return calibrate_jobs(*parsed);
  const std::string want = parsed->get("backend", "auto");
  job::CalibrateSpec spec = job::calibrate_defaults(want, parsed->has("quick"));
  const int64_t configs = parsed->get_int("configs", spec.configs, &error);
  const int64_t seed = parsed->get_int("seed", 1, &error);
  const int64_t threads = parsed->get_int("threads", spec.threads, &error);
  const int64_t repeats = parsed->get_int("repeats", spec.repeats, &error);
  const int64_t budget_s = parsed->get_int("budget", int64_t(spec.budget_s), &error);
  if (!error.empty()) return usage_error(cmd, error);
  if (budget_s < 0) return usage_error(cmd, "--budget must be >= 0");
  if (configs < 1 || configs > 100000) return usage_error(cmd, "--configs must be in 1..100000");
  if (threads < 0 || threads > 4096) return usage_error(cmd, "--threads must be in 0..4096");
  if (repeats < 1 || repeats > 100) return usage_error(cmd, "--repeats must be in 1..100");
  const std::string radius = parsed->get("radius", "1");
  double lo = 0, hi = 0;
  if (!parse_radius(radius, &lo, &hi) || !(lo >= 0.01) || !(hi >= lo) || !(hi <= 50))
    return usage_error(cmd, "--radius must be P or LO:HI percent, 0.01 <= LO <= HI <= 50, got '" +
                                radius + "'");
  if (want != "cpu" && want != "cuda" && want != "auto")
    return usage_error(cmd, "unknown --backend '" + want + "' (cpu, cuda, auto)");
  spec.configs = configs;
  spec.seed = static_cast<uint64_t>(seed);
  spec.threads = static_cast<int>(threads);
  spec.repeats = static_cast<int>(repeats);
  spec.budget_s = static_cast<double>(budget_s);
  spec.radius_lo_pct = lo, spec.radius_hi_pct = hi;
  spec.out_path = parsed->get("out");
  if (!collidoscope_executable(&spec.executable, &error)) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, error.c_str());
    return kExitFailure;
  }
  if (Status s = job::validate(spec); !s) return usage_error(cmd, s.message());

  job::CalibrateHooks hooks;
  hooks.note = [](const std::string& line) { std::fprintf(stderr, "calibrate: %s\n", line.c_str()); };
  hooks.progress = print_progress;
  const auto summary = job::calibrate(spec, hooks);
  if (!summary) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, summary.status().message().c_str());
    return exit_code(summary.status());
  }
  std::printf("%zu configurations (%zu failed) x %d repeats in %.1f s: %s\n", summary->measured,
              summary->failed, summary->repeats, summary->took_s, spec.out_path.c_str());
  if (summary->failed) {
    std::fprintf(stderr, "collidoscope %s: %zu of %zu configurations failed\n", cmd,
                 summary->failed, summary->configs);
    return kExitFailure;
  }
  return kExitOk;
}

int cmd_calibrate_exec(const Args& args) {
  const char* cmd = "calibrate-exec";
  std::string err;
  auto p = parse_args(args, kExecFlags, &err);
  if (!p) return usage_error(cmd, err);
  if (p->has("help")) {
    print_help("usage: collidoscope calibrate-exec REQUEST [--result-fd N]\n\n"
               "Runs one request of a calibration sweep (the GPU probe, the wall survey or one\n"
               "configuration) and writes its result as one JSON line; `calibrate` starts it.\n"
               "REQUEST is the JSON object itself or a file that holds it (job/calibrate.h).",
               kExecFlags);
    return kExitOk;
  }
  if (p->positional().size() != 1) return usage_error(cmd, "one request expected");
  const int fd = p->get_int32("result-fd", STDOUT_FILENO, &err);
  if (!err.empty()) return usage_error(cmd, err);
  std::string request = p->positional()[0];
  if (request.empty() || request[0] != '{') {
    std::ifstream in(request, std::ios::binary);
    if (!in) return usage_error(cmd, request + ": cannot open");
    std::ostringstream text;
    text << in.rdbuf();
    request = text.str();
  }
  std::string line;
  const Status s = job::calibrate_exec(request, &line);
  write_all(fd, line);
  return exit_code(s);
}

#else  // built without the job library: the sweep is not there

int cmd_calibrate(const Args&) {
  std::fprintf(stderr, "collidoscope calibrate: this build has no job module (job/calibrate.h)\n");
  return kExitFailure;
}
int cmd_calibrate_exec(const Args& args) { return cmd_calibrate(args); }

#endif

}  // namespace collido::app
