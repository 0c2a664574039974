// Small scenes the dynamics tests share: particles placed by hand, a lattice
// of them, a floor of many triangles, and a Simulation on the backend under test.
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <vector>

#include "sim/dynamics.h"
#include "sim/particles.h"
#include "sim/shapes.h"
#include "tests/sim/gpu_suite.h"

namespace collido::sim {

inline ParticleSet particles_at(const std::vector<Vec3d>& pos, const std::vector<Vec3d>& vel, double r) {
  ParticleSet p;
  p.resize(pos.size());
  for (size_t i = 0; i < pos.size(); ++i) {
    p.x[i] = pos[i].x, p.y[i] = pos[i].y, p.z[i] = pos[i].z, p.r[i] = r;
    if (i < vel.size()) p.vx[i] = vel[i].x, p.vy[i] = vel[i].y, p.vz[i] = vel[i].z;
  }
  return p;
}

// n particles on a lattice inside the box [-h, h]^2 x [z0, z0 + 2h] with random velocities of size
// `speed`.
inline ParticleSet lattice(int per_side, double h, double z0, double r, double speed, uint64_t seed) {
  SplitMix64 rng(seed);
  std::vector<Vec3d> pos, vel;
  const double step = 2 * h / per_side;
  for (int i = 0; i < per_side; ++i)
    for (int j = 0; j < per_side; ++j)
      for (int k = 0; k < per_side; ++k) {
        pos.push_back({-h + (i + 0.5) * step, -h + (j + 0.5) * step, z0 + (k + 0.5) * step});
        Vec3d d{rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)};
        vel.push_back(d * (speed / length(d)));
      }
  return particles_at(pos, vel, r);
}

inline std::unique_ptr<Simulation> make_sim(const TriangleMesh& wall, DynamicsConfig cfg,
                                     const ParticleSet& p) {
  cfg.backend = backend_under_test();
  auto s = Simulation::create(wall, cfg, p);
  EXPECT_TRUE(s.has_value()) << s.status().message();
  return s.has_value() ? std::move(s.value()) : nullptr;
}

inline FrameStats measure(Simulation& s) {
  FrameStats st;
  EXPECT_TRUE(s.measure(&st));
  return st;
}

// A flat square floor [-h, h]^2 at z = 0 cut into cells x cells squares of two triangles each.
inline TriangleMesh floor_mesh(double h, int cells) {
  TriangleMesh m;
  for (int j = 0; j <= cells; ++j)
    for (int i = 0; i <= cells; ++i)
      m.vertices.push_back({-h + 2 * h * i / cells, -h + 2 * h * j / cells, 0});
  auto v = [&](int i, int j) { return uint32_t(j * (cells + 1) + i); };
  for (int j = 0; j < cells; ++j)
    for (int i = 0; i < cells; ++i) {
      m.triangles.push_back({v(i, j), v(i + 1, j), v(i + 1, j + 1)});
      m.triangles.push_back({v(i, j), v(i + 1, j + 1), v(i, j + 1)});
    }
  for (uint32_t t = 0; t < m.triangles.size(); ++t) m.source_ids.push_back(t);
  return m;
}

// A ball of radius 0.5 dropped at 2 m/s on the floor of a 10 m box without
// gravity: its upward speed 1 s later (2 e after one bounce).
inline double rebound_speed(const DynamicsConfig& cfg) {
  auto s = make_sim(make_box(10, 10, 10), cfg, particles_at({{0, 0, 1}}, {{0, 0, -2}}, 0.5));
  if (!s) return 0;
  FrameStats st;
  EXPECT_TRUE(s->advance(1.0, &st));
  ParticleSet out;
  EXPECT_TRUE(s->download(&out, nullptr));
  return out.vz[0];
}

}  // namespace collido::sim
