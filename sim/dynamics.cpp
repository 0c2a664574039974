// Validation, the physics of the time step, and the CPU instantiation of the dynamics.
#include "sim/dynamics.h"

#include <cstdio>

#include <algorithm>
#include <cmath>

#include "sim/backend_cpu.h"
#include "sim/detect_cuda.h"
#include "sim/dynamics_pipeline.h"

namespace collido::sim {

const char* to_string(Integrator i) {
  return i == Integrator::kSymplecticEuler ? "symplectic_euler" : "velocity_verlet";
}

bool parse_integrator(const std::string& s, Integrator* out) {
  if (s == "symplectic_euler" || s == "euler") return *out = Integrator::kSymplecticEuler, true;
  if (s == "velocity_verlet" || s == "verlet") return *out = Integrator::kVelocityVerlet, true;
  return false;
}

void ParticleSet::resize(size_t n) {
  for (auto* v : {&x, &y, &z, &vx, &vy, &vz, &r, &release}) v->resize(n, 0.0);
}

double damping_ratio(double e) {
  if (e >= 1) return 0;
  const double l = std::log(e);
  return -l / std::sqrt(M_PI * M_PI + l * l);
}

namespace {

bool finite_nonneg(double v) {
  return std::isfinite(v) && v >= 0;
}

Status validate(const TriangleMesh& wall, const DynamicsConfig& c, const ParticleSet& p) {
  if (wall.triangles.empty()) return invalid_argument("wall: the wall has no triangles");
  if (c.method == Method::kReference)
    return invalid_argument(
        "method: the dynamics prepares the wall as bin or a division method, not reference");
  const Material& m = c.material;
  if (!(m.density > 0) || !std::isfinite(m.density))
    return invalid_argument("material.density must be a positive density in kg/m^3");
  if (!(m.restitution > 0 && m.restitution <= 1))
    return invalid_argument("material.restitution must lie in (0, 1], got " +
                            std::to_string(m.restitution));
  if (!finite_nonneg(m.friction) || m.friction > 10)
    return invalid_argument("material.friction must lie in [0, 10], got " +
                            std::to_string(m.friction));
  if (!finite_nonneg(m.stiffness)) return invalid_argument("material.stiffness must be >= 0 N/m");
  if (!finite_nonneg(m.youngs_modulus))
    return invalid_argument("material.youngs_modulus must be >= 0 Pa");
  if (!std::isfinite(c.gravity.x) || !std::isfinite(c.gravity.y) || !std::isfinite(c.gravity.z))
    return invalid_argument("gravity must be finite");
  if (!finite_nonneg(c.time_step))
    return invalid_argument("time_step must be >= 0 s (0 = automatic)");
  if (!(c.step_fraction > 0 && c.step_fraction <= 1))
    return invalid_argument("step_fraction must lie in (0, 1]");
  if (!(c.motion_fraction > 0 && c.motion_fraction <= 1))
    return invalid_argument("motion_fraction must lie in (0, 1]");
  if (!finite_nonneg(c.impact_speed)) return invalid_argument("impact_speed must be >= 0 m/s");
  if (p.size() == 0) return invalid_argument("particles: a run needs at least one particle");
  if (p.size() > (size_t(1) << 31)) return invalid_argument("particles: more than 2^31 particles");
  for (size_t i = 0; i < p.size(); ++i) {
    if (!(p.r[i] > 0) || !std::isfinite(p.r[i]))
      return invalid_argument("particle " + std::to_string(i) + ": radius must be positive");
    for (double v : {p.x[i], p.y[i], p.z[i], p.vx[i], p.vy[i], p.vz[i]})
      if (!std::isfinite(v))
        return invalid_argument("particle " + std::to_string(i) +
                                ": non-finite position or velocity");
    if (!finite_nonneg(p.release[i]))
      return invalid_argument("particle " + std::to_string(i) + ": release time must be >= 0 s");
  }
  return Status::ok();
}

// The contact spring and the steps it allows for a particle set (see DESIGN.md "Dynamics").
TimeStepInfo time_step_physics(const DynamicsConfig& c, const ParticleSet& p,
                               const Bounds3d& wall_box) {
  const double r_min = *std::min_element(p.r.begin(), p.r.end());
  const double r_max = *std::max_element(p.r.begin(), p.r.end());
  double r_sum = 0, v_max = 0, r3_sum = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    r_sum += p.r[i];
    r3_sum += p.r[i] * p.r[i] * p.r[i];
    v_max = std::max(v_max, std::sqrt(p.vx[i] * p.vx[i] + p.vy[i] * p.vy[i] + p.vz[i] * p.vz[i]));
  }
  TimeStepInfo ts = contact_time_step(c, r_min, r_max, r_sum / double(p.size()), v_max, wall_box.extent());
  // With particle contacts one particle may gather its neighbours' energy, so
  // only the total is bounded: every particle at the speed bound at most.
  const double mass = c.material.density * 4.0 / 3.0 * M_PI * r3_sum;
  ts.kinetic_bound = 0.5 * mass * ts.speed_bound * ts.speed_bound;
  return ts;
}

// The fall across the wall's box along gravity (m/s) and the speed the automatic
// stiffness is sized for: the fastest expected impact.
double fall_speed(const DynamicsConfig& c, Vec3d e) {
  const double g = length(c.gravity);
  const double drop = g > 0 ? (std::fabs(e.x * c.gravity.x) + std::fabs(e.y * c.gravity.y) +
                               std::fabs(e.z * c.gravity.z)) /
                                  g
                            : 0.0;
  return std::sqrt(2 * g * drop);
}
double impact_speed(const DynamicsConfig& c, double v_max, Vec3d e) {
  return c.impact_speed > 0 ? c.impact_speed : std::max({v_max + fall_speed(c, e), 1e-3});
}

}  // namespace

Expected<std::unique_ptr<Simulation>> Simulation::create(const TriangleMesh& wall,
                                                         const DynamicsConfig& config,
                                                         const ParticleSet& particles) {
  if (Status s = validate(wall, config, particles); !s) return s;
  const Bounds3d wall_box = mesh_bounds(wall);
  const TimeStepInfo ts = time_step_physics(config, particles, wall_box);
  // The domain: the wall's box and every starting position, grown by the margin.
  Bounds3d box = wall_box;
  for (size_t i = 0; i < particles.size(); ++i)
    box.grow({particles.x[i], particles.y[i], particles.z[i]});
  const double margin =
      config.domain_margin >= 0 ? config.domain_margin : 0.1 * length(box.extent()) + 4 * ts.r_max;
  const Vec3d pad{margin, margin, margin};
  if (config.backend == Backend::kCuda) {
#if defined(COLLIDO_HAVE_CUDA)
    return make_cuda_simulation(wall, config, particles, ts, box.lo - pad, box.hi + pad);
#else
    return Status(ErrorCode::kBackend, "this build has no CUDA backend");
#endif
  }
  return DynamicsPipeline<CpuBackend>::make(wall, config, particles, ts, box.lo - pad,
                                            box.hi + pad);
}

TimeStepInfo contact_time_step(const DynamicsConfig& c, double r_min, double r_max, double r_mean,
                               double v_max, Vec3d wall_extent) {
  TimeStepInfo ts;
  ts.r_min = r_min;
  ts.r_max = r_max;
  auto mass = [&](double r) { return c.material.density * 4.0 / 3.0 * M_PI * r * r * r; };
  ts.m_min = mass(ts.r_min);
  const Material& m = c.material;
  if (m.stiffness > 0) {
    ts.stiffness = m.stiffness;
  } else if (m.youngs_modulus > 0) {
    // Linearised elastic contact: a sphere of radius r pressed into a flat of modulus E.
    ts.stiffness = m.youngs_modulus * r_mean;
  } else {
    // Automatic: stiff enough that the fastest expected impact (the initial speed
    // and the longest fall inside the wall's box, along gravity) overlaps at most
    // 2 % of the radius (the largest particle has the most mass per radius^2).
    const double v = impact_speed(c, v_max, wall_extent);
    const double delta = 0.02 * ts.r_max;
    ts.stiffness = mass(ts.r_max) * (v / delta) * (v / delta);
  }
  ts.damping_ratio = damping_ratio(m.restitution);
  // Lightest contact: a small particle on the wall, or two of them.
  const double m_eff = c.particle_contacts ? ts.m_min / 2 : ts.m_min;
  const double omega = std::sqrt(ts.stiffness / m_eff);
  const double z = ts.damping_ratio;
  // Explicit integration of a damped oscillator is stable for omega dt < 2 (sqrt(1 + z^2) - z).
  ts.critical_step = 2.0 / omega * (std::sqrt(1 + z * z) - z);
  ts.spring_step = c.step_fraction * ts.critical_step;
  ts.explicit_step = c.time_step;
  ts.beyond_stable = c.time_step > ts.critical_step;
  ts.speed_bound = v_max + fall_speed(c, wall_extent);
  ts.particle_contacts = c.particle_contacts;
  return ts;
}

FrameWarnings frame_warnings(const FrameStats& st, const TimeStepInfo& ts) {
  FrameWarnings w;
  char line[256];
  if (ts.explicit_step > kUnstableStepShare * ts.critical_step) {
    // Known before any contact: an explicit step this close to the bound adds
    // energy in every contact, however slowly the scene moves.
    w.blow_up = true;
    std::snprintf(line, sizeof line,
                  "the fixed step %.3g s is %.0f %% of the contact spring's stability bound %.3g s: "
                  "energy grows in every contact",
                  ts.explicit_step, 100 * ts.explicit_step / ts.critical_step, ts.critical_step);
    w.message = line;
  } else if (st.invalid > 0 || !std::isfinite(st.total_energy())) {
    w.blow_up = true;
    std::snprintf(line, sizeof line, "%llu particles non-finite: the run blew up",
                  static_cast<unsigned long long>(st.invalid));
    w.message = line;
  } else if (ts.particle_contacts && ts.kinetic_bound > 0 &&
             st.kinetic > kRunawaySpeedFactor * kRunawaySpeedFactor * ts.kinetic_bound) {
    w.blow_up = true;
    std::snprintf(line, sizeof line,
                  "the particles hold %.3g J of kinetic energy, %.1f x what the scene's energy allows "
                  "(%.3g J): the step is unstable",
                  st.kinetic, st.kinetic / ts.kinetic_bound, ts.kinetic_bound);
    w.message = line;
  } else if (const double v = std::max(st.max_speed, st.peak_speed);
             !ts.particle_contacts && ts.speed_bound > 0 && v > kRunawaySpeedFactor * ts.speed_bound) {
    w.blow_up = true;
    std::snprintf(line, sizeof line,
                  "a particle moved at %.3g m/s; %.1f x what the scene's energy allows (%.3g m/s): "
                  "the step is unstable",
                  v, v / ts.speed_bound, ts.speed_bound);
    w.message = line;
  }
  if (st.peak_travel > kTunnelRiskShare || st.peak_wall_overlap > kTunnelRiskShare) {
    w.tunnel_risk = true;
    std::snprintf(line, sizeof line,
                  "%sa particle moved %.2f radii in one step and went %.2f radii into the wall: "
                  "it may pass through (use the automatic step, or a stiffer contact / impact_speed)",
                  w.message.empty() ? "" : "; ", st.peak_travel, st.peak_wall_overlap);
    w.message += line;
  }
  return w;
}

StepPlan plan_steps(const DynamicsConfig& c, double r_min, double r_max, double r_mean,
                    double v_max, Vec3d wall_extent, double frame_duration, uint64_t frames) {
  StepPlan plan;
  plan.contact = contact_time_step(c, r_min, r_max, r_mean, v_max, wall_extent);
  plan.expected_speed = impact_speed(c, v_max, wall_extent);
  if (c.time_step > 0) {
    plan.step = c.time_step;
  } else {
    plan.step = automatic_step_size(plan.contact.spring_step, c.motion_fraction, r_min,
                                    plan.expected_speed, length(c.gravity));
    plan.motion_limited = plan.step < plan.contact.spring_step;
  }
  // As advance() lands on each frame's end: what remains split into equal steps.
  if (frame_duration > 0 && plan.step > 0) {
    const double per = std::ceil(frame_duration / plan.step * (1 - 1e-12));
    plan.steps_per_frame = uint64_t(std::min(std::max(per, 1.0), 1e18));
  }
  plan.steps = plan.steps_per_frame * frames;
  return plan;
}

}  // namespace collido::sim
