// `collidoscope run SCENE.json --out DIR`: the collision frames of a scene,
// written as snapshots the renderer reads, per-frame statistics, optional
// ParaView frames, and (--video) the rendered PNGs and videos.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "app/cli.h"
#include "app/commands.h"
#include "app/scene_args.h"
#include "scene/scene.h"
#include "sim/dynamics.h"
#include "sim/placement.h"
#include "sim/snapshot.h"
#include "sim/vtp_io.h"

namespace collido::app {

namespace fs = std::filesystem;

namespace {

const std::vector<FlagSpec> kFlags = {
    {"out", true, "run directory (default results/<scene name>)"},
    {"backend", true, "auto | cpu | cuda: overrides the scene's backend"},
    {"duration", true, "simulated seconds: overrides the scene's duration (a quick preview)"},
    {"vtp", false, "also write VTK PolyData frames (DIR/vtp/*.vtp, DIR/frames.pvd) for ParaView"},
    {"video", false,
     "render the frames into DIR/render (PNG, poster, MP4, WebM) when the run ends"},
    {"width", true, "video width (default 1280)"},
    {"height", true, "video height (default 720)"},
    {"camera", true, "front | iso | top | orbit (default iso)"},
    {"quiet", false, "no progress output"},
    {"help", false, "this help"},
};

const char* kStatsHeader =
    "frame,time_s,substeps,dt_min_s,dt_max_s,active,waiting,escaped,invalid,wall_contacts,particle_"
    "contacts,"
    "touching_wall,kinetic_J,potential_J,elastic_J,total_J,max_speed_m_s,max_overlap,history_"
    "overflow,wall_ms\n";

void write_stats_row(std::FILE* f, const sim::FrameStats& s, double wall_ms) {
  std::fprintf(f,
               "%llu,%.9g,%llu,%.6g,%.6g,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%.9g,%.9g,%.9g,%.9g,%."
               "6g,%.6g,%llu,%.3f\n",
               (unsigned long long)s.frame, s.time, (unsigned long long)s.substeps, s.dt_min,
               s.dt_max, (unsigned long long)s.active, (unsigned long long)s.waiting,
               (unsigned long long)s.escaped, (unsigned long long)s.invalid,
               (unsigned long long)s.wall_contacts, (unsigned long long)s.particle_contacts,
               (unsigned long long)s.touching_wall, s.kinetic, s.potential, s.elastic,
               s.total_energy(), s.max_speed, s.max_overlap, (unsigned long long)s.history_overflow,
               wall_ms);
}

// The particles that take part (released, finite, inside the domain), in the
// float snapshot form relative to `origin`. Escaped and non-finite ones are
// counted in the statistics and never written.
sim::Snapshot to_snapshot(const sim::ParticleSet& p, const std::vector<uint8_t>& flags,
                          uint64_t frame, double time, sim::Vec3d origin) {
  sim::Snapshot s;
  s.frame = frame;
  s.time = time;
  s.origin = origin;
  size_t n = 0;
  for (uint8_t f : flags) n += (f & sim::kStateMask) == sim::kActive;
  s.resize(n);
  size_t k = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    if ((flags[i] & sim::kStateMask) != sim::kActive) continue;
    s.x[k] = float(p.x[i] - origin.x), s.y[k] = float(p.y[i] - origin.y),
    s.z[k] = float(p.z[i] - origin.z);
    s.r[k] = float(p.r[i]);
    s.vx[k] = float(p.vx[i]), s.vy[k] = float(p.vy[i]), s.vz[k] = float(p.vz[i]);
    s.contact[k] = (flags[i] & sim::kFlagWallContact) ? 1 : 0;
    ++k;
  }
  return s;
}

// A progress bar on a terminal, a plain line every tenth otherwise.
class Progress {
 public:
  Progress(uint64_t total, bool quiet) : total_(total), quiet_(quiet), tty_(stderr_is_terminal()) {}
  void update(uint64_t done, const sim::FrameStats& s, double elapsed_s) {
    if (quiet_) return;
    const double share = total_ ? double(done) / double(total_) : 1.0;
    const double eta = done ? elapsed_s * (double(total_) / double(done) - 1) : 0;
    if (tty_) {
      const int width = 30, filled = int(share * width + 0.5);
      std::fprintf(stderr,
                   "\r[%.*s%*s] %3.0f%% frame %llu/%llu t=%.3g s, %llu contacts, eta %.0f s   ",
                   filled, "##############################", width - filled, "", 100 * share,
                   (unsigned long long)done, (unsigned long long)total_, s.time,
                   (unsigned long long)(s.wall_contacts + s.particle_contacts), eta);
      if (done == total_) std::fprintf(stderr, "\n");
    } else if (done == total_ || int(share * 10) > last_tenth_) {
      last_tenth_ = int(share * 10);
      std::fprintf(stderr,
                   "run: frame %llu/%llu (%.0f%%), t = %.4g s, %llu steps so far, eta %.0f s\n",
                   (unsigned long long)done, (unsigned long long)total_, 100 * share, s.time,
                   (unsigned long long)steps_, eta);
    }
  }
  void set_steps(uint64_t steps) { steps_ = steps; }

 private:
  uint64_t total_, steps_ = 0;
  bool quiet_, tty_;
  int last_tenth_ = 0;
};

int fail(const std::string& message) {
  std::fprintf(stderr, "collidoscope run: %s\n", message.c_str());
  return kExitFailure;
}

}  // namespace

int cmd_run(const Args& args) {
  std::string err;
  auto p = parse_args(args, kFlags, &err);
  if (!p) return usage_error("run", err);
  if (p->has("help")) {
    print_help(
        "usage: collidoscope run SCENE.json [--out DIR] [--video] [--vtp] [--backend "
        "auto|cpu|cuda]\n\n"
        "Runs the scene's collision frames and writes DIR/wall.stl, DIR/frames/frame_NNNNNN.snap,\n"
        "DIR/stats.csv (one row per frame), DIR/scene.json (with defaults) and DIR/run.json.",
        kFlags);
    return kExitOk;
  }
  if (p->positional().size() != 1)
    return usage_error("run", "one scene file expected (see --help)");
  const std::string scene_path = p->positional()[0];
  auto scene = scene::load_scene(scene_path);
  if (!scene) return usage_error("run", scene.status().message());
  if (p->has("vtp")) scene->vtp = true;
  if (p->has("backend")) {
    const std::string b = p->get("backend");
    scene->backend_auto = b == "auto";
    if (!scene->backend_auto && !sim::parse_backend(b, &scene->dynamics.backend))
      return usage_error("run", "--backend must be auto, cpu or cuda");
  }
  if (p->has("duration")) {
    scene->duration = p->get_double("duration", 0, &err);
    if (!err.empty()) return usage_error("run", err);
    if (auto st = scene::check_timing(*scene); !st)
      return usage_error("run", "--duration: " + st.message());
  }
  const std::string out_dir = p->get("out", "results/" + fs::path(scene_path).stem().string());
  const bool quiet = p->has("quiet");

  // The backend: the GPU when asked (or auto and usable), else the CPU with a note.
  std::string why;
  const bool gpu = sim::cuda_available(&why);
  if (scene->backend_auto) scene->dynamics.backend = sim::Backend::kCuda;
  if (scene->dynamics.backend == sim::Backend::kCuda && !gpu) {
    // Asked for the GPU by name: always say so; by "auto": unless --quiet.
    if (!(scene->backend_auto && quiet))
      std::fprintf(stderr, "collidoscope run: note: no usable GPU (%s); running on the CPU\n",
                   why.c_str());
    scene->dynamics.backend = sim::Backend::kCpu;
  }

  const auto t_start = std::chrono::steady_clock::now();
  sim::MeshReport report;
  auto wall = load_wall(scene->wall, &report);
  if (!wall) return fail("wall: " + wall.status().message());
  auto particles = sim::place_particles(*wall, scene->particles, scene->placement,
                                        scene->dynamics.gravity, scene->seed);
  if (!particles) return fail(particles.status().message());
  auto sim_or = sim::Simulation::create(*wall, scene->dynamics, *particles);
  if (!sim_or) return fail(sim_or.status().message());
  sim::Simulation& sim = **sim_or;
  const sim::TimeStepInfo& ts = sim.time_step_info();

  std::error_code ec;
  fs::create_directories(fs::path(out_dir) / "frames", ec);
  if (ec) return fail(out_dir + ": " + ec.message());
  if (scene->vtp) fs::create_directories(fs::path(out_dir) / "vtp", ec);
  if (Status s = sim::save_stl(*wall, (fs::path(out_dir) / "wall.stl").string()); !s)
    return fail(s.message());
  {
    std::ofstream sj(fs::path(out_dir) / "scene.json");
    sj << scene::to_json(*scene) << "\n";
  }
  const uint64_t frames = scene->frames();
  const double frame_dt = scene->duration / double(frames);
  if (!quiet) {
    std::fprintf(
        stderr,
        "run: %zu particles (%s), wall %zu triangles (%s), %s on the %s, %llu frames of %.4g s\n"
        "run: stiffness %.4g N/m, damping ratio %.3g, critical step %.3g s, %s step %.3g s\n",
        particles->size(), sim::to_string(scene->placement.kind), wall->triangles.size(),
        sim::to_string(scene->dynamics.method),
        scene->dynamics.particle_contacts ? "with particle contacts" : "wall contacts only",
        sim::to_string(scene->dynamics.backend), (unsigned long long)frames, frame_dt, ts.stiffness,
        ts.damping_ratio, ts.critical_step, ts.explicit_step > 0 ? "fixed" : "automatic",
        ts.explicit_step > 0 ? ts.explicit_step : ts.spring_step);
  }
  if (ts.beyond_stable)
    std::fprintf(stderr,
                 "collidoscope run: warning: time_step %.3g s is beyond the stable bound %.3g s of "
                 "the contact "
                 "spring; expect energy to blow up and particles to tunnel\n",
                 ts.explicit_step, ts.critical_step);

  std::FILE* stats = std::fopen((fs::path(out_dir) / "stats.csv").c_str(), "w");
  if (!stats) return fail(out_dir + "/stats.csv: cannot write");
  std::fputs(kStatsHeader, stats);
  const sim::Vec3d origin = mesh_bounds(*wall).center();
  std::vector<sim::PvdEntry> pvd;
  sim::ParticleSet state;
  std::vector<uint8_t> flags;
  Progress progress(frames, quiet);
  uint64_t lost = 0;
  sim::FrameStats st;
  const auto t_loop = std::chrono::steady_clock::now();
  for (uint64_t f = 0; f <= frames; ++f) {
    const auto t0 = std::chrono::steady_clock::now();
    Status s = f == 0 ? sim.measure(&st) : sim.advance(frame_dt, &st);
    if (!s) {
      std::fclose(stats);
      return fail("frame " + std::to_string(f) + ": " + s.message());
    }
    st.frame = f;
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    if (Status d = sim.download(&state, &flags); !d) return fail(d.message());
    const sim::Snapshot snap = to_snapshot(state, flags, f, st.time, origin);
    if (Status w = sim::write_snapshot(sim::snapshot_path(out_dir, f), snap); !w)
      return fail(w.message());
    if (scene->vtp) {
      char name[32];
      std::snprintf(name, sizeof name, "frame_%06llu.vtp", (unsigned long long)f);
      if (Status w = sim::write_vtp((fs::path(out_dir) / "vtp" / name).string(), snap); !w)
        return fail(w.message());
      pvd.push_back({st.time, std::string("vtp/") + name});
    }
    write_stats_row(stats, st, ms);
    if (st.escaped + st.invalid > lost) {
      std::fprintf(
          stderr,
          "%scollidoscope run: frame %llu: %llu particles escaped, %llu non-finite (not written)\n",
          stderr_is_terminal() && !quiet ? "\n" : "", (unsigned long long)f,
          (unsigned long long)st.escaped, (unsigned long long)st.invalid);
      lost = st.escaped + st.invalid;
    }
    progress.set_steps(sim.steps_taken());
    progress.update(
        f, st, std::chrono::duration<double>(std::chrono::steady_clock::now() - t_loop).count());
  }
  std::fclose(stats);
  if (scene->vtp) {
    if (Status w = sim::write_pvd((fs::path(out_dir) / "frames.pvd").string(), pvd); !w)
      return fail(w.message());
  }
  const double total_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  const double loop_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_loop).count();
  {
    std::ofstream rj(fs::path(out_dir) / "run.json");
    char buf[1024];
    std::snprintf(buf, sizeof buf,
                  "{\n  \"particles\": %zu,\n  \"triangles\": %zu,\n  \"backend\": \"%s\",\n  "
                  "\"frames\": %llu,\n"
                  "  \"steps\": %llu,\n  \"simulated_s\": %.9g,\n  \"wall_clock_s\": %.6g,\n  "
                  "\"loop_s\": %.6g,\n"
                  "  \"ms_per_step\": %.6g,\n  \"stiffness\": %.9g,\n  \"critical_step_s\": %.9g,\n"
                  "  \"fixed_step_s\": %.9g,\n  \"beyond_stable\": %s,\n  \"escaped\": %llu,\n  "
                  "\"invalid\": %llu,\n"
                  "  \"device_bytes\": %llu\n}\n",
                  particles->size(), wall->triangles.size(),
                  sim::to_string(scene->dynamics.backend), (unsigned long long)frames,
                  (unsigned long long)sim.steps_taken(), sim.time(), total_s, loop_s,
                  sim.steps_taken() ? 1e3 * loop_s / double(sim.steps_taken()) : 0.0, ts.stiffness,
                  ts.critical_step, ts.explicit_step, ts.beyond_stable ? "true" : "false",
                  (unsigned long long)st.escaped, (unsigned long long)st.invalid,
                  (unsigned long long)sim.device_bytes());
    rj << buf;
  }
  if (!quiet)
    std::fprintf(stderr, "run: %llu steps in %.1f s (%.3g ms per step); results in %s\n",
                 (unsigned long long)sim.steps_taken(), loop_s,
                 sim.steps_taken() ? 1e3 * loop_s / double(sim.steps_taken()) : 0.0,
                 out_dir.c_str());
  if (p->has("video")) {
#ifdef COLLIDO_HAVE_RENDER
    Args r = {out_dir};
    // The video plays at the scene's frame rate, so a second on screen is a simulated second.
    const int fps = std::max(1, std::min(240, int(std::lround(scene->fps))));
    r.insert(r.end(), {"--fps", std::to_string(fps)});
    for (const char* flag : {"width", "height", "camera"})
      if (p->has(flag)) r.insert(r.end(), {std::string("--") + flag, p->get(flag)});
    return cmd_render(r);
#else
    return fail("--video: this build has no renderer");
#endif
  }
  return kExitOk;
}

}  // namespace collido::app
