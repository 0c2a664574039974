// A built-in wall for a test, failing the test (not aborting it) on a bad spec.
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "sim/shapes.h"

namespace collido::sim {

inline TriangleMesh shape(const std::string& spec) {
  auto m = make_shape(spec);
  EXPECT_TRUE(m.has_value()) << spec;
  return m ? std::move(*m) : TriangleMesh{};
}

// A row of n right triangles of legs `size` along x (in the plane z = 0),
// their source ids in order, then a sliver as long as the row above it at
// z = 3 size: the octree's leaves list triangles far apart along the row.
inline TriangleMesh triangle_row_under_a_sliver(uint32_t n, double size) {
  TriangleMesh row;
  auto add = [&row](Vec3d a, Vec3d b, Vec3d c) {
    const uint32_t v = uint32_t(row.vertices.size());
    row.vertices.insert(row.vertices.end(), {a, b, c});
    row.triangles.push_back({v, v + 1, v + 2});
  };
  for (uint32_t k = 0; k < n; ++k)
    add({size * k, 0, 0}, {size * k + size, 0, 0}, {size * k, size, 0});
  add({0, 0.5 * size, 3 * size}, {size * n, 0.5 * size, 3 * size},
      {size * n, 0.501 * size, 3 * size});
  row.source_ids.resize(row.triangles.size());
  for (size_t t = 0; t < row.triangles.size(); ++t) row.source_ids[t] = uint32_t(t);
  return row;
}

// A crowded wall: a fine ball (20,480 triangles about 0.03 across) inside a
// 6 x 4 x 4 box, with a long sliver through both.
inline TriangleMesh crowded_wall() {
  TriangleMesh m = shape("sphere:r=1,subdivisions=5");
  const TriangleMesh box = shape("box:x=6,y=4,z=4");
  const uint32_t base = uint32_t(m.vertices.size());
  m.vertices.insert(m.vertices.end(), box.vertices.begin(), box.vertices.end());
  for (const auto& t : box.triangles)
    m.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  const uint32_t s = uint32_t(m.vertices.size());
  m.vertices.push_back({-2.9, -1.9, -0.5});
  m.vertices.push_back({2.9, 1.9, 0.5});
  m.vertices.push_back({2.9, 1.9002, 0.5});
  m.triangles.push_back({s, s + 1, s + 2});
  m.source_ids.resize(m.triangles.size());
  for (size_t t = 0; t < m.triangles.size(); ++t) m.source_ids[t] = uint32_t(t);
  return m;
}

}  // namespace collido::sim
