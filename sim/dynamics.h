// Particle dynamics: the collision frames of a run. Each step detects wall
// contacts through the engine's prepared wall (bin or divided pieces), adds
// particle-particle contacts through a grid only when the scene asks for them,
// computes linear spring-dashpot forces (optional Coulomb friction with a
// tangential spring) and integrates with gravity. The time step comes from the
// physics: a fraction of the contact spring's critical step and a bound on how
// far a particle may move in one step.
//
// Units are SI throughout (m, kg, s); wall and particle coordinates are world units = metres.
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "sim/contact_force.h"
#include "sim/detect.h"
#include "sim/hd.h"
#include "sim/mesh.h"
#include "sim/status.h"

namespace collido::sim {

enum class Integrator {
  kSymplecticEuler,  // v += a dt, x += v dt: one force evaluation, first order
  kVelocityVerlet,   // half kick, drift, force, half kick: second order, same cost
};
const char* to_string(Integrator i);
bool parse_integrator(const std::string& s, Integrator* out);

const char* to_string(ContactModel m);
bool parse_contact_model(const std::string& s, ContactModel* out);

struct Material {
  double density = 2500;      // particle density, kg/m^3
  // Linear model: the normal contact spring, N/m; 0 = from youngs_modulus, else automatic.
  double stiffness = 0;
  // Pa. Linear: stiffness = E * mean radius. Hertz-Mindlin: the elastic modulus
  // itself (0 = automatic: a modulus that lets the fastest impact overlap 2 % of a radius).
  double youngs_modulus = 0;
  double poisson_ratio = 0.3;  // Hertz-Mindlin's shear modulus and effective moduli
  double restitution = 0.5;    // normal coefficient of restitution, (0, 1]
  double friction = 0;         // Coulomb coefficient; 0 = frictionless, no tangential state kept
  // Rolling resistance coefficient (constant torque mu_r F_n R*, against the rolling spin);
  // 0 = none: a ball rolls on forever.
  double rolling_friction = 0;
};

// How the wall moves (a rigid motion; the wall's triangles are given at time
// 0): the whole wall, or one part of it while the rest stands still (a paddle
// in a tank). The wall index is built once in the wall's own frame (a moving
// part's in its own): each step looks particles up there, so the motion costs
// a transform per particle, never a rebuild.
enum class WallMotionKind { kNone, kRotate, kTranslate, kOscillate };
const char* to_string(WallMotionKind k);

// The wall's pose at one time: world = R (body - c) + c + d; its velocity
// field v(p) = v + w x (p - c - d).
struct WallPose {
  Vec3d r0{1, 0, 0}, r1{0, 1, 0}, r2{0, 0, 1};  // rows of R
  Vec3d c{0, 0, 0}, d{0, 0, 0};                 // centre of rotation (body frame), offset
  Vec3d w{0, 0, 0}, v{0, 0, 0};                 // angular (rad/s) and linear (m/s) velocity
  bool moving = false;
  COLLIDO_HD Vec3d rotate(Vec3d b) const { return {dot(r0, b), dot(r1, b), dot(r2, b)}; }
  COLLIDO_HD Vec3d unrotate(Vec3d x) const {
    return r0 * x.x + r1 * x.y + r2 * x.z;  // R^T x
  }
  COLLIDO_HD Vec3d to_body(Vec3d x) const { return unrotate(x - c - d) + c; }
  COLLIDO_HD Vec3d to_world(Vec3d b) const { return rotate(b - c) + c + d; }
  COLLIDO_HD Vec3d velocity_at(Vec3d x) const { return v + cross(w, x - c - d); }
};

struct WallMotion {
  WallMotionKind kind = WallMotionKind::kNone;
  Vec3d axis{0, 0, 1};       // rotate: the axis; oscillate: the direction (normalised when used)
  Vec3d center{0, 0, 0};     // rotate: a point on the axis, world, m
  double angular_speed = 0;  // rotate: rad/s, right-handed about axis
  Vec3d velocity{0, 0, 0};   // translate: m/s
  double amplitude = 0;      // oscillate: m, d(t) = axis amplitude sin(2 pi frequency t)
  double frequency = 0;      // oscillate: Hz
  // One part moves: the wall's triangles [part_begin, part_end), whose box is
  // part_box; the others stand still. part_end = 0: the whole wall moves. A
  // scene names the part of its union (part, from 1); the job sets the range
  // and the box when it builds the wall. A part turns or shakes, never translates
  // (it would leave the rest behind for good).
  int part = 0;
  size_t part_begin = 0, part_end = 0;
  Bounds3d part_box;
  bool moving() const { return kind != WallMotionKind::kNone; }
  bool moves_part() const { return moving() && part_end > part_begin; }
  Vec3d unit_axis() const;  // axis normalised (z for a zero axis, which validation refuses)
  // The pose at time t, with `origin` subtracted from the centre (the engine's local frame).
  WallPose pose(double t, Vec3d origin = {0, 0, 0}) const;
  // The fastest any point of the wall moves (m/s), the wall's box given at time
  // 0 (a moving part's own box is part_box).
  double surface_speed(const Bounds3d& wall_box) const;
  // A box holding every place the wall reaches (rotation sweeps; a translation
  // or oscillation of the whole wall is followed by the domain check, which
  // moves with the wall; a part's shake is held, as the rest stands still).
  Bounds3d swept_box(const Bounds3d& wall_box) const;

 private:
  Bounds3d turned_box(const Bounds3d& box) const;
};

struct DynamicsConfig {
  Method method = Method::kBin;  // how the wall is prepared (bin or a division method)
  Backend backend = Backend::kCpu;
  Integrator integrator = Integrator::kVelocityVerlet;
  ContactModel contact_model = ContactModel::kLinear;
  Material material;
  // The wall's side of particle-wall contacts: the contact's restitution,
  // friction and rolling resistance, and the wall's own stiffness (linear; 0 =
  // the particles') or Young's modulus and Poisson's ratio (Hertz-Mindlin).
  // Unset: the particles' material throughout. density is not used.
  bool wall_material_set = false;
  Material wall_material;
  WallMotion wall_motion;
  Vec3d gravity{0, 0, -9.81};  // m/s^2
  bool particle_contacts = false;
  double time_step = 0;          // s; 0 = automatic (re-evaluated as speeds change)
  double step_fraction = 0.1;    // automatic: share of the critical step of the stiffest contact
  double motion_fraction = 0.1;  // automatic: largest travel per step, in smallest radii
  // Speed used to size the automatic stiffness (m/s): the fastest impact the
  // scene expects; 0 = estimated from the initial speeds and a fall across the wall's box.
  double impact_speed = 0;
  double grid_length = 0;     // wall cells, m; 0 = 2 r_max
  // Particle-particle candidates are kept in a neighbour list of every pair
  // within r_i + r_j + skin, and a still wall's in a list of the triangles
  // within r + skin / 2 (see wall_lists), rebuilt only when some particle has
  // moved half the skin since the last build (or a particle they do not hold
  // was released). m; < 0 = automatic (from the fastest expected speed and the
  // step, within 0.1-0.5 r_min, doubled up to 0.5 r_min while lists last under
  // 3 steps); 0 = search the grids every step.
  double neighbour_skin = -1;
  // With a neighbour list, how a pair's force is evaluated: once per pair, its
  // result then gathered by both particles (Newton's third law: half the
  // contact arithmetic, a pass and a record per listed pair more), or by each
  // of the two particles for itself. -1: the backend's faster way; 0: each
  // particle; 1: once per pair. The trajectories are the same bit for bit.
  int pairs_once = -1;
  // The CPU's AVX2 vectors (sim/pair_batch.h): pairs evaluated once four at
  // a time, and Verlet's opening pass four particles at a time; the same
  // bits as one at a time. -1: where the CPU has AVX2; 0: one at a time.
  int simd = -1;
  // With neighbour lists on the GPU: the threads that share a particle's
  // candidates (pairs from both sides, the wall's), 1, 2, 4 or 8; 0: the
  // backend's choice (several only where few particles would leave the GPU
  // idle). The CPU runs one. Only the order of the pair forces' sum differs
  // between counts; the wall's forces are the same bits.
  int lanes = 0;
  // When the particles are renumbered in the order of their cells (for
  // locality; results keep the caller's numbering): -1 at a list build where
  // the numbering has scattered (kScatteredCells); 0 never; N at the first
  // list build and every N-th after (counted from the start, a resume included).
  int renumber_every = -1;
  // With lists on the GPU: the steps launched between two looks at the lists'
  // check, which the device takes itself (a step after the one that calls a
  // build does nothing; the host then builds and launches it again). 0:
  // automatic, from the lists' life; 1: a look every step. The trajectories
  // are the same bit for bit.
  int run_ahead = 0;
  // Without particle contacts, whether the still wall's candidates are kept in
  // lists with the skin too (with them they always are), or searched every
  // step. -1: the backend's choice (wall_lists_without_pairs); 0 searched; 1 listed.
  int wall_lists = -1;
  double domain_margin = -1;  // escape distance outside the wall's box, m; < 0 = automatic
  uint64_t max_dense_cells = 1ull << 24;
  // A CPU scene of fewer particles steps on the calling thread alone, its wall
  // prepared on the pool's threads: a small step's passes are too short to
  // share (docs/dynamics.md). 0: every pass on the pool's threads.
  uint64_t one_thread_below = 1500;
  // Threads of the CPU backend, owned by the caller; nullptr = default_pool().
  ThreadPool* pool = nullptr;
};

// Particles at the start of a run (world units, SI). A particle takes part
// from its release time on (pour and jet placements release over time).
struct ParticleSet {
  std::vector<double> x, y, z, vx, vy, vz, r, release;
  size_t size() const { return x.size(); }
  void resize(size_t n);
};

// Per-particle state in download()'s flags: the low two bits.
enum ParticleState : uint8_t {
  kWaiting = 0,  // not released yet
  kActive = 1,
  kEscaped = 2,  // left the domain (the wall's box grown by the margin); frozen and counted
  kInvalid = 3,  // a non-finite position or velocity appeared; frozen and counted
};
inline constexpr uint8_t kStateMask = 3;
inline constexpr uint8_t kFlagWallContact = 4;      // touches the wall in the last step
inline constexpr uint8_t kFlagParticleContact = 8;  // touches another particle in the last step

// How the time step was chosen: printed by the CLI and written with the run.
struct TimeStepInfo {
  // N/m: the linear model's particle stiffness; Hertz-Mindlin's stiffness of
  // the stiffest contact at the fastest expected impact (what sizes the step).
  double stiffness = 0;
  double damping_ratio = 0;    // from the restitution (of the contact that sizes the step)
  double youngs_modulus = 0;   // Pa, Hertz-Mindlin: as used (given or automatic)
  ContactLaw pair_law, wall_law;  // the contact laws as sized
  double critical_step = 0;    // s: explicit stability bound of the stiffest contact
  double spring_step = 0;      // s: step_fraction * critical_step
  double explicit_step = 0;    // s: the scene's fixed step (0 = automatic)
  bool beyond_stable = false;  // the fixed step exceeds the critical one
  double r_min = 0, r_max = 0, m_min = 0;
  // m/s: the fastest speed the scene's energy allows (the fastest initial speed
  // plus a fall across the wall's box); contacts only take energy away.
  // (plus the fastest the wall moves, when it moves).
  double speed_bound = 0;
  // J: the most kinetic energy all particles together may hold (each at
  // speed_bound); with particle contacts only the total is bounded. 0 = unknown.
  double kinetic_bound = 0;
  bool particle_contacts = false;
  double neighbour_skin = 0;  // m, as used (0: the grid is searched every step)
};

// What one frame ended with, for the stats file and the progress line.
struct FrameStats {
  uint64_t frame = 0;
  double time = 0;                // s
  uint64_t substeps = 0;          // steps taken in this frame
  double dt_min = 0, dt_max = 0;  // s, over the frame's steps
  uint64_t waiting = 0, active = 0, escaped = 0, invalid = 0;
  uint64_t held = 0;  // of the waiting, those due whose place is still taken (a jammed inlet)
  uint64_t wall_contacts = 0;      // one per touched wall feature
  uint64_t particle_contacts = 0;  // pairs
  uint64_t touching_wall = 0;      // particles with at least one wall contact
  double kinetic = 0;              // J, translation and rotation
  double potential = 0;            // J, gravity, relative to the wall's centre
  double elastic = 0;              // J, stored in the contact springs
  double max_speed = 0;            // m/s
  double max_overlap = 0;          // deepest overlap as a share of that particle's radius
  uint64_t history_overflow =
      0;  // friction contacts beyond the per-particle slots (no memory kept)
  // Over every step of the frame (not only its end), the two precursors of
  // tunnelling: the longest move of one step, in smallest radii (read at each
  // speed check), and the deepest wall overlap, as a share of the radius.
  double peak_travel = 0;
  double peak_wall_overlap = 0;
  double peak_speed = 0;  // m/s, the fastest speed read during the frame (a particle may leave after)
  double total_energy() const { return kinetic + potential + elastic; }
};

// Milliseconds spent in each part of the steps since timing was switched on
// (each stage ends with a device sync, so the sum is a little above untimed steps).
struct StepTimes {
  uint64_t steps = 0;
  uint64_t neighbour_builds = 0;  // neighbour-list builds within those steps
  // GPU steps launched ahead of the lists' check (run_ahead) that a build made
  // void, so they were launched again.
  uint64_t steps_retaken = 0;
  // Reads of the steps launched ahead (their lists' check) and of the fastest
  // speed, each a wait for the device on the GPU: the count shows whether
  // advance shares one wait between them.
  uint64_t waits = 0;
  double drift_ms = 0, grid_ms = 0, pair_ms = 0, wall_ms = 0, kick_ms = 0;
};

// The changing part of a run (positions, velocities, spins, accelerations,
// states, friction springs, time, step count) at a frame boundary, as plain
// bytes: what a checkpoint saves. The constant part (the prepared wall, the
// contact law, the time-step plan) is rebuilt from the scene by create().
struct SimState {
  uint64_t particles = 0;
  double time = 0;  // s
  uint64_t steps = 0;
  bool all_released = false;
  std::vector<std::vector<uint8_t>> arrays;  // the backend's buffers, in the pipeline's order
  // The neighbour lists as they were built (their skin, when and where, the
  // build count): a run restored with them builds its next lists at the step
  // the saved run would have, so it renumbers and sums its forces alike.
  // Empty: none, or a state saved without them (the lists are built afresh).
  std::vector<std::vector<uint8_t>> lists;
};

class Simulation {
 public:
  virtual ~Simulation() = default;
  // Prepares the wall and loads the particles. Errors name the bad setting.
  static Expected<std::unique_ptr<Simulation>> create(const TriangleMesh& wall,
                                                      const DynamicsConfig& config,
                                                      const ParticleSet& particles);

  // Advances the state by `duration` seconds in steps of the automatic (or the
  // fixed) size and measures the end state into *stats (frame and time set).
  virtual Status advance(double duration, FrameStats* stats) = 0;
  // Exactly `steps` steps of `dt` seconds, no step control (tests, benchmarks).
  virtual Status step(uint64_t steps, double dt) = 0;
  // Measures the current state.
  virtual Status measure(FrameStats* stats) = 0;
  // Copies the state back: positions and velocities in world units (release
  // kept from the input) and per-particle flags (ParticleState | contact bits).
  virtual Status download(ParticleSet* state, std::vector<uint8_t>* flags) = 0;

  // Copies the changing state out / back in. restore_state() takes only a state
  // saved by a Simulation created from the same wall, config and particles;
  // the run then continues exactly as the saved one would have.
  virtual Status save_state(SimState* out) = 0;
  virtual Status restore_state(const SimState& state) = 0;

  // Times each stage of the following steps (benchmarks); off by default.
  virtual void set_stage_timing(bool on) = 0;
  virtual const StepTimes& stage_times() const = 0;

  virtual const TimeStepInfo& time_step_info() const = 0;
  virtual const PrepareInfo& wall_info() const = 0;
  virtual double time() const = 0;  // s
  virtual uint64_t steps_taken() const = 0;
  virtual uint64_t device_bytes() const = 0;  // memory held by the backend
  // Host threads the steps run on: the pool's, 1 for a small CPU scene
  // (DynamicsConfig::one_thread_below), 0 on the GPU.
  virtual int step_threads() const = 0;
};

// The materials, the contact model and the wall's motion checked together (what
// Simulation::create checks before anything else); the message names the key
// ("wall_material.stiffness: ..."). The scene parser calls it too, so a scene
// document is refused when it is read, not when its run starts.
Status check_contact_settings(const DynamicsConfig& config);

// What a frame says about the run's health: the three ways a setting fails.
struct FrameWarnings {
  bool blow_up = false;      // non-finite values, or speeds beyond what the scene's energy allows
  bool tunnel_risk = false;  // a step or an overlap deep enough for a centre to cross a wall
  std::string message;       // one line naming what was seen, empty when healthy
};
// Speeds above this multiple of TimeStepInfo::speed_bound (without particle
// contacts; with them, kinetic energy above its square times kinetic_bound)
// mean energy was created.
inline constexpr double kRunawaySpeedFactor = 1.25;
// A fixed step above this share of the critical step is flagged as a blow-up risk.
inline constexpr double kUnstableStepShare = 0.95;
// A move or a wall overlap beyond this share of a radius can carry a centre through a thin wall.
inline constexpr double kTunnelRiskShare = 0.5;
FrameWarnings frame_warnings(const FrameStats& stats, const TimeStepInfo& ts);

// Linear spring-dashpot damping ratio for a restitution e in (0, 1].
double damping_ratio(double restitution);
// Hertz-Mindlin's damping factor eta (gamma = eta sqrt(m_eff S)) that gives the
// restitution e in (0, 1]: the rebound of the Hertz contact with that damping
// does not depend on the impact speed, so it is solved once, by integrating the
// dimensionless contact and bisecting on eta.
double hertz_damping_factor(double restitution);
// The restitution that damping factor gives (the integration alone).
double hertz_restitution(double eta);

// ---- The time-step plan, known before a run ------------------------------------
// Simulation::create() sizes the contact spring and its step from these same
// functions; exposing them lets a job's steps be counted (and priced) from the
// scene alone, before any particle is placed.

// Steps between re-evaluations of the motion bound (the fastest speed).
inline constexpr int kSpeedCheckInterval = 8;
// With a neighbour list the engine renumbers the particles in the order of
// their cells (results come back in the caller's numbering) when, at a list
// build, consecutively numbered particles lie on average more than this many
// cells apart (each distance counted up to 64 cells).
inline constexpr double kScatteredCells = 4;

// Whether a scene without particle contacts keeps its still wall's candidates
// in lists (DynamicsConfig::wall_lists): the CPU does by default; the GPU
// searches a binned wall every step: with the lists' check waiting on the host
// every step the H200 log's jobs without pairs ran a median 2.0 times as long,
// and without the wait (run_ahead) the lists win only at 10^6 particles. A
// divided wall is listed on the GPU too: a search visits every piece in up to
// 27 cells around a particle, and a pour of 2,925 into a finely divided
// cylinder took 620 us a step searched, 50 listed (docs/dynamics.md).
bool wall_lists_without_pairs(const DynamicsConfig& config);

// The contact laws and the critical step they allow, from the material, the
// particle radii (m; r_mean sizes a stiffness from youngs_modulus), the fastest
// initial speed v_max (m/s) and the wall's bounding box at time 0 (m; the
// longest fall along gravity and the wall's own speed size the automatic stiffness).
TimeStepInfo contact_time_step(const DynamicsConfig& config, double r_min, double r_max,
                               double r_mean, double v_max, const Bounds3d& wall_box);

// The automatic step (s) at the fastest current speed v_max (m/s): the spring
// step, or less where a particle would travel more than motion_fraction of the
// smallest radius before the next speed check (speed may grow by g over those
// steps), never below a thousandth of the spring step. g is |gravity|, m/s^2.
inline double automatic_step_size(double spring_step, double motion_fraction, double r_min,
                                  double v_max, double g) {
  const double vb = v_max + g * spring_step * kSpeedCheckInterval;
  double dt = spring_step;
  if (vb > 0) dt = std::min(dt, motion_fraction * r_min / vb);
  return std::max(dt, spring_step * 1e-3);
}

// The steps a run will take, planned from the scene before it runs.
struct StepPlan {
  TimeStepInfo contact;        // as Simulation::create() will size it
  double expected_speed = 0;   // m/s: the fastest speed the motion bound is sized for
  double step = 0;             // s: the step expected (fixed, or automatic at expected_speed)
  bool motion_limited = false; // the motion bound, not the spring, sets the step
  uint64_t steps_per_frame = 0;
  uint64_t steps = 0;          // over every frame
};

// The plan for `frames` frames of frame_duration seconds each. The automatic
// step is evaluated at the fastest speed the scene expects: the initial speed
// plus a fall across the wall's box (the speed the automatic stiffness is sized
// for), or impact_speed when the scene gives it. Where the spring sets the step
// (the automatic stiffness always makes it so: its step is about 0.004 r_max / v
// against the motion bound's 0.1 r_min / v) the count is exact; where the
// motion bound does, it is an upper estimate (particles are slower most of the run).
StepPlan plan_steps(const DynamicsConfig& config, double r_min, double r_max, double r_mean,
                    double v_max, const Bounds3d& wall_box, double frame_duration,
                    uint64_t frames);

}  // namespace collido::sim
