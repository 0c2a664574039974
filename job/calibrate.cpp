// The calibration sweep (job/calibrate.h): the parent draws the sweep and writes the
// log; each configuration, the wall survey and the GPU probe run in a child
// (`collidoscope calibrate-exec`), which answers with one JSON line.
//
// Peak host memory is the one figure the parent cannot take from wait4() alone: Linux
// gives a child the larger of its own peak and that of the memory it was spawned from
// (the parent's, until exec), so a service worker holding a gigabyte would see every
// row at a gigabyte or more. The child therefore reads its own peak (VmHWM, the peak of
// its memory after exec, less the shared libraries it started with: calibrate_exec)
// and sends it; wait4()'s figure stands in only where the child could not read it.
#include "job/calibrate.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <new>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "common/atomic_file.h"
#include "common/median.h"
#include "common/process_memory.h"
#include "common/stopwatch.h"
#include "gvm/rng.h"
#include "gvm/run_log.h"
#include "job/subprocess.h"
#include "sim/detect.h"
#include "sim/detect_cuda.h"
#include "sim/divide.h"
#include "sim/parallel.h"
#include "sim/particles.h"
#include "sim/shapes.h"

namespace collido::job {

namespace {

namespace g = collido::gvm;
using json = nlohmann::json;

constexpr int kResultFd = 3;

// The walls of the sweep: the paper's two vessels, an open funnel and icospheres from
// 320 to 81,920 triangles. `quick` marks the small set used by a quick sweep.
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
// with a range, drawn per configuration log-uniform in [lo, hi], so that the geometry
// ratios the predictor sees (area / r^2, box volume / r^3, ...) span a range for every
// wall instead of one point per wall. The log records r_max, the wall's area and its
// box volume grown by r_max.
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
  int64_t triangles = 0;          // as built; 0 = not surveyed (quick)
  double longest = 0;             // longest bounding-box side, world units
  double extent[3] = {};          // bounding-box sides, world units
  double area = 0;                // triangle area, world units^2
  int64_t bisect_ref[2] = {};     // after gravity, circumcircle division at radius_ref
  int64_t m4[kRadiusSteps] = {};  // after midpoint4 division at radius_step(i)
};
struct Survey {
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

// What a configuration's child measured.
struct RunResult {
  int64_t triangles = 0, triangles_original = 0, threads = 0;
  double total_s = 0, gpu_busy_s = 0;
  double frame_s = 0;  // steady time per frame: median of the frames after the first
  uint64_t device_bytes = 0;
};

// ---------------------------------------------------------------------------
// The child's side: what one calibrate-exec request runs.

// The run log's wall_box_volume: grown by the radius, so a flat wall has a volume too
// (the engine's grid pads its box the same way).
double wall_box_volume(const double (&e)[3], double r) {
  return (e[0] + 2 * r) * (e[1] + 2 * r) * (e[2] + 2 * r);
}

// Triangle counts of every wall at its particle scales, for keeping divisions from
// growing absurdly large. midpoint4's count needs no division
// (sim::midpoint4_piece_count); bisection (gravity, circumcircle) stops each piece as
// soon as it fits and makes far fewer (wall1 at 1 %: 0.36 and 0.16 million against
// 2.2), so its leaves are counted (sim::division_piece_count, no pieces made), once,
// at radius_ref.
Expected<Survey> survey_walls(bool quick, const RadiusRange& rr) {
  Survey s;
  for (size_t w = 0; w < kWallCount; ++w) {
    if (quick && !kWalls[w].quick) continue;
    auto mesh = sim::make_shape(kWalls[w].spec);
    if (!mesh) return Status(mesh.status().code(), std::string(kWalls[w].spec) + ": " +
                                                       mesh.status().message());
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
                       : static_cast<int64_t>(sim::division_piece_count(
                             *mesh,
                             d == 0 ? sim::DivisionMethod::kGravity
                                    : sim::DivisionMethod::kCircumcircle,
                             radius_ref(rr) * ws.longest));
  }
  return s;
}

// One configuration, start to end, in the child. A frame is one detection frame: take
// the particles (converted and, on the GPU, uploaded) and detect with the contact list
// collected. Every frame sees the same particles; the simulation steps of
// `collidoscope run` (sim/dynamics.h) are not what this sweep measures.
Expected<RunResult> run_config(const std::string& wall_spec, const Plan& p,
                               sim::Backend backend, int threads, uint64_t seed) {
  RunResult r;
  const auto t0 = SteadyClock::now();
  sim::ThreadPool pool(threads);
  r.threads = pool.size();
  auto wall = sim::make_shape(wall_spec);
  if (!wall) return wall.status();
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
  if (!det) return det.status();
  sim::DetectResult res;
  Status failed;
  auto frame = [&](double* took) {
    const auto tf = SteadyClock::now();
    sim::Status s = (*det)->set_particles(particles);
    if (s) s = (*det)->detect(&res);
    *took = seconds_since(tf);
    if (!s) failed = s;
    return bool(s);
  };
  std::vector<double> timed;  // the frames that measure the steady time per frame
  for (int64_t f = 0; f < p.frames; ++f) {
    double took = 0;
    if (!frame(&took)) return failed;
    if (f > 0) timed.push_back(took);
    // detect() syncs the device before it stops its clock, so frame_ms is GPU-busy time.
    r.gpu_busy_s += res.times.frame_ms * 1e-3;
  }
  r.total_s = seconds_since(t0);
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
    if (!frame(&took)) return failed;
    timed.push_back(took);
    timed_s += took;
  }
  r.frame_s = median_of(std::move(timed));
  r.triangles = static_cast<int64_t>((*det)->info().triangles_used);
  r.triangles_original = static_cast<int64_t>((*det)->info().triangles_original);
  r.device_bytes = (*det)->info().device_bytes;
  return r;
}

json survey_to_json(const Survey& s) {
  json walls = json::array();
  for (size_t w = 0; w < kWallCount; ++w) {
    const WallSurvey& ws = s.walls[w];
    if (ws.triangles == 0) continue;
    walls.push_back({{"wall", w},
                     {"triangles", ws.triangles},
                     {"longest", ws.longest},
                     {"extent", ws.extent},
                     {"area", ws.area},
                     {"bisect_ref", ws.bisect_ref},
                     {"m4", ws.m4}});
  }
  return walls;
}

// Throws nlohmann's exceptions on a malformed answer; the caller catches them.
Survey survey_from_json(const json& walls) {
  Survey s;
  for (const json& j : walls) {
    const size_t w = j.at("wall").get<size_t>();
    if (w >= kWallCount) throw std::out_of_range("wall index");
    WallSurvey& ws = s.walls[w];
    ws.triangles = j.at("triangles").get<int64_t>();
    ws.longest = j.at("longest").get<double>();
    ws.area = j.at("area").get<double>();
    for (int i = 0; i < 3; ++i) ws.extent[i] = j.at("extent").at(i).get<double>();
    for (int d = 0; d < 2; ++d) ws.bisect_ref[d] = j.at("bisect_ref").at(d).get<int64_t>();
    for (int i = 0; i < kRadiusSteps; ++i) ws.m4[i] = j.at("m4").at(i).get<int64_t>();
  }
  return s;
}

json failure(const Status& s) {
  return {{"ok", false}, {"status", to_string(s.code())}, {"error", s.message()}};
}

// The request's answer, without the peak memory that calibrate_exec adds.
json exec_request(const json& req) {
  const std::string task = req.at("task").get<std::string>();
  if (task == "probe") {
    std::string why;
    const bool ok = sim::cuda_available(&why);
    if (!ok) return failure(backend_error(why.empty() ? "no CUDA device" : why));
    return {{"ok", true}, {"device", sim::cuda_device_name()}};
  }
  if (task == "survey") {
    RadiusRange rr;
    rr.lo = req.at("radius_lo").get<double>();
    rr.hi = req.at("radius_hi").get<double>();
    if (!(rr.lo > 0) || !(rr.hi >= rr.lo) || !std::isfinite(rr.hi))
      return failure(invalid_argument("radius_lo and radius_hi must be 0 < lo <= hi"));
    auto s = survey_walls(req.at("quick").get<bool>(), rr);
    if (!s) return failure(s.status());
    return {{"ok", true}, {"walls", survey_to_json(*s)}};
  }
  if (task == "run") {
    Plan p;
    p.r_max = req.at("r_max").get<double>();
    p.particles = req.at("particles").get<int64_t>();
    p.frames = req.at("frames").get<int64_t>();
    sim::Backend backend = sim::Backend::kCpu;
    if (!sim::parse_method(req.at("method").get<std::string>(), &p.method) ||
        !sim::parse_traversal(req.at("traversal").get<std::string>(), &p.traversal) ||
        !sim::parse_backend(req.at("backend").get<std::string>(), &backend))
      return failure(invalid_argument("unknown method, traversal or backend"));
    if (!(p.r_max > 0) || p.particles < 1 || p.frames < 1)
      return failure(invalid_argument("r_max, particles and frames must be > 0"));
    auto r = run_config(req.at("wall").get<std::string>(), p, backend,
                        req.at("threads").get<int>(), req.at("seed").get<uint64_t>());
    if (!r) return failure(r.status());
    return {{"ok", true},
            {"triangles", r->triangles},
            {"triangles_original", r->triangles_original},
            {"threads", r->threads},
            {"total_s", r->total_s},
            {"gpu_busy_s", r->gpu_busy_s},
            {"frame_s", r->frame_s},
            {"device_bytes", r->device_bytes}};
  }
  return failure(invalid_argument("unknown task '" + task + "'"));
}

// ---------------------------------------------------------------------------
// The parent's side.

// Runs one request in `executable calibrate-exec` and returns its answer (ok true) and
// the child's peak resident bytes. A child that answers nothing (it crashed or was
// killed) is kBackend; a cancelled one kCancelled.
Expected<json> run_child(const std::string& executable, const json& request,
                         const std::atomic<bool>* cancel, double* peak_host_bytes) {
  auto child = Subprocess::start({executable, "calibrate-exec", request.dump(), "--result-fd",
                                  std::to_string(kResultFd)},
                                 kResultFd);
  if (!child) return child.status();
  json answer;
  auto on_line = [&](const std::string& line) {
    json j = json::parse(line, nullptr, false);
    if (j.is_object() && j.contains("ok")) answer = std::move(j);
  };
  // SIGKILL: a run's result is thrown away when cancelled, so nothing is worth waiting for.
  const ExitInfo e = (*child)->wait(on_line, cancel, SIGKILL);
  if (cancel && cancel->load()) return cancelled("calibration cancelled");
  if (!answer.is_object())
    return backend_error("the run ended without a result (" + describe(e) + ")");
  const json ok = answer.value("ok", json(false));
  if (!ok.is_boolean() || !ok.get<bool>()) {
    const std::string why = answer.value("error", json("")).is_string()
                                ? answer.value("error", std::string())
                                : std::string();
    return backend_error(why.empty() ? "the run failed (" + describe(e) + ")" : why);
  }
  if (peak_host_bytes) {
    const json own = answer.value("peak_host_bytes", json(0.0));
    const double own_bytes = own.is_number() ? own.get<double>() : 0.0;
    *peak_host_bytes = own_bytes > 0 ? own_bytes : static_cast<double>(e.peak_host_bytes);
  }
  return answer;
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
std::vector<Plan> draw_plans(size_t count, uint64_t seed, const Survey& survey,
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
    const size_t before = plans.size();
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
        if (ws.triangles == 0) continue;  // not surveyed (quick)
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
    // No pipeline fits any wall (bin always does, so this guards a broken survey):
    // a sweep that can draw nothing must not spin.
    if (plans.size() == before) break;
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
  c.wall_box_volume = wall_box_volume(wall.extent, p.r_max);
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

RunResult run_result_from_json(const json& j) {
  RunResult r;
  r.triangles = j.at("triangles").get<int64_t>();
  r.triangles_original = j.at("triangles_original").get<int64_t>();
  r.threads = j.at("threads").get<int64_t>();
  r.total_s = j.at("total_s").get<double>();
  r.gpu_busy_s = j.at("gpu_busy_s").get<double>();
  r.frame_s = j.at("frame_s").get<double>();
  r.device_bytes = j.at("device_bytes").get<uint64_t>();
  return r;
}

std::string plan_text(const Plan& p) {
  char text[256];
  std::snprintf(text, sizeof text, "%s/%s %s r=%.3g, %lld particles x %lld frames",
                sim::to_string(p.method), sim::to_string(p.traversal), kWalls[p.wall].spec,
                p.r_max, static_cast<long long>(p.particles), static_cast<long long>(p.frames));
  return text;
}

// The sweep itself; calibrate() adds the boundary (no exception leaves it).
Expected<CalibrateSummary> run_sweep(const CalibrateSpec& spec, const CalibrateHooks& hooks) {
  auto note = [&](const std::string& line) {
    if (hooks.note) hooks.note(line);
  };
  auto cancel_requested = [&] { return hooks.cancel && hooks.cancel->load(); };
  const std::string& exe = spec.executable;
  RadiusRange radius;
  radius.lo = spec.radius_lo_pct / 100, radius.hi = spec.radius_hi_pct / 100;

  CalibrateSummary summary;
  sim::Backend backend = sim::Backend::kCpu;
  const std::string cpu_name = cpu_model_name();
  std::string device = cpu_name;
  if (spec.backend != "cpu") {
    // In a child: the caller must not hold a CUDA context (a service's memory, and a
    // context the sweep's own runs would not share anyway).
    auto probe = run_child(exe, {{"task", "probe"}}, hooks.cancel, nullptr);
    if (!probe && probe.status().code() == ErrorCode::kCancelled) return probe.status();
    if (probe) {
      backend = sim::Backend::kCuda;
      device = probe->value("device", std::string("cuda"));
    } else if (spec.backend == "cuda") {
      return backend_error("backend cuda asked for, but no usable GPU (" +
                           probe.status().message() + ")");
    } else {
      note("no usable GPU (" + probe.status().message() + "): calibrating the CPU");
    }
  }
  summary.backend = sim::to_string(backend);
  summary.device = device;
  summary.repeats = spec.repeats;

  // Fail before an hour of runs, not after.
  auto write_log = [&](const std::vector<g::RunRecord>& rows) {
    return write_file_atomic(spec.out_path, g::format_run_log(rows));
  };
  if (Status s = write_log({}); !s) return s;
  if (cancel_requested()) return cancelled("calibration cancelled");
  const auto t_start = SteadyClock::now();
  auto surveyed = run_child(exe,
                            {{"task", "survey"},
                             {"quick", spec.quick},
                             {"radius_lo", radius.lo},
                             {"radius_hi", radius.hi}},
                            hooks.cancel, nullptr);
  if (!surveyed) {
    if (surveyed.status().code() == ErrorCode::kCancelled) return surveyed.status();
    return backend_error("wall survey failed: " + surveyed.status().message());
  }
  Survey survey;
  try {
    survey = survey_from_json(surveyed->at("walls"));
  } catch (const std::exception& e) {
    return backend_error(std::string("wall survey failed: a malformed answer (") + e.what() + ")");
  }
  const std::vector<Plan> plans = draw_plans(static_cast<size_t>(spec.configs), spec.seed, survey,
                                             radius, backend, spec.quick);
  if (plans.empty()) return backend_error("the wall survey left no configuration to run");
  summary.configs = plans.size();
  note(std::to_string(plans.size()) + " configurations on " + summary.backend + " (" + device +
       "), seed " + std::to_string(spec.seed) + " -> " + spec.out_path);

  // Repeats are whole passes over the sweep, every run in a child of its own, so that
  // a burst of load elsewhere on the machine meets at most one repeat of a
  // configuration. Such load only ever adds time: a row keeps the smallest times (and
  // the GPU load of its fastest repeat) and the largest memory (a peak).
  std::vector<Best> best(plans.size());
  size_t rows_written = 0;
  for (int pass = 0; pass < spec.repeats && !summary.out_of_budget; ++pass)
    for (size_t i = 0; i < plans.size(); ++i) {
      const Plan& p = plans[i];
      Best& b = best[i];
      if (b.failed) continue;
      if (cancel_requested()) return cancelled("calibration cancelled");
      if (spec.budget_s > 0 && seconds_since(t_start) > spec.budget_s) {
        summary.out_of_budget = true;
        char line[96];
        std::snprintf(line, sizeof line, "budget of %g s reached in pass %d", spec.budget_s,
                      pass + 1);
        note(line);
        break;
      }
      CalibrateProgress pr;
      pr.pass = pass + 1, pr.passes = spec.repeats;
      pr.index = i + 1, pr.count = plans.size();
      pr.backend = summary.backend;
      pr.running = plan_text(p);
      pr.rows = rows_written;
      if (hooks.progress) hooks.progress(pr);
      // Each configuration gets its own particle seed, still fixed by the sweep's seed.
      const uint64_t particle_seed = spec.seed * 1000003u + i;
      double peak_host = 0;
      auto answer = run_child(exe,
                              {{"task", "run"},
                               {"wall", kWalls[p.wall].spec},
                               {"r_max", p.r_max},
                               {"method", sim::to_string(p.method)},
                               {"traversal", sim::to_string(p.traversal)},
                               {"particles", p.particles},
                               {"frames", p.frames},
                               {"backend", sim::to_string(backend)},
                               {"threads", spec.threads},
                               {"seed", particle_seed}},
                              hooks.cancel, &peak_host);
      if (!answer && answer.status().code() == ErrorCode::kCancelled) return answer.status();
      RunResult r;
      Status run_status = answer ? Status::ok() : answer.status();
      if (answer) {
        try {
          r = run_result_from_json(*answer);
        } catch (const std::exception& e) {
          run_status = backend_error(std::string("a malformed result (") + e.what() + ")");
        }
      }
      pr.finished = true;
      if (!run_status) {
        b.failed = true;
        pr.error = run_status.message();
        if (hooks.progress) hooks.progress(pr);
        continue;
      }
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
      if (Status s = write_log(rows); !s) return s;
      rows_written = rows.size();
      pr.triangles = r.triangles;
      pr.frame_s = r.frame_s;
      pr.total_s = r.total_s;
      pr.peak_host_bytes = peak_host;
      pr.device_bytes = static_cast<double>(r.device_bytes);
      pr.rows = rows_written;
      if (hooks.progress) hooks.progress(pr);
    }
  for (const Best& b : best) summary.failed += b.failed, summary.measured += b.measured && !b.failed;
  summary.took_s = seconds_since(t_start);
  // Out of time: the log holds what was measured; an empty one is a failure.
  if (summary.measured == 0)
    return summary.out_of_budget
               ? resource_exhausted("the budget ran out before a configuration was measured")
               : backend_error("no configuration was measured (" +
                               std::to_string(summary.failed) + " failed)");
  return summary;
}

}  // namespace

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

Expected<std::string> probe_gpu(const std::string& executable, const std::atomic<bool>* cancel) {
  auto probe = run_child(executable, {{"task", "probe"}}, cancel, nullptr);
  if (!probe) return probe.status();
  return probe->value("device", std::string("cuda"));
}

CalibrateSpec calibrate_defaults(const std::string& backend, bool quick) {
  CalibrateSpec s;
  s.backend = backend;
  s.quick = quick;
  // The GPU sweep's defaults keep it within about six minutes on an H100 (each run is a
  // fresh process with a CUDA context: about 0.8 s a run there). "auto" keeps the CPU's:
  // it is what a machine without a GPU gets.
  const bool cuda = backend == "cuda";
  s.configs = quick ? 6 : cuda ? 200 : 300;
  s.repeats = cuda ? 2 : 3;
  s.budget_s = cuda && !quick ? 330 : 0;
  return s;
}

Status validate(const CalibrateSpec& s) {
  if (s.backend != "cpu" && s.backend != "cuda" && s.backend != "auto")
    return invalid_argument("unknown backend '" + s.backend + "' (cpu, cuda, auto)");
  if (s.configs < 1 || s.configs > 100000) return invalid_argument("configs must be in 1..100000");
  if (s.threads < 0 || s.threads > 4096) return invalid_argument("threads must be in 0..4096");
  if (s.repeats < 1 || s.repeats > 100) return invalid_argument("repeats must be in 1..100");
  if (!(s.budget_s >= 0) || !std::isfinite(s.budget_s))
    return invalid_argument("budget must be >= 0 seconds");
  if (!(s.radius_lo_pct >= 0.01) || !(s.radius_hi_pct >= s.radius_lo_pct) ||
      !(s.radius_hi_pct <= 50))
    return invalid_argument("radius must be in 0.01..50 % of the wall's longest side, lo <= hi");
  if (s.out_path.empty()) return invalid_argument("no output path for the run log");
  if (s.executable.empty()) return invalid_argument("no collidoscope executable to run configurations in");
  return Status::ok();
}

Expected<CalibrateSummary> calibrate(const CalibrateSpec& spec, const CalibrateHooks& hooks) {
  if (Status s = validate(spec); !s) return s;
  try {
    return run_sweep(spec, hooks);
  } catch (const std::bad_alloc&) {
    return resource_exhausted("out of memory in the calibration sweep");
  } catch (const std::exception& e) {
    return backend_error(std::string("calibration failed: ") + e.what());
  }
}

Status calibrate_exec(const std::string& request_json, std::string* result_line) {
  const ProcessMemory start = own_process_memory();
  json answer;
  try {
    const json req = json::parse(request_json);
    answer = req.is_object()
                 ? exec_request(req)
                 : failure(parse_error("calibrate-exec request: not a JSON object"));
  } catch (const json::exception& e) {
    answer = failure(parse_error(std::string("calibrate-exec request: ") + e.what()));
  } catch (const std::bad_alloc&) {  // a configuration too large for this machine
    answer = failure(resource_exhausted("out of memory"));
  } catch (const std::exception& e) {
    answer = failure(backend_error(std::string("exception: ") + e.what()));
  }
  // The row's peak is the peak resident set less the file-backed pages this process
  // had at its start: the libraries a fresh collidoscope maps (about 60 of its 75 MiB
  // here, OSMesa's LLVM the most) are shared by every process and dropped under
  // pressure, and the runs of the committed logs, forked from a parent that had them
  // mapped already, did not count them either. What the run itself touches (its code,
  // on the GPU the driver it loads) counts, as it did for them.
  const ProcessMemory end = own_process_memory();
  answer["vm_hwm_bytes"] = end.peak_resident_bytes;
  answer["start_rss_file_bytes"] = start.file_backed_bytes;
  answer["peak_host_bytes"] = end.peak_resident_bytes > start.file_backed_bytes
                                   ? end.peak_resident_bytes - start.file_backed_bytes
                                   : end.peak_resident_bytes;
  *result_line = answer.dump() + "\n";
  if (answer.value("ok", false)) return Status::ok();
  ErrorCode code = ErrorCode::kBackend;
  const std::string name = answer.value("status", std::string());
  for (ErrorCode c : {ErrorCode::kInvalidArgument, ErrorCode::kNotFound, ErrorCode::kIo,
                      ErrorCode::kParse, ErrorCode::kResourceExhausted, ErrorCode::kCancelled})
    if (name == to_string(c)) code = c;
  return Status(code, answer.value("error", std::string()));
}

}  // namespace collido::job
