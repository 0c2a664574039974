// The dynamics half of the study: where each wall representation stops giving
// the right motion. Three small scenes without gravity (so every energy change
// is the integrator's or the contact's): a ball bouncing obliquely off a floor
// (restitution and friction have analytic answers), a ball fired at a slab
// thinner than its radius, and a box of 27 elastic particles with and without
// particle contacts. Each runs across time-step factors (x the automatic step
// at that speed) and impact speeds (x the speed the contact stiffness is sized
// for), against a reference with a step 16 times below the smallest factor.
#include <algorithm>
#include <cmath>

#include "sim/dynamics.h"
#include "sim/particles.h"
#include "sim/shapes.h"
#include "study/study.h"

namespace collido::study {
namespace {

constexpr double kRadius = 0.05;      // m
constexpr double kSceneSpeed = 1.0;   // m/s: the impact speed the stiffness is sized for
constexpr double kRestitution = 0.5;

struct Setup {
  sim::TriangleMesh wall;
  sim::ParticleSet particles;
  sim::DynamicsConfig cfg;
  double duration = 0;      // s
  bool per_step = false;    // one frame per step (contact time is counted per step)
};

// The study's scenes size the contact from their own speeds (impact_speed), not a fall.
const sim::Bounds3d kUnitBox{{0, 0, 0}, {1, 1, 1}, false};

// The contact duration of the linear spring at the stiffness sized for kSceneSpeed.
double contact_time(const sim::DynamicsConfig& cfg) {
  const sim::TimeStepInfo ts = sim::contact_time_step(cfg, kRadius, kRadius, kRadius, 0, kUnitBox);
  const double omega = std::sqrt(ts.stiffness / ts.m_min);
  return M_PI / (omega * std::sqrt(std::max(1e-12, 1 - ts.damping_ratio * ts.damping_ratio)));
}

sim::DynamicsConfig base_config(sim::Method m, sim::Backend b, sim::ThreadPool* pool) {
  sim::DynamicsConfig c;
  c.method = m, c.backend = b, c.pool = pool;
  c.gravity = {0, 0, 0};
  c.material.restitution = kRestitution;
  c.impact_speed = kSceneSpeed;  // sizes the automatic stiffness
  return c;
}

Setup make_setup(const std::string& scene, double speed, bool pairs, sim::Method m, sim::Backend b,
                 sim::ThreadPool* pool) {
  Setup s;
  s.cfg = base_config(m, b, pool);
  s.cfg.particle_contacts = pairs;
  const double tc = contact_time(s.cfg);
  s.particles.resize(scene == "box" ? 27 : 1);
  if (scene == "bounce") {
    // Oblique impact: tangential speed half the normal one, friction 0.3,
    // enough to reach rolling (the analytic answer is 5/7 of the tangential speed).
    s.wall = sim::make_box(1, 1, 0.5);
    s.cfg.material.friction = 0.3;
    const double gap = 0.2 * kRadius;
    s.particles.x[0] = 0, s.particles.y[0] = 0, s.particles.z[0] = kRadius + gap;
    s.particles.vx[0] = 0.5 * speed, s.particles.vz[0] = -speed;
    s.duration = gap / speed + 3 * tc;
    s.per_step = true;
  } else if (scene == "thin_wall") {
    // A closed slab half a radius thick, the ball fired straight at it.
    s.wall = sim::make_box(1, 1, 0.5 * kRadius);
    const double gap = 0.2 * kRadius;
    s.particles.x[0] = 0.1, s.particles.y[0] = 0.1, s.particles.z[0] = 0.5 * kRadius + kRadius + gap;
    s.particles.vz[0] = -speed;
    s.duration = gap / speed + 3 * tc;
    s.per_step = true;
  } else {  // box: 27 elastic particles, random directions, 0.4 r apart
    s.wall = sim::make_box(0.5, 0.5, 0.5);
    s.cfg.material.restitution = 1;
    sim::SplitMix64 rng(5);
    const double pitch = 2.4 * kRadius;
    for (int i = 0, k = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        for (int l = 0; l < 3; ++l, ++k) {
          s.particles.x[k] = (i - 1) * pitch, s.particles.y[k] = (j - 1) * pitch;
          s.particles.z[k] = 0.25 + (l - 1) * pitch;
          sim::Vec3d d{rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)};
          d = d * (speed / sim::length(d));
          s.particles.vx[k] = d.x, s.particles.vy[k] = d.y, s.particles.vz[k] = d.z;
        }
    s.duration = 3 * 0.4 * kRadius / speed + 3 * tc;
  }
  for (size_t i = 0; i < s.particles.size(); ++i) s.particles.r[i] = kRadius;
  return s;
}

// The automatic step at the setting's own speed (spring bound and motion bound).
double automatic_step(const Setup& s, double speed) {
  const sim::TimeStepInfo ts = sim::contact_time_step(s.cfg, kRadius, kRadius, kRadius, speed, kUnitBox);
  return sim::automatic_step_size(ts.spring_step, s.cfg.motion_fraction, kRadius, speed, 0);
}

struct Outcome {
  sim::ParticleSet end;
  std::vector<uint8_t> flags;
  double e0 = 0, e_end = 0;
  double contact_time = 0;  // s the first particle spent touching the wall (per-step runs)
  uint64_t steps = 0, escaped = 0, invalid = 0;
  std::string warnings;
  bool blow_up_reported = false, tunnel_reported = false;
};

Status run(const Setup& s, double dt, Outcome* out) {
  sim::DynamicsConfig cfg = s.cfg;
  cfg.time_step = dt;
  auto sim_or = sim::Simulation::create(s.wall, cfg, s.particles);
  if (!sim_or) return sim_or.status();
  sim::Simulation& simu = **sim_or;
  sim::FrameStats st;
  if (Status e = simu.measure(&st); !e) return e;
  out->e0 = st.total_energy();
  // (A duration that is a whole number of steps is not taken for one more by rounding.)
  const uint64_t steps = static_cast<uint64_t>(std::ceil(s.duration / dt * (1 - 1e-12)));
  const uint64_t frames = s.per_step ? steps : 20;
  const double frame = s.per_step ? dt : s.duration / 20;
  for (uint64_t f = 0; f < frames; ++f) {
    if (Status e = simu.advance(frame, &st); !e) return e;
    if (s.per_step && st.touching_wall > 0) out->contact_time += dt;
    const sim::FrameWarnings w = sim::frame_warnings(st, simu.time_step_info());
    if ((w.blow_up && !out->blow_up_reported) || (w.tunnel_risk && !out->tunnel_reported))
      out->warnings += (out->warnings.empty() ? "" : "; ") + w.message;
    out->blow_up_reported |= w.blow_up;
    out->tunnel_reported |= w.tunnel_risk;
    if (st.active == 0) break;
  }
  out->e_end = st.total_energy();
  out->escaped = st.escaped, out->invalid = st.invalid, out->steps = simu.steps_taken();
  return simu.download(&out->end, &out->flags);
}

// Particles that ended on the wrong side of the wall.
uint64_t crossed(const std::string& scene, const Setup& s, const Outcome& o) {
  uint64_t n = 0;
  for (size_t i = 0; i < o.end.size(); ++i) {
    const uint8_t state = o.flags[i] & sim::kStateMask;
    if (state == sim::kInvalid) continue;
    const sim::Vec3d p{o.end.x[i], o.end.y[i], o.end.z[i]};
    if (scene == "bounce") n += p.z < 0 || state == sim::kEscaped;
    else if (scene == "thin_wall") n += p.z < 0.25 * kRadius;  // the far side of the slab's middle
    else n += state == sim::kEscaped || sim::winding_number(s.wall, p) < 0.5;
  }
  return n;
}

}  // namespace

Status run_dynamics_study(const StudyOptions& o, std::vector<DynamicsRow>* rows) {
  const std::vector<double> dt_factors = {0.05, 0.3, 1, 3, 10, 30};
  const std::vector<double> speeds = {0.1, 1, 10, 100};
  const std::vector<sim::Method> methods =
      o.quick ? std::vector<sim::Method>{sim::Method::kBin, sim::Method::kCircumcircle}
              : std::vector<sim::Method>{sim::Method::kBin, sim::Method::kGravity, sim::Method::kCircumcircle,
                                         sim::Method::kMidpoint4};
  for (const std::string scene : {"bounce", "thin_wall", "box"})
    for (sim::Method m : methods)
      for (bool pairs : {false, true}) {
        if (pairs && scene != "box") continue;  // one particle: no pairs to switch on
        if (scene == "box" && o.quick && m != sim::Method::kBin) continue;
        for (double sf : speeds) {
          const double speed = sf * kSceneSpeed;
          Setup s = make_setup(scene, speed, pairs, m, o.backend, o.pool);
          const double auto_dt = automatic_step(s, speed);
          // A run step by step ends after a whole number of its steps: every
          // run ends at the same time only when the duration is a whole number
          // of the largest step (a multiple of every smaller one and of the
          // reference's). Else the coarse runs flew on past the reference's end
          // and the trajectory error measured that flight, not the step.
          if (s.per_step) {
            const double largest = auto_dt * dt_factors.back();
            s.duration = std::ceil(s.duration / largest * (1 - 1e-12)) * largest;
          }
          // One reference per setting: 16 times below the smallest factor's step.
          Outcome ref;
          if (Status e = run(s, auto_dt * dt_factors.front() / 16, &ref); !e) return e;
          for (double f : dt_factors) {
            Outcome got;
            if (Status e = run(s, auto_dt * f, &got); !e) return e;
            DynamicsRow r;
            r.backend = sim::to_string(o.backend), r.scene = scene, r.method = sim::to_string(m);
            r.dt_factor = f, r.speed_factor = sf, r.particle_contacts = pairs, r.dt = auto_dt * f;
            r.steps = got.steps, r.escaped = got.escaped, r.invalid = got.invalid;
            r.tunnelled = crossed(scene, s, got);
            r.warnings = got.warnings;
            double traj = 0;
            for (size_t i = 0; i < got.end.size(); ++i) {
              const double d = std::sqrt(std::pow(got.end.x[i] - ref.end.x[i], 2) +
                                         std::pow(got.end.y[i] - ref.end.y[i], 2) +
                                         std::pow(got.end.z[i] - ref.end.z[i], 2));
              traj = std::max(traj, std::isfinite(d) ? d / kRadius : INFINITY);
            }
            r.trajectory_error = traj;
            const double scale = std::max(std::fabs(got.e0), 1e-300);
            r.energy_drift = (got.e_end - ref.e_end) / scale;
            if (scene == "bounce" && got.end.size() == 1) {
              const double vn = speed, vt = 0.5 * speed;
              r.restitution_error = std::fabs(got.end.vz[0] / vn - kRestitution) / kRestitution;
              r.friction_error = std::fabs(got.end.vx[0] - 5.0 / 7.0 * vt) / vt;
            }
            // The verdict from what happened, not from what the engine said.
            const bool blew = got.invalid > 0 || !std::isfinite(got.e_end) || got.e_end > 1.1 * got.e0;
            if (blew) r.verdict = "blows_up";
            else if (r.tunnelled > 0) r.verdict = "tunnels";
            else if (ref.contact_time > 0 && got.contact_time < 0.5 * ref.contact_time && s.per_step)
              r.verdict = "loses_contacts";
            else r.verdict = "stable";
            rows->push_back(r);
          }
        }
        if (o.progress)
          o.progress(std::string("dynamics: ") + scene + " / " + sim::to_string(m) +
                     (pairs ? " with particle contacts" : "") + " done");
      }
  return Status::ok();
}

}  // namespace collido::study
