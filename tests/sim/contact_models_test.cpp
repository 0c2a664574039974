// Contact models and moving walls against what the physics says: the Hertz
// contact's analytic duration and the requested restitution, rolling
// resistance's stopping distance, a wall material of its own, a plate that
// vibrates, a turntable, and a rotating drum whose bed settles at one angle
// (CPU and GPU, two time steps). The GPU suite runs the same scenes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "sim/dynamics.h"
#include "sim/parallel.h"
#include "sim/shapes.h"
#include "tests/sim/dynamics_scenes.h"
#include "tests/sim/gpu_suite.h"

namespace collido::sim {
namespace {

double sphere_mass(double density, double r) { return density * 4.0 / 3.0 * M_PI * r * r * r; }

// The undamped Hertz contact at impact speed v: t_c = 2 B(2/5, 1/2) / (5/2) d_max / v,
// d_max = (5 m v^2 / (4 K))^(2/5), K = 4/3 E* sqrt(R*).
double hertz_duration(double m_eff, double r_eff, double e_star, double v) {
  const double k = 4.0 / 3.0 * e_star * std::sqrt(r_eff);
  const double d_max = std::pow(1.25 * m_eff * v * v / k, 0.4);
  const double integral = 0.4 * std::tgamma(0.4) * std::tgamma(0.5) / std::tgamma(0.9);
  return 2 * integral * d_max / v;
}

TEST(HertzDamping, GivesTheRestitutionAskedFor) {
  EXPECT_EQ(hertz_damping_factor(1.0), 0.0);
  EXPECT_NEAR(hertz_restitution(0.0), 1.0, 1e-6);
  for (double e : {0.05, 0.3, 0.5, 0.9, 0.99})
    EXPECT_NEAR(hertz_restitution(hertz_damping_factor(e)), e, 1e-6) << e;
  // The DEM codes' closed form, 2 sqrt(5/6) |ln e| / sqrt(ln^2 e + pi^2), is close at e = 0.5.
  const double l = std::log(0.5);
  EXPECT_NEAR(hertz_damping_factor(0.5), 2 * std::sqrt(5.0 / 6) * -l / std::hypot(l, M_PI), 2e-3);
}

// One Hertz-Mindlin impact, stepped finely, on the wall (a particle falling on
// the floor of a box whose material is stiffer) or between two particles
// (head on): the steps in contact against the analytic duration, and the
// rebound speed against the restitution.
struct Impact {
  double duration = 0, analytic = 0, rebound = 0;  // s, s, share of the impact speed
};
Impact hertz_impact(bool pair, double e, double v) {
  const TriangleMesh box = make_box(1, 1, 1);
  DynamicsConfig cfg;
  cfg.gravity = {0, 0, 0};
  cfg.contact_model = ContactModel::kHertzMindlin;
  cfg.material.youngs_modulus = 1e8;
  cfg.material.poisson_ratio = 0.3;
  cfg.material.restitution = e;
  cfg.particle_contacts = pair;
  cfg.wall_material_set = true;
  cfg.wall_material = cfg.material;
  cfg.wall_material.youngs_modulus = 1e9;
  cfg.wall_material.poisson_ratio = 0.25;
  const double r = 0.01, gap = 1e-5, m = sphere_mass(cfg.material.density, r);
  Impact out;
  ParticleSet p;
  double e_star = 0;
  if (pair) {
    p = particles_at({{-r - gap, 0, 0.5}, {r + gap, 0, 0.5}}, {{v, 0, 0}, {-v, 0, 0}}, r);
    e_star = 1e8 / (2 * (1 - 0.09));
    out.analytic = hertz_duration(m / 2, r / 2, e_star, 2 * v);
  } else {
    p = particles_at({{0, 0, r + gap}}, {{0, 0, -v}}, r);
    e_star = 1 / ((1 - 0.09) / 1e8 + (1 - 0.0625) / 1e9);
    out.analytic = hertz_duration(m, r, e_star, v);
  }
  auto s = make_sim(box, cfg, p);
  if (!s) return out;
  const double dt = out.analytic / 2000;
  uint64_t in_contact = 0;
  const int steps = int(2 * gap / v / dt) + 4000;
  for (int k = 0; k < steps; ++k) {
    EXPECT_TRUE(s->step(1, dt));
    const FrameStats st = measure(*s);
    in_contact += (pair ? st.particle_contacts : st.wall_contacts) > 0;
  }
  ParticleSet end;
  EXPECT_TRUE(s->download(&end, nullptr));
  out.duration = double(in_contact) * dt;
  out.rebound = pair ? -end.vx[0] / v : end.vz[0] / v;
  return out;
}

void hertz_impacts_follow_the_theory() {
  for (bool pair : {false, true}) {
    const Impact elastic = hertz_impact(pair, 1.0, 1.0);
    std::printf("%s: contact %.4g us, analytic %.4g us, rebound %.4f\n", pair ? "pair" : "wall",
                1e6 * elastic.duration, 1e6 * elastic.analytic, elastic.rebound);
    EXPECT_NEAR(elastic.duration, elastic.analytic, 0.02 * elastic.analytic) << pair;
    EXPECT_NEAR(elastic.rebound, 1.0, 0.02) << pair;
    // The damping is solved for the restitution, which then holds at any speed.
    for (double v : {0.5, 4.0}) {
      const Impact damped = hertz_impact(pair, 0.5, v);
      std::printf("%s at %.1f m/s, e = 0.5: rebound %.4f\n", pair ? "pair" : "wall", v,
                  damped.rebound);
      EXPECT_NEAR(damped.rebound, 0.5, 0.01) << pair << " " << v;
    }
  }
}

// Rolling resistance (constant torque mu_r F_n r) stops a ball launched
// sliding along a floor. Sliding first: friction mu g slows it and spins it up
// against the rolling torque until v = w r at t1 = v0 / (g (mu + 5/2 (mu - mu_r))),
// then it rolls, slowing at 5/7 mu_r g: distance x1 + 7 v1^2 / (10 mu_r g).
void rolling_resistance_stops_the_ball(ContactModel model) {
  const TriangleMesh floor = floor_mesh(5, 4);
  DynamicsConfig cfg;
  cfg.contact_model = model;
  cfg.material.restitution = 0.3;
  cfg.material.friction = 0.5;
  cfg.material.rolling_friction = 0.05;
  cfg.impact_speed = 1;
  const double r = 0.05, v0 = 1, g = 9.81, mu = 0.5, mr = 0.05;
  auto probe = make_sim(floor, cfg, particles_at({{0, 0, r}}, {}, r));
  ASSERT_TRUE(probe);
  // Start at rest height: let it settle, then launch it from there.
  FrameStats st;
  ASSERT_TRUE(probe->advance(0.2, &st));
  ParticleSet rest;
  ASSERT_TRUE(probe->download(&rest, nullptr));
  auto s = make_sim(floor, cfg, particles_at({{-3, 0, rest.z[0]}}, {{v0, 0, 0}}, r));
  ASSERT_TRUE(s);
  double t = 0;
  for (; t < 4; t += 0.05) ASSERT_TRUE(s->advance(0.05, &st));
  ParticleSet end;
  ASSERT_TRUE(s->download(&end, nullptr));
  const double t1 = v0 / (g * (mu + 2.5 * (mu - mr)));
  const double v1 = v0 - mu * g * t1, x1 = v0 * t1 - 0.5 * mu * g * t1 * t1;
  const double expected = x1 + 7 * v1 * v1 / (10 * mr * g);
  const double travelled = end.x[0] + 3;
  std::printf("%s: stopped after %.4f m, model %.4f m, speed %.2g m/s\n", to_string(model),
              travelled, expected, std::hypot(end.vx[0], end.vy[0]));
  EXPECT_NEAR(travelled, expected, 0.05 * expected);
  EXPECT_LT(std::hypot(end.vx[0], end.vy[0]), 1e-3);
  // Without rolling resistance it rolls on at 5/7 of its speed.
  cfg.material.rolling_friction = 0;
  auto free = make_sim(floor, cfg, particles_at({{-3, 0, rest.z[0]}}, {{v0, 0, 0}}, r));
  ASSERT_TRUE(free);
  ASSERT_TRUE(free->advance(1.0, &st));
  ASSERT_TRUE(free->download(&end, nullptr));
  EXPECT_NEAR(end.vx[0], v0 * 5 / 7, 0.02);
}

// The wall's side of the contact has its own restitution: a ball of e = 0.2
// bounces off a wall material of e = 0.9 at 0.9 of its speed.
void wall_material_sets_the_wall_contact() {
  DynamicsConfig cfg;
  cfg.gravity = {0, 0, 0};
  cfg.material.restitution = 0.2;
  cfg.material.stiffness = 1e6;
  cfg.wall_material_set = true;
  cfg.wall_material = cfg.material;
  cfg.wall_material.stiffness = 0;  // the particles' spring
  cfg.wall_material.restitution = 0.9;
  EXPECT_NEAR(rebound_speed(cfg), 2 * 0.9, 0.03 * 2 * 0.9);
}

// A ball on a plate vibrating up and down with amplitude A and frequency f:
// below one g of peak acceleration (A (2 pi f)^2 < g) it rides the plate, rising
// and falling 2 A; above, the plate throws it and it spends time in the air.
void vibrating_plate(double gamma, bool* airborne, double* rise) {
  const TriangleMesh plate = floor_mesh(1, 2);
  DynamicsConfig cfg;
  cfg.material.restitution = 0.5;
  cfg.material.friction = 0.3;
  const double a = 1e-3, f = std::sqrt(gamma * 9.81 / a) / (2 * M_PI), r = 0.01;
  cfg.wall_motion.kind = WallMotionKind::kOscillate;
  cfg.wall_motion.axis = {0, 0, 1};
  cfg.wall_motion.amplitude = a;
  cfg.wall_motion.frequency = f;
  cfg.impact_speed = 0.5;
  auto s = make_sim(plate, cfg, particles_at({{0, 0, r * 0.999}}, {}, r));
  ASSERT_TRUE(s);
  FrameStats st;
  double lo = 1e9, hi = -1e9;
  uint64_t frames_off = 0;
  for (int k = 0; k < 400; ++k) {
    ASSERT_TRUE(s->advance(1.0 / (40 * f), &st));  // 40 samples a period, 10 periods
    ParticleSet p;
    ASSERT_TRUE(s->download(&p, nullptr));
    if (k >= 80) {
      lo = std::min(lo, p.z[0]), hi = std::max(hi, p.z[0]);
      frames_off += st.touching_wall == 0;
    }
    ASSERT_EQ(st.escaped, 0u);
    ASSERT_GT(p.z[0], -a);  // never below the plate's lowest point
  }
  *airborne = frames_off > 0;
  *rise = hi - lo;
}

void plates_carry_or_throw() {
  bool airborne = false;
  double rise = 0;
  vibrating_plate(0.5, &airborne, &rise);
  EXPECT_FALSE(airborne);
  EXPECT_NEAR(rise, 2e-3, 0.1e-3);  // rides the plate: 2 A up and down
  vibrating_plate(3.0, &airborne, &rise);
  EXPECT_TRUE(airborne);
  EXPECT_GT(rise, 3e-3);
}

// A ball on a turntable turning at W: once it rolls without slipping, its
// centre circles at 2/7 W in the lab (the classic result for a solid sphere),
// which needs the table's velocity at the contact point and the ball's spin.
// A table turning at w rad/s about the z axis, and a grippy ball on it.
DynamicsConfig turntable(double w) {
  DynamicsConfig cfg;
  cfg.material.restitution = 0.3;
  cfg.material.friction = 0.8;
  cfg.impact_speed = 1;
  cfg.wall_motion.kind = WallMotionKind::kRotate;
  cfg.wall_motion.axis = {0, 0, 1};
  cfg.wall_motion.angular_speed = w;
  return cfg;
}

void turntable_ball_circles_at_two_sevenths() {
  const TriangleMesh table = floor_mesh(1, 4);
  const double w = 3, r = 0.02;
  auto s = make_sim(table, turntable(w), particles_at({{0.3, 0, r * 0.9999}}, {}, r));
  ASSERT_TRUE(s);
  FrameStats st;
  double heading0 = 0, heading = 0, last = 0;
  const double dt = 0.02, settle = 1.0, span = 4.0;
  for (double t = 0; t < settle + span - 1e-9; t += dt) {
    ASSERT_TRUE(s->advance(dt, &st));
    ParticleSet p;
    ASSERT_TRUE(s->download(&p, nullptr));
    ASSERT_EQ(st.escaped, 0u);
    const double a = std::atan2(p.vy[0], p.vx[0]);
    if (t + dt < settle - 1e-9) {
      last = a;
      continue;
    }
    double d = a - last;  // unwrapped change of the heading
    d -= 2 * M_PI * std::round(d / (2 * M_PI));
    heading += d;
    last = a;
    if (std::fabs(t + dt - settle) < 1e-9) heading0 = heading;
  }
  const double rate = (heading - heading0) / (span - dt);
  std::printf("turntable at %.2f rad/s: the ball's heading turns at %.4f rad/s (2/7 W = %.4f)\n",
              w, rate, 2 * w / 7);
  EXPECT_NEAR(rate, 2 * w / 7, 0.02 * 2 * w / 7);
}

// A drum of radius R lying on its side (axis y), a third full of spheres,
// turning at w: the bed's angle, from where its centroid sits (a flat free
// surface is perpendicular to the line from the axis to the bed's centroid).
struct DrumResult {
  double angle = 0;  // degrees, averaged over the last second
  double outside = 0;  // the farthest any centre got beyond R - r (m; <= 0 inside)
  uint64_t escaped = 0;
};
DrumResult rotating_drum(double step_fraction, uint64_t* particles = nullptr) {
  const double R = 0.05, h = 0.02, r = 0.003, w = 2.0;
  TriangleMesh drum = make_cylinder(R, h, 48);
  for (Vec3d& v : drum.vertices) v = {v.x, v.z, -v.y};  // axis along y, from y = 0 to h
  std::vector<Vec3d> pos;
  for (double y : {0.0035, 0.01, 0.0165})
    for (double x = -0.045; x <= 0.045; x += 0.0066)
      for (double z = -0.045; z <= 0.0; z += 0.0066)
        if (std::hypot(x, z) < R - 1.5 * r) pos.push_back({x, y, z});
  DynamicsConfig cfg;
  cfg.particle_contacts = true;
  cfg.material.restitution = 0.5;
  cfg.material.friction = 0.5;
  cfg.material.rolling_friction = 0.05;
  cfg.impact_speed = 0.3;
  cfg.step_fraction = step_fraction;
  cfg.wall_motion.kind = WallMotionKind::kRotate;
  cfg.wall_motion.axis = {0, 1, 0};
  cfg.wall_motion.center = {0, h / 2, 0};
  cfg.wall_motion.angular_speed = w;
  // A few hundred particles: one thread (a pool's hand-offs would cost more than the work).
  ThreadPool pool(1);
  cfg.pool = &pool;
  if (particles) *particles = pos.size();
  DrumResult out;
  auto s = make_sim(drum, cfg, particles_at(pos, {}, r));
  if (!s) return out;
  FrameStats st;
  int samples = 0;
  out.outside = -R;
  for (int k = 0; k < 30; ++k) {
    EXPECT_TRUE(s->advance(0.05, &st));
    ParticleSet p;
    EXPECT_TRUE(s->download(&p, nullptr));
    for (size_t i = 0; i < p.size(); ++i)
      out.outside = std::max(out.outside, std::hypot(p.x[i], p.z[i]) - (R - r));
    out.escaped = st.escaped + st.invalid;
    if (k < 20) continue;  // 1 s to reach the steady bed
    double cx = 0, cz = 0;
    for (size_t i = 0; i < p.size(); ++i) cx += p.x[i], cz += p.z[i];
    out.angle += std::atan2(std::fabs(cx), -cz) * 180 / M_PI;
    ++samples;
  }
  out.angle /= samples;
  return out;
}

void drum_bed_keeps_its_angle_and_its_wall() {
  uint64_t n = 0;
  const DrumResult a = rotating_drum(0.2, &n), b = rotating_drum(0.1);
  std::printf("drum, %llu spheres: bed angle %.2f deg (step fraction 0.2), %.2f deg (0.1); "
              "closest to the wall %.3g r inside it\n",
              (unsigned long long)n, a.angle, b.angle, -a.outside / 0.003);
  EXPECT_GT(a.angle, 10.0);  // the turning wall lifts the bed ...
  EXPECT_LT(a.angle, 60.0);  // ... and it slides back at a finite angle
  EXPECT_NEAR(a.angle, b.angle, 3.0);
  for (const DrumResult& d : {a, b}) {
    EXPECT_EQ(d.escaped, 0u);
    EXPECT_LT(d.outside, 0.1 * 0.003);  // no centre passes the turning wall
  }
}

// A moving part is the whole wall moving where the rest is never touched: a
// ball on a turntable, the table alone turning against the table turning as
// one part of a union whose other part (a box) lies far away. The engine
// prepares the two in frames of their own, so the paths agree to rounding.
void a_part_moves_as_the_whole_wall_would() {
  const double r = 0.02;
  const DynamicsConfig cfg = turntable(3);
  const TriangleMesh table = floor_mesh(1, 4);
  TriangleMesh both = make_box(0.5, 0.5, 0.5);
  translate(both, {5, 0, 0});
  const size_t box_triangles = both.triangles.size();
  append_mesh(both, table);
  DynamicsConfig part = cfg;
  part.wall_motion.part_begin = box_triangles;
  part.wall_motion.part_end = both.triangles.size();
  const ParticleSet ball = particles_at({{0.3, 0, r * 0.9999}}, {}, r);
  auto whole = make_sim(table, cfg, ball);
  auto one_part = make_sim(both, part, ball);
  ASSERT_TRUE(whole && one_part);
  FrameStats a, b;
  for (int k = 0; k < 25; ++k) {
    ASSERT_TRUE(whole->advance(0.04, &a));
    ASSERT_TRUE(one_part->advance(0.04, &b));
  }
  ParticleSet pa, pb;
  ASSERT_TRUE(whole->download(&pa, nullptr));
  ASSERT_TRUE(one_part->download(&pb, nullptr));
  EXPECT_EQ(a.escaped + b.escaped, 0u);
  EXPECT_EQ(b.wall_contacts, a.wall_contacts);
  const double moved = std::hypot(pa.x[0] - 0.3, pa.y[0]);
  EXPECT_GT(moved, 0.05);  // the table carried it round
  EXPECT_NEAR(pb.x[0], pa.x[0], 1e-9);
  EXPECT_NEAR(pb.y[0], pa.y[0], 1e-9);
  EXPECT_NEAR(pb.z[0], pa.z[0], 1e-9);
  EXPECT_NEAR(pb.vx[0], pa.vx[0], 1e-7);
  EXPECT_NEAR(pb.vy[0], pa.vy[0], 1e-7);
}

// A paddle turning in a still cup: the balls in its sweep are pushed round
// the way it turns and thrown to the cup's wall, never through the paddle,
// the wall or the floor; a ball on the floor beyond the paddle's reach stays
// where it is (the floor does not turn).
struct Stirred {
  double spin = 0;       // the swept balls' mean angular velocity about the axis at the end, rad/s
  double outside = 0;    // farthest any centre got beyond the cup's wall (R - r; <= 0 inside)
  double lowest = 1;     // lowest centre over the run, m (r when resting on the floor)
  double lone_moved = 0;  // how far the ball beyond the paddle moved, m
  uint64_t escaped = 0;
  uint64_t hit_paddle = 0;  // frames in which some ball touched the paddle
};
Stirred stirred_cup() {
  const double R = 0.1, r = 0.005, w = 2 * M_PI;  // one turn a second
  TriangleMesh cup = make_cylinder(R, 0.08, 64, Caps::kBottom);
  const size_t cup_triangles = cup.triangles.size();
  TriangleMesh paddle = make_box(0.15, 0.012, 0.04);
  translate(paddle, {0, 0, 0.006});
  append_mesh(cup, paddle);
  DynamicsConfig cfg = turntable(w);  // the paddle turns as the table did
  cfg.material.restitution = 0.4;
  cfg.material.friction = 0.3;
  cfg.wall_motion.center = {0, 0, 0.026};
  cfg.wall_motion.part_begin = cup_triangles;
  cfg.wall_motion.part_end = cup.triangles.size();
  std::vector<Vec3d> pos;
  for (int k = 0; k < 8; ++k) {  // between the paddle's arms at t = 0
    const double a = M_PI / 4 + k * M_PI / 2 + (k >= 4 ? 0.3 : 0.0);
    const double rho = k >= 4 ? 0.06 : 0.035;
    pos.push_back({rho * std::cos(a), rho * std::sin(a), r});
  }
  const Vec3d lone{0.09 * std::cos(0.2), 0.09 * std::sin(0.2), r};  // beyond the paddle's tip (0.075 + r)
  pos.push_back(lone);
  ThreadPool pool(1);
  cfg.pool = &pool;
  Stirred out;
  auto s = make_sim(cup, cfg, particles_at(pos, {}, r));
  if (!s) return out;
  out.outside = -R;
  FrameStats st;
  ParticleSet p;
  for (int k = 0; k < 40; ++k) {
    EXPECT_TRUE(s->advance(0.025, &st));
    EXPECT_TRUE(s->download(&p, nullptr));
    for (size_t i = 0; i < p.size(); ++i) {
      out.outside = std::max(out.outside, std::hypot(p.x[i], p.y[i]) - (R - r));
      out.lowest = std::min(out.lowest, p.z[i]);
    }
    out.escaped = st.escaped + st.invalid;
    // The paddle's arm at this time: a ball within r of its box, in its frame.
    const double a = -w * (k + 1) * 0.025;
    for (size_t i = 0; i + 1 < p.size(); ++i) {
      const double bx = std::cos(a) * p.x[i] - std::sin(a) * p.y[i];
      const double by = std::sin(a) * p.x[i] + std::cos(a) * p.y[i];
      if (std::fabs(bx) < 0.075 + r && std::fabs(by) < 0.006 + r * 1.01) {
        ++out.hit_paddle;
        break;
      }
    }
  }
  for (size_t i = 0; i + 1 < p.size(); ++i)
    out.spin += (p.x[i] * p.vy[i] - p.y[i] * p.vx[i]) / (p.x[i] * p.x[i] + p.y[i] * p.y[i]);
  out.spin /= double(p.size() - 1);
  out.lone_moved = std::hypot(p.x.back() - lone.x, p.y.back() - lone.y);
  return out;
}

void a_paddle_stirs_a_still_cup() {
  const Stirred s = stirred_cup();
  std::printf("paddle at 1 turn/s: the balls turn at %.2f rad/s, the one beyond it moved %.2g m, "
              "%llu frames touching the paddle\n",
              s.spin, s.lone_moved, (unsigned long long)s.hit_paddle);
  EXPECT_GT(s.spin, 0.5);  // pushed round the way the paddle turns (2 pi rad/s)
  EXPECT_LT(s.spin, 2 * M_PI * 1.2);
  EXPECT_GT(s.hit_paddle, 3u);
  EXPECT_LT(s.lone_moved, 1e-6);
  EXPECT_EQ(s.escaped, 0u);
  EXPECT_LT(s.outside, 0.1 * 0.005);  // nothing passes the cup's wall ...
  EXPECT_GT(s.lowest, 0.9 * 0.005);   // ... or its floor
}

TEST(ContactModels, HertzImpactsLastTheAnalyticTimeAndKeepTheRestitution) {
  hertz_impacts_follow_the_theory();
}
TEST(ContactModels, RollingResistanceStopsABallWhereTheModelSays) {
  rolling_resistance_stops_the_ball(ContactModel::kLinear);
  rolling_resistance_stops_the_ball(ContactModel::kHertzMindlin);
}
TEST(ContactModels, WallMaterialSetsTheWallContact) { wall_material_sets_the_wall_contact(); }
TEST(MovingWalls, AVibratingPlateCarriesOrThrowsABall) { plates_carry_or_throw(); }
TEST(MovingWalls, ABallOnATurntableCirclesAtTwoSevenths) {
  turntable_ball_circles_at_two_sevenths();
}
TEST(MovingWalls, ARotatingDrumBedKeepsOneAngleAndStaysInside) {
  drum_bed_keeps_its_angle_and_its_wall();
}

TEST(MovingWalls, APartMovesAsTheWholeWallWould) { a_part_moves_as_the_whole_wall_would(); }
TEST(MovingWalls, APaddleStirsAStillCup) { a_paddle_stirs_a_still_cup(); }
TEST(ContactModels, BadSettingsNameTheKey) {
  const TriangleMesh box = make_box(10, 10, 10);
  const ParticleSet p = particles_at({{0, 0, 2}}, {}, 0.5);
  auto expect_error = [&](const DynamicsConfig& c, const std::string& key) {
    auto s = Simulation::create(box, c, p);
    ASSERT_FALSE(s.has_value()) << key;
    EXPECT_NE(s.status().message().find(key), std::string::npos) << s.status().message();
  };
  DynamicsConfig c;
  c.material.poisson_ratio = 0.7;
  expect_error(c, "material.poisson_ratio");
  c = {};
  c.material.rolling_friction = -1;
  expect_error(c, "material.rolling_friction");
  c = {};
  c.contact_model = ContactModel::kHertzMindlin;
  c.material.stiffness = 1e5;
  expect_error(c, "stiffness");
  c = {};
  c.wall_material_set = true;
  c.wall_material.restitution = 2;
  expect_error(c, "wall_material.restitution");
  c = {};
  c.wall_motion.kind = WallMotionKind::kRotate;
  c.wall_motion.axis = {0, 0, 0};
  expect_error(c, "wall_motion.axis");
  c.wall_motion.axis = {0, 0, 1};
  c.wall_motion.angular_speed = NAN;
  expect_error(c, "wall_motion");
  c.wall_motion.angular_speed = 1;
  c.wall_motion.part = 2;  // named, but its triangles never set
  expect_error(c, "wall_motion.part");
  c.wall_motion.part = 0;
  c.wall_motion.part_end = 1u << 20;  // beyond the wall
  expect_error(c, "wall_motion.part");
  c.wall_motion.part_end = 0;
  c.wall_motion.kind = WallMotionKind::kTranslate;
  c.wall_motion.part = 1;
  expect_error(c, "translate moves the whole wall");
}

// The GPU suite: the same scenes, and a drum bed at the CPU's angle.
class ContactModelsCuda : public GpuSuite {};
TEST_F(ContactModelsCuda, HertzImpactsLastTheAnalyticTimeAndKeepTheRestitution) {
  hertz_impacts_follow_the_theory();
}
TEST_F(ContactModelsCuda, RollingResistanceStopsABallWhereTheModelSays) {
  rolling_resistance_stops_the_ball(ContactModel::kHertzMindlin);
}
TEST_F(ContactModelsCuda, AVibratingPlateCarriesOrThrowsABall) { plates_carry_or_throw(); }
TEST_F(ContactModelsCuda, ABallOnATurntableCirclesAtTwoSevenths) {
  turntable_ball_circles_at_two_sevenths();
}
TEST_F(ContactModelsCuda, APartMovesAsTheWholeWallWould) { a_part_moves_as_the_whole_wall_would(); }
TEST_F(ContactModelsCuda, APaddleStirsAStillCupAsOnTheCpu) {
  const Stirred gpu = stirred_cup();
  backend_under_test() = Backend::kCpu;
  const Stirred cpu = stirred_cup();
  backend_under_test() = Backend::kCuda;
  std::printf("paddle: the balls turn at %.4f rad/s on the GPU, %.4f on the CPU\n", gpu.spin, cpu.spin);
  EXPECT_NEAR(gpu.spin, cpu.spin, 0.02 * std::fabs(cpu.spin));
  EXPECT_EQ(gpu.hit_paddle, cpu.hit_paddle);
  EXPECT_LT(gpu.lone_moved, 1e-6);
  EXPECT_EQ(gpu.escaped, 0u);
  EXPECT_LT(gpu.outside, 0.1 * 0.005);
}
TEST_F(ContactModelsCuda, ARotatingDrumBedLiesAtTheCpusAngle) {
  const DrumResult gpu = rotating_drum(0.1);
  backend_under_test() = Backend::kCpu;
  const DrumResult cpu = rotating_drum(0.1);
  backend_under_test() = Backend::kCuda;
  std::printf("drum bed angle: GPU %.2f deg, CPU %.2f deg\n", gpu.angle, cpu.angle);
  EXPECT_NEAR(gpu.angle, cpu.angle, 3.0);
  EXPECT_EQ(gpu.escaped, 0u);
  EXPECT_LT(gpu.outside, 0.1 * 0.003);
}

}  // namespace
}  // namespace collido::sim
