// The job sweep (job/calibrate_jobs.h): the parent draws every job up front from the
// seed, sizes it from its assessment and time-step plan, and runs it as a job-exec
// child; the child's result.json gives the cost.
#include "job/calibrate_jobs.h"

#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "common/atomic_file.h"
#include "common/stopwatch.h"
#include "gvm/rng.h"
#include "job/assess.h"
#include "job/child.h"
#include "job/cost_model.h"
#include "job/job_log.h"

namespace collido::job {

namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

// Where a sweep keeps the job it runs, in its work folder: the spec, and the
// job's run folder (calibrate_jobs removes both when the sweep ends).
std::string job_spec_path(const std::string& work_dir) {
  return work_dir + "/job.json";
}
std::string job_run_dir(const std::string& work_dir) {
  return work_dir + "/run";
}

// Parametric walls: the paper's two vessels, an open funnel, and closed shapes of
// several sizes and triangle counts. Left out on purpose (the unseen-scene check in
// docs/gvm.md uses them): the Wuson and plate-with-holes meshes, and a wide short
// cylinder.
const std::vector<std::string> kShapes = {
    "wall1",
    "wall2",
    "funnel:r1=5,r2=30,h=40,segments=64",
    "box:x=20,y=20,z=20",
    "cylinder:r=10,h=30,segments=24",
    "cone:r1=20,r2=5,h=30,segments=32",
    "sphere:r=10,subdivisions=3",
    "box:x=2,y=1,z=1",
};
const std::vector<std::string> kMeshes = {
    "teapot_trimesh.stl",
    "3dsmax_export_assimp.stl",
    "sphere_with_hole_assimp.stl",
};

bool is_file(const std::string& p) {
  struct stat st;
  return ::stat(p.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

double log_uniform(gvm::Rng& rng, double lo, double hi) {
  return std::pow(10.0, rng.uniform(std::log10(lo), std::log10(hi)));
}

// What one job of the sweep asks for, before it is sized.
struct Draw {
  std::string wall;       // a shape spec or a file name in mesh_dir
  bool wall_file = false;
  double radius_frac = 0.01;  // r_max as a share of the wall's longest side
  bool radius_range = false;  // r in [r_max / 2, r_max]
  int64_t particles = 0;
  std::string placement = "pour";
  bool contacts = false;
  double friction = 0, restitution = 0.5;
  bool zero_gravity = false;
  std::string method = "bin";
  double target_steps = 1000;
  int64_t frames = 10;
  int width = 0, height = 0;
  std::string formats = "none";
  std::vector<double> velocity{0, 0, 0};  // m/s, a share of the wall's size per second
  double settle_falls = 0;  // > 0: the duration is this many falls across the wall's height
  double work_bound = 1;    // this job's particle-step bound, in the sweep's usual bounds
};

// Sweep ranges per backend. Particle-steps bound a job's work: on the CPU about 0.3
// us each on one thread (1,000 particles, 21,120 steps: 5.8 s with contacts and
// friction), so 5e6 keeps a job near 2 s at most on a quiet core (divided walls and rendering add to it).
struct Ranges {
  double particles_lo, particles_hi, steps_lo, steps_hi, frames_hi, particle_steps;
  double divided_share, render_share;
};
Ranges ranges_for(const std::string& backend, bool quick) {
  if (quick) return {20, 300, 50, 300, 3, 3e4, 0.25, 0.5};
  if (backend == "cuda") return {500, 3e5, 300, 8000, 60, 1.5e9, 0.2, 0};
  return {40, 2e4, 200, 2.5e4, 60, 5e6, 0.2, 0.45};
}

Draw draw_job(gvm::Rng& rng, const Ranges& rg, const std::vector<std::string>& walls,
              size_t shapes, bool render, bool quick) {
  Draw d;
  const size_t w = rng.below(walls.size());
  d.wall = walls[w];
  d.wall_file = w >= shapes;
  d.radius_frac = quick ? 0.05 : log_uniform(rng, 0.006, 0.03);
  d.radius_range = rng.uniform01() < 0.4;
  d.particles = std::llround(log_uniform(rng, rg.particles_lo, rg.particles_hi));
  const double p = rng.uniform01();
  d.placement = p < 0.5 ? "pour" : p < 0.85 ? "fill" : "jet";
  d.contacts = rng.uniform01() < 0.5;
  d.friction = rng.uniform01() < 0.4 ? 0.0 : rng.uniform(0.1, 0.6);
  d.restitution = rng.uniform(0.3, 0.9);
  d.zero_gravity = d.placement == "fill" && rng.uniform01() < 0.2;
  if (rng.uniform01() < rg.divided_share) {
    const char* divided[] = {"gravity", "circumcircle", "midpoint4"};
    d.method = divided[rng.below(3)];
  }
  d.target_steps = log_uniform(rng, rg.steps_lo, rg.steps_hi);
  d.frames = std::llround(log_uniform(rng, 1, rg.frames_hi));
  if (d.placement == "jet" || (d.placement == "fill" && rng.uniform01() < 0.5))
    for (double& v : d.velocity) v = rng.uniform(-0.3, 0.3);
  if (d.placement == "jet" && d.velocity[0] == 0) d.velocity[0] = 0.2;
  if (render && rng.uniform01() < rg.render_share) {
    // The web UI's sizes (web/static/js/pages/newjob.js) but its largest, 1920 x 1080.
    const int sizes[][2] = {{160, 96}, {320, 180}, {640, 360}, {1280, 720}};
    const auto& s = sizes[quick ? 0 : rng.below(4)];
    d.width = s[0], d.height = s[1];
    d.formats.clear();
    for (const char* f : {"mp4", "webm", "gif"})
      if (rng.uniform01() < 0.45) d.formats += (d.formats.empty() ? "" : "+") + std::string(f);
    if (d.formats.empty()) d.formats = "none";
  }
  return d;
}

// The scene document of a draw, its lengths scaled to the wall's longest side L.
json scene_of(const Draw& d, double L, const double (&lo)[3], const double (&hi)[3],
              double duration, double fps, int64_t particles, uint64_t seed) {
  const double r = d.radius_frac * L;
  json s;
  s["wall"] = d.wall;
  s["particles"] = {{"count", particles}};
  if (d.radius_range)
    s["particles"]["radius"] = {0.5 * r, r};
  else
    s["particles"]["radius"] = r;
  json pl = {{"kind", d.placement}};
  const std::vector<double> v = {d.velocity[0] * L, d.velocity[1] * L, d.velocity[2] * L};
  if (d.placement == "fill") {
    if (v[0] != 0 || v[1] != 0 || v[2] != 0) pl["velocity"] = v;
  } else if (d.placement == "jet") {
    pl["velocity"] = v;
    // A jet from the upper side of the box, across it.
    pl["inlet"] = {lo[0] + 0.2 * (hi[0] - lo[0]), 0.5 * (lo[1] + hi[1]), lo[2] + 0.8 * (hi[2] - lo[2])};
    pl["inlet_radius"] = std::max(0.1 * L, 3 * r);
  }
  s["placement"] = pl;
  s["material"] = {{"restitution", d.restitution}, {"friction", d.friction}};
  if (d.zero_gravity) s["gravity"] = {0, 0, 0};
  s["particle_contacts"] = d.contacts;
  s["method"] = d.method;
  s["duration"] = duration;
  s["fps"] = fps;
  s["seed"] = seed;
  return s;
}

// One job of the sweep, sized: its spec and its inputs (as the log row holds them).
struct Planned {
  JobSpec spec;
  JobInputs inputs;
  std::string text;  // "bin pour wall1 r=0.62, 1200 particles, 40 frames, 3120 steps"
};

JobSpec spec_of(const json& scene, const Draw& d, const JobSweepSpec& sw) {
  JobSpec spec;
  spec.scene_json = scene.dump();
  spec.scene_dir = d.wall_file ? sw.mesh_dir : "";
  spec.dir_policy = DirPolicy::kReplace;
  spec.threads = sw.threads;
  spec.backend = sw.backend;
  spec.render = d.width > 0;
  if (spec.render) {
    RenderSettings& rs = spec.render_settings;
    rs.width = d.width, rs.height = d.height;
    rs.mp4 = d.formats.find("mp4") != std::string::npos;
    rs.webm = d.formats.find("webm") != std::string::npos;
    rs.gif = d.formats.find("gif") != std::string::npos;
  }
  return spec;
}

// A settling draw's work bound, in the usual bound: piles of hundreds of particles over
// 10^5 steps (on the CPU, 2026-11-24: median 1.8 s, 90th percentile 48 s, longest 304 s).
constexpr double kSettledWork = 10;

// Sizes a draw: the step from the plan sets the duration for its target steps, the
// particle-step bound trims the steps (a settling draw keeps its steps and trims the
// particles, within kSettledWork times the bound), a fill keeps to what its box can hold. An
// error when the job would be refused (budget, placement) or the wall cannot load.
Expected<Planned> size_job(const Draw& d, const Ranges& rg, const JobSweepSpec& sw,
                           const std::string& device, uint64_t seed) {
  // First the wall's size, through an assessment of a one-second job.
  JobSpec probe;
  json s0 = {{"wall", d.wall}, {"particles", {{"count", 1}, {"radius", 1e-3}}}, {"duration", 1}};
  probe.scene_json = s0.dump();
  probe.scene_dir = d.wall_file ? sw.mesh_dir : "";
  auto resolved = resolve_scene(probe);
  if (!resolved) return resolved.status();
  auto wall = load_scene_wall(&resolved->scene);
  if (!wall) return wall.status();
  const sim::Bounds3d b = sim::mesh_bounds(*wall);
  const double lo[3] = {b.lo.x, b.lo.y, b.lo.z}, hi[3] = {b.hi.x, b.hi.y, b.hi.z};
  const double L = std::max({b.extent().x, b.extent().y, b.extent().z});
  const double r = d.radius_frac * L;
  int64_t particles = d.particles;
  if (d.placement == "fill") {
    // A jittered lattice of pitch 2.1 r fills at most the box; closed vessels hold
    // less (a sphere about half its box), so a third keeps most fills placeable.
    const double cap = (b.extent().x * b.extent().y * b.extent().z) / std::pow(2.1 * r, 3) / 3;
    particles = std::min<int64_t>(particles, std::max<int64_t>(1, int64_t(cap)));
  }
  auto build = [&](double duration, double fps) -> Expected<Planned> {
    Planned p;
    p.spec = spec_of(scene_of(d, L, lo, hi, duration, fps, particles, seed), d, sw);
    auto a = assess_job(p.spec);
    if (!a) return a.status();
    p.inputs = job_inputs(*a, sw.backend, device, sw.threads);
    return p;
  };
  // The step does not depend on the duration: plan once at one second.
  auto first = build(1.0, double(d.frames));
  if (!first) return first.status();
  const double step = first->inputs.step_s;
  // Particles active on average over a run of `steps`, from the release plan.
  auto active_share = [&](double steps) {
    return mean_released_share(first->inputs.release_s, steps * step);
  };
  double steps = d.target_steps;
  const double bound = rg.particle_steps * d.work_bound;
  if (d.settle_falls > 0) {
    // Long enough to land: the steps are set, the particles shrink to the work bound.
    const double fall = std::sqrt(2 * b.extent().z / first->inputs.gravity);
    steps = d.settle_falls * fall / step;
    if (steps > 4e5) return resource_exhausted("settling takes more steps than the sweep's");
    const double most = kSettledWork * bound / (std::max(active_share(steps), 0.02) * steps);
    if (most < 20) return resource_exhausted("too few particles would settle in the sweep's work");
    if (double(particles) > most) {
      particles = int64_t(most);
      first = build(1.0, double(d.frames));  // the release plan follows the count
      if (!first) return first.status();
    }
  } else {
    // The particle-step bound trims the steps.
    for (int k = 0; k < 3; ++k) {
      const double work = double(particles) * std::max(active_share(steps), 0.02) * steps;
      if (work <= bound) break;
      steps = std::max(rg.steps_lo * 0.5, steps * bound / work);
    }
  }
  const double duration = steps * step;
  const int64_t frames = std::max<int64_t>(1, std::min<int64_t>(d.frames, int64_t(steps)));
  auto p = build(duration, double(frames) / duration);
  if (!p) return p.status();
  // Preparation bounded too: a bin wall of many (triangle, cell) pairs or a division
  // into many pieces takes seconds before the first step.
  if (p->inputs.wall_cells > 3e7 || p->inputs.pieces > 3e5)
    return resource_exhausted("the wall's preparation is beyond the sweep's sizes");
  char text[256];
  std::snprintf(text, sizeof text, "%s %s %s r=%.3g, %llu particles, %llu frames, %llu steps%s%s",
                p->inputs.method.c_str(), p->inputs.placement.c_str(), d.wall.c_str(), r,
                (unsigned long long)p->inputs.particles, (unsigned long long)p->inputs.frames,
                (unsigned long long)p->inputs.steps, p->inputs.renders() ? ", render " : "",
                p->inputs.renders() ? p->inputs.formats.c_str() : "");
  p->text = text;
  return p;
}

double load_average() {
  std::ifstream in("/proc/loadavg");
  double l = 0;
  in >> l;
  return in ? l : 0.0;
}

// Runs one planned job as a job-exec child and reads its cost from result.json.
Expected<JobMeasure> run_one(const Planned& p, const JobSweepSpec& sw, const std::string& dir,
                             const std::atomic<bool>* cancel, std::string* backend_ran) {
  JobSpec spec = p.spec;
  spec.out_dir = dir;
  const std::string spec_path = job_spec_path(sw.work_dir);
  if (Status st = write_file_atomic(spec_path, spec_to_json(spec)); !st) return st;
  JobMeasure m;
  m.load_avg = load_average();
  auto child = ChildJob::start(sw.executable, spec_path, sw.work_dir + "/jobs.log");
  if (!child) return child.status();
  ChildResult cr = (*child)->wait(nullptr, cancel);
  if (cancel && cancel->load()) return cancelled("calibration cancelled");
  if (!cr.status) return cr.status;
  std::ifstream in(dir + "/result.json");
  if (!in) return backend_error("the job left no readable result.json");
  std::stringstream text;
  text << in.rdbuf();
  auto measured = job_measure_from_manifest(text.str(), backend_ran);
  if (!measured) return measured.status();
  measured->load_avg = m.load_avg;
  return *measured;
}

Expected<CalibrateSummary> run_sweep(const JobSweepSpec& sw, const CalibrateHooks& hooks) {
  auto note = [&](const std::string& line) {
    if (hooks.note) hooks.note(line);
  };
  auto cancel_requested = [&] { return hooks.cancel && hooks.cancel->load(); };
  CalibrateSummary summary;
  summary.backend = sw.backend;
  summary.repeats = sw.repeats;
  std::string device = cpu_model_name();
  if (sw.backend == "cuda") {
    auto gpu = probe_gpu(sw.executable, hooks.cancel);
    if (!gpu) {
      if (gpu.status().code() == ErrorCode::kCancelled) return gpu.status();
      return backend_error("backend cuda asked for, but no usable GPU (" + gpu.status().message() +
                           ")");
    }
    device = *gpu;
  }
  summary.device = device;
  std::error_code ec;
  fs::create_directories(sw.work_dir, ec);
  if (ec) return io_error(sw.work_dir + ": " + ec.message());
  if (Status s = write_job_log(sw.out_path, {}); !s) return s;

  // The walls: parametric ones always, the meshes found in mesh_dir.
  std::vector<std::string> walls = sw.quick ? std::vector<std::string>{"box:x=2,y=1,z=1", "wall1"}
                                            : kShapes;
  const size_t shapes = walls.size();
  if (!sw.quick && !sw.mesh_dir.empty()) {
    for (const std::string& m : kMeshes)
      if (is_file(sw.mesh_dir + "/" + m)) walls.push_back(m);
    if (walls.size() == shapes) note("no STL walls in " + sw.mesh_dir + ": parametric walls only");
  }
  const Ranges rg = ranges_for(sw.backend, sw.quick);
  gvm::Rng rng(sw.seed);
  gvm::Rng settle_rng(sw.seed ^ 0x5E771EDull);  // its own stream: share 0 draws as before
  gvm::Rng work_rng(sw.seed ^ 0x3D0B0Dull);     // and the work's: spread 1 draws as before
  std::vector<Planned> plans;
  size_t refused = 0;
  const auto t_start = SteadyClock::now();
  for (int64_t tries = 0; int64_t(plans.size()) < sw.configs && tries < 20 * sw.configs; ++tries) {
    if (cancel_requested()) return cancelled("calibration cancelled");
    Draw d = draw_job(rng, rg, walls, shapes, sw.render, sw.quick);
    if (!d.zero_gravity && settle_rng.uniform01() < sw.settled_share)
      d.settle_falls = settle_rng.uniform(1.5, 3.0);
    if (sw.work_spread > 1) d.work_bound = log_uniform(work_rng, 1, sw.work_spread);
    auto p = size_job(d, rg, sw, device, sw.seed * 1000003u + plans.size());
    if (!p) {
      ++refused;
      continue;
    }
    plans.push_back(std::move(*p));
  }
  if (plans.empty()) return backend_error("the sweep drew no job that could run");
  summary.configs = plans.size();
  note(std::to_string(plans.size()) + " jobs on " + sw.backend + " (" + device + "), seed " +
       std::to_string(sw.seed) + ", " + std::to_string(refused) +
       " draws refused while sizing -> " + sw.out_path);

  std::vector<std::vector<JobRecord>> runs(plans.size());  // each plan's measured repeats
  std::vector<JobRecord> merged(plans.size());              // and their row, kept up to date
  // 0 not run, 1 measured, 2 failed, 3 measured and then failed on a repeat
  // (its measure is kept; a failing job is not run again).
  std::vector<int> state(plans.size(), 0);
  const std::string dir = job_run_dir(sw.work_dir);
  size_t rows_written = 0;
  for (int pass = 0; pass < sw.repeats && !summary.out_of_budget; ++pass)
    for (size_t i = 0; i < plans.size(); ++i) {
      if (state[i] >= 2) continue;
      if (cancel_requested()) return cancelled("calibration cancelled");
      if (sw.budget_s > 0 && seconds_since(t_start) > sw.budget_s) {
        summary.out_of_budget = true;
        note("budget of " + std::to_string(int(sw.budget_s)) + " s reached in pass " +
             std::to_string(pass + 1));
        break;
      }
      CalibrateProgress pr;
      pr.pass = pass + 1, pr.passes = sw.repeats;
      pr.index = i + 1, pr.count = plans.size();
      pr.backend = sw.backend;
      pr.running = plans[i].text;
      pr.rows = rows_written;
      if (hooks.progress) hooks.progress(pr);
      std::string ran;
      auto m = run_one(plans[i], sw, dir, hooks.cancel, &ran);
      fs::remove_all(dir, ec);
      if (!m && m.status().code() == ErrorCode::kCancelled) return m.status();
      Status st = m ? Status::ok() : m.status();
      if (st && ran != sw.backend)
        st = backend_error("the job ran on " + ran + ", not on " + sw.backend);
      pr.finished = true;
      if (!st) {
        state[i] = state[i] == 1 ? 3 : 2;
        pr.error = st.message();
        if (hooks.progress) hooks.progress(pr);
        continue;
      }
      JobRecord row{plans[i].inputs, *m};
      runs[i].push_back(row);
      merged[i] = merge_job_repeats(runs[i]).front();
      state[i] = 1;
      std::vector<JobRecord> rows;
      for (size_t j = 0; j < plans.size(); ++j)
        if (state[j] == 1 || state[j] == 3) rows.push_back(merged[j]);
      if (Status s = write_job_log(sw.out_path, rows); !s) return s;
      rows_written = rows.size();
      pr.triangles = int64_t(row.inputs.triangles);
      pr.frame_s = m->per_frame_s;
      pr.total_s = m->total_s;
      pr.peak_host_bytes = m->peak_host_bytes;
      pr.device_bytes = m->peak_device_bytes;
      pr.rows = rows_written;
      if (hooks.progress) hooks.progress(pr);
    }
  for (int s : state) summary.failed += s == 2, summary.measured += s == 1 || s == 3;
  summary.took_s = seconds_since(t_start);
  if (summary.measured == 0)
    return summary.out_of_budget
               ? resource_exhausted("the budget ran out before a job was measured")
               : backend_error("no job was measured (" + std::to_string(summary.failed) +
                               " failed)");
  return summary;
}

}  // namespace

const std::vector<std::string>& job_sweep_shapes() { return kShapes; }
const std::vector<std::string>& job_sweep_meshes() { return kMeshes; }

Status validate(const JobSweepSpec& s) {
  if (s.backend != "cpu" && s.backend != "cuda")
    return invalid_argument("backend must be cpu or cuda for a job sweep, got '" + s.backend + "'");
  if (s.configs < 1 || s.configs > 100000) return invalid_argument("configs must be in 1..100000");
  if (s.threads < 0 || s.threads > kMaxThreads)
    return invalid_argument("threads must be in 0.." + std::to_string(kMaxThreads));
  if (s.repeats < 1 || s.repeats > 100) return invalid_argument("repeats must be in 1..100");
  if (!(s.budget_s >= 0) || !std::isfinite(s.budget_s))
    return invalid_argument("budget must be >= 0 seconds");
  if (s.out_path.empty()) return invalid_argument("no output path for the job log");
  if (s.work_dir.empty()) return invalid_argument("no work folder for the jobs' run directories");
  if (s.executable.empty()) return invalid_argument("no collidoscope executable to run jobs in");
  if (!(s.settled_share >= 0 && s.settled_share <= 1))
    return invalid_argument("settled share must be in [0, 1]");
  if (!(s.work_spread >= 1 && s.work_spread <= 1000))
    return invalid_argument("work spread must be in [1, 1000]");
  return Status::ok();
}

Expected<CalibrateSummary> calibrate_jobs(const JobSweepSpec& spec, const CalibrateHooks& hooks) {
  if (Status s = validate(spec); !s) return s;
  // What the sweep leaves in its work folder goes when it ends, however it
  // ends: the last job's spec and run folder, and (a folder it made, whole)
  // the jobs' output, whose failures the notes have said. A folder that was
  // there keeps the rest of what it held.
  std::error_code ec;
  const bool made = !fs::exists(spec.work_dir, ec);
  struct Tidy {
    const std::string& dir;
    bool made;
    ~Tidy() {
      std::error_code e;
      if (made) {
        fs::remove_all(dir, e);
      } else {
        fs::remove(job_spec_path(dir), e);
        fs::remove_all(job_run_dir(dir), e);
      }
    }
  } tidy{spec.work_dir, made};
  try {
    return run_sweep(spec, hooks);
  } catch (const std::bad_alloc&) {
    return resource_exhausted("out of memory in the job sweep");
  } catch (const std::exception& e) {
    return backend_error(std::string("job sweep failed: ") + e.what());
  }
}

}  // namespace collido::job
