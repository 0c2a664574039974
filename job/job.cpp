#include "job/job.h"

#include "sim/accuracy.h"
#include "sim/auto_choice.h"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <new>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>

#include "common/atomic_file.h"
#include "common/process_memory.h"
#include "common/stopwatch.h"
#include "job/assess.h"
#include "job/budget.h"
#include "job/checkpoint.h"
#include "job/run_dir.h"
#include "job/stats_file.h"
#include "scene/scene.h"
#include "sim/parallel.h"
#include "sim/placement.h"
#include "sim/snapshot.h"
#include "sim/vtp_io.h"

namespace collido::job {

namespace fs = std::filesystem;
using json = nlohmann::json;
using Clock = SteadyClock;

const char* to_string(DirPolicy p) {
  switch (p) {
    case DirPolicy::kRefuse: return "refuse";
    case DirPolicy::kReplace: return "replace";
    case DirPolicy::kResume: return "resume";
  }
  return "refuse";
}

bool parse_dir_policy(const std::string& s, DirPolicy* out) {
  for (DirPolicy p : {DirPolicy::kRefuse, DirPolicy::kReplace, DirPolicy::kResume})
    if (s == to_string(p)) return *out = p, true;
  return false;
}

const char* to_string(Stage s) {
  switch (s) {
    case Stage::kPrepare: return "prepare";
    case Stage::kSimulate: return "simulate";
    case Stage::kRender: return "render";
    case Stage::kDone: return "done";
  }
  return "prepare";
}

namespace {

// The particles that take part (released, finite, inside the domain), in the
// float snapshot form relative to `origin`. Escaped and non-finite ones are
// counted in the statistics and never written.
sim::Snapshot snapshot_of(const sim::ParticleSet& p, const std::vector<uint8_t>& flags,
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

std::string vtp_name(uint64_t frame) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%06llu.vtp", (unsigned long long)frame);
  return name;
}

json render_to_json(const RenderSettings& r) {
  return {{"width", r.width},         {"height", r.height},     {"fps", r.fps},
          {"png_every", r.png_every}, {"camera", r.camera},     {"color", r.color},
          {"wall", r.wall},           {"speed_max", r.speed_max}, {"mp4", r.mp4},
          {"webm", r.webm},           {"gif", r.gif},           {"gif_width", r.gif_width},
          {"gif_fps", r.gif_fps},     {"msaa", r.msaa},         {"overlay", r.overlay},
          {"cull", r.cull}};
}

// The manifest: what the run produced and what it cost, one JSON writer.
json manifest(const JobResult& r, const scene::Scene* scene) {
  json j;
  j["version"] = 1;
  j["status"] = r.status.is_ok() ? "done"
                : r.status.code() == ErrorCode::kCancelled ? "cancelled"
                                                            : "failed";
  j["complete"] = r.status.is_ok();
  if (!r.status.is_ok())
    j["error"] = {{"code", to_string(r.status.code())}, {"message", r.status.message()}};
  // Outputs are in SI whatever unit the scene was written in.
  j["units"] = {{"length", "m"}, {"time", "s"}, {"speed", "m/s"}, {"energy", "J"}};
  if (scene) j["scene_length_unit"] = scene->length_unit;
  j["backend"] = r.backend;
  j["threads"] = r.threads;
  j["step_threads"] = r.step_threads;
  j["particles"] = r.particles;
  j["triangles"] = r.triangles;
  if (scene) {
    j["frames"] = scene->frames() + 1;
    j["fps"] = scene->fps;
    j["duration_s"] = scene->duration;
  }
  j["escaped"] = r.escaped;
  j["invalid"] = r.invalid;
  j["warnings"] = {{"blow_up_frames", r.blow_up_frames}, {"tunnel_risk_frames", r.tunnel_risk_frames}};
  j["resumed_from_frame"] = r.resumed_from_frame;
  const sim::TimeStepInfo& ts = r.time_step;
  j["method"] = {{"method", r.method}, {"grid_length_m", r.grid_length}, {"automatic_choice", r.choice}};
  j["time_step"] = {{"stiffness_N_m", ts.stiffness},       {"damping_ratio", ts.damping_ratio},
                    {"critical_step_s", ts.critical_step}, {"spring_step_s", ts.spring_step},
                    {"fixed_step_s", ts.explicit_step},    {"beyond_stable", ts.beyond_stable},
                    {"neighbour_skin_m", ts.neighbour_skin}};
  const Cost& c = r.cost;
  j["cost"] = {{"total_s", c.total_s},
               {"prepare_s", c.prepare_s},
               {"simulate_s", c.simulate_s},
               {"render_s", c.render_s},
               {"frames", c.frames},
               {"steps", c.steps},
               {"ms_per_step", c.steps ? 1e3 * c.simulate_s / double(c.steps) : 0.0},
               {"peak_host_bytes", c.peak_host_bytes},
               {"peak_device_bytes", c.peak_device_bytes},
               {"gpu_busy_fraction", c.gpu_busy_fraction},
               {"active_steps", c.active_steps},
               {"wall_contact_steps", c.wall_contact_steps},
               {"pair_contact_steps", c.pair_contact_steps},
               {"list_builds", c.list_builds}};
  j["notes"] = r.notes;
  json arts = json::array();
  for (const Artifact& a : r.artifacts)
    arts.push_back({{"path", a.path}, {"bytes", a.bytes}, {"mime", a.mime}, {"role", a.role},
                    {"count", a.count}});
  j["artifacts"] = arts;
  return j;
}

// Everything run_job does, inside the boundary that turns exceptions into a status.
class JobRunner {
 public:
  JobRunner(const JobSpec& spec, const Hooks& hooks) : spec_(spec), hooks_(hooks) {
    paths_.dir = spec.out_dir;
  }

  JobResult run() {
    t_start_ = Clock::now();
    result_.out_dir = spec_.out_dir;
    // Resuming a run that finished (a cluster job requeued or submitted again
    // after its end) must not touch it: its manifest already says done.
    if (spec_.dir_policy == DirPolicy::kResume && read_finished_run()) {
      note("the run in " + spec_.out_dir + " is complete: nothing to resume");
      report(Stage::kDone, 1, 1, 0);
      return result_;
    }
    // Everything the input decides is checked before the directory is touched,
    // so a bad scene leaves nothing behind.
    Status st = guarded([&] { return prepare(); });
    if (st) st = claim_run_dir(spec_.out_dir, spec_.dir_policy);
    if (!st) {
      result_.status = st;
      result_.cost.total_s = seconds_since(t_start_);
      return result_;  // not our directory (yet): write nothing into it
    }
    owns_dir_ = true;
    return finish(guarded([&] { return execute(); }));
  }

 private:
  void note(const std::string& line) {
    result_.notes.push_back(line);
    if (hooks_.note) hooks_.note(line);
  }
  bool cancel_requested() const { return hooks_.cancel && hooks_.cancel->load(); }
  // A finished run's result.json (status done, complete) into result_; false
  // when the directory holds no finished run.
  bool read_finished_run() {
    std::ifstream in(paths_.result());
    const json m = json::parse(in, nullptr, false);
    if (!m.is_object() || m.value("status", "") != "done" || !m.value("complete", false)) return false;
    try {
      result_.backend = m.value("backend", "");
      result_.threads = m.value("threads", 0);
      result_.step_threads = m.value("step_threads", result_.threads);
      result_.particles = m.value("particles", uint64_t(0));
      result_.triangles = m.value("triangles", uint64_t(0));
      result_.escaped = m.value("escaped", uint64_t(0));
      result_.invalid = m.value("invalid", uint64_t(0));
      result_.resumed_from_frame = m.value("resumed_from_frame", uint64_t(0));
      const json c = m.value("cost", json::object());
      result_.cost.total_s = c.value("total_s", 0.0);
      result_.cost.prepare_s = c.value("prepare_s", 0.0);
      result_.cost.simulate_s = c.value("simulate_s", 0.0);
      result_.cost.render_s = c.value("render_s", 0.0);
      result_.cost.frames = c.value("frames", uint64_t(0));
      result_.cost.steps = c.value("steps", uint64_t(0));
      result_.cost.peak_host_bytes = c.value("peak_host_bytes", uint64_t(0));
      result_.cost.peak_device_bytes = c.value("peak_device_bytes", uint64_t(0));
      result_.cost.active_steps = c.value("active_steps", 0.0);
      result_.cost.wall_contact_steps = c.value("wall_contact_steps", 0.0);
      result_.cost.pair_contact_steps = c.value("pair_contact_steps", 0.0);
      result_.cost.list_builds = c.value("list_builds", 0.0);
    } catch (const json::exception&) {
      return false;  // a field of the wrong type: not a manifest we wrote
    }
    result_.artifacts = list_artifacts(paths_, nullptr);
    return true;
  }
  void report(Stage stage, uint64_t done, uint64_t total, double eta) {
    if (!hooks_.progress) return;
    Progress p;
    p.stage = stage;
    p.done = done;
    p.total = total;
    p.elapsed_s = seconds_since(t_start_);
    p.eta_s = eta;
    p.steps = sim_ ? sim_->steps_taken() : 0;
    p.sim_time = last_.time;
    p.contacts = last_.wall_contacts + last_.particle_contacts;
    hooks_.progress(p);
  }

  Status prepare_scene() {
    auto resolved = resolve_scene(spec_);
    if (!resolved) return resolved.status();
    scene_ = std::move(resolved->scene);
    render_settings_ = resolved->render;
    return Status::ok();
  }

  void choose_backend() {
    std::string why;
    sim::Backend wanted = scene_.backend_auto ? sim::Backend::kCuda : scene_.dynamics.backend;
    scene_.dynamics.backend = sim::usable_backend(wanted, &why);
    // Asked for the GPU by name: say so; "auto" on a machine without one is the normal case.
    if (!why.empty() && !scene_.backend_auto) note(why);
    result_.backend = sim::to_string(scene_.dynamics.backend);
  }

  // Runs a stage; an exception thrown inside (an allocation failure above all)
  // becomes its status, so the job still ends with a result.json.
  template <class F>
  static Status guarded(F&& stage) {
    try {
      return stage();
    } catch (const std::bad_alloc&) {
      return resource_exhausted("out of memory: the scene needs more than this machine can give; "
                                "use fewer particles or a coarser wall");
    } catch (const std::exception& e) {
      return backend_error(std::string("internal error: ") + e.what());
    }
  }

  // The scene, wall, budget, particles and the engine: no file is written.
  Status prepare() {
    if (Status st = prepare_scene(); !st) return st;
    choose_backend();
    pool_ = std::make_unique<sim::ThreadPool>(spec_.threads);
    result_.threads = pool_->size();
    scene_.dynamics.pool = pool_.get();

    auto wall = load_scene_wall(&scene_);
    if (!wall) return wall.status();
    wall_ = std::move(*wall);
    if (scene_.length_scale() != 1)
      note("wall and scene lengths in " + scene_.length_unit + ", run in metres");
    result_.triangles = wall_.triangles.size();
    const WorkEstimate work =
        estimate_work(wall_, scene_.dynamics, scene_.particles.count, scene_.particles.r_max);
    if (Status st = check_budget(work, spec_.budget); !st) return st;

    auto particles = sim::place_particles(wall_, scene_.particles, scene_.placement,
                                          scene_.dynamics.gravity, scene_.seed, pool_.get());
    if (!particles) return particles.status();
    result_.particles = particles->size();
    // A resumed run's checkpoint, read before the wall's representation is chosen.
    if (spec_.dir_policy == DirPolicy::kResume) {
      auto ck = read_checkpoint(paths_.checkpoint());
      if (!ck && ck.status().code() != ErrorCode::kNotFound) return ck.status();
      if (ck) resume_ = std::move(*ck);
      if (Status st = check_same_wall(); !st) return st;
    }
    if (Status st = choose_wall_representation(*particles); !st) return st;
    auto sim_or = sim::Simulation::create(wall_, scene_.dynamics, *particles);
    if (!sim_or) return sim_or.status();
    sim_ = std::move(*sim_or);
    result_.grid_length = sim_->wall_info().grid_length;  // as the engine prepared it
    result_.step_threads = sim_->step_threads();
    particles->resize(0);
    const sim::TimeStepInfo& ts = sim_->time_step_info();
    result_.time_step = ts;
    if (ts.beyond_stable)
      note("time_step " + std::to_string(ts.explicit_step) + " s is beyond the stable bound " +
           std::to_string(ts.critical_step) +
           " s of the contact spring; expect energy to blow up and particles to tunnel");
    return Status::ok();
  }

  // A resumed run continues on the wall it started with: the run's wall.stl,
  // written from it before the first frame. A wall file changed or replaced
  // since then would give the saved state another wall (and wall lists that
  // name its triangles).
  Status check_same_wall() {
    if (!resume_) return Status::ok();
    std::ifstream in(paths_.wall(), std::ios::binary);
    if (!in) return Status::ok();  // never written: nothing to hold it to
    std::ostringstream saved;
    saved << in.rdbuf();
    if (saved.str() == sim::stl_bytes(wall_)) return Status::ok();
    return invalid_argument("wall: " + scene_.wall + " is not the wall this run started with (" +
                            paths_.wall() +
                            " holds that one); put the original back, or start the run again");
  }

  // method / grid_length "auto": time the candidates where the particles will
  // meet the wall and run the fastest; the choice and the times behind it are
  // noted and kept. A fill is timed as placed. A pour or a jet starts at its
  // inlet, away from the wall it will spend the run on, so it is timed on as
  // many particles of its sizes, half within 1.5 r_max of the wall and half
  // in the wall's box (the benchmarks' placement).
  Status choose_wall_representation(const sim::ParticleSet& placed) {
    sim::DynamicsConfig& d = scene_.dynamics;
    sim::Method kept = d.method;
    if ((scene_.method_auto || scene_.grid_auto) && resume_ && !resume_->method.empty() &&
        sim::parse_method(resume_->method, &kept)) {
      // The state continues with the representation it was made with.
      if (scene_.method_auto) d.method = kept;
      if (scene_.grid_auto) d.grid_length = resume_->grid_length;
      result_.choice = "kept from the run's first attempt: " + resume_->method;
      note("automatic choice: " + result_.choice);
    } else if (scene_.method_auto || scene_.grid_auto) {
      sim::Particles p;
      const bool inlet = scene_.placement.kind != sim::PlacementKind::kFill;
      if (inlet) {
        p = sim::particles_near_surface(wall_, placed.size(), scene_.particles.r_min,
                                        scene_.particles.r_max, 0.5, 1.5 * scene_.particles.r_max,
                                        scene_.seed);
      } else {
        p.resize(placed.size());
        for (size_t i = 0; i < placed.size(); ++i)
          p.x[i] = placed.x[i], p.y[i] = placed.y[i], p.z[i] = placed.z[i], p.r[i] = placed.r[i];
      }
      sim::DetectConfig base;
      base.backend = d.backend, base.pool = d.pool, base.r_max = scene_.particles.r_max;
      base.method = d.method, base.grid_length = d.grid_length;
      sim::AutoRequest req;
      req.method = scene_.method_auto, req.grid_length = scene_.grid_auto;
      req.for_dynamics = true;
      // A candidate is held to the run's budget, as the scene's own setting was.
      req.admit = [&](sim::Method m, double grid_length) {
        sim::DynamicsConfig c = d;
        c.method = m;
        c.grid_length = grid_length;
        return check_budget(estimate_work(wall_, c, scene_.particles.count, scene_.particles.r_max),
                            spec_.budget);
      };
      auto choice = sim::choose_detection(wall_, p, base, req);
      if (!choice) return choice.status();
      d.method = choice->method;
      if (scene_.grid_auto) d.grid_length = choice->grid_length;
      result_.choice = (inlet ? "timed near the wall, where the " +
                                    std::string(sim::to_string(scene_.placement.kind)) +
                                    "'s particles go: "
                              : std::string()) +
                       choice->reason;
      note("automatic choice: " + result_.choice);
    }
    result_.method = sim::to_string(d.method);
    return Status::ok();
  }

  Status execute() {
    // Outputs that do not change during the run.
    if (spec_.dir_policy != DirPolicy::kResume) {
      JobSpec saved = spec_;
      saved.dir_policy = DirPolicy::kResume;
      if (Status st = write_file_atomic(paths_.job(), spec_to_json(saved) + "\n"); !st) return st;
    }
    if (Status st = write_file_atomic(paths_.scene(), scene::to_json(scene_) + "\n"); !st)
      return st;
    if (Status st = sim::save_stl(wall_, paths_.wall()); !st) return st;
    if (scene_.vtp) {
      std::error_code ec;
      fs::create_directories(paths_.vtp(), ec);
      if (ec) return io_error(paths_.vtp() + ": " + ec.message());
    }
    result_.cost.prepare_s = seconds_since(t_start_);
    if (Status st = simulate(); !st) return st;
    if (spec_.render) return render();
    return Status::ok();
  }

  Status simulate() {
    const uint64_t frames = scene_.frames();
    const double frame_dt = scene_.duration / double(frames);
    const sim::Vec3d origin = sim::mesh_bounds(wall_).center();
    uint64_t first = 0;
    std::vector<double> times;  // simulated time of each frame written, for the PVD index
    std::optional<Checkpoint>& ck = resume_;  // read by prepare()
    if (ck) {
      if (Status st = sim_->restore_state(ck->state); !st) return st;
      // Killed after its last frame (while rendering, say): the statistics are
      // whole under their final name; they continue from there, as from a partial file.
      std::error_code ec;
      if (ck->frame == frames && !fs::exists(paths_.stats_partial(), ec) &&
          fs::exists(paths_.stats(), ec)) {
        fs::rename(paths_.stats(), paths_.stats_partial(), ec);
        if (ec) return io_error(paths_.stats() + ": " + ec.message());
      }
      if (Status st = stats_.resume(paths_.stats_partial(), ck->frame, &times); !st) return st;
      first = ck->frame + 1;
      result_.resumed_from_frame = ck->frame;
      note("resumed from the checkpoint of frame " + std::to_string(ck->frame));
      ck.reset();  // its state is the engine's now
    } else {
      // A fresh run, or one killed before its first checkpoint: from frame 0.
      if (spec_.dir_policy == DirPolicy::kResume) note("no checkpoint yet: starting from frame 0");
      if (Status st = stats_.create(paths_.stats_partial()); !st) return st;
    }
    std::vector<sim::PvdEntry> pvd;
    for (size_t f = 0; f < times.size(); ++f) pvd.push_back({times[f], "vtp/" + vtp_name(f)});

    sim::ParticleSet state;
    std::vector<uint8_t> flags;
    const auto t_loop = Clock::now();
    auto last_save = Clock::now();
    double engine_s = 0;
    for (uint64_t f = first; f <= frames; ++f) {
      if (cancel_requested())
        return cancelled("cancelled at frame " + std::to_string(f) + " of " + std::to_string(frames));
      const auto t0 = Clock::now();
      Status s = f == 0 ? sim_->measure(&last_) : sim_->advance(frame_dt, &last_);
      if (!s) return Status(s.code(), "frame " + std::to_string(f) + ": " + s.message());
      last_.frame = f;
      const double engine_ms = 1e3 * seconds_since(t0);
      engine_s += engine_ms * 1e-3;
      if (Status d = sim_->download(&state, &flags); !d) return d;
      const sim::Snapshot snap = snapshot_of(state, flags, f, last_.time, origin);
      if (Status w = sim::write_snapshot(sim::snapshot_path(paths_.dir, f), snap); !w) return w;
      if (scene_.vtp) {
        if (Status w = sim::write_vtp(paths_.vtp() + "/" + vtp_name(f), snap); !w) return w;
        pvd.push_back({last_.time, "vtp/" + vtp_name(f)});
      }
      if (Status w = stats_.append(last_, engine_ms); !w) return w;
      const double substeps = double(last_.substeps);
      result_.cost.active_steps += double(last_.active) * substeps;
      result_.cost.wall_contact_steps += double(last_.wall_contacts) * substeps;
      result_.cost.pair_contact_steps += double(last_.particle_contacts) * substeps;
      if (last_.escaped + last_.invalid > lost_) {
        note("frame " + std::to_string(f) + ": " + std::to_string(last_.escaped) +
             " particles escaped, " + std::to_string(last_.invalid) +
             " non-finite (frozen, not written)");
        lost_ = last_.escaped + last_.invalid;
      }
      if (last_.held > 0 && !held_noted_) {
        note("frame " + std::to_string(f) + ": releases wait at the inlet for their place (" +
             std::to_string(last_.held) + " now; each goes once nothing touches it)");
        held_noted_ = true;
      }
      // Say the first time each kind of failure shows, and count every frame it shows in.
      const sim::FrameWarnings w = sim::frame_warnings(last_, sim_->time_step_info());
      if ((w.blow_up && result_.blow_up_frames == 0) ||
          (w.tunnel_risk && result_.tunnel_risk_frames == 0))
        note("frame " + std::to_string(f) + ": " + w.message);
      result_.blow_up_frames += w.blow_up;
      result_.tunnel_risk_frames += w.tunnel_risk;
      // The state after this frame, so a kill loses at most the frames since.
      if (f == frames || seconds_since(last_save) >= spec_.checkpoint_interval_s) {
        Checkpoint ck;
        ck.frame = f;
        ck.method = sim::to_string(scene_.dynamics.method);
        ck.grid_length = scene_.dynamics.grid_length;
        if (Status c = sim_->save_state(&ck.state); !c) return c;
        // The frames, statistics and files so far on the disk before the
        // checkpoint names them done: a node that goes down keeps both or neither.
        if (Status c = sync_file_system(paths_.dir); !c) return c;
        if (Status c = write_checkpoint(paths_.checkpoint(), ck); !c) return c;
        last_save = Clock::now();
      }
      const double elapsed = seconds_since(t_loop);
      const double per_frame = elapsed / double(f - first + 1);
      report(Stage::kSimulate, f, frames, per_frame * double(frames - f));
    }
    // Resumed past the last frame: the end state's figures, which the loop did not measure.
    if (first > frames)
      if (Status s = sim_->measure(&last_); !s) return s;
    if (Status st = stats_.finish(paths_.stats()); !st) return st;
    if (scene_.vtp)
      if (Status w = sim::write_pvd(paths_.pvd(), pvd); !w) return w;
    result_.cost.simulate_s = seconds_since(t_loop);
    result_.cost.list_builds = double(sim_->stage_times().neighbour_builds);  // this process's
    result_.cost.frames = frames + 1;
    if (last_.held > 0)
      note("the run ended with releases still waiting at the inlet for their place (" +
           std::to_string(last_.held) + ")");
    result_.escaped = last_.escaped;
    result_.invalid = last_.invalid;
    if (scene_.dynamics.backend == sim::Backend::kCuda && result_.cost.simulate_s > 0)
      result_.cost.gpu_busy_fraction = std::min(1.0, engine_s / result_.cost.simulate_s);
    return Status::ok();
  }

  Status render() {
#ifdef COLLIDO_HAVE_RENDER
    const auto t0 = Clock::now();
    RenderOutcome out;
    auto progress = [&](size_t done, size_t total) {
      const double per = seconds_since(t0) / double(done);
      report(Stage::kRender, done, total, per * double(total - done));
    };
    Status st =
        render_run(paths_.dir, paths_.render(), render_settings_, progress, hooks_.cancel, &out);
    result_.cost.render_s = seconds_since(t0);
    return st;
#else
    return invalid_argument("render: this build has no renderer");
#endif
  }

  JobResult finish(Status st) {
    stats_.close();
    result_.status = st;
    if (sim_) {
      result_.cost.steps = sim_->steps_taken();
      result_.cost.peak_device_bytes =
          scene_.dynamics.backend == sim::Backend::kCuda ? sim_->device_bytes() : 0;
    }
    result_.cost.peak_host_bytes = own_peak_resident_bytes();
    result_.cost.total_s = seconds_since(t_start_);
    if (owns_dir_) {
      result_.artifacts = list_artifacts(paths_, nullptr);
      const json m = manifest(result_, scene_.wall.empty() ? nullptr : &scene_);
      Status w = write_file_atomic(paths_.result(), m.dump(2) + "\n");
      if (result_.status.is_ok() && !w) result_.status = w;
    }
    // Done only when it is: a failed or cancelled job's last report says how far it got.
    if (result_.status.is_ok()) report(Stage::kDone, 1, 1, 0);
    return result_;
  }

  const JobSpec& spec_;
  const Hooks& hooks_;
  RunPaths paths_;
  JobResult result_;
  Clock::time_point t_start_;
  bool owns_dir_ = false;
  scene::Scene scene_;
  RenderSettings render_settings_;  // the spec's, with the frame rate resolved
  std::unique_ptr<sim::ThreadPool> pool_;
  sim::TriangleMesh wall_;
  std::unique_ptr<sim::Simulation> sim_;
  StatsFile stats_;
  sim::FrameStats last_;
  uint64_t lost_ = 0;
  bool held_noted_ = false;
  std::optional<Checkpoint> resume_;  // the checkpoint a resumed run continues
};

}  // namespace

JobResult run_job(const JobSpec& spec, const Hooks& hooks) {
  // The boundary: nothing thrown inside leaves it. The stages catch their own
  // (JobRunner::guarded); this is the last net, for the bookkeeping around them.
  try {
    JobRunner runner(spec, hooks);
    return runner.run();
  } catch (const std::bad_alloc&) {
    JobResult r;
    r.out_dir = spec.out_dir;
    r.status = resource_exhausted("out of memory");
    return r;
  } catch (const std::exception& e) {
    JobResult r;
    r.out_dir = spec.out_dir;
    r.status = backend_error(std::string("internal error: ") + e.what());
    return r;
  }
}

std::string spec_to_json(const JobSpec& s) {
  json scene = json::parse(s.scene_json, nullptr, false);
  json j = {{"version", 1},
            {"scene", scene.is_discarded() ? json(s.scene_json) : scene},
            {"scene_dir", s.scene_dir},
            {"out_dir", s.out_dir},
            {"dir_policy", to_string(s.dir_policy)},
            {"threads", s.threads},
            {"backend", s.backend},
            {"duration", s.duration},
            {"vtp", s.vtp},
            {"render", s.render},
            {"render_settings", render_to_json(s.render_settings)},
            {"checkpoint_interval_s", s.checkpoint_interval_s},
            {"budget",
             {{"host_bytes", s.budget.host_bytes},
              {"wall_cells", s.budget.wall_cells},
              {"pieces", s.budget.pieces}}}};
  return j.dump(2);
}

namespace {

// Reads j[key] into *out when present; an error names the key when it has the wrong type.
template <class T>
Status read_key(const json& j, const char* key, T* out, const std::string& where = "") {
  if (!j.contains(key)) return Status::ok();
  const json& v = j.at(key);
  const std::string name = where.empty() ? key : where + "." + key;
  if constexpr (std::is_same_v<T, bool>) {
    if (!v.is_boolean()) return invalid_argument(name + ": expected true or false");
  } else if constexpr (std::is_same_v<T, std::string>) {
    if (!v.is_string()) return invalid_argument(name + ": expected a string");
  } else if constexpr (std::is_integral_v<T>) {
    if (!v.is_number_integer()) return invalid_argument(name + ": expected an integer");
    if (v.is_number_unsigned() ? v.get<uint64_t>() > uint64_t(std::numeric_limits<T>::max())
                               : (v.get<int64_t>() < int64_t(std::numeric_limits<T>::min()) ||
                                  (v.get<int64_t>() > 0 &&
                                   uint64_t(v.get<int64_t>()) > uint64_t(std::numeric_limits<T>::max()))))
      return invalid_argument(name + ": out of range");
  } else {
    if (!v.is_number()) return invalid_argument(name + ": expected a number");
    if (!std::isfinite(v.get<double>())) return invalid_argument(name + ": not finite");
  }
  *out = v.get<T>();
  return Status::ok();
}

#define COLLIDO_READ(...)                                    \
  do {                                                       \
    if (Status read_status = read_key(__VA_ARGS__); !read_status) return read_status; \
  } while (0)

}  // namespace

Expected<JobSpec> spec_from_json(const std::string& text) {
  const json j = json::parse(text, nullptr, false);
  if (j.is_discarded()) return parse_error("job spec: not valid JSON");
  if (!j.is_object()) return invalid_argument("job spec: expected a JSON object");
  static const char* kKeys[] = {"version", "scene",    "scene_dir",       "out_dir",
                                "dir_policy", "threads", "backend",       "duration",
                                "vtp",     "render",   "render_settings", "checkpoint_interval_s",
                                "budget"};
  for (auto it = j.begin(); it != j.end(); ++it) {
    bool known = false;
    for (const char* k : kKeys) known = known || it.key() == k;
    if (!known) return invalid_argument(it.key() + ": unknown key of the job spec");
  }
  JobSpec s;
  if (!j.contains("scene")) return invalid_argument("scene: missing");
  const json& scene = j.at("scene");
  if (scene.is_string())
    s.scene_json = scene.get<std::string>();
  else if (scene.is_object())
    s.scene_json = scene.dump();
  else
    return invalid_argument("scene: expected the scene document (an object)");
  COLLIDO_READ(j, "scene_dir", &s.scene_dir);
  COLLIDO_READ(j, "out_dir", &s.out_dir);
  if (s.out_dir.empty()) return invalid_argument("out_dir: missing");
  std::string policy = to_string(s.dir_policy);
  COLLIDO_READ(j, "dir_policy", &policy);
  if (!parse_dir_policy(policy, &s.dir_policy))
    return invalid_argument("dir_policy: must be refuse, replace or resume");
  COLLIDO_READ(j, "threads", &s.threads);
  COLLIDO_READ(j, "backend", &s.backend);
  COLLIDO_READ(j, "duration", &s.duration);
  COLLIDO_READ(j, "vtp", &s.vtp);
  COLLIDO_READ(j, "render", &s.render);
  COLLIDO_READ(j, "checkpoint_interval_s", &s.checkpoint_interval_s);
  if (!(s.checkpoint_interval_s >= 0)) return invalid_argument("checkpoint_interval_s: must be >= 0");
  if (j.contains("render_settings")) {
    const json& r = j.at("render_settings");
    if (!r.is_object()) return invalid_argument("render_settings: expected an object");
    RenderSettings& rs = s.render_settings;
    const std::string w = "render_settings";
    COLLIDO_READ(r, "width", &rs.width, w);
    COLLIDO_READ(r, "height", &rs.height, w);
    COLLIDO_READ(r, "fps", &rs.fps, w);
    COLLIDO_READ(r, "png_every", &rs.png_every, w);
    COLLIDO_READ(r, "camera", &rs.camera, w);
    COLLIDO_READ(r, "color", &rs.color, w);
    COLLIDO_READ(r, "wall", &rs.wall, w);
    COLLIDO_READ(r, "speed_max", &rs.speed_max, w);
    COLLIDO_READ(r, "mp4", &rs.mp4, w);
    COLLIDO_READ(r, "webm", &rs.webm, w);
    COLLIDO_READ(r, "gif", &rs.gif, w);
    COLLIDO_READ(r, "gif_width", &rs.gif_width, w);
    COLLIDO_READ(r, "gif_fps", &rs.gif_fps, w);
    COLLIDO_READ(r, "msaa", &rs.msaa, w);
    COLLIDO_READ(r, "overlay", &rs.overlay, w);
    COLLIDO_READ(r, "cull", &rs.cull, w);
  }
  if (j.contains("budget")) {
    const json& b = j.at("budget");
    if (!b.is_object()) return invalid_argument("budget: expected an object");
    COLLIDO_READ(b, "host_bytes", &s.budget.host_bytes, "budget");
    COLLIDO_READ(b, "wall_cells", &s.budget.wall_cells, "budget");
    COLLIDO_READ(b, "pieces", &s.budget.pieces, "budget");
  }
  return s;
}

}  // namespace collido::job
