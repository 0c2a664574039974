// The dynamics where methods fail on purpose: time steps beyond the critical
// one, particles fast enough to tunnel, shared vertices that would push twice,
// energy over long elastic runs, pouring into the paper's wall1; and the same
// scenes on the GPU, which must follow the CPU's trajectories.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <map>
#include <cstdio>

#include "sim/dynamics.h"
#include "sim/pair_batch.h"
#include "sim/parallel.h"
#include "sim/particles.h"
#include "sim/shapes.h"
#include "tests/sim/dynamics_scenes.h"
#include "tests/sim/gpu_suite.h"

namespace collido::sim {
namespace {


// Elastic particles in a closed box, no gravity, no friction: the total
// energy (kinetic + springs) may drift by at most 1 % over 10^4 steps.
void elastic_box_energy() {
  const TriangleMesh box = make_box(10, 10, 10);
  const ParticleSet p = lattice(4, 4, 1, 0.5, 2.0, 11);
  DynamicsConfig cfg;
  cfg.gravity = {0, 0, 0};
  cfg.material.restitution = 1;
  cfg.particle_contacts = true;
  auto s = make_sim(box, cfg, p);
  ASSERT_TRUE(s);
  const double e0 = measure(*s).total_energy();
  double worst = 0;
  uint64_t wall_hits = 0, pair_hits = 0;
  while (s->steps_taken() < 10000) {
    FrameStats st;
    ASSERT_TRUE(s->advance(0.05, &st));
    worst = std::max(worst, std::fabs(st.total_energy() - e0) / e0);
    wall_hits += st.wall_contacts, pair_hits += st.particle_contacts;
    ASSERT_EQ(st.escaped + st.invalid, 0u);
  }
  std::printf(
      "elastic box: %llu steps, worst energy drift %.3g %%, frames with wall/pair contacts "
      "%llu/%llu\n",
      (unsigned long long)s->steps_taken(), 100 * worst, (unsigned long long)wall_hits,
      (unsigned long long)pair_hits);
  EXPECT_GT(wall_hits, 0u);  // the particles did meet the walls and each other
  EXPECT_GT(pair_hits, 0u);
  EXPECT_LE(worst, 0.01);
}

// A ball resting on a floor under gravity with a fixed step: beyond the
// critical step its energy blows up, under the automatic step it does not.
void time_step_sweep() {
  const TriangleMesh box = make_box(10, 10, 10);
  DynamicsConfig cfg;
  cfg.material.restitution = 1;
  cfg.material.stiffness = 1e6;
  const double r = 0.5, m = cfg.material.density * 4.0 / 3.0 * M_PI * r * r * r;
  // Slightly off its rest height (r - m g / k), so it oscillates in contact.
  const ParticleSet p = particles_at({{0, 0, r - 0.9 * m * 9.81 / cfg.material.stiffness}}, {}, r);
  const double scale = m * 9.81 * r;
  auto probe = make_sim(box, cfg, p);
  ASSERT_TRUE(probe);
  const double crit = probe->time_step_info().critical_step;
  // The worst energy error each stable step may show, in m g r: ten times
  // what it measures (3.2e-7, 1.2e-5, 1.0e-4 and 1.3e-6 automatic), so a
  // regression of the integrator shows while rounding noise does not.
  const std::map<double, double> stable_bound = {{0.05, 3e-6}, {0.3, 1.2e-4}, {0.9, 1.0e-3}, {0.0, 1.3e-5}};
  for (double factor : {0.05, 0.3, 0.9, 1.1, 1.5, 0.0}) {
    DynamicsConfig c = cfg;
    c.time_step = factor * crit;  // 0.0: automatic
    auto s = make_sim(box, c, p);
    ASSERT_TRUE(s);
    EXPECT_EQ(s->time_step_info().beyond_stable, factor > 1);
    const double e0 = measure(*s).total_energy();
    double worst = 0;
    bool lost = false, blow_up_reported = false, tunnel_reported = false;
    // 200 frames of one fixed step each, or 2 s of automatic frames.
    for (int f = 0; f < (factor > 0 ? 200 : 40) && !lost; ++f) {
      FrameStats st;
      ASSERT_TRUE(s->advance(factor > 0 ? c.time_step : 0.05, &st));
      lost = st.escaped + st.invalid > 0;
      worst = std::max(worst, std::fabs(st.total_energy() - e0) / scale);
      const FrameWarnings w = frame_warnings(st, s->time_step_info());
      blow_up_reported |= w.blow_up;
      tunnel_reported |= w.tunnel_risk;
    }
    std::printf("step %.2f x critical%s: worst energy error %.3g of m g r%s%s\n", factor,
                factor == 0 ? " (automatic)" : "", worst, lost ? ", particle lost" : "",
                blow_up_reported ? ", blow-up reported" : "");
    if (factor > 1) {
      EXPECT_TRUE(lost || worst > 10) << "a step beyond the critical one should blow up";
      EXPECT_TRUE(blow_up_reported) << "the blow-up at " << factor << " x critical went unreported";
    } else {
      EXPECT_FALSE(lost) << factor;
      EXPECT_LT(worst, stable_bound.at(factor)) << factor;
      EXPECT_FALSE(blow_up_reported) << factor;
      EXPECT_FALSE(tunnel_reported) << factor;
    }
  }
}

// Fast particles in a closed box of single-triangle walls: a coarse fixed step
// lets some tunnel out (and they are counted); the automatic step keeps all in.
void tunnelling() {
  const TriangleMesh box = make_box(10, 10, 10);
  ASSERT_TRUE(is_closed_manifold(box));
  const ParticleSet p = lattice(3, 3, 2, 0.2, 100.0, 5);
  DynamicsConfig cfg;
  cfg.gravity = {0, 0, 0};
  cfg.material.density = 1;
  cfg.material.stiffness = 1e6;  // overlap at 100 m/s: about 9 % of the radius
  cfg.material.restitution = 0.9;
  for (double dt : {5e-3, 0.0}) {
    DynamicsConfig c = cfg;
    c.time_step = dt;
    auto s = make_sim(box, c, p);
    ASSERT_TRUE(s);
    FrameStats st;
    bool tunnel_reported = false;
    for (int f = 0; f < 20; ++f) {
      ASSERT_TRUE(s->advance(0.01, &st));
      tunnel_reported |= frame_warnings(st, s->time_step_info()).tunnel_risk;
    }
    ParticleSet out;
    std::vector<uint8_t> flags;
    ASSERT_TRUE(s->download(&out, &flags));
    size_t outside = 0;
    for (size_t i = 0; i < out.size(); ++i)
      if ((flags[i] & kStateMask) != kActive ||
          winding_number(box, {out.x[i], out.y[i], out.z[i]}) < 0.5)
        ++outside;
    std::printf("fast particles, %s step: %zu of %zu outside (escaped %llu, non-finite %llu)\n",
                dt > 0 ? "fixed 5 ms" : "automatic", outside, out.size(),
                (unsigned long long)st.escaped, (unsigned long long)st.invalid);
    // The tunnelling is found (outside the box) and was reported while it happened.
    if (dt > 0) {
      EXPECT_GT(st.escaped, 0u);
      EXPECT_GT(outside, 0u);
      EXPECT_TRUE(tunnel_reported);
    } else {
      EXPECT_EQ(outside, 0u);
      EXPECT_EQ(st.escaped + st.invalid, 0u);
      EXPECT_FALSE(tunnel_reported);
    }
  }
}

// A ball fired at a slab half its radius thick, with the contact stiffness
// sized for 1 m/s: at 1 m/s it bounces back, at 100 m/s it overlaps its whole
// radius and comes out on the far side, even with the automatic step. The
// study's thin-wall failure: it must happen where it is measured and be reported.
void thin_wall_tunnels_and_says_so() {
  const double r = 0.05;
  const TriangleMesh slab = make_box(1, 1, 0.5 * r);
  for (double speed : {1.0, 100.0}) {
    DynamicsConfig cfg;
    cfg.gravity = {0, 0, 0};
    cfg.impact_speed = 1.0;
    auto s = make_sim(slab, cfg, particles_at({{0.1, 0.1, 0.5 * r + 1.2 * r}}, {{0, 0, -speed}}, r));
    ASSERT_TRUE(s);
    bool reported = false;
    FrameStats st;
    for (int f = 0; f < 40; ++f) {
      ASSERT_TRUE(s->advance(0.5 * r / speed, &st));
      reported |= frame_warnings(st, s->time_step_info()).tunnel_risk;
    }
    ParticleSet out;
    std::vector<uint8_t> flags;
    ASSERT_TRUE(s->download(&out, &flags));
    const bool through = out.z[0] < 0.25 * r;  // an escaped particle keeps where it left
    std::printf("thin slab at %g m/s: %s, %s\n", speed, through ? "went through" : "bounced back",
                reported ? "tunnelling reported" : "nothing reported");
    EXPECT_EQ(through, speed > 10);
    EXPECT_EQ(reported, speed > 10);
  }
}

// A ball settling on a finely tessellated floor rests at the height it rests
// at on one large triangle: a shared vertex or edge pushes once, not six or two times.
void floor_settles_once() {
  const double r = 0.5;
  DynamicsConfig cfg;
  cfg.material.stiffness = 1e7;
  cfg.material.restitution = 0.2;
  TriangleMesh big;
  big.vertices = {{-100, -100, 0}, {100, -100, 0}, {0, 100, 0}};
  big.triangles = {{0, 1, 2}};
  big.source_ids = {0};
  const TriangleMesh fine = floor_mesh(5, 40);  // vertices every 0.25
  const std::vector<Vec3d> spots = {
      {0, 0, 0.6}, {0.125, 0, 0.6}, {0.125, 0.125, 0.6}, {0.06, 0.2, 0.6}};
  const double m = cfg.material.density * 4.0 / 3.0 * M_PI * r * r * r;
  const double expected = r - m * 9.81 / cfg.material.stiffness;
  for (const Vec3d& at : spots) {
    double z[2];
    int k = 0;
    for (const TriangleMesh* wall : {static_cast<const TriangleMesh*>(&big), &fine}) {
      auto s = make_sim(*wall, cfg, particles_at({at}, {}, r));
      ASSERT_TRUE(s);
      FrameStats st;
      for (int f = 0; f < 30; ++f) ASSERT_TRUE(s->advance(0.1, &st));
      ParticleSet out;
      ASSERT_TRUE(s->download(&out, nullptr));
      z[k++] = out.z[0];
      EXPECT_EQ(st.wall_contacts, 1u) << "at (" << at.x << ", " << at.y << ")";
      EXPECT_NEAR(out.x[0], at.x, 1e-6);
      EXPECT_NEAR(out.y[0], at.y, 1e-6);
    }
    EXPECT_NEAR(z[0], expected, 1e-4 * r);
    EXPECT_NEAR(z[1], z[0], 1e-5 * r) << "at (" << at.x << ", " << at.y << ")";
  }
  // Over an edge whose vertices carry rounding: a cup's bottom is a fan whose
  // diameter runs from (10, 0) to (-10, 1.2e-15), so a ball at (9, 0) lies
  // 6e-17 m outside one of its two triangles. It stays put, with friction or
  // without (the edge's own normal there walked it off, as off a ridge).
  const TriangleMesh cup = make_cylinder(10, 2, 64, Caps::kBottom);
  for (double mu : {0.0, 0.3}) {
    cfg.material.friction = mu;
    auto s = make_sim(cup, cfg, particles_at({{9, 0, 0.6}}, {}, r));
    ASSERT_TRUE(s);
    FrameStats st;
    for (int f = 0; f < 30; ++f) ASSERT_TRUE(s->advance(0.1, &st));
    ParticleSet out;
    ASSERT_TRUE(s->download(&out, nullptr));
    EXPECT_EQ(st.wall_contacts, 1u);
    EXPECT_NEAR(out.x[0], 9, 1e-12) << "friction " << mu;
    EXPECT_NEAR(out.y[0], 0, 1e-12) << "friction " << mu;
  }
}

// The paper's division methods and the tree as the wall's preparation: the
// pieces of one triangle are coplanar, so a ball on them is pushed once and
// rests where it rests on the binned original triangles.
void division_methods_push_once() {
  const TriangleMesh floor = floor_mesh(5, 4);
  const double r = 0.5;
  double z_bin = 0;
  for (Method m : {Method::kBin, Method::kGravity, Method::kCircumcircle, Method::kMidpoint4,
                   Method::kBvh}) {
    DynamicsConfig cfg;
    cfg.method = m;
    cfg.material.stiffness = 1e7;
    cfg.material.restitution = 0.2;
    auto s = make_sim(floor, cfg, particles_at({{0.3, 0.2, 0.6}}, {}, r));
    ASSERT_TRUE(s);
    if (m != Method::kBin && m != Method::kBvh) {
      EXPECT_GT(s->wall_info().triangles_used, floor.triangles.size()) << to_string(m);
    }
    FrameStats st;
    for (int f = 0; f < 30; ++f) ASSERT_TRUE(s->advance(0.1, &st));
    ParticleSet out;
    ASSERT_TRUE(s->download(&out, nullptr));
    EXPECT_EQ(st.wall_contacts, 1u) << to_string(m);
    if (m == Method::kBin) z_bin = out.z[0];
    EXPECT_NEAR(out.z[0], z_bin, 1e-6 * r) << to_string(m);
    EXPECT_NEAR(out.x[0], 0.3, 1e-9) << to_string(m);
  }
}

// Restitution: a ball dropped onto the floor without gravity leaves with e times its speed.
void restitution_is_kept() {
  for (double e : {0.3, 0.7, 1.0}) {
    DynamicsConfig cfg;
    cfg.gravity = {0, 0, 0};
    cfg.material.restitution = e;
    cfg.material.stiffness = 1e6;
    // The contact starts and ends between steps: a few per cent of the speed.
    EXPECT_NEAR(rebound_speed(cfg), 2 * e, 0.03 * 2 * e) << "restitution " << e;
  }
}

// Friction turns sliding into rolling: a ball launched along a floor ends
// slower (5/7 of its speed for a solid sphere) and rolls on.
void friction_makes_it_roll() {
  const TriangleMesh floor = floor_mesh(50, 10);
  DynamicsConfig cfg;
  cfg.material.stiffness = 1e6;
  cfg.material.restitution = 0.3;
  cfg.material.friction = 0.5;
  const double r = 0.5;
  const double m = cfg.material.density * 4.0 / 3.0 * M_PI * r * r * r;
  const double rest = r - m * 9.81 / 1e6;
  auto s = make_sim(floor, cfg, particles_at({{-20, 0, rest}}, {{4, 0, 0}}, r));
  ASSERT_TRUE(s);
  FrameStats st;
  for (int f = 0; f < 20; ++f) ASSERT_TRUE(s->advance(0.1, &st));
  ParticleSet out;
  ASSERT_TRUE(s->download(&out, nullptr));
  EXPECT_NEAR(out.vx[0], 4.0 * 5 / 7, 0.05);
  EXPECT_NEAR(out.vy[0], 0, 1e-6);
  // Without friction it slides on at its launch speed.
  cfg.material.friction = 0;
  auto t = make_sim(floor, cfg, particles_at({{-20, 0, rest}}, {{4, 0, 0}}, r));
  ASSERT_TRUE(t);
  for (int f = 0; f < 20; ++f) ASSERT_TRUE(t->advance(0.1, &st));
  ASSERT_TRUE(t->download(&out, nullptr));
  EXPECT_NEAR(out.vx[0], 4.0, 1e-6);
}

// Particles released over time from an inlet into a cylinder settle and none escape.
void pour_into(const TriangleMesh& wall, int per_layer_side, int layers, uint64_t min_steps) {
  std::vector<Vec3d> pos, vel;
  ParticleSet p;
  const double r = 1, spacing = 2.5;
  for (int l = 0; l < layers; ++l)
    for (int i = 0; i < per_layer_side; ++i)
      for (int j = 0; j < per_layer_side; ++j)
        pos.push_back({(i - 0.5 * (per_layer_side - 1)) * spacing,
                       (j - 0.5 * (per_layer_side - 1)) * spacing, 20});
  // Layers leave the inlet at 10 m/s every 0.3 s: 3 m apart, clear of the one
  // before. A little sideways speed keeps them from stacking into columns: at
  // one place after another, straight down, they would (upright, in exact
  // arithmetic), and columns of ten reach the inlet, where releases then wait.
  SplitMix64 rng(17);
  for (size_t i = 0; i < pos.size(); ++i)
    vel.push_back({rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), -10});
  p = particles_at(pos, vel, r);
  const size_t per_layer = size_t(per_layer_side) * per_layer_side;
  for (size_t i = 0; i < p.size(); ++i) p.release[i] = 0.3 * double(i / per_layer);
  DynamicsConfig cfg;
  cfg.particle_contacts = true;
  cfg.material.restitution = 0.3;
  cfg.material.friction = 0.3;
  cfg.impact_speed = 22;  // a 20 m drop after a 10 m/s start
  auto s = make_sim(wall, cfg, p);
  ASSERT_TRUE(s);
  FrameStats st;
  double t = 0;
  // Settled: everything released and a mean speed below 5 cm/s (a ball may
  // roll on over the flat bottom: nothing resists rolling, so the maximum never falls).
  const double m = cfg.material.density * 4.0 / 3.0 * M_PI * r * r * r;
  auto mean_speed = [&] { return std::sqrt(2 * st.kinetic / (m * double(p.size()))); };
  while (s->steps_taken() < min_steps || st.waiting > 0 || mean_speed() > 0.05) {
    ASSERT_TRUE(s->advance(0.1, &st));
    t += 0.1;
    ASSERT_EQ(st.escaped + st.invalid, 0u) << "at t = " << t;
    ASSERT_LT(t, 30) << "did not settle: mean speed " << mean_speed();
  }
  ParticleSet out;
  ASSERT_TRUE(s->download(&out, nullptr));
  double top = 0;
  for (size_t i = 0; i < out.size(); ++i) {
    EXPECT_GT(winding_number(wall, {out.x[i], out.y[i], out.z[i]}), 0.5) << "particle " << i;
    top = std::max(top, out.z[i]);
  }
  std::printf(
      "poured %zu particles into the cylinder: settled after %.1f s, %llu steps, pile top z = "
      "%.2f, max overlap %.2f %%\n",
      out.size(), t, (unsigned long long)s->steps_taken(), top, 100 * st.max_overlap);
  EXPECT_LT(st.max_overlap, 0.05);
}

// A particle of radius 3 touched by 14 of radius 1 (6 along the axes, 8 on the
// diagonals, 3.9 from its centre and clear of each other) has more frictional contacts
// than its 8 history slots (kPairSlots); the frame's statistics count the 6 without one.
// A pair's spring is kept by its particle of lower index, here the large one:
// the grid is searched every step, so the particles keep the numbers given
// (a neighbour list renumbers them in the order of their cells).
void friction_history_overflow_is_counted() {
  const Vec3d c{0, 0, 50};
  std::vector<Vec3d> pos{c};
  for (const Vec3d& d : {Vec3d{1, 0, 0}, Vec3d{-1, 0, 0}, Vec3d{0, 1, 0}, Vec3d{0, -1, 0},
                         Vec3d{0, 0, 1}, Vec3d{0, 0, -1}})
    pos.push_back(c + d * 3.9);
  for (double x : {-1.0, 1.0})
    for (double y : {-1.0, 1.0})
      for (double z : {-1.0, 1.0}) pos.push_back(c + Vec3d{x, y, z} * (3.9 / std::sqrt(3.0)));
  ParticleSet p = particles_at(pos, {}, 1.0);
  p.r[0] = 3.0;
  DynamicsConfig cfg;
  cfg.gravity = {0, 0, 0};
  cfg.particle_contacts = true;
  cfg.material.friction = 0.3;
  cfg.neighbour_skin = 0;
  auto s = make_sim(make_cylinder(50, 100, 40), cfg, p);
  ASSERT_TRUE(s);
  ASSERT_TRUE(s->step(1, s->time_step_info().spring_step));
  const FrameStats st = measure(*s);
  EXPECT_EQ(st.particle_contacts, 14u);
  EXPECT_EQ(st.history_overflow, 6u);
}

TEST(Dynamics, FrictionHistoryOverflowIsCounted) { friction_history_overflow_is_counted(); }


// A state saved at a frame and restored into a new Simulation of the same
// scene continues bit for bit as the original (what a checkpoint relies on):
// friction springs, spins, pair contacts and Verlet's accelerations included.
void saved_state_continues_exactly() {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  ParticleSet p = lattice(8, 8.2, -0.05, 1, 5.0, 5);
  DynamicsConfig cfg;
  cfg.particle_contacts = true;
  cfg.material.friction = 0.4;
  ThreadPool pool(2);
  cfg.pool = &pool;
  cfg.one_thread_below = 0;  // 512 particles, on both threads
  auto a = make_sim(wall, cfg, p);
  ASSERT_TRUE(a);
  FrameStats st;
  ASSERT_TRUE(a->advance(0.01, &st));
  SimState saved;
  ASSERT_TRUE(a->save_state(&saved));
  ASSERT_TRUE(a->advance(0.01, &st));
  ParticleSet end_a;
  ASSERT_TRUE(a->download(&end_a, nullptr));

  auto b = make_sim(wall, cfg, p);
  ASSERT_TRUE(b);
  ASSERT_TRUE(b->restore_state(saved));
  EXPECT_EQ(b->time(), saved.time);
  EXPECT_EQ(b->steps_taken(), saved.steps);
  ASSERT_TRUE(b->advance(0.01, &st));
  ParticleSet end_b;
  ASSERT_TRUE(b->download(&end_b, nullptr));
  EXPECT_EQ(a->steps_taken(), b->steps_taken());
  EXPECT_EQ(end_a.x, end_b.x);
  EXPECT_EQ(end_a.vz, end_b.vz);

  // A state from another scene is refused, not half applied.
  DynamicsConfig frictionless = cfg;
  frictionless.material.friction = 0;
  auto c = make_sim(wall, frictionless, p);
  ASSERT_TRUE(c);
  EXPECT_FALSE(c->restore_state(saved));
  saved.particles += 1;
  EXPECT_FALSE(b->restore_state(saved));
}
TEST(Dynamics, SavedStateContinuesExactly) { saved_state_continues_exactly(); }

// A state restored at any frame continues bit for bit through list builds,
// renumberings and friction: the restored run has the saved run's lists (when
// and where they were built, their skin, the build count), so it builds,
// renumbers and sums its forces at the same steps. Without them it built its
// lists at its first step, with the skin it started with (this pack, pressed
// 10 % deep, throws particles off fast and the skin grows), and renumbered at
// other builds: pair sums in another order part the runs in their last bits.
// Without particle contacts the wall's lists alone are saved and restored;
// the particles are thrown 30 times faster there, to reach the walls.
void restored_state_continues_exactly_at_every_frame(bool pairs) {
  const TriangleMesh wall = make_box(23, 23, 22);
  const ParticleSet p = lattice(10, 9.0, 0, 1, pairs ? 1.0 : 30.0, 7);  // 1.8 apart
  DynamicsConfig cfg;
  cfg.particle_contacts = pairs;
  cfg.wall_lists = 1;  // without pairs, on the GPU too (its default searches)
  cfg.material.friction = 0.4;
  cfg.material.restitution = 0.9;
  cfg.renumber_every = 1;
  auto run = make_sim(wall, cfg, p);
  ASSERT_TRUE(run);
  const double skin0 = run->time_step_info().neighbour_skin;
  constexpr int kFrames = 10;
  constexpr double kFrame = 0.01;
  std::vector<SimState> saved(kFrames);
  FrameStats st;
  uint64_t contacts = 0;
  for (int f = 0; f < kFrames; ++f) {
    ASSERT_TRUE(run->save_state(&saved[f]));
    ASSERT_TRUE(run->advance(kFrame, &st));
    contacts += pairs ? st.particle_contacts : st.wall_contacts;
  }
  ASSERT_GT(contacts, pairs ? 1000u : 5u);  // without pairs, the few at a frame's end
  EXPECT_GT(skin0, 0);  // listed
  if (pairs) {
    EXPECT_GT(run->time_step_info().neighbour_skin, skin0);  // it grew
  }
  ParticleSet end;
  ASSERT_TRUE(run->download(&end, nullptr));
  for (int from = 1; from < kFrames; ++from) {
    auto resumed = make_sim(wall, cfg, p);
    ASSERT_TRUE(resumed);
    ASSERT_TRUE(resumed->restore_state(saved[from]));
    for (int f = from; f < kFrames; ++f) ASSERT_TRUE(resumed->advance(kFrame, &st));
    ParticleSet got;
    ASSERT_TRUE(resumed->download(&got, nullptr));
    EXPECT_EQ(got.x, end.x) << "restored at frame " << from;
    EXPECT_EQ(got.z, end.z) << "restored at frame " << from;
    EXPECT_EQ(got.vy, end.vy) << "restored at frame " << from;
  }
}
TEST(Dynamics, RestoredStateContinuesExactlyAtEveryFrame) {
  restored_state_continues_exactly_at_every_frame(true);
}
TEST(Dynamics, RestoredWallListsContinueExactlyAtEveryFrame) {
  restored_state_continues_exactly_at_every_frame(false);
}

// A particle that leaves the domain escapes in the step it leaves, before
// that step's forces: its partner gets no push from it, whether a pair list
// built before it left holds the pair (a skin) or the grid is searched that
// step (no skin; the grid ends at the domain). Two particles, the second
// faster, meet as the first leaves an open tube's domain, at many phases of
// their contact; one contact each, so both searches sum the same bits.
void a_leaving_particle_pushes_nothing() {
  const TriangleMesh wall = make_cylinder(2, 4, 24, Caps::kNone);
  DynamicsConfig listed;
  listed.particle_contacts = true;
  listed.gravity = Vec3d{0, 0, 0};
  listed.domain_margin = 0.3;  // the domain's floor at z = -0.3
  listed.neighbour_skin = 0.1;
  DynamicsConfig searched = listed;
  searched.neighbour_skin = 0;
  int met_leaving = 0;
  for (int trial = 0; trial < 40; ++trial) {
    // The leader leaves after 0.2 s; the follower meets it after 0.18-0.2 s.
    const double gap = 0.18 + 0.0005 * trial;
    const ParticleSet p =
        particles_at({{0, 0, 0.1}, {0, 0, 0.5 + gap}}, {{0, 0, -2.0}, {0, 0, -3.0}}, 0.2);
    std::vector<uint8_t> flags[2];
    ParticleSet end[2];
    for (int k = 0; k < 2; ++k) {
      auto s = make_sim(wall, k ? searched : listed, p);
      ASSERT_TRUE(s);
      FrameStats st;
      ASSERT_TRUE(s->advance(0.3, &st));
      ASSERT_TRUE(s->download(&end[k], &flags[k]));
    }
    const bool touched = end[0].vz[1] != -3.0;  // the follower was slowed
    EXPECT_EQ(flags[0], flags[1]) << "trial " << trial;
    EXPECT_EQ(end[0].vz, end[1].vz) << "trial " << trial;
    EXPECT_EQ(end[0].z, end[1].z) << "trial " << trial;
    met_leaving += touched && (flags[0][0] & kStateMask) == kEscaped;
  }
  EXPECT_GT(met_leaving, 20);
}
TEST(Dynamics, ALeavingParticlePushesNothing) { a_leaving_particle_pushes_nothing(); }

// Releases the particles in `groups` groups, one every 3 spring steps of the scene.
void release_in_groups(const TriangleMesh& wall, const DynamicsConfig& cfg, ParticleSet* p,
                       int groups = 50) {
  auto probe = make_sim(wall, cfg, *p);
  ASSERT_TRUE(probe);
  const double step = probe->time_step_info().spring_step;
  for (size_t i = 0; i < p->size(); ++i) p->release[i] = 3 * step * double(i % groups);
}

// The neighbour list finds exactly the contacts a search of the grid finds:
// every step, the list run's state is copied into a run that searches the grid
// every step (neighbour_skin 0), and both measure it: the same pair and wall
// contacts, the same particles touching, the same elastic energy. Dense
// frictional scenes, one with radii from 0.5 to 1.5, one that pours
// (groups of 100 released near their neighbours, while a list stands), and the first again with the
// wall divided (its pieces listed) and as a tree; and the first and the pour
// without particle contacts, where the wall alone is listed, and the first
// without them on the divided wall (the GPU's default lists those).
void neighbour_list_finds_every_contact() {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  for (int scene = 0; scene < 8; ++scene) {
    const bool pairs = scene < 5;
    // 2.1 apart: colliding at once; the pour 2.0002 apart, each group released
    // just clear of its neighbours (the lists must hold it at once).
    ParticleSet p = lattice(10, scene == 2 || scene == 6 ? 10.001 : 10.5, -0.05, 1, 5.0, 7);
    if (scene == 1) {
      SplitMix64 rng(9);
      for (double& r : p.r) r = rng.uniform(0.5, 1.05);
    }
    DynamicsConfig cfg;
    cfg.particle_contacts = pairs;
    cfg.wall_lists = 1;  // without pairs, on the GPU too (its default searches)
    cfg.material.friction = 0.4;
    cfg.material.restitution = 0.5;
    if (scene == 3) cfg.method = Method::kCircumcircle;
    if (scene == 4) cfg.method = Method::kBvh;
    if (scene == 7) cfg.method = Method::kMidpoint4;
    // Groups of 100: more than the lists hold past the released at first, so
    // a release must rebuild them; later a group is held before it is released.
    if (scene == 2 || scene == 6) release_in_groups(wall, cfg, &p, 10);
    DynamicsConfig grid = cfg;
    grid.neighbour_skin = 0;
    auto listed = make_sim(wall, cfg, p);
    auto searched = make_sim(wall, grid, p);
    ASSERT_TRUE(listed && searched);
    ASSERT_GT(listed->time_step_info().neighbour_skin, 0);
    EXPECT_EQ(searched->time_step_info().neighbour_skin, 0);
    listed->set_stage_timing(true);
    const double dt = listed->time_step_info().spring_step;
    uint64_t contacts = 0, walls = 0;
    const int steps = 300;
    for (int k = 0; k < steps; ++k) {
      ASSERT_TRUE(listed->step(1, dt));
      SimState state;
      ASSERT_TRUE(listed->save_state(&state));
      ASSERT_TRUE(searched->restore_state(state));
      const FrameStats a = measure(*listed), b = measure(*searched);
      ASSERT_EQ(a.particle_contacts, b.particle_contacts) << "scene " << scene << " step " << k;
      ASSERT_EQ(a.wall_contacts, b.wall_contacts) << "scene " << scene << " step " << k;
      ASSERT_EQ(a.active, b.active);
      ASSERT_NEAR(a.elastic, b.elastic, 1e-9 * b.elastic) << "scene " << scene << " step " << k;
      ParticleSet pa, pb;
      std::vector<uint8_t> fa, fb;
      ASSERT_TRUE(listed->download(&pa, &fa));
      ASSERT_TRUE(searched->download(&pb, &fb));
      ASSERT_EQ(fa, fb) << "scene " << scene << " step " << k;  // who touches whom, per particle
      contacts += a.particle_contacts;
      walls += a.wall_contacts;
    }
    const uint64_t builds = listed->stage_times().neighbour_builds;
    std::printf("scene %d: %llu pair contacts over %d steps, skin %.3g r, list built %llu times\n",
                scene, (unsigned long long)contacts, steps,
                listed->time_step_info().neighbour_skin / listed->time_step_info().r_min,
                (unsigned long long)builds);
    if (pairs) {
      EXPECT_GT(contacts, uint64_t(steps / 2));
    }
    EXPECT_GT(walls, uint64_t(steps));  // the floor's candidates come from the list too
    EXPECT_LT(builds, uint64_t(steps / 2));  // reused: the point of the skin
  }
}
TEST(Dynamics, NeighbourListFindsEveryContactTheGridDoes) { neighbour_list_finds_every_contact(); }

// Without particle contacts the CPU lists the wall's candidates and the GPU
// searches a binned wall every step (faster there below 10^6 particles) and
// lists a divided one (whose search visits the pieces of up to 27 cells),
// unless the scene says otherwise.
TEST(Dynamics, WallListsWithoutPairsAreTheBackendsChoice) {
  DynamicsConfig c;
  c.backend = Backend::kCpu;
  EXPECT_TRUE(wall_lists_without_pairs(c));
  c.backend = Backend::kCuda;
  EXPECT_FALSE(wall_lists_without_pairs(c));
  for (Method m : {Method::kGravity, Method::kCircumcircle, Method::kMidpoint4}) {
    c.method = m;
    EXPECT_TRUE(wall_lists_without_pairs(c)) << to_string(m);
  }
  c.method = Method::kBvh;
  EXPECT_FALSE(wall_lists_without_pairs(c));
  c.wall_lists = 0;
  c.method = Method::kMidpoint4;
  EXPECT_FALSE(wall_lists_without_pairs(c));  // the scene's word stands
  c.method = Method::kBin;
  c.wall_lists = 1;
  EXPECT_TRUE(wall_lists_without_pairs(c));
  c.backend = Backend::kCpu;
  c.wall_lists = 0;
  EXPECT_FALSE(wall_lists_without_pairs(c));
  c.wall_lists = 2;
  EXPECT_FALSE(Simulation::create(make_box(2, 2, 2), c, particles_at({{0, 0, 1}}, {{0, 0, 0}}, 0.1)));
}

// A small CPU scene steps on the calling thread alone (one_thread_below), and
// the same scene on two threads gives the same bits: every pass writes each
// particle's values from its own reads, whichever thread runs it. With pairs
// and friction, and without pairs (the wall's lists alone), over a pour.
TEST(Dynamics, OneThreadOrTwoGiveTheSameBits) {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  for (bool pairs : {true, false}) {
    ParticleSet p = lattice(8, 8.2, 0.0, 1, 5.0, 5);  // 512 particles, just over the floor
    DynamicsConfig cfg;
    cfg.particle_contacts = pairs;
    cfg.material.friction = 0.4;
    cfg.material.restitution = 0.1;  // the floor's layer stays on it
    release_in_groups(wall, cfg, &p, 8);
    ThreadPool two(2);
    cfg.pool = &two;
    DynamicsConfig shared = cfg;
    shared.one_thread_below = 0;
    ParticleSet end[2];
    for (int k = 0; k < 2; ++k) {
      auto s = make_sim(wall, k ? shared : cfg, p);
      ASSERT_TRUE(s);
      EXPECT_EQ(s->step_threads(), k ? 2 : 1);  // 512 particles: under one_thread_below
      uint64_t contacts = 0;
      for (int f = 0; f < 40; ++f) {
        FrameStats st;
        ASSERT_TRUE(s->advance(0.005, &st));
        st = measure(*s);
        contacts += pairs ? st.particle_contacts : st.wall_contacts;
      }
      ASSERT_TRUE(s->download(&end[k], nullptr));
      EXPECT_GT(contacts, 0u) << "pairs " << pairs;
    }
    EXPECT_EQ(end[0].x, end[1].x) << "pairs " << pairs;
    EXPECT_EQ(end[0].z, end[1].z) << "pairs " << pairs;
    EXPECT_EQ(end[0].vy, end[1].vy) << "pairs " << pairs;
  }
}

// A listed pair's force evaluated once and gathered by both particles
// (pairs_once 1) and evaluated by each of them (0) give the same trajectories
// bit for bit: the pair's arithmetic is odd in its orientation, and both ways
// sum a particle's pairs in the same order (on the CPU; the GPU's fused
// multiply-adds may differ between kernels). On the CPU the pairs evaluated
// once run one at a time and four at a time in AVX2 vectors (simd,
// where the CPU has them): all three agree, for both laws, with and without
// rolling resistance. Dense colliding scenes with
// friction, rolling resistance, both contact laws, mixed radii, particles
// released while the list stands, particles numbered at random (renumbered by
// cell, results in the caller's numbering), and two threads.
void pairs_once_or_from_both_sides_agree() {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  for (int scene = 0; scene < 5; ++scene) {
    // 1.98 apart: pressed together; the pour 2.0002 apart (a release waits while its place is taken)
    ParticleSet p = lattice(10, scene == 2 ? 10.001 : 9.9, -0.05, 1, 5.0, 11);
    SplitMix64 rng(5);
    if (scene == 3)  // the lattice numbered at random
      for (size_t i = p.size(); i > 1; --i) {
        const size_t j = size_t(rng.next() % i);
        for (std::vector<double>* a : {&p.x, &p.y, &p.z, &p.vx, &p.vy, &p.vz})
          std::swap((*a)[i - 1], (*a)[j]);
      }
    if (scene != 0)  // mixed radii; the pour's (scene 2) keep its particles just clear of one another
      for (double& r : p.r) r = scene == 2 ? rng.uniform(0.99, 1.0) : rng.uniform(0.9, 1.05);
    DynamicsConfig cfg;
    cfg.particle_contacts = true;
    cfg.material.friction = scene == 2 ? 0 : 0.4;
    cfg.material.rolling_friction = scene == 1 || scene == 4 ? 0.05 : 0;  // Hertz, then linear
    cfg.material.restitution = 0.5;
    if (scene == 1) cfg.contact_model = ContactModel::kHertzMindlin;
    ThreadPool pool(2);
    cfg.pool = &pool;
    cfg.one_thread_below = 0;  // 512 particles, on both threads
    if (scene == 2) release_in_groups(wall, cfg, &p);
    // 0: from both sides; 1: once, four at a time where the CPU can; 2: once,
    // one at a time; 3: once, four at a time on one thread, which adds each
    // pair to its particles as it goes instead of gathering records.
    ThreadPool one(1);
    const int ways = backend_under_test() == Backend::kCpu ? 4 : 2;
    ParticleSet end[4];
    std::vector<uint8_t> flags[4];
    uint64_t contacts[4] = {0, 0, 0, 0}, overflow[4] = {0, 0, 0, 0};
    for (int way = 0; way < ways; ++way) {
      const int once = way > 0;
      DynamicsConfig c = cfg;
      c.pairs_once = once;
      c.simd = way == 2 ? 0 : -1;
      if (way == 3) c.pool = &one;
      auto s = make_sim(wall, c, p);
      ASSERT_TRUE(s);
      ASSERT_GT(s->time_step_info().neighbour_skin, 0);
      for (int k = 0; k < 30; ++k) {
        ASSERT_TRUE(s->step(10, s->time_step_info().spring_step));
        const FrameStats now = measure(*s);
        contacts[way] += now.particle_contacts;
        overflow[way] += now.history_overflow;
      }
      ASSERT_TRUE(s->download(&end[way], &flags[way]));
    }
    EXPECT_GT(contacts[1], 5000u) << "scene " << scene;
    EXPECT_EQ(contacts[0], contacts[1]) << "scene " << scene;
    EXPECT_EQ(overflow[0], overflow[1]) << "scene " << scene;
    EXPECT_EQ(flags[0], flags[1]) << "scene " << scene;
    if (backend_under_test() == Backend::kCpu) {
      for (int way = 1; way < ways; ++way) {
        EXPECT_EQ(contacts[0], contacts[way]) << "scene " << scene << ", way " << way;
        EXPECT_EQ(flags[0], flags[way]) << "scene " << scene << ", way " << way;
        EXPECT_EQ(end[0].x, end[way].x) << "scene " << scene << ", way " << way;
        EXPECT_EQ(end[0].y, end[way].y) << "scene " << scene << ", way " << way;
        EXPECT_EQ(end[0].z, end[way].z) << "scene " << scene << ", way " << way;
        EXPECT_EQ(end[0].vx, end[way].vx) << "scene " << scene << ", way " << way;
        EXPECT_EQ(end[0].vz, end[way].vz) << "scene " << scene << ", way " << way;
      }
      continue;
    }
    // nvcc fuses multiplies and adds as each kernel's code allows, so the two
    // kernels may round a pair differently: the same contacts, positions to 1e-9 radii.
    double worst = 0;
    for (size_t i = 0; i < p.size(); ++i)
      worst = std::max({worst, std::fabs(end[0].x[i] - end[1].x[i]),
                        std::fabs(end[0].y[i] - end[1].y[i]), std::fabs(end[0].z[i] - end[1].z[i])});
    EXPECT_LE(worst, 1e-9) << "scene " << scene;
  }
}
TEST(Dynamics, PairsOnceOrFromBothSidesAgreeBitForBit) { pairs_once_or_from_both_sides_agree(); }

// Verlet's opening pass four particles at a time in AVX2 vectors (simd -1)
// gives the bits of one particle at a time (0): every array of the state,
// spins, accelerations and springs included. A group of four that holds a
// waiting particle, or one leaving the domain, goes one at a time; both
// scenes have them: particles let go over a box's lid, some flying out of the
// domain (pairs and friction, on one thread and on two), and fast particles
// tunnelling out of a box at a coarse step (no pairs, no spins).
TEST(Dynamics, TheOpeningPassInVectorsGivesTheScalarBits) {
  if (!pair_batch_supported()) GTEST_SKIP() << "this CPU has no AVX2";
  for (int scene = 0; scene < 3; ++scene) {
    const bool lid = scene < 2;
    const TriangleMesh wall = lid ? make_box(20, 20, 20) : make_box(10, 10, 10);
    ParticleSet p =
        lid ? lattice(scene == 0 ? 4 : 12, 2, 20.2, 0.3 / (scene == 0 ? 1 : 3), 100.0, 17)
            : lattice(3, 3, 2, 0.2, 100.0, 5);
    DynamicsConfig cfg;
    ThreadPool one(1), two(2);
    cfg.pool = scene == 1 ? &two : &one;
    cfg.one_thread_below = 0;
    if (lid) {
      for (size_t i = 0; i < p.size(); ++i) p.release[i] = 2e-5 * double(i % 10);
      cfg.particle_contacts = true;
      cfg.material.friction = 0.3;
      cfg.domain_margin = 0.3;
    } else {  // tunnelling() in a box of single triangles
      cfg.gravity = {0, 0, 0};
      cfg.material.density = 1;
      cfg.material.stiffness = 1e6;
      cfg.material.restitution = 0.9;
      cfg.time_step = 5e-3;
    }
    SimState end[2];
    std::vector<uint8_t> flags[2];
    for (int vectors = 0; vectors < 2; ++vectors) {
      DynamicsConfig c = cfg;
      c.simd = vectors ? -1 : 0;
      auto s = make_sim(wall, c, p);
      ASSERT_TRUE(s);
      const double dt = lid ? s->time_step_info().spring_step : 5e-3;
      ASSERT_TRUE(s->step(lid ? 2000 : 12, dt));
      ASSERT_TRUE(s->save_state(&end[vectors]));
      ParticleSet out;
      ASSERT_TRUE(s->download(&out, &flags[vectors]));
    }
    size_t escaped = 0;
    for (uint8_t f : flags[1]) escaped += (f & kStateMask) == kEscaped;
    EXPECT_GT(escaped, 0u) << "scene " << scene;
    EXPECT_LT(escaped, p.size()) << "scene " << scene;
    std::printf("scene %d: %zu of %zu particles escaped\n", scene, escaped, p.size());
    EXPECT_EQ(flags[0], flags[1]) << "scene " << scene;
    ASSERT_EQ(end[0].arrays.size(), end[1].arrays.size());
    for (size_t a = 0; a < end[0].arrays.size(); ++a)
      EXPECT_TRUE(end[0].arrays[a] == end[1].arrays[a]) << "scene " << scene << ", array " << a;
  }
}

// Several GPU threads sharing a particle's candidates (lanes) find the same
// contacts and file the same springs as one: only the pair forces' sums run
// in another order, so the trajectories agree to rounding (the wall's
// contacts are offered in candidate order, its forces one lane's bits).
// Dense pressed lattices with friction (springs filed in order by lanes that
// each hold a share), mixed radii, and one with rolling resistance and
// Hertz-Mindlin.
void pair_lanes_agree() {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  for (int scene = 0; scene < 3; ++scene) {
    ParticleSet p = lattice(10, 9.9, -0.05, 1, 5.0, 11);  // 1.98 apart: pressed together
    SplitMix64 rng(7);
    if (scene > 0)
      for (double& r : p.r) r = rng.uniform(0.9, 1.05);
    DynamicsConfig cfg;
    cfg.particle_contacts = true;
    cfg.pairs_once = 0;  // the GPU's way, on both backends
    cfg.material.friction = 0.4;
    cfg.material.rolling_friction = scene == 1 ? 0.05 : 0;
    cfg.material.restitution = 0.5;
    if (scene == 1) cfg.contact_model = ContactModel::kHertzMindlin;
    ParticleSet end[2];
    uint64_t contacts[2][30], overflow[2] = {0, 0};
    const int lanes[2] = {1, scene == 0 ? 8 : scene == 1 ? 4 : 2};
    for (int k = 0; k < 2; ++k) {
      DynamicsConfig c = cfg;
      c.lanes = lanes[k];
      auto s = make_sim(wall, c, p);
      ASSERT_TRUE(s);
      for (int f = 0; f < 30; ++f) {
        ASSERT_TRUE(s->step(10, s->time_step_info().spring_step));
        const FrameStats now = measure(*s);
        contacts[k][f] = now.particle_contacts;
        overflow[k] += now.history_overflow;
      }
      ASSERT_TRUE(s->download(&end[k], nullptr));
    }
    uint64_t all = 0;
    for (int f = 0; f < 30; ++f) {
      ASSERT_EQ(contacts[0][f], contacts[1][f]) << "scene " << scene << ", frame " << f;
      all += contacts[0][f];
    }
    EXPECT_GT(all, 5000u) << "scene " << scene;
    EXPECT_EQ(overflow[0], overflow[1]) << "scene " << scene;
    double worst = 0;
    for (size_t i = 0; i < p.size(); ++i)
      worst = std::max({worst, std::fabs(end[0].x[i] - end[1].x[i]),
                        std::fabs(end[0].y[i] - end[1].y[i]), std::fabs(end[0].z[i] - end[1].z[i])});
    if (backend_under_test() == Backend::kCpu)
      EXPECT_EQ(worst, 0.0) << "scene " << scene;
    else
      EXPECT_LE(worst, 1e-9) << "scene " << scene;
  }
}
// GPU only (DynamicsCuda below): the CPU runs one lane whatever is asked.

// The wall's candidates shared by lanes give one lane's forces bit for bit:
// particles 3 apart (no pair touches) sliding with friction on the floor of
// a 40-sided cylinder and along the corner with its side (two contacts a
// particle), 8 lanes against one.
void wall_lanes_agree() {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  std::vector<Vec3d> at, vel;
  SplitMix64 rng(3);
  for (int i = 0; i < 10; ++i)
    for (int j = 0; j < 10; ++j) {
      at.push_back({-13.5 + 3 * i, -13.5 + 3 * j, 1.0});
      vel.push_back({rng.uniform(-2, 2), rng.uniform(-2, 2), 0});
    }
  for (int k = 0; k < 40; ++k) {
    const double a = 2 * M_PI * (k + 0.3) / 40;
    at.push_back({48.9 * std::cos(a), 48.9 * std::sin(a), 1.0});  // into the corner
    vel.push_back({std::cos(a) - std::sin(a), std::sin(a) + std::cos(a), 0});
  }
  const ParticleSet p = particles_at(at, vel, 1.0);
  DynamicsConfig cfg;
  cfg.particle_contacts = true;  // the wall's lists come with the pairs'
  cfg.material.friction = 0.4;
  cfg.material.restitution = 0.5;
  ParticleSet end[2];
  uint64_t walls = 0;
  for (int k = 0; k < 2; ++k) {
    DynamicsConfig c = cfg;
    c.lanes = k == 0 ? 1 : 8;
    auto s = make_sim(wall, c, p);
    ASSERT_TRUE(s);
    for (int f = 0; f < 20; ++f) {
      ASSERT_TRUE(s->step(200, s->time_step_info().spring_step));
      const FrameStats now = measure(*s);
      EXPECT_EQ(now.particle_contacts, 0u);
      if (k == 0) walls += now.wall_contacts;
    }
    ASSERT_TRUE(s->download(&end[k], nullptr));
  }
  EXPECT_GT(walls, 20u * 120);  // the floor's 100, and the corner's
  EXPECT_EQ(end[0].x, end[1].x);
  EXPECT_EQ(end[0].y, end[1].y);
  EXPECT_EQ(end[0].z, end[1].z);
  EXPECT_EQ(end[0].vx, end[1].vx);
  EXPECT_EQ(end[0].vz, end[1].vz);
}
// GPU only, as above.

// A neighbour list renumbers the particles in the order of their cells (here
// at its first build and every 4th after, renumber_every), handing each
// friction spring to its pair's new owner; the grid searched every step keeps
// the caller's numbers. The two runs differ only in the order their sums are
// taken, so a spring lost or turned the wrong way in a renumbering would part
// them at once: a frictional pile poured in 50 groups into a pressed lattice
// (the list built about 40 times; most releases wait for their place, which
// the lists and the grid decide alike) keeps the two within rounding, and the
// caller sees its own numbering.
void renumbering_keeps_the_springs() {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  ParticleSet p = lattice(10, 9.9, -0.05, 1, 5.0, 7);  // 1.98 apart: pressed together
  DynamicsConfig cfg;
  cfg.particle_contacts = true;
  cfg.material.friction = 0.4;
  cfg.material.restitution = 0.5;
  release_in_groups(wall, cfg, &p);
  DynamicsConfig grid = cfg;
  grid.neighbour_skin = 0;
  cfg.renumber_every = 4;
  auto listed = make_sim(wall, cfg, p), searched = make_sim(wall, grid, p);
  ASSERT_TRUE(listed && searched);
  listed->set_stage_timing(true);
  const double dt = listed->time_step_info().spring_step;
  double worst = 0, elastic = 0;
  uint64_t held = 0;
  for (int k = 0; k < 400; ++k) {
    ASSERT_TRUE(listed->step(1, dt));
    ASSERT_TRUE(searched->step(1, dt));
    const FrameStats a = measure(*listed), b = measure(*searched);
    ASSERT_EQ(a.particle_contacts, b.particle_contacts) << "step " << k;
    ASSERT_NEAR(a.elastic, b.elastic, 1e-6 * b.elastic + 1e-12) << "step " << k;
    elastic = std::max(elastic, b.elastic);
    held = std::max(held, a.held);
    ASSERT_EQ(a.held, b.held) << "step " << k;
  }
  ParticleSet pa, pb;
  ASSERT_TRUE(listed->download(&pa, nullptr));
  ASSERT_TRUE(searched->download(&pb, nullptr));
  for (size_t i = 0; i < p.size(); ++i) {
    EXPECT_EQ(pa.r[i], p.r[i]);
    worst = std::max({worst, std::fabs(pa.x[i] - pb.x[i]), std::fabs(pa.z[i] - pb.z[i]),
                      std::fabs(pa.vx[i] - pb.vx[i]) * dt});
  }
  std::printf(
      "listed against searched over 400 steps, %llu builds, up to %llu releases waiting for their "
      "place: largest difference %.3g r\n",
      (unsigned long long)listed->stage_times().neighbour_builds, (unsigned long long)held, worst);
  EXPECT_GT(listed->stage_times().neighbour_builds, 30u);
  EXPECT_GT(held, 0u);  // pressed together: releases wait, decided alike by lists and grid
  EXPECT_GT(elastic, 0);
  EXPECT_LT(worst, 1e-9);
}
TEST(Dynamics, RenumberingKeepsTheSprings) { renumbering_keeps_the_springs(); }

// Velocity Verlet closes a step in the next step's first pass; taken one call
// at a time, each step is closed on its own pass. Both give the same bits (the
// same arithmetic per particle), with releases, escapes and the wall's
// contacts in the scene: particles let go over a box's lid, some of them
// flying out of the domain.
void steps_one_at_a_time_or_together_agree() {
  const TriangleMesh wall = make_box(20, 20, 20);
  // On the box's lid (z = 20) and above it; the domain ends 0.3 over the highest.
  ParticleSet p = lattice(4, 2, 20.2, 0.3, 100.0, 17);
  for (size_t i = 0; i < p.size(); ++i) p.release[i] = 2e-5 * double(i % 10);
  DynamicsConfig cfg;
  cfg.particle_contacts = true;
  cfg.material.friction = 0.3;
  cfg.domain_margin = 0.3;
  ParticleSet end[2];
  std::vector<uint8_t> flags[2];
  for (int together = 0; together < 2; ++together) {
    auto s = make_sim(wall, cfg, p);
    ASSERT_TRUE(s);
    const double dt = s->time_step_info().spring_step;
    if (together) {
      ASSERT_TRUE(s->step(2000, dt));
    } else {
      for (int k = 0; k < 2000; ++k) ASSERT_TRUE(s->step(1, dt));
    }
    ASSERT_TRUE(s->download(&end[together], &flags[together]));
  }
  EXPECT_EQ(flags[0], flags[1]);
  size_t released = 0, escaped = 0;
  for (uint8_t f : flags[1]) {
    released += (f & kStateMask) != kWaiting;
    escaped += (f & kStateMask) == kEscaped;
  }
  EXPECT_EQ(released, p.size());
  EXPECT_GT(escaped, 0u);
  EXPECT_LT(escaped, p.size() / 2);
  std::printf("%zu of %zu particles escaped\n", escaped, p.size());
  if (backend_under_test() == Backend::kCpu) {
    EXPECT_EQ(end[0].x, end[1].x);
    EXPECT_EQ(end[0].z, end[1].z);
    EXPECT_EQ(end[0].vy, end[1].vy);
    EXPECT_EQ(end[0].vz, end[1].vz);
    return;
  }
  double worst = 0;  // nvcc may fuse the two kernels' arithmetic differently
  for (size_t i = 0; i < p.size(); ++i)
    worst = std::max({worst, std::fabs(end[0].x[i] - end[1].x[i]),
                      std::fabs(end[0].z[i] - end[1].z[i])});
  EXPECT_LE(worst, 1e-9);
}
TEST(Dynamics, StepsOneAtATimeOrTogetherAgreeBitForBit) { steps_one_at_a_time_or_together_agree(); }

// On the GPU the host launches several steps before it reads the lists'
// check, which the device takes itself; a build voids the steps after the one
// that called it, and they are launched again. The run is that of a look
// every step, bit for bit, with builds called mid-window: a dense frictional
// scene with a thin skin (a build every 20-40 steps), stepped by step() and by
// frames; particles escaping over a box's lid; the wall's lists alone; a
// turning drum; and the first while its particles are released over 150 steps,
// with and without particle contacts (a release past the lists' cover is a
// build the host calls, the releases decided on the device). The CPU looks
// every step; it runs the same scenes.
void steps_run_ahead_as_a_look_every_step_would() {
  struct Scene {
    TriangleMesh wall;
    ParticleSet p;
    DynamicsConfig cfg;
  };
  std::vector<Scene> scenes;
  {
    Scene s{make_cylinder(50, 100, 40), lattice(10, 10.5, -0.05, 1, 5.0, 7), {}};
    s.cfg.particle_contacts = true;
    s.cfg.material.friction = 0.4;
    s.cfg.material.restitution = 0.5;
    s.cfg.neighbour_skin = 0.02;
    scenes.push_back(s);
  }
  {
    Scene s{make_box(20, 20, 20), lattice(4, 2, 20.2, 0.3, 100.0, 17), {}};
    s.cfg.particle_contacts = true;
    s.cfg.material.friction = 0.3;
    s.cfg.domain_margin = 0.3;
    scenes.push_back(s);
  }
  {
    Scene s = scenes[0];
    s.cfg.particle_contacts = false;
    s.cfg.wall_lists = 1;
    scenes.push_back(s);
  }
  {
    Scene s = scenes[0];
    s.cfg.wall_motion.kind = WallMotionKind::kRotate;
    s.cfg.wall_motion.axis = {1, 0, 0};
    s.cfg.wall_motion.center = {0, 0, 50};
    s.cfg.wall_motion.angular_speed = 20;
    scenes.push_back(s);
  }
  for (bool pairs : {true, false}) {
    Scene s = scenes[pairs ? 0 : 2];
    release_in_groups(s.wall, s.cfg, &s.p, 50);
    scenes.push_back(s);
  }
  for (size_t scene = 0; scene < scenes.size(); ++scene) {
    const Scene& sc = scenes[scene];
    ParticleSet end[3];
    std::vector<uint8_t> flags[3];
    uint64_t builds[3] = {}, retaken[3] = {};
    const int ahead[3] = {1, 0, 5};  // a look every step; automatic; 5
    for (int a = 0; a < 3; ++a) {
      DynamicsConfig cfg = sc.cfg;
      cfg.run_ahead = ahead[a];
      auto s = make_sim(sc.wall, cfg, sc.p);
      ASSERT_TRUE(s);
      const double dt = s->time_step_info().spring_step;
      ASSERT_TRUE(s->step(300, dt));
      FrameStats st;
      for (int f = 0; f < 4; ++f) ASSERT_TRUE(s->advance(97.5 * dt, &st));
      ASSERT_TRUE(s->download(&end[a], &flags[a]));
      builds[a] = s->stage_times().neighbour_builds;
      retaken[a] = s->stage_times().steps_retaken;
    }
    std::printf("scene %zu: lists built %llu times; steps launched again %llu / %llu / %llu\n",
                scene, (unsigned long long)builds[0], (unsigned long long)retaken[0],
                (unsigned long long)retaken[1], (unsigned long long)retaken[2]);
    EXPECT_GT(builds[0], 5u) << "scene " << scene;
    // A window of one step takes again only the step that called the build (its forces).
    EXPECT_LE(retaken[0], builds[0]);
    for (int a = 1; a < 3; ++a) {
      EXPECT_EQ(builds[a], builds[0]) << "scene " << scene;
      EXPECT_EQ(flags[a], flags[0]) << "scene " << scene;
      EXPECT_EQ(end[a].x, end[0].x) << "scene " << scene;
      EXPECT_EQ(end[a].z, end[0].z) << "scene " << scene;
      EXPECT_EQ(end[a].vx, end[0].vx) << "scene " << scene;
      EXPECT_EQ(end[a].vz, end[0].vz) << "scene " << scene;
      if (backend_under_test() == Backend::kCuda) {
        EXPECT_GT(retaken[a], retaken[0]) << "scene " << scene;  // builds called mid-window
      } else {
        EXPECT_EQ(retaken[a], 0u);
      }
    }
  }
}
TEST(Dynamics, StepsRunAheadAsALookEveryStepWould) {
  steps_run_ahead_as_a_look_every_step_would();
}

// In advance, a window of as many steps as lie between two reads of the
// fastest speed ends at that read, and one wait for the device serves both:
// particles at rest without gravity (lists built once, never again), windows
// of 8, frames of 98 steps. Each frame reads the speed at its start and every
// 8 steps (13 reads) and settles its last 2 steps at its end. Settling each
// full window apart from the read would wait about twice as often. On the CPU
// nothing runs ahead and only the speed is read.
void advance_waits_once_for_the_window_and_the_speed() {
  DynamicsConfig cfg;
  cfg.particle_contacts = true;
  cfg.gravity = {0, 0, 0};
  cfg.run_ahead = 8;
  auto s = make_sim(make_box(20, 20, 20), cfg, lattice(4, 6, 5, 0.5, 0.0, 3));
  ASSERT_TRUE(s);
  const double dt = s->time_step_info().spring_step;
  FrameStats st;
  ASSERT_TRUE(s->advance(10 * dt, &st));  // the lists built
  const StepTimes before = s->stage_times();
  const uint64_t steps_before = s->steps_taken();
  const int frames = 5;
  uint64_t expected = 0;
  for (int f = 0; f < frames; ++f) {
    ASSERT_TRUE(s->advance(97.5 * dt, &st));
    ASSERT_EQ(st.substeps, 98u);
    expected += 13 + (backend_under_test() == Backend::kCuda ? 1 : 0);
  }
  const StepTimes& after = s->stage_times();
  EXPECT_EQ(after.neighbour_builds, before.neighbour_builds);
  EXPECT_EQ(after.steps_retaken, before.steps_retaken);
  EXPECT_EQ(s->steps_taken() - steps_before, 98u * frames);
  EXPECT_EQ(after.waits - before.waits, expected);
}
TEST(Dynamics, AdvanceWaitsOnceForTheWindowAndTheSpeed) {
  advance_waits_once_for_the_window_and_the_speed();
}

// The engine numbers the particles by release and runs a step's passes over
// the released prefix only. Each particle still starts moving at the first
// step that begins at or after its release time, none sooner and none later:
// release times drawn at random, with and without particle contacts (whose
// lists hold the particles due next, so a release need not rebuild them).
// Continued from a checkpoint numbered in the caller's order (as checkpoints
// were before the release order), the run goes on exactly as the original:
// without contacts, each particle's path does not depend on the numbering.
void releases_keep_their_times() {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  ParticleSet p = lattice(6, 8, 10, 0.5, 1.0, 3);  // 2.67 apart, slow: no contacts
  SplitMix64 rng(21);
  const int steps = 40;
  std::vector<int> due(p.size());  // released at (due + 0.5) dt: by the step from (due + 1) dt
  for (int contacts = 0; contacts < 2; ++contacts) {
    DynamicsConfig cfg;
    cfg.particle_contacts = contacts == 1;
    auto probe = make_sim(wall, cfg, p);
    ASSERT_TRUE(probe);
    const double dt = probe->time_step_info().spring_step;
    for (size_t i = 0; i < p.size(); ++i) {
      due[i] = int(rng.next() % uint64_t(steps + 1)) - 1;  // -1: out from the start
      p.release[i] = due[i] < 0 ? 0.0 : (due[i] + 0.5) * dt;
    }
    auto s = make_sim(wall, cfg, p);
    ASSERT_TRUE(s);
    ParticleSet start;  // as the engine holds them (relative to the wall's centre and back)
    ASSERT_TRUE(s->download(&start, nullptr));
    SimState half;
    for (int m = 1; m <= steps; ++m) {
      ASSERT_TRUE(s->step(1, dt));
      // Step m began at (m - 1) dt: moving are those with due <= m - 2. Those
      // due by its end, m dt, are out too (they move from the next step).
      ParticleSet now;
      ASSERT_TRUE(s->download(&now, nullptr));
      size_t waiting = 0;
      for (size_t i = 0; i < p.size(); ++i) {
        const bool released = due[i] <= m - 2;
        waiting += due[i] > m - 1;
        ASSERT_EQ(now.z[i] != start.z[i], released)
            << "particle " << i << " due " << due[i] << " after step " << m;
      }
      EXPECT_EQ(measure(*s).waiting, waiting) << "after step " << m;
      if (m == steps / 2) {
        ASSERT_TRUE(s->save_state(&half));
      }
    }
    // Nothing touches, so each particle has fallen freely since it moved, from
    // its first kick on (velocity Verlet is exact under a constant force):
    // a waiting particle's acceleration is gravity's, not zero.
    ParticleSet fallen;
    ASSERT_TRUE(s->download(&fallen, nullptr));
    const double g = -cfg.gravity.z;
    for (size_t i = 0; i < p.size(); ++i) {
      const double tau = (steps - (due[i] < 0 ? 0 : due[i] + 1)) * dt;
      EXPECT_NEAR(fallen.x[i], start.x[i] + start.vx[i] * tau, 1e-9) << "particle " << i;
      EXPECT_NEAR(fallen.z[i], start.z[i] + start.vz[i] * tau - 0.5 * g * tau * tau, 1e-9)
          << "particle " << i << " due " << due[i];
    }
    if (contacts) continue;  // springs and lists aside: the plain case suffices below
    // The saved state renumbered into the caller's order: every array's
    // element k moves to the place of the particle it holds.
    ParticleSet ref;
    ASSERT_TRUE(s->download(&ref, nullptr));
    const size_t n = p.size();
    std::vector<uint32_t> order(n);
    const std::vector<uint8_t>& order_bytes = half.arrays.back();  // the order is saved last
    ASSERT_EQ(order_bytes.size(), n * sizeof(uint32_t));
    std::memcpy(order.data(), order_bytes.data(), order_bytes.size());
    size_t moved = 0;
    for (size_t k = 0; k < n; ++k) moved += order[k] != k;
    ASSERT_GT(moved, n / 2);  // the engine's numbering is not the caller's
    SimState caller = half;
    for (std::vector<uint8_t>& a : caller.arrays) {
      const size_t width = a.size() / n;
      std::vector<uint8_t> b(a.size());
      for (size_t k = 0; k < n; ++k)
        std::memcpy(&b[order[k] * width], &a[k * width], width);
      a = std::move(b);
    }
    for (uint32_t k = 0; k < n; ++k) std::memcpy(&caller.arrays.back()[k * sizeof k], &k, sizeof k);
    auto resumed = make_sim(wall, cfg, p);
    ASSERT_TRUE(resumed);
    ASSERT_TRUE(resumed->restore_state(caller));
    ASSERT_TRUE(resumed->step(steps - steps / 2, dt));
    ParticleSet end;
    ASSERT_TRUE(resumed->download(&end, nullptr));
    EXPECT_EQ(end.z, ref.z);
    EXPECT_EQ(end.vz, ref.vz);
    EXPECT_EQ(measure(*resumed).waiting, measure(*s).waiting);
  }
}
TEST(Dynamics, ReleasesKeepTheirTimes) { releases_keep_their_times(); }

// A particle due where another one is waits until its place is free (released
// into it, it would start deep inside and be fired out: a jammed jet blew up
// so). B is due where A starts and A moves away: B goes at the first step
// boundary where A no longer touches it, never sooner and never later. C and D
// are due together at one place: C, numbered first, goes at once and D when C
// has left. E's place is free: it goes when due. The same with the neighbour
// lists and with the grid searched each step, for both integrators (Verlet
// decides at a step's end, symplectic Euler at its start, where the positions
// are); without particle contacts particles pass through one another and
// every one goes when due.
void a_release_waits_for_its_place() {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  enum { A, B, C, D, E };
  ParticleSet p = particles_at({{0, 0, 50}, {0, 0, 50}, {20, 0, 50}, {20, 0, 50}, {-20, 0, 50}},
                               {}, 1.0);
  for (int run = 0; run < 5; ++run) {
    DynamicsConfig cfg;
    cfg.gravity = {0, 0, 0};
    cfg.particle_contacts = run < 4;
    if (run % 2 == 1) cfg.neighbour_skin = 0;  // the grid searched every step
    if (run >= 2 && run < 4) cfg.integrator = Integrator::kSymplecticEuler;
    const bool euler = cfg.integrator == Integrator::kSymplecticEuler;
    auto probe = make_sim(wall, cfg, p);
    ASSERT_TRUE(probe);
    const double dt = probe->time_step_info().spring_step;
    const double v = 2.0 / (37.5 * dt);  // A and C clear their places after 37.5 steps
    p.vx = {v, 0, 0, 0, 0};
    p.vy = {0, 0, v, -v, 0};
    p.release = {0, 0.5 * dt, 0.5 * dt, 0.5 * dt, 0.5 * dt};
    auto s = make_sim(wall, cfg, p);
    ASSERT_TRUE(s);
    ParticleSet now;
    std::vector<uint8_t> flags;
    ASSERT_TRUE(s->download(&now, &flags));
    auto dist = [&](int a, int b) {
      return std::hypot(now.x[a] - now.x[b], now.y[a] - now.y[b], now.z[a] - now.z[b]);
    };
    double ab = dist(A, B), cd = dist(C, D);  // where the last decision was taken
    int b_out = -1, d_out = -1;
    for (int m = 1; m <= 60; ++m) {
      ASSERT_TRUE(s->step(1, dt));
      ASSERT_TRUE(s->download(&now, &flags));
      if (!euler) ab = dist(A, B), cd = dist(C, D);  // Verlet decides at the step's end
      if (euler && m == 1) {  // due at 0.5 dt: Euler's first decision is at step 2's start
        ab = dist(A, B), cd = dist(C, D);
        continue;
      }
      const bool b_active = (flags[B] & kStateMask) == kActive;
      const bool d_active = (flags[D] & kStateMask) == kActive;
      if (!cfg.particle_contacts) {
        for (int i = B; i <= E; ++i) EXPECT_EQ(flags[i] & kStateMask, kActive) << i;
        continue;
      }
      // Out once, and only once, nothing touches it where it waits.
      if (b_out < 0) {
        EXPECT_EQ(b_active, ab >= 2.0) << "run " << run << " step " << m << " A-B " << ab;
      }
      if (d_out < 0) {
        EXPECT_EQ(d_active, cd >= 2.0) << "run " << run << " step " << m << " C-D " << cd;
      }
      EXPECT_EQ(flags[C] & kStateMask, kActive) << "run " << run << " step " << m;
      EXPECT_EQ(flags[E] & kStateMask, kActive) << "run " << run << " step " << m;
      if (b_active && b_out < 0) b_out = m;
      if (d_active && d_out < 0) d_out = m;
      const FrameStats st = measure(*s);
      EXPECT_EQ(st.held, uint64_t(!b_active) + uint64_t(!d_active)) << "run " << run << " step " << m;
      EXPECT_EQ(st.waiting, st.held);
      EXPECT_LT(st.max_overlap, 1e-9);  // no release went into another particle
      if (euler) ab = dist(A, B), cd = dist(C, D);  // Euler decides at the next step's start
    }
    std::printf("run %d: B out after step %d, D after step %d\n", run, b_out, d_out);
    if (!cfg.particle_contacts) continue;
    EXPECT_EQ(b_out, euler ? 39 : 38) << "run " << run;
    EXPECT_EQ(d_out, b_out + 1) << "run " << run;  // C moves from its release at step 1's end
  }
}
TEST(Dynamics, AReleaseWaitsForItsPlace) { a_release_waits_for_its_place(); }

// An automatic skin grows when the lists would be built every step: particles
// fly at 20 m/s where the scene expects impacts of 0.5 m/s, so the automatic
// step moves the fastest 0.1 radii a step, twice half the smallest skin. The
// skin doubles (up to half a radius) until the lists last a few steps, and the
// run matches one that keeps the first skin bit for bit (renumbering off: the
// lists' sums run in ascending index however often they were built).
void fast_particles_grow_the_skin() {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  const ParticleSet p = lattice(8, 4.5, 10, 0.5, 20.0, 13);  // 1.125 apart: they meet, then the wall
  DynamicsConfig cfg;
  cfg.particle_contacts = true;
  cfg.impact_speed = 0.5;
  cfg.renumber_every = 0;
  DynamicsConfig kept = cfg;
  kept.neighbour_skin = 0.05;  // the automatic choice at the start: 0.1 r
  ParticleSet end[2];
  uint64_t builds[2] = {0, 0}, steps = 0, walls = 0, pairs = 0;
  for (int k = 0; k < 2; ++k) {
    auto s = make_sim(wall, k ? kept : cfg, p);
    ASSERT_TRUE(s);
    EXPECT_NEAR(s->time_step_info().neighbour_skin, 0.05, 1e-12);
    s->set_stage_timing(true);
    FrameStats st;
    for (int f = 0; f < 20; ++f) {
      ASSERT_TRUE(s->advance(0.05, &st));
      walls += st.wall_contacts;
      pairs += st.particle_contacts;
    }
    const double skin = s->time_step_info().neighbour_skin;
    if (k == 0) {
      EXPECT_GT(skin, 0.05);
      EXPECT_LE(skin, 0.25);
    } else {
      EXPECT_EQ(skin, 0.05);
    }
    builds[k] = s->stage_times().neighbour_builds;
    steps = s->stage_times().steps;
    std::printf("skin %s (%.3g m): %llu builds in %llu steps, %llu pair contacts\n", k ? "kept" : "grown", skin,
                (unsigned long long)builds[k], (unsigned long long)steps, (unsigned long long)pairs);
    ASSERT_TRUE(s->download(&end[k], nullptr));
  }
  EXPECT_GT(steps, 300u);
  EXPECT_GT(builds[1] * 10, steps * 9);  // kept: about every step
  EXPECT_LT(builds[0] * 2, builds[1]);   // grown: less than half as often
  EXPECT_GT(walls, 0u);                  // they reached the wall
  EXPECT_GT(pairs, 0u);                  // and met (a grid too fine for the grown skin misses them)
  if (backend_under_test() == Backend::kCpu) {
    EXPECT_EQ(end[0].x, end[1].x);
    EXPECT_EQ(end[0].z, end[1].z);
    EXPECT_EQ(end[0].vz, end[1].vz);
    return;
  }
  double worst = 0;  // nvcc may fuse a kernel's arithmetic differently once the lists differ
  for (size_t i = 0; i < p.size(); ++i) worst = std::max(worst, std::fabs(end[0].z[i] - end[1].z[i]));
  EXPECT_LE(worst, 1e-9);
}
TEST(Dynamics, FastParticlesGrowTheSkin) { fast_particles_grow_the_skin(); }
TEST(Dynamics, ElasticBoxKeepsItsEnergy) {
  elastic_box_energy();
}
TEST(Dynamics, TimeStepBeyondTheCriticalOneBlowsUp) {
  time_step_sweep();
}
TEST(Dynamics, FastParticlesTunnelOnlyWithACoarseFixedStep) {
  tunnelling();
}
TEST(Dynamics, ThinWallTunnelsAtHighSpeedAndSaysSo) { thin_wall_tunnels_and_says_so(); }
TEST(Dynamics, SharedVerticesAndEdgesPushOnce) {
  floor_settles_once();
}
TEST(Dynamics, RestitutionIsKept) {
  restitution_is_kept();
}
TEST(Dynamics, DivisionMethodsPushOnceToo) {
  division_methods_push_once();
}
TEST(Dynamics, FrictionTurnsSlidingIntoRolling) {
  friction_makes_it_roll();
}
// On the CPU a narrower wall1 (radius 8, height 40, 40 segments) and 200 particles, so
// they pile up (the GPU suite pours the 10^4 into wall1 itself).
TEST(Dynamics, PourIntoACylinderSettles) {
  pour_into(make_cylinder(8, 40, 40), 5, 8, 20000);
}

TEST(Dynamics, BadSettingsNameTheKey) {
  const TriangleMesh box = make_box(10, 10, 10);
  const ParticleSet p = particles_at({{0, 0, 2}}, {}, 0.5);
  auto expect_error = [&](DynamicsConfig c, const ParticleSet& ps, const std::string& key) {
    auto s = Simulation::create(box, c, ps);
    ASSERT_FALSE(s.has_value()) << key;
    EXPECT_NE(s.status().message().find(key), std::string::npos) << s.status().message();
  };
  DynamicsConfig c;
  c.material.restitution = 0;
  expect_error(c, p, "restitution");
  c = {};
  c.material.density = -1;
  expect_error(c, p, "density");
  c = {};
  c.time_step = -1;
  expect_error(c, p, "time_step");
  c = {};
  c.material.friction = NAN;
  expect_error(c, p, "friction");
  c = {};
  c.method = Method::kReference;
  expect_error(c, p, "method");
  c.method = Method::kOctree;  // a detection method: the wall's lists do not read it
  expect_error(c, p, "octree");
  ParticleSet bad = p;
  bad.r[0] = 0;
  expect_error({}, bad, "radius");
  expect_error({}, ParticleSet{}, "particle");
}

// The GPU suite: the same scenes, and trajectories that follow the CPU's.
class DynamicsCuda : public GpuSuite {};
TEST_F(DynamicsCuda, FrictionHistoryOverflowIsCounted) {
  friction_history_overflow_is_counted();
}
TEST_F(DynamicsCuda, ElasticBoxKeepsItsEnergy) {
  elastic_box_energy();
}
TEST_F(DynamicsCuda, TimeStepBeyondTheCriticalOneBlowsUp) {
  time_step_sweep();
}
TEST_F(DynamicsCuda, FastParticlesTunnelOnlyWithACoarseFixedStep) {
  tunnelling();
}
TEST_F(DynamicsCuda, ThinWallTunnelsAtHighSpeedAndSaysSo) { thin_wall_tunnels_and_says_so(); }
TEST_F(DynamicsCuda, SharedVerticesAndEdgesPushOnce) {
  floor_settles_once();
}
TEST_F(DynamicsCuda, RestitutionIsKept) {
  restitution_is_kept();
}
TEST_F(DynamicsCuda, DivisionMethodsPushOnceToo) {
  division_methods_push_once();
}
TEST_F(DynamicsCuda, SavedStateContinuesExactly) { saved_state_continues_exactly(); }
TEST_F(DynamicsCuda, RestoredStateContinuesExactlyAtEveryFrame) {
  restored_state_continues_exactly_at_every_frame(true);
}
TEST_F(DynamicsCuda, RestoredWallListsContinueExactlyAtEveryFrame) {
  restored_state_continues_exactly_at_every_frame(false);
}
TEST_F(DynamicsCuda, ALeavingParticlePushesNothing) { a_leaving_particle_pushes_nothing(); }
// A job resumed where the backend is chosen again ("auto") may move between
// the CPU and the GPU: the lists' layouts differ (the CPU keeps each pair's
// record place), so the GPU builds its own, and the run goes on.
TEST_F(DynamicsCuda, AStateSavedOnTheCpuRestoresOnTheGpu) {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  const ParticleSet p = lattice(8, 8.2, -0.05, 1, 5.0, 5);
  DynamicsConfig cfg;
  cfg.particle_contacts = true;
  cfg.material.friction = 0.4;
  cfg.backend = Backend::kCpu;
  auto cpu = Simulation::create(wall, cfg, p);
  ASSERT_TRUE(cpu) << cpu.status().message();
  FrameStats st;
  ASSERT_TRUE((*cpu)->advance(0.01, &st));
  SimState saved;
  ASSERT_TRUE((*cpu)->save_state(&saved));
  ASSERT_FALSE(saved.lists.empty());
  auto gpu = make_sim(wall, cfg, p);  // the suite's backend: CUDA
  ASSERT_TRUE(gpu);
  ASSERT_TRUE(gpu->restore_state(saved));
  ASSERT_TRUE((*cpu)->advance(0.01, &st));
  FrameStats on_gpu;
  ASSERT_TRUE(gpu->advance(0.01, &on_gpu));
  EXPECT_EQ(on_gpu.active, st.active);
  EXPECT_NEAR(on_gpu.kinetic, st.kinetic, 1e-3 * st.kinetic);  // rounding apart, the same run
}
TEST_F(DynamicsCuda, ReleasesKeepTheirTimes) { releases_keep_their_times(); }
TEST_F(DynamicsCuda, AReleaseWaitsForItsPlace) { a_release_waits_for_its_place(); }
TEST_F(DynamicsCuda, FastParticlesGrowTheSkin) { fast_particles_grow_the_skin(); }
TEST_F(DynamicsCuda, NeighbourListFindsEveryContactTheGridDoes) {
  neighbour_list_finds_every_contact();
}
TEST_F(DynamicsCuda, PairsOnceOrFromBothSidesAgreeBitForBit) {
  pairs_once_or_from_both_sides_agree();
}
TEST_F(DynamicsCuda, PairLanesAgreeWithOneLane) { pair_lanes_agree(); }
TEST_F(DynamicsCuda, WallLanesGiveOneLanesBits) { wall_lanes_agree(); }
TEST_F(DynamicsCuda, StepsOneAtATimeOrTogetherAgreeBitForBit) {
  steps_one_at_a_time_or_together_agree();
}
TEST_F(DynamicsCuda, RenumberingKeepsTheSprings) { renumbering_keeps_the_springs(); }
TEST_F(DynamicsCuda, StepsRunAheadAsALookEveryStepWould) {
  steps_run_ahead_as_a_look_every_step_would();
}
TEST_F(DynamicsCuda, AdvanceWaitsOnceForTheWindowAndTheSpeed) {
  advance_waits_once_for_the_window_and_the_speed();
}
TEST_F(DynamicsCuda, FrictionTurnsSlidingIntoRolling) {
  friction_makes_it_roll();
}
// The full size: 10^4 particles, at least 10^5 steps.
TEST_F(DynamicsCuda, PourTenThousandIntoWall1Settles) {
  pour_into(make_cylinder(50, 100, 40), 20, 25, 100000);
}

TEST_F(DynamicsCuda, TrajectoriesAgreeWithTheCpu) {
  // A dense, frictional, colliding scene in wall1: 100 steps on each backend.
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  ParticleSet p = lattice(12, 12.3, -0.05, 1, 5.0, 3);  // 2.05 apart: they collide at once
  DynamicsConfig cfg;
  cfg.particle_contacts = true;
  cfg.material.friction = 0.4;
  cfg.material.restitution = 0.5;
  ParticleSet out[2];
  for (int b = 0; b < 2; ++b) {
    cfg.backend = b ? Backend::kCuda : Backend::kCpu;
    auto s = Simulation::create(wall, cfg, p);
    ASSERT_TRUE(s.has_value()) << s.status().message();
    const double dt = s.value()->time_step_info().spring_step;
    ASSERT_TRUE(s.value()->step(100, dt));
    FrameStats st;
    ASSERT_TRUE(s.value()->measure(&st));
    EXPECT_GT(st.particle_contacts + st.wall_contacts, 0u);
    ASSERT_TRUE(s.value()->download(&out[b], nullptr));
  }
  double worst = 0;
  for (size_t i = 0; i < p.size(); ++i)
    worst = std::max({worst, std::fabs(out[0].x[i] - out[1].x[i]),
                      std::fabs(out[0].y[i] - out[1].y[i]), std::fabs(out[0].z[i] - out[1].z[i])});
  std::printf("CPU vs GPU after 100 steps: largest position difference %.3g radii\n", worst / 1.0);
  EXPECT_LE(worst, 1e-4);
}

}  // namespace
}  // namespace collido::sim
