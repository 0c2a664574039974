// `collidoscope study`: flags and printing over the study library (study/study.h).
#include <sys/stat.h>

#include <cerrno>
#include <chrono>
#include <cstdio>

#include "app/cli.h"
#include "app/commands.h"
#include "sim/detect_cuda.h"
#include "sim/parallel.h"
#include "study/study.h"

namespace collido::app {
namespace {

const std::vector<FlagSpec> kFlags = {
    {"out", true, "folder for study_detect.csv, study_dynamics.csv and study.json (required)"},
    {"quick", false, "the small matrix: minutes on two cores (default: the full size)"},
    {"backend", true, "cpu | cuda (default cpu; cuda falls back to cpu with a note)"},
    {"meshes", true, "folder of third-party STL files (default tests/data/meshes)"},
    {"only", true, "detect | dynamics: run one half (default both)"},
    {"scenes", true, "comma list of detection scenes (wall1, wall2, mesh file names without .stl; default all)"},
    {"max-particles", true, "largest particle count (default 1e5 on the CPU, 1e6 on the GPU)"},
    {"threads", true, "CPU threads (default all cores)"},
    {"help", false, "show this help"},
};

}  // namespace

int cmd_study(const Args& args) {
  std::string err;
  auto parsed = parse_args(args, kFlags, &err);
  if (!parsed) return usage_error("study", err);
  if (parsed->has("help")) {
    print_help("usage: collidoscope study --out DIR [--quick] [--backend cpu|cuda]", kFlags);
    return kExitOk;
  }
  if (!parsed->has("out")) return usage_error("study", "--out DIR is required");
  const std::string dir = parsed->get("out");
  const std::string only = parsed->get("only", "");
  if (!only.empty() && only != "detect" && only != "dynamics")
    return usage_error("study", "--only is detect or dynamics");
  const int64_t threads = parsed->get_int("threads", 0, &err);
  if (!err.empty() || threads < 0 || threads > 4096) return usage_error("study", "--threads must be in [0, 4096]");
  sim::Backend wanted = sim::Backend::kCpu;
  if (parsed->has("backend") && !sim::parse_backend(parsed->get("backend"), &wanted))
    return usage_error("study", "unknown --backend '" + parsed->get("backend") + "' (cpu, cuda)");
  std::string note;
  sim::ThreadPool pool(static_cast<int>(threads));
  study::StudyOptions o;
  o.quick = parsed->has("quick");
  o.backend = sim::usable_backend(wanted, &note);
  if (!note.empty()) std::fprintf(stderr, "collidoscope study: note: %s\n", note.c_str());
  o.mesh_dir = parsed->get("meshes", "tests/data/meshes");
  if (parsed->has("scenes")) o.scenes = split_list(parsed->get("scenes"));
  const int64_t max_particles = parsed->get_int("max-particles", 0, &err);
  if (!err.empty() || max_particles < 0) return usage_error("study", "--max-particles must be a count");
  o.max_particles = static_cast<size_t>(max_particles);
  o.pool = &pool;
  const auto t0 = std::chrono::steady_clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  o.progress = [&](const std::string& line) {
    std::printf("[%6.1f s] %s\n", elapsed(), line.c_str());
    std::fflush(stdout);
  };
  if (mkdir(dir.c_str(), 0755) != 0 && errno != EEXIST) {
    std::fprintf(stderr, "collidoscope study: cannot create %s\n", dir.c_str());
    return kExitFailure;
  }
  auto failed = [](const Status& s) {
    std::fprintf(stderr, "collidoscope study: %s\n", s.message().c_str());
    return exit_code(s);  // a missing mesh folder or an unknown scene is bad input: 2
  };
  std::vector<study::DetectRow> detect;
  std::vector<study::DynamicsRow> dynamics;
  if (only != "dynamics")
    if (Status s = study::run_detect_study(o, &detect); !s) return failed(s);
  if (only != "detect")
    if (Status s = study::run_dynamics_study(o, &dynamics); !s) return failed(s);
  std::string machine = std::to_string(pool.size()) + " CPU threads";
  if (o.backend == sim::Backend::kCuda) machine += ", " + sim::cuda_device_name();
  if (Status s = study::write_study(dir, only != "dynamics" ? &detect : nullptr,
                                    only != "detect" ? &dynamics : nullptr, machine);
      !s)
    return failed(s);
  // The findings in brief: failures by kind, and the automatic choices.
  size_t lost = 0, auto_rows = 0, auto_inexact = 0;
  for (const auto& r : detect) {
    lost += r.verdict == "loses_contacts" || r.verdict == "invents_contacts";
    if (r.is_auto) ++auto_rows, auto_inexact += r.verdict != "exact";
  }
  size_t blow = 0, tunnel = 0, loses = 0, unreported = 0;
  for (const auto& r : dynamics) {
    blow += r.verdict == "blows_up", tunnel += r.verdict == "tunnels", loses += r.verdict == "loses_contacts";
    unreported += (r.verdict == "blows_up" || r.verdict == "tunnels") && r.warnings.empty();
  }
  std::printf("detection: %zu settings, %zu differ from the reference (all float precision: %s); "
              "%zu automatic choices, %zu not exact\n",
              detect.size(), lost, lost ? "see study_detect.csv" : "none", auto_rows, auto_inexact);
  std::printf("dynamics: %zu settings: %zu blow up, %zu tunnel, %zu lose contacts; %zu failures the engine "
              "did not report\n",
              dynamics.size(), blow, tunnel, loses, unreported);
  std::printf("wrote %s/study_detect.csv, study_dynamics.csv, study.json in %.1f s\n", dir.c_str(), elapsed());
  std::printf("charts: /usr/bin/python3 bench/study_charts.py %s\n", dir.c_str());
  return kExitOk;
}

}  // namespace collido::app
