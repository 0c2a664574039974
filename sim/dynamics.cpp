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

const char* to_string(ContactModel m) {
  return m == ContactModel::kHertzMindlin ? "hertz_mindlin" : "linear";
}

bool parse_contact_model(const std::string& s, ContactModel* out) {
  if (s == "linear" || s == "linear_spring_dashpot") return *out = ContactModel::kLinear, true;
  if (s == "hertz_mindlin" || s == "hertz") return *out = ContactModel::kHertzMindlin, true;
  return false;
}

const char* to_string(WallMotionKind k) {
  switch (k) {
    case WallMotionKind::kRotate: return "rotate";
    case WallMotionKind::kTranslate: return "translate";
    case WallMotionKind::kOscillate: return "oscillate";
    default: return "none";
  }
}

WallPose WallMotion::pose(double t, Vec3d origin) const {
  WallPose p;
  p.moving = moving();
  p.c = center - origin;
  const Vec3d a = unit_axis();
  switch (kind) {
    case WallMotionKind::kRotate: {
      // Rodrigues: R = cos I + sin [a]x + (1 - cos) a a^T.
      const double th = angular_speed * t, c = std::cos(th), s = std::sin(th), k = 1 - c;
      p.r0 = {c + k * a.x * a.x, k * a.x * a.y - s * a.z, k * a.x * a.z + s * a.y};
      p.r1 = {k * a.y * a.x + s * a.z, c + k * a.y * a.y, k * a.y * a.z - s * a.x};
      p.r2 = {k * a.z * a.x - s * a.y, k * a.z * a.y + s * a.x, c + k * a.z * a.z};
      p.w = a * angular_speed;
      break;
    }
    case WallMotionKind::kTranslate:
      p.d = velocity * t;
      p.v = velocity;
      break;
    case WallMotionKind::kOscillate: {
      const double om = 2 * M_PI * frequency;
      p.d = a * (amplitude * std::sin(om * t));
      p.v = a * (amplitude * om * std::cos(om * t));
      break;
    }
    default: break;
  }
  return p;
}

Vec3d WallMotion::unit_axis() const {
  const double l = length(axis);
  return l > 0 ? axis * (1.0 / l) : Vec3d{0, 0, 1};
}

namespace {
// Where a box lies about an axis through `center`: the farthest corner's
// distance from it, and the corners' span along it (the box is convex, so its
// corners bound both).
struct AxialReach {
  double rho = 0, lo = 1e300, hi = -1e300;
};
AxialReach axial_reach(const Bounds3d& b, Vec3d center, Vec3d a) {
  AxialReach out;
  for (int i = 0; i < 8; ++i) {
    const Vec3d d = Vec3d{i & 1 ? b.hi.x : b.lo.x, i & 2 ? b.hi.y : b.lo.y,
                          i & 4 ? b.hi.z : b.lo.z} - center;
    const double t = dot(d, a);
    out.lo = std::min(out.lo, t), out.hi = std::max(out.hi, t);
    out.rho = std::max(out.rho, length(d - a * t));
  }
  return out;
}
}  // namespace

double WallMotion::surface_speed(const Bounds3d& wall_box) const {
  const Bounds3d& box = moves_part() ? part_box : wall_box;
  switch (kind) {
    case WallMotionKind::kRotate:
      return std::fabs(angular_speed) * axial_reach(box, center, unit_axis()).rho;
    case WallMotionKind::kTranslate: return length(velocity);
    case WallMotionKind::kOscillate: return std::fabs(amplitude) * 2 * M_PI * std::fabs(frequency);
    default: return 0;
  }
}

// Where a turn about the axis takes the box: the box of the cylinder that
// holds its corners' circles.
Bounds3d WallMotion::turned_box(const Bounds3d& box) const {
  const Vec3d a = unit_axis();
  const AxialReach reach = axial_reach(box, center, a);
  const double rho = reach.rho;
  Bounds3d out;
  const Vec3d ext{rho * std::sqrt(std::max(0.0, 1 - a.x * a.x)),
                  rho * std::sqrt(std::max(0.0, 1 - a.y * a.y)),
                  rho * std::sqrt(std::max(0.0, 1 - a.z * a.z))};
  for (double t : {reach.lo, reach.hi}) {
    const Vec3d p = center + a * t;
    out.grow(p - ext);
    out.grow(p + ext);
  }
  return out;
}

Bounds3d WallMotion::swept_box(const Bounds3d& wall_box) const {
  if (!moves_part()) return kind == WallMotionKind::kRotate ? turned_box(wall_box) : wall_box;
  // A part's sweep (its whole stroke for a shake), with the still rest.
  Bounds3d out = part_box;
  if (kind == WallMotionKind::kRotate) {
    out = turned_box(part_box);
  } else if (kind == WallMotionKind::kOscillate) {
    const Vec3d s = unit_axis() * std::fabs(amplitude);
    const Vec3d reach{std::fabs(s.x), std::fabs(s.y), std::fabs(s.z)};
    out.grow(part_box.lo - reach);
    out.grow(part_box.hi + reach);
  }
  out.merge(wall_box);
  return out;
}

double hertz_restitution(double eta) {
  // x'' = -x^3/2 - c x^1/4 x', x(0) = 0, x'(0) = 1 (units where m = K = v = 1: the
  // rebound does not depend on them), c = eta sqrt(3/2) (S_n = 3/2 K sqrt(x)).
  // RK4 until the overlap closes; the rebound speed is the restitution.
  const double c = eta * std::sqrt(1.5);
  auto acc = [c](double x, double v) {
    const double xp = x > 0 ? x : 0;
    return -xp * std::sqrt(xp) - c * std::sqrt(std::sqrt(xp)) * v;
  };
  double x = 0, v = 1;
  const double h = 1e-3;  // the undamped contact lasts 3.218: e to 1e-6 (checked at 2e-4)
  for (int k = 0; k < 200000; ++k) {
    const double k1x = v, k1v = acc(x, v);
    const double k2x = v + 0.5 * h * k1v, k2v = acc(x + 0.5 * h * k1x, v + 0.5 * h * k1v);
    const double k3x = v + 0.5 * h * k2v, k3v = acc(x + 0.5 * h * k2x, v + 0.5 * h * k2v);
    const double k4x = v + h * k3v, k4v = acc(x + h * k3x, v + h * k3v);
    const double xn = x + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
    const double vn = v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
    if (k > 0 && xn <= 0) {
      // Interpolate the speed at the crossing.
      const double f = x / (x - xn);
      return -(v + f * (vn - v));
    }
    x = xn, v = vn;
  }
  return 0;  // still pressed in at 60 contact times: no rebound to speak of
}

double hertz_damping_factor(double e) {
  if (!(e < 1)) return 0;
  // The restitution falls as eta grows: bisect.
  double lo = 0, hi = 1;
  while (hertz_restitution(hi) > e && hi < 1e6) hi *= 2;
  for (int i = 0; i < 60 && hi - lo > 1e-12 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (hertz_restitution(mid) > e ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

namespace {

bool finite_nonneg(double v) {
  return std::isfinite(v) && v >= 0;
}

// The material's coefficients; messages name the key under `where`.
Status validate_material(const Material& m, const std::string& where, bool density,
                         ContactModel model) {
  if (density && (!(m.density > 0) || !std::isfinite(m.density)))
    return invalid_argument(where + ".density must be a positive density in kg/m^3");
  if (!(m.restitution > 0 && m.restitution <= 1))
    return invalid_argument(where + ".restitution must lie in (0, 1], got " +
                            std::to_string(m.restitution));
  if (!finite_nonneg(m.friction) || m.friction > 10)
    return invalid_argument(where + ".friction must lie in [0, 10], got " +
                            std::to_string(m.friction));
  if (!finite_nonneg(m.rolling_friction) || m.rolling_friction > 1)
    return invalid_argument(where + ".rolling_friction must lie in [0, 1], got " +
                            std::to_string(m.rolling_friction));
  if (!finite_nonneg(m.stiffness)) return invalid_argument(where + ".stiffness must be >= 0 N/m");
  if (!finite_nonneg(m.youngs_modulus))
    return invalid_argument(where + ".youngs_modulus must be >= 0 Pa");
  if (!(m.poisson_ratio >= 0 && m.poisson_ratio <= 0.5))
    return invalid_argument(where + ".poisson_ratio must lie in [0, 0.5], got " +
                            std::to_string(m.poisson_ratio));
  if (m.stiffness > 0 && m.youngs_modulus > 0)
    return invalid_argument(where + ".stiffness: give stiffness or youngs_modulus, not both");
  if (model == ContactModel::kHertzMindlin && m.stiffness > 0)
    return invalid_argument(where +
                            ".stiffness: the hertz_mindlin model takes youngs_modulus (Pa) and "
                            "poisson_ratio, not a spring stiffness");
  return Status::ok();
}

Status validate_motion(const WallMotion& w) {
  if (!w.moving()) return Status::ok();
  for (double v : {w.axis.x, w.axis.y, w.axis.z, w.center.x, w.center.y, w.center.z,
                   w.velocity.x, w.velocity.y, w.velocity.z, w.angular_speed, w.amplitude,
                   w.frequency})
    if (!std::isfinite(v)) return invalid_argument("wall_motion: values must be finite");
  if ((w.kind == WallMotionKind::kRotate || w.kind == WallMotionKind::kOscillate) &&
      !(length(w.axis) > 0))
    return invalid_argument("wall_motion.axis: must not be zero");
  if (!(std::fabs(w.angular_speed) <= 1e4))
    return invalid_argument("wall_motion.angular_speed: must lie within +-1e4 rad/s");
  if (w.amplitude < 0 || w.frequency < 0 || w.frequency > 1e5)
    return invalid_argument("wall_motion: amplitude must be >= 0 m and frequency in [0, 1e5] Hz");
  if (w.part < 0 || w.part > 64)
    return invalid_argument("wall_motion.part: a part of the wall's union, 1 to 64 (0: the whole wall)");
  if (w.part > 0 && w.kind == WallMotionKind::kTranslate)
    return invalid_argument("wall_motion.part: a part turns or shakes; translate moves the whole wall");
  return Status::ok();
}

}  // namespace

Status check_contact_settings(const DynamicsConfig& c) {
  if (Status s = validate_material(c.material, "material", true, c.contact_model); !s) return s;
  if (c.wall_material_set)
    if (Status s = validate_material(c.wall_material, "wall_material", false, c.contact_model); !s) return s;
  return validate_motion(c.wall_motion);
}

namespace {

Status validate(const TriangleMesh& wall, const DynamicsConfig& c, const ParticleSet& p) {
  if (wall.triangles.empty()) return invalid_argument("wall: the wall has no triangles");
  if (!dynamics_can_use(c.method))
    return invalid_argument(std::string("method: the dynamics prepares the wall as bin, bvh or a "
                                        "division method, not ") +
                            to_string(c.method));
  if (Status s = check_contact_settings(c); !s) return s;
  const WallMotion& w = c.wall_motion;
  if (w.part > 0 && !w.moves_part())
    return invalid_argument("wall_motion.part: the part's triangles were not set (the job sets them "
                            "when it builds the wall)");
  if (w.part_end > 0 &&
      (w.part_end > wall.triangles.size() || w.part_begin >= w.part_end ||
       w.part_end - w.part_begin == wall.triangles.size()))
    return invalid_argument("wall_motion.part: the moving triangles must be some of the wall's, "
                            "not all (move the whole wall instead)");
  if (!std::isfinite(c.gravity.x) || !std::isfinite(c.gravity.y) || !std::isfinite(c.gravity.z))
    return invalid_argument("gravity must be finite");
  if (!finite_nonneg(c.time_step))
    return invalid_argument("time_step must be >= 0 s (0 = automatic)");
  if (!(c.step_fraction > 0 && c.step_fraction <= 1))
    return invalid_argument("step_fraction must lie in (0, 1]");
  if (!(c.motion_fraction > 0 && c.motion_fraction <= 1))
    return invalid_argument("motion_fraction must lie in (0, 1]");
  if (!finite_nonneg(c.impact_speed)) return invalid_argument("impact_speed must be >= 0 m/s");
  if (!std::isfinite(c.neighbour_skin))
    return invalid_argument("neighbour_skin must be a length in m (or < 0 for automatic)");
  if (c.renumber_every < -1)
    return invalid_argument("renumber_every must be -1 (when scattered), 0 (never) or a count of builds");
  if (c.pairs_once < -1 || c.pairs_once > 1)
    return invalid_argument("pairs_once must be -1 (the backend's choice), 0 or 1");
  if (c.simd < -1 || c.simd > 0)
    return invalid_argument("simd must be -1 (where the CPU has AVX2) or 0");
  if (c.wall_lists < -1 || c.wall_lists > 1)
    return invalid_argument("wall_lists must be -1 (the backend's choice), 0 or 1");
  if (c.run_ahead < 0 || c.run_ahead > 1024)
    return invalid_argument("run_ahead must be 0 (automatic) or a count of steps up to 1024");
  if (!(c.lanes == 0 || c.lanes == 1 || c.lanes == 2 || c.lanes == 4 ||
        c.lanes == 8))
    return invalid_argument("lanes must be 0 (the backend's choice), 1, 2, 4 or 8");
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
  // A skin of many radii would list most of the particles as every one's neighbours.
  const double r_max = *std::max_element(p.r.begin(), p.r.end());
  if (c.neighbour_skin > 4 * r_max)
    return invalid_argument("neighbour_skin: " + std::to_string(c.neighbour_skin) +
                            " m is more than 4 particle radii");
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
  TimeStepInfo ts = contact_time_step(c, r_min, r_max, r_sum / double(p.size()), v_max, wall_box);
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
// The fastest a particle may move: its start, a fall across the wall's box, and
// what the wall's own motion can give it.
double speed_bound(const DynamicsConfig& c, double v_max, const Bounds3d& box) {
  return v_max + fall_speed(c, box.extent()) + c.wall_motion.surface_speed(box);
}
double impact_speed(const DynamicsConfig& c, double v_max, const Bounds3d& box) {
  return c.impact_speed > 0 ? c.impact_speed : std::max(speed_bound(c, v_max, box), 1e-3);
}

// Explicit integration of a damped oscillator is stable for omega dt < 2 (sqrt(1 + z^2) - z).
double critical_step(double k, double m_eff, double zeta) {
  return 2.0 / std::sqrt(k / m_eff) * (std::sqrt(1 + zeta * zeta) - zeta);
}

}  // namespace

Expected<std::unique_ptr<Simulation>> Simulation::create(const TriangleMesh& wall,
                                                         const DynamicsConfig& given,
                                                         const ParticleSet& particles) {
  if (Status s = validate(wall, given, particles); !s) return s;
  DynamicsConfig config = given;
  WallMotion& motion = config.wall_motion;
  // A moving part's box from its triangles, whatever the caller set.
  if (motion.moves_part())
    motion.part_box = mesh_bounds(mesh_range(wall, motion.part_begin, motion.part_end, true));
  const Bounds3d wall_box = mesh_bounds(wall);
  const TimeStepInfo ts = time_step_physics(config, particles, wall_box);
  // The domain: the wall's box (every place a rotating wall turns to) and
  // every starting position, grown by the margin.
  Bounds3d box = config.wall_motion.swept_box(wall_box);
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

bool wall_lists_without_pairs(const DynamicsConfig& c) {
  return c.wall_lists > 0 ||
         (c.wall_lists < 0 && (c.backend == Backend::kCpu || divides(c.method)));
}

TimeStepInfo contact_time_step(const DynamicsConfig& c, double r_min, double r_max, double r_mean,
                               double v_max, const Bounds3d& wall_box) {
  TimeStepInfo ts;
  ts.r_min = r_min;
  ts.r_max = r_max;
  auto mass = [&](double r) { return c.material.density * 4.0 / 3.0 * M_PI * r * r * r; };
  ts.m_min = mass(ts.r_min);
  const Material& pm = c.material;
  const Material& wm = c.wall_material_set ? c.wall_material : c.material;
  const double v = impact_speed(c, v_max, wall_box);
  ContactLaw& pl = ts.pair_law;
  ContactLaw& wl = ts.wall_law;
  pl.model = wl.model = c.contact_model;
  pl.mu = pm.friction, pl.mu_roll = pm.rolling_friction;
  wl.mu = wm.friction, wl.mu_roll = wm.rolling_friction;
  pl.zeta = damping_ratio(pm.restitution);
  wl.zeta = damping_ratio(wm.restitution);
  // The stiffest contact sizes the step: a small particle on the wall, or two of them.
  double k_wall = 0, k_pair = 0;
  if (c.contact_model == ContactModel::kLinear) {
    if (pm.stiffness > 0) {
      k_pair = pm.stiffness;
    } else if (pm.youngs_modulus > 0) {
      // Linearised elastic contact: a sphere of radius r pressed into a flat of modulus E.
      k_pair = pm.youngs_modulus * r_mean;
    } else {
      // Automatic: stiff enough that the fastest expected impact (the initial speed,
      // the longest fall inside the wall's box along gravity, the wall's own speed)
      // overlaps at most 2 % of the radius (the largest particle has the most mass per radius^2).
      const double delta = 0.02 * ts.r_max;
      k_pair = mass(ts.r_max) * (v / delta) * (v / delta);
    }
    k_wall = c.wall_material_set && wm.stiffness > 0        ? wm.stiffness
             : c.wall_material_set && wm.youngs_modulus > 0 ? wm.youngs_modulus * r_mean
                                                            : k_pair;
    pl.k = k_pair, pl.kt = 2.0 / 7.0 * k_pair;
    wl.k = k_wall, wl.kt = 2.0 / 7.0 * k_wall;
  } else {
    const double nu = pm.poisson_ratio, nw = wm.poisson_ratio;
    double e = pm.youngs_modulus;
    if (!(e > 0)) {
      // Automatic: the largest particle hitting a wall of its own material at the
      // fastest expected speed overlaps 2 % of its radius. Energy: 1/2 m v^2 =
      // 2/5 K d^5/2 with K = 4/3 E* sqrt(r), E* = E / (2 (1 - nu^2)).
      const double r = ts.r_max, d = 0.02 * r;
      const double k = 1.25 * mass(r) * v * v / (d * d * std::sqrt(d));
      e = 0.75 * k / std::sqrt(r) * 2 * (1 - nu * nu);
    }
    const double ew = c.wall_material_set && wm.youngs_modulus > 0 ? wm.youngs_modulus : e;
    ts.youngs_modulus = e;
    pl.e_star = e / (2 * (1 - nu * nu));
    pl.g_star = e / (4 * (2 - nu) * (1 + nu));
    wl.e_star = 1 / ((1 - nu * nu) / e + (1 - nw * nw) / ew);
    wl.g_star = 1 / (2 * (2 - nu) * (1 + nu) / e + 2 * (2 - nw) * (1 + nw) / ew);
    pl.eta = hertz_damping_factor(pm.restitution);
    wl.eta = wm.restitution == pm.restitution ? pl.eta : hertz_damping_factor(wm.restitution);
    // The stiffness at the deepest overlap of an impact at v: dF/dd = 3/2 K sqrt(d_max).
    auto stiffest = [&](double e_star, double r_eff, double m_eff) {
      const double k = 4.0 / 3.0 * e_star * std::sqrt(r_eff);
      const double d = std::pow(1.25 * m_eff * v * v / k, 0.4);
      return 1.5 * k * std::sqrt(d);
    };
    k_wall = stiffest(wl.e_star, ts.r_min, ts.m_min);
    k_pair = stiffest(pl.e_star, ts.r_min / 2, ts.m_min / 2);
  }
  ts.stiffness = k_wall, ts.damping_ratio = wl.zeta;
  ts.critical_step = critical_step(k_wall, ts.m_min, wl.zeta);
  if (c.particle_contacts) {
    const double pair_step = critical_step(k_pair, ts.m_min / 2, pl.zeta);
    if (pair_step < ts.critical_step)
      ts.critical_step = pair_step, ts.stiffness = k_pair, ts.damping_ratio = pl.zeta;
  }
  ts.spring_step = c.step_fraction * ts.critical_step;
  ts.explicit_step = c.time_step;
  ts.beyond_stable = c.time_step > ts.critical_step;
  ts.speed_bound = speed_bound(c, v_max, wall_box);
  ts.particle_contacts = c.particle_contacts;
  if (c.particle_contacts || (wall_lists_without_pairs(c) && !c.wall_motion.moving())) {
    // A rebuild every ~10 steps at the fastest expected speed, within bounds
    // that keep the lists short (large) and the rebuilds rare (small).
    const double step = c.time_step > 0 ? c.time_step : ts.spring_step;
    ts.neighbour_skin =
        c.neighbour_skin >= 0
            ? c.neighbour_skin
            : std::clamp(20 * impact_speed(c, v_max, wall_box) * step, 0.1 * r_min, 0.5 * r_min);
  }
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
                    double v_max, const Bounds3d& wall_box, double frame_duration,
                    uint64_t frames) {
  StepPlan plan;
  plan.contact = contact_time_step(c, r_min, r_max, r_mean, v_max, wall_box);
  plan.expected_speed = impact_speed(c, v_max, wall_box);
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
