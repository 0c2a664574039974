// Small scenes shared by the renderer tests.
#pragma once

#include <cmath>
#include <cstdint>
#include <random>

#include "render/render.h"

namespace collido::render::testing {

// A closed cylinder around the z axis, from z0 to z0 + height, outward normals.
inline WallMesh cylinder(float radius, float z0, float height, int segments) {
  WallMesh w;
  for (int i = 0; i < segments; ++i) {
    const float a = 2.f * 3.14159265f * float(i) / float(segments);
    const float x = radius * std::cos(a), y = radius * std::sin(a);
    w.vertices.insert(w.vertices.end(), {x, y, z0, x, y, z0 + height});
  }
  for (int i = 0; i < segments; ++i) {
    const uint32_t b0 = 2 * i, t0 = b0 + 1, b1 = 2 * ((i + 1) % segments), t1 = b1 + 1;
    w.indices.insert(w.indices.end(), {b0, b1, t1, b0, t1, t0});
  }
  for (int i = 1; i + 1 < segments; ++i) {
    w.indices.insert(w.indices.end(), {0u, uint32_t(2 * (i + 1)), uint32_t(2 * i)});
    w.indices.insert(w.indices.end(), {1u, uint32_t(2 * i + 1), uint32_t(2 * (i + 1) + 1)});
  }
  return w;
}

// One particle of radius r at the origin inside a cylinder centred on it.
inline Snapshot one_particle_scene(float r, float speed) {
  Snapshot s;
  s.wall = cylinder(10.f, -10.f, 20.f, 48);
  s.positions = {0.f, 0.f, 0.f};
  s.radius = {r};
  s.scalar = {speed};
  s.contact = {0};
  s.bounds = compute_bounds(s);
  s.time = 0.5;
  s.frame = 7;
  return s;
}

// n particles scattered in the same cylinder, fixed seed.
inline Snapshot cloud_scene(int n, uint32_t seed) {
  Snapshot s;
  s.wall = cylinder(10.f, -10.f, 20.f, 32);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  for (int i = 0; i < n; ++i) {
    const float rho = 9.f * std::sqrt(u(rng)), phi = 6.2831853f * u(rng);
    s.positions.insert(s.positions.end(),
                       {rho * std::cos(phi), rho * std::sin(phi), -9.f + 18.f * u(rng)});
    s.radius.push_back(0.3f + 0.3f * u(rng));
    s.scalar.push_back(u(rng));
    s.contact.push_back(rho > 8.5f ? 1 : 0);
  }
  s.bounds = compute_bounds(s);
  return s;
}

// Options for exact pixel checks: no lighting, no overlay, no multisampling,
// a flat background.
inline RenderOptions flat_options(int w, int h) {
  RenderOptions o;
  o.width = w;
  o.height = h;
  o.shading = false;
  o.overlay = false;
  o.msaa_samples = 0;
  o.background_top = o.background_bottom = {10, 20, 30};
  o.color_min = 0;
  o.color_max = 1;
  return o;
}

}  // namespace collido::render::testing
