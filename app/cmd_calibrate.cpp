// `collidoscope calibrate`: a seeded sweep of real, small configurations run on this
// machine with the backend at hand, one row each in the run-log format the predictor
// trains on and the service stores (gvm/run_log.h).
//
// Peak host memory: every configuration runs in a child process of its own (fork), so
// its peak resident set is its own. The child sends its times back over a pipe; the
// parent takes the peak from wait4()'s ru_maxrss when the child exits. A forked child
// starts with the parent's resident pages, so the parent stays lean: it never holds a
// wall or particles, never starts the engine's thread pool (a pool forked mid-use
// would deadlock the child) and never creates a CUDA context (CUDA does not survive a
// fork); the wall survey and the GPU probe run in children too. What the parent adds
// is about the baseline a fresh `collidoscope` process pays anyway.
#include <sys/resource.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>
#include <type_traits>
#include <vector>

#include "app/cli.h"
#include "app/commands.h"
#include "gvm/rng.h"
#include "gvm/run_log.h"
#include "sim/detect.h"
#include "sim/detect_cuda.h"
#include "sim/divide.h"
#include "sim/parallel.h"
#include "sim/particles.h"
#include "sim/shapes.h"

namespace collido::app {

namespace {

namespace g = collido::gvm;
using Clock = std::chrono::steady_clock;

const std::vector<FlagSpec>& calibrate_flags() {
  static const std::vector<FlagSpec> specs = {
      {"out", true, "run log CSV to write (required; rewritten after every configuration)"},
      {"backend", true, "cpu | cuda | auto (default auto: cuda when a GPU is usable)"},
      {"configs", true, "number of configurations (default 300 on cpu, 200 on cuda, 6 with --quick)"},
      {"seed", true, "seed of the sweep and of the particles (default 1)"},
      {"radius", true,
       "largest particle radius, % of the wall's longest side: P, or LO:HI for one drawn "
       "log-uniform per configuration (default 1)"},
      {"quick", false, "tiny sweep (small walls, <= 2000 particles, <= 3 frames) for tests"},
      {"threads", true,
       "CPU threads of every run (default 0 = all cores; 1 is steadier on "
       "a machine shared with other work)"},
      {"repeats", true,
       "runs per configuration; smallest times, largest memory kept (default 3 on cpu, 2 on "
       "cuda)"},
      {"budget", true,
       "seconds; start no run after this, keep the rows measured by then (default 0 = none on "
       "cpu, 330 on cuda)"},
      {"help", false, "show this help"},
  };
  return specs;
}

// The walls of the sweep: the paper's two vessels, an open funnel and icospheres from
// 320 to 81,920 triangles. `quick` marks the small set used by --quick.
struct WallChoice {
  const char* spec;
  bool quick;
};
constexpr WallChoice kWalls[] = {
    {"wall1", true},
    {"wall2", false},
    {"funnel", true},
    {"sphere:r=50,subdivisions=2", true},
    {"sphere:r=50,subdivisions=3", false},
    {"sphere:r=50,subdivisions=4", false},
    {"sphere:r=50,subdivisions=5", false},
    {"sphere:r=50,subdivisions=6", false},
};
constexpr size_t kWallCount = sizeof kWalls / sizeof kWalls[0];

// Particle radii are uniform in [r_max / 2, r_max]. r_max is a fraction of the wall's
// longest bounding-box side: by default 1 % (wall1: 0.5..1, as in bench detect), or,
// with --radius LO:HI, drawn per configuration log-uniform in [LO, HI] %, so that the
// geometry ratios the predictor sees (area / r^2, box volume / r^3, ...) span a range
// for every wall instead of one point per wall. The log records r_max, the wall's area
// and its box volume grown by r_max.
struct RadiusRange {
  double lo = 0.01, hi = 0.01;  // fractions of the longest side
  bool fixed() const { return lo == hi; }
};
// Bisection (gravity, circumcircle) is counted by dividing once, at this fraction
// clamped into the range; other radii scale its count by area.
constexpr double kRadiusRef = 0.01;
double radius_ref(const RadiusRange& rr) { return std::clamp(kRadiusRef, rr.lo, rr.hi); }
// midpoint4 counts at kRadiusSteps fractions log-spaced over [lo, hi].
constexpr int kRadiusSteps = 16;
double radius_step(const RadiusRange& rr, int i) {
  return rr.lo * std::pow(rr.hi / rr.lo, static_cast<double>(i) / (kRadiusSteps - 1));
}

// Sizes of one wall, measured once in a child (see survey_walls).
struct WallSurvey {
  int64_t triangles = 0;     // as built
  double longest = 0;        // longest bounding-box side, world units
  double extent[3] = {};     // bounding-box sides, world units
  double area = 0;           // triangle area, world units^2
  int64_t bisect_ref[2] = {};  // after gravity, circumcircle division at radius_ref
  int64_t m4[kRadiusSteps] = {};  // after midpoint4 division at radius_step(i)
};
struct SurveyResult {
  int ok = 0;
  char error[256] = {};
  WallSurvey walls[kWallCount];
};

int division_index(sim::Method m) {
  return m == sim::Method::kGravity ? 0 : m == sim::Method::kCircumcircle ? 1 : 2;
}

// One configuration of the sweep.
struct Plan {
  size_t wall = 0;
  double r_max = 0;  // world units
  sim::Method method = sim::Method::kBin;
  sim::Traversal traversal = sim::Traversal::kParticle;
  int64_t particles = 0, frames = 0;
};

// What a configuration's child sends back: plain bytes over the pipe.
struct RunResult {
  int ok = 0;
  char error[256] = {};
  int64_t triangles = 0, triangles_original = 0, threads = 0;
  double total_s = 0, gpu_busy_s = 0;
  double frame_s = 0;  // steady time per frame: median of the frames after the first
  uint64_t device_bytes = 0;
};

// Whether CUDA is usable (ok) and the device's name, or why not (error).
struct ProbeResult {
  int ok = 0;
  char error[256] = {};
  char device[128] = {};
};

template <size_t N>
void copy_text(char (&dst)[N], const std::string& s) {
  std::snprintf(dst, N, "%s", s.c_str());
}

// Runs f() in a forked child and hands back its result (a plain struct) and the
// child's peak resident bytes. False, with *why, when the child sent no result.
template <class T, class F>
bool run_in_child(F&& f, T* out, double* peak_host_bytes, std::string* why) {
  static_assert(std::is_trivially_copyable_v<T>, "results cross a pipe as bytes");
  int fd[2];
  if (pipe(fd) != 0) {
    *why = std::string("pipe: ") + std::strerror(errno);
    return false;
  }
  std::fflush(nullptr);  // else the child would write the parent's buffered output again
  const pid_t pid = fork();
  if (pid < 0) {
    *why = std::string("fork: ") + std::strerror(errno);
    close(fd[0]);
    close(fd[1]);
    return false;
  }
  if (pid == 0) {
    close(fd[0]);
    T result{};
    try {
      result = f();
    } catch (const std::exception& e) {  // bad_alloc from a too large configuration
      copy_text(result.error, std::string("exception: ") + e.what());
      result.ok = 0;
    }
    const char* p = reinterpret_cast<const char*>(&result);
    for (size_t left = sizeof result; left > 0;) {
      const ssize_t w = write(fd[1], p, left);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) _exit(3);
      p += w, left -= static_cast<size_t>(w);
    }
    // _exit: no atexit handlers or static destructors, which belong to the parent.
    _exit(0);
  }
  close(fd[1]);
  T result{};
  size_t got = 0;
  char* p = reinterpret_cast<char*>(&result);
  while (got < sizeof result) {
    const ssize_t r = read(fd[0], p + got, sizeof result - got);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) break;
    got += static_cast<size_t>(r);
  }
  close(fd[0]);
  int status = 0;
  struct rusage ru {};
  while (wait4(pid, &status, 0, &ru) < 0 && errno == EINTR) {
  }
  if (got != sizeof result) {
    *why = WIFSIGNALED(status) ? "the run was killed by signal " + std::to_string(WTERMSIG(status))
                               : "the run ended without a result";
    return false;
  }
  *out = result;
  if (peak_host_bytes) *peak_host_bytes = static_cast<double>(ru.ru_maxrss) * 1024.0;  // KiB
  return true;
}

// The run log's wall_box_volume: grown by the radius, so a flat wall has a volume too
// (the engine's grid pads its box the same way).
double wall_box_volume(double ex, double ey, double ez, double r) {
  return (ex + 2 * r) * (ey + 2 * r) * (ez + 2 * r);
}

// Triangle counts of every wall at its particle scales, for keeping divisions from
// growing absurdly large. midpoint4's count needs no division
// (sim::midpoint4_piece_count); bisection (gravity, circumcircle) stops each piece as soon as it fits and makes far
// fewer (wall1 at 1 %: 0.36 and 0.16 million against 2.2), so it is counted by dividing,
// once, at radius_ref.
SurveyResult survey_walls(bool quick, const RadiusRange& rr) {
  SurveyResult s;
  for (size_t w = 0; w < kWallCount; ++w) {
    if (quick && !kWalls[w].quick) continue;
    auto mesh = sim::make_shape(kWalls[w].spec);
    if (!mesh) {
      copy_text(s.error, std::string(kWalls[w].spec) + ": " + mesh.status().message());
      return s;
    }
    WallSurvey& ws = s.walls[w];
    ws.triangles = static_cast<int64_t>(mesh->triangles.size());
    const sim::Vec3d e = sim::mesh_bounds(*mesh).extent();
    ws.longest = std::max({e.x, e.y, e.z});
    ws.extent[0] = e.x, ws.extent[1] = e.y, ws.extent[2] = e.z;
    ws.area = sim::mesh_area(*mesh);
    double m4_ref = 0;
    for (int i = 0; i <= kRadiusSteps; ++i) {  // i == kRadiusSteps: at radius_ref
      const double r = (i < kRadiusSteps ? radius_step(rr, i) : radius_ref(rr)) * ws.longest;
      const double m4 = sim::midpoint4_piece_count(*mesh, r);
      if (i < kRadiusSteps)
        ws.m4[i] = static_cast<int64_t>(std::min(m4, 9e18));
      else
        m4_ref = m4;
    }
    // A wall whose four-way count is astronomical is not divided at all: too large.
    for (int d = 0; d < 2; ++d)
      ws.bisect_ref[d] =
          m4_ref > 5e7 ? static_cast<int64_t>(std::min(m4_ref, 9e18))
                       : static_cast<int64_t>(
                             sim::divide(*mesh,
                                         d == 0 ? sim::DivisionMethod::kGravity
                                                : sim::DivisionMethod::kCircumcircle,
                                         radius_ref(rr) * ws.longest)
                                 .pieces.size());
  }
  s.ok = 1;
  return s;
}

// One configuration, start to end, in the child. A frame is one detection frame: take
// the particles (converted and, on the GPU, uploaded) and detect with the contact list
// collected. Every frame sees the same particles; the simulation steps of
// `collidoscope run` (sim/dynamics.h) are not what this sweep measures.
RunResult run_config(const std::string& wall_spec, const Plan& p,
                     sim::Backend backend, int threads, uint64_t seed) {
  RunResult r;
  const auto t0 = Clock::now();
  auto seconds = [](Clock::time_point a) {
    return std::chrono::duration<double>(Clock::now() - a).count();
  };
  sim::ThreadPool pool(threads);
  r.threads = pool.size();
  auto wall = sim::make_shape(wall_spec);
  if (!wall) {
    copy_text(r.error, wall.status().message());
    return r;
  }
  const double r_max = p.r_max;
  const sim::Particles particles = sim::random_particles(
      static_cast<size_t>(p.particles), sim::mesh_bounds(*wall), 0.5 * r_max, r_max, seed);
  sim::DetectConfig cfg;
  cfg.method = p.method;
  cfg.traversal = p.traversal;
  cfg.backend = p.method == sim::Method::kReference ? sim::Backend::kCpu : backend;
  cfg.pool = &pool;
  cfg.r_max = r_max;
  cfg.collect_contacts = true;
  cfg.time_stages = false;  // a sync between stages would slow the frames it measures
  auto det = sim::Detector::create(*wall, cfg, particles.size());
  if (!det) {
    copy_text(r.error, det.status().message());
    return r;
  }
  sim::DetectResult res;
  auto frame = [&](double* took) {
    const auto tf = Clock::now();
    sim::Status s = (*det)->set_particles(particles);
    if (s) s = (*det)->detect(&res);
    *took = seconds(tf);
    if (!s) copy_text(r.error, s.message());
    return bool(s);
  };
  std::vector<double> timed;  // the frames that measure the steady time per frame
  for (int64_t f = 0; f < p.frames; ++f) {
    double took = 0;
    if (!frame(&took)) return r;
    if (f > 0) timed.push_back(took);
    // detect() syncs the device before it stops its clock, so frame_ms is GPU-busy time.
    r.gpu_busy_s += res.times.frame_ms * 1e-3;
  }
  r.total_s = seconds(t0);
  // Time per frame is the steady cost, the one a run of many frames pays: the first
  // frame also pays first-touch allocation (and, for the wall traversals, a rerun after
  // the contact buffer grows), which total time already holds. So the first frame is
  // left out, and frames beyond the run's own are timed (not counted in total time)
  // until there are enough of them that a run of one or two short frames is not one
  // noisy sample: at least kMinTimedSeconds, and kMinTimedFrames unless that many would
  // take longer than kEnoughSeconds (one frame of a slow configuration is precise
  // enough). The median keeps a burst of other work on the machine out of it.
  constexpr size_t kMinTimedFrames = 5, kMaxTimedFrames = 1000;
  constexpr double kMinTimedSeconds = 0.02, kEnoughSeconds = 0.25;
  double timed_s = 0;
  for (double t : timed) timed_s += t;
  auto need_more = [&] {
    const size_t n = timed.size();
    if (n == 0) return true;
    if (n >= kMaxTimedFrames) return false;
    return timed_s < kMinTimedSeconds || (n < kMinTimedFrames && timed_s < kEnoughSeconds);
  };
  while (need_more()) {
    double took = 0;
    if (!frame(&took)) return r;
    timed.push_back(took);
    timed_s += took;
  }
  std::sort(timed.begin(), timed.end());
  const size_t n = timed.size();
  r.frame_s = n % 2 ? timed[n / 2] : 0.5 * (timed[n / 2 - 1] + timed[n / 2]);
  r.triangles = static_cast<int64_t>((*det)->info().triangles_used);
  r.triangles_original = static_cast<int64_t>((*det)->info().triangles_original);
  r.device_bytes = (*det)->info().device_bytes;
  r.ok = 1;
  return r;
}

std::string cpu_model_name() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) {
        std::string name = line.substr(colon + 1);
        name.erase(0, name.find_first_not_of(" \t"));
        if (!name.empty()) return name;
      }
    }
  return "cpu";
}

// Sweep ranges per backend: particle counts are log-uniform in [lo, hi] per method,
// frames log-uniform in [1, max_frames]; divisions above max_pieces are skipped, and
// the brute-force reference runs only where particles x triangles stays small.
struct Ranges {
  double lo, hi_bin, hi_divided, hi_reference, reference_pairs, max_pieces, max_frames;
};
Ranges ranges_for(sim::Backend b, bool quick) {
  if (quick) return {100, 2000, 2000, 2000, 2e6, 2e5, 3};
  if (b == sim::Backend::kCuda) return {1e3, 3e7, 3e6, 0, 0, 3e6, 20};
  return {100, 3e5, 1e5, 3e4, 2e6, 1e6, 20};
}

int64_t log_uniform(g::Rng& rng, double lo, double hi) {
  return std::llround(std::pow(10.0, rng.uniform(std::log10(lo), std::log10(hi))));
}

// Pieces after dividing wall ws by method m at radius fraction radius_step(i), as the
// survey counted them (midpoint4) or estimated from radius_ref by area (bisection, never
// below the wall's own count). Counts fall as the radius grows, so the count at step i
// bounds every radius in [radius_step(i), radius_step(i + 1)).
double pieces_at(const WallSurvey& ws, const RadiusRange& rr, sim::Method m, int i) {
  const int d = division_index(m);
  if (d == 2) return static_cast<double>(ws.m4[i]);
  if (rr.fixed()) return static_cast<double>(ws.bisect_ref[d]);
  const double s = radius_ref(rr) / radius_step(rr, i);
  return std::max(static_cast<double>(ws.triangles), static_cast<double>(ws.bisect_ref[d]) * s * s);
}

// The smallest radius step at which method m divides wall ws into at most max_pieces,
// or -1 when none does.
int first_radius_step(const WallSurvey& ws, const RadiusRange& rr, sim::Method m,
                      double max_pieces) {
  const bool divided = m != sim::Method::kBin && m != sim::Method::kReference;
  for (int i = 0; i < kRadiusSteps; ++i)
    if (!divided || pieces_at(ws, rr, m, i) <= max_pieces) return i;
  return -1;
}

// Draws the whole sweep up front from the seed, so a failed run changes no other. The
// pipelines (method and traversal) take turns in a shuffled order, so each gets an
// equal share of the rows; wall, radius, particle count and frames are drawn for each.
// The radius is log-uniform in the range's [lo, hi] of the wall's longest side, its
// lower end raised where a smaller radius would divide the wall into more than
// max_pieces; a fixed radius draws nothing (the sweep of a seed stays as it was).
std::vector<Plan> draw_plans(size_t count, uint64_t seed, const SurveyResult& survey,
                             const RadiusRange& rr, sim::Backend backend, bool quick) {
  const Ranges rg = ranges_for(backend, quick);
  std::vector<std::pair<sim::Method, sim::Traversal>> pipelines;
  for (sim::Method m : {sim::Method::kBin, sim::Method::kGravity, sim::Method::kCircumcircle,
                        sim::Method::kMidpoint4})
    for (sim::Traversal t : {sim::Traversal::kParticle, sim::Traversal::kWall})
      pipelines.push_back({m, t});
  // The reference ignores the traversal, and does not run on the GPU.
  if (rg.reference_pairs > 0)
    pipelines.push_back({sim::Method::kReference, sim::Traversal::kParticle});

  g::Rng rng(seed);
  std::vector<Plan> plans;
  while (plans.size() < count) {
    rng.shuffle(pipelines);
    for (const auto& [method, traversal] : pipelines) {
      if (plans.size() == count) break;
      Plan p;
      p.method = method;
      p.traversal = traversal;
      const bool divided = method != sim::Method::kBin && method != sim::Method::kReference;
      std::vector<size_t> walls;
      for (size_t w = 0; w < kWallCount; ++w) {
        const WallSurvey& ws = survey.walls[w];
        if (ws.triangles == 0) continue;  // not surveyed (--quick)
        if (first_radius_step(ws, rr, method, rg.max_pieces) < 0) continue;
        if (method == sim::Method::kReference &&
            rg.reference_pairs / static_cast<double>(ws.triangles) < 10 * rg.lo)
          continue;
        walls.push_back(w);
      }
      if (walls.empty()) continue;  // this pipeline fits no wall of the sweep
      p.wall = walls[rng.below(walls.size())];
      double hi = method == sim::Method::kBin ? rg.hi_bin
                  : divided                   ? rg.hi_divided
                                              : rg.hi_reference;
      if (method == sim::Method::kReference)
        hi = std::min(hi, rg.reference_pairs / static_cast<double>(survey.walls[p.wall].triangles));
      const WallSurvey& ws = survey.walls[p.wall];
      if (rr.fixed()) {
        p.r_max = rr.lo * ws.longest;
      } else {
        const double f_lo = radius_step(rr, first_radius_step(ws, rr, method, rg.max_pieces));
        p.r_max =
            ws.longest * std::pow(10.0, rng.uniform(std::log10(f_lo), std::log10(rr.hi)));
      }
      p.particles = log_uniform(rng, rg.lo, hi);
      p.frames = log_uniform(rng, 1, rg.max_frames);
      plans.push_back(p);
    }
  }
  return plans;
}

// The best of a configuration's repeats so far.
struct Best {
  bool measured = false, failed = false;
  RunResult fastest;  // the repeat with the smallest total time
  double frame_s = 0, peak_host = 0;
  uint64_t device_bytes = 0;
};

g::RunRecord make_row(const Plan& p, const WallSurvey& wall, const Best& b, sim::Backend backend,
                      const std::string& device, const std::string& cpu_name) {
  g::RunRecord row;
  g::RunConfig& c = row.config;
  c.particles = p.particles;
  c.triangles = b.fastest.triangles;
  c.triangles_original = b.fastest.triangles_original;
  c.radius = p.r_max;
  c.wall_area = wall.area;
  c.wall_box_volume = wall_box_volume(wall.extent[0], wall.extent[1], wall.extent[2], p.r_max);
  c.method = *g::parse_method(sim::to_string(p.method));
  c.traversal = *g::parse_traversal(sim::to_string(p.traversal));
  c.frames = p.frames;
  // The reference always runs on the CPU; its row says so.
  const bool on_gpu = backend == sim::Backend::kCuda && p.method != sim::Method::kReference;
  c.backend = on_gpu ? g::Backend::kCuda : g::Backend::kCpu;
  c.device = on_gpu ? device : cpu_name;
  c.threads = b.fastest.threads;
  g::RunMeasure& m = row.measure;
  m.time_per_frame_s = b.frame_s;
  m.total_time_s = b.fastest.total_s;
  m.peak_host_bytes = b.peak_host;
  m.peak_device_bytes = on_gpu ? static_cast<double>(b.device_bytes) : 0.0;
  m.gpu_load = on_gpu && b.fastest.total_s > 0
                   ? std::min(1.0, b.fastest.gpu_busy_s / b.fastest.total_s)
                   : 0.0;
  return row;
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
        "                              [--budget SECONDS] [--radius P|LO:HI]\n\n"
        "Runs a seeded sweep of real configurations (walls, particle counts, methods,\n"
        "traversals, frames) on this machine, each in a process of its own, and writes one\n"
        "run-log row per configuration: time per frame (the steady cost: median of the\n"
        "frames after the first, timing extra frames where the run has too few), total\n"
        "time (set-up and the run's frames), peak host and device memory, GPU load.\n"
        "Repeats are whole passes over the sweep; with --budget, no run starts after that\n"
        "many seconds and the log keeps the configurations measured by then. Measure on an\n"
        "otherwise idle machine: other work slows runs unevenly (docs/gvm.md).\n"
        "`collidoscope gvm train --logs RUNS.csv` trains on the log.\n"
        "Exit codes: 0 every configuration ran, 1 a run or the output failed, 2 bad arguments.",
        calibrate_flags());
    return kExitOk;
  }
  if (!parsed->positional().empty())
    return usage_error(cmd, "unexpected argument '" + parsed->positional()[0] + "'");
  if (!parsed->has("out")) return usage_error(cmd, "--out RUNS.csv is required");
  const bool quick = parsed->has("quick");
  // The GPU sweep's defaults keep it within about six minutes on an H100 (each run is a
  // fresh process with a CUDA context: about 0.8 s a run there).
  const bool cuda_defaults = parsed->get("backend", "auto") == "cuda";
  const int64_t configs = parsed->get_int("configs", quick ? 6 : cuda_defaults ? 200 : 300, &error);
  const int64_t seed = parsed->get_int("seed", 1, &error);
  const int64_t threads = parsed->get_int("threads", 0, &error);
  const int64_t repeats = parsed->get_int("repeats", cuda_defaults ? 2 : 3, &error);
  const int64_t budget_s = parsed->get_int("budget", cuda_defaults && !quick ? 330 : 0, &error);
  if (!error.empty()) return usage_error(cmd, error);
  if (budget_s < 0) return usage_error(cmd, "--budget must be >= 0");
  if (configs < 1 || configs > 100000) return usage_error(cmd, "--configs must be in 1..100000");
  if (threads < 0 || threads > 4096) return usage_error(cmd, "--threads must be in 0..4096");
  if (repeats < 1 || repeats > 100) return usage_error(cmd, "--repeats must be in 1..100");
  RadiusRange radius;
  {
    const std::string text = parsed->get("radius", "1");
    const auto colon = text.find(':');
    char* end = nullptr;
    const std::string a = text.substr(0, colon);
    const double lo = std::strtod(a.c_str(), &end);
    bool ok = !a.empty() && end && *end == 0;
    double hi = lo;
    if (colon != std::string::npos) {
      const std::string b = text.substr(colon + 1);
      hi = std::strtod(b.c_str(), &end);
      ok = ok && !b.empty() && end && *end == 0;
    }
    if (!ok || !(lo >= 0.01) || !(hi >= lo) || !(hi <= 50))
      return usage_error(cmd, "--radius must be P or LO:HI percent, 0.01 <= LO <= HI <= 50, got '" +
                                  text + "'");
    radius.lo = lo / 100, radius.hi = hi / 100;
  }
  const std::string want = parsed->get("backend", "auto");
  if (want != "cpu" && want != "cuda" && want != "auto")
    return usage_error(cmd, "unknown --backend '" + want + "' (cpu, cuda, auto)");
  const std::string out_path = parsed->get("out");
  std::string why;
  sim::Backend backend = sim::Backend::kCpu;
  std::string device = cpu_model_name();
  if (want != "cpu") {
    ProbeResult probe;
    const bool ran = run_in_child(
        [] {
          ProbeResult r;
          std::string w;
          r.ok = sim::cuda_available(&w) ? 1 : 0;
          copy_text(r.error, w);
          if (r.ok) copy_text(r.device, sim::cuda_device_name());
          return r;
        },
        &probe, nullptr, &why);
    if (ran && probe.ok) {
      backend = sim::Backend::kCuda;
      device = probe.device;
    } else {
      const std::string reason = ran ? probe.error : why;
      if (want == "cuda") {
        std::fprintf(stderr, "collidoscope %s: --backend cuda, but no usable GPU (%s)\n", cmd,
                     reason.c_str());
        return kExitFailure;
      }
      std::fprintf(stderr, "collidoscope %s: note: no usable GPU (%s): calibrating the CPU\n", cmd,
                   reason.c_str());
    }
  }

  // Fail before an hour of runs, not after.
  if (auto s = g::write_run_log(out_path, {}); !s) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, s.message().c_str());
    return kExitFailure;
  }
  const auto t_start = Clock::now();
  SurveyResult survey;
  if (!run_in_child([quick, radius] { return survey_walls(quick, radius); }, &survey, nullptr,
                    &why) ||
      !survey.ok) {
    std::fprintf(stderr, "collidoscope %s: wall survey failed: %s\n", cmd,
                 survey.error[0] ? survey.error : why.c_str());
    return kExitFailure;
  }
  const std::vector<Plan> plans =
      draw_plans(static_cast<size_t>(configs), static_cast<uint64_t>(seed), survey, radius,
                 backend, quick);
  std::fprintf(stderr, "calibrate: %lld configurations on %s (%s), seed %lld -> %s\n",
               static_cast<long long>(configs), sim::to_string(backend), device.c_str(),
               static_cast<long long>(seed), out_path.c_str());

  // Repeats are whole passes over the sweep, every run in a child of its own, so that
  // a burst of load elsewhere on the machine meets at most one repeat of a
  // configuration. Such load only ever adds time: a row keeps the smallest times (and
  // the GPU load of its fastest repeat) and the largest memory (a peak).
  std::vector<Best> best(plans.size());
  const std::string cpu_name = cpu_model_name();
  bool out_of_time = false;
  for (int64_t pass = 0; pass < repeats && !out_of_time; ++pass)
    for (size_t i = 0; i < plans.size(); ++i) {
      const Plan& p = plans[i];
      Best& b = best[i];
      if (b.failed) continue;
      if (budget_s > 0 &&
          std::chrono::duration<double>(Clock::now() - t_start).count() > budget_s) {
        out_of_time = true;
        std::fprintf(stderr, "calibrate: --budget %lld s reached in pass %lld\n",
                     static_cast<long long>(budget_s), static_cast<long long>(pass + 1));
        break;
      }
      const char* spec = kWalls[p.wall].spec;
      // Each configuration gets its own particle seed, still fixed by --seed.
      const uint64_t particle_seed = static_cast<uint64_t>(seed) * 1000003u + i;
      RunResult r;
      double peak_host = 0;
      std::string fail;
      bool ok = run_in_child(
          [&] {
            return run_config(spec, p, backend, static_cast<int>(threads), particle_seed);
          },
          &r, &peak_host, &fail);
      if (ok && !r.ok) ok = false, fail = r.error;
      std::fprintf(stderr, "[%lld/%lld %3zu/%zu] %s/%s %s r=%.3g, %lld particles x %lld frames: ",
                   static_cast<long long>(pass + 1), static_cast<long long>(repeats), i + 1,
                   plans.size(), sim::to_string(p.method), sim::to_string(p.traversal), spec,
                   p.r_max, static_cast<long long>(p.particles), static_cast<long long>(p.frames));
      if (!ok) {
        b.failed = true;
        std::fprintf(stderr, "FAILED: %s\n", fail.c_str());
        continue;
      }
      std::fprintf(stderr, "%lld triangles, %.3f ms/frame, total %.3f s, host %s",
                   static_cast<long long>(r.triangles), 1e3 * r.frame_s, r.total_s,
                   human_bytes(peak_host).c_str());
      if (backend == sim::Backend::kCuda)
        std::fprintf(stderr, ", device %s", human_bytes(static_cast<double>(r.device_bytes)).c_str());
      std::fprintf(stderr, "\n");
      if (!b.measured || r.total_s < b.fastest.total_s) b.fastest = r;
      b.frame_s = b.measured ? std::min(b.frame_s, r.frame_s) : r.frame_s;
      b.peak_host = std::max(b.peak_host, peak_host);
      b.device_bytes = std::max(b.device_bytes, r.device_bytes);
      b.measured = true;
      // Rewritten every time, so an interrupted sweep keeps what it measured.
      std::vector<g::RunRecord> rows;
      for (size_t j = 0; j < plans.size(); ++j)
        if (best[j].measured && !best[j].failed)
          rows.push_back(
              make_row(plans[j], survey.walls[plans[j].wall], best[j], backend, device, cpu_name));
      if (auto s = g::write_run_log(out_path, rows); !s) {
        std::fprintf(stderr, "collidoscope %s: %s\n", cmd, s.message().c_str());
        return kExitFailure;
      }
    }
  size_t failed = 0, measured = 0;
  for (const Best& b : best) failed += b.failed, measured += b.measured && !b.failed;
  // Out of time: the log holds what was measured; an empty one is a failure.
  if (measured == 0) {
    std::fprintf(stderr, "collidoscope %s: no configuration was measured\n", cmd);
    return kExitFailure;
  }
  const double took = std::chrono::duration<double>(Clock::now() - t_start).count();
  std::printf("%zu configurations (%zu failed) x %lld repeats in %.1f s: %s\n", measured, failed,
              static_cast<long long>(repeats), took, out_path.c_str());
  if (failed) {
    std::fprintf(stderr, "collidoscope %s: %zu of %zu configurations failed\n", cmd, failed,
                 plans.size());
    return kExitFailure;
  }
  return kExitOk;
}

}  // namespace collido::app
