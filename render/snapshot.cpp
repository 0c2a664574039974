#include "render/snapshot.h"

#include <algorithm>
#include <cmath>

namespace collido::render {

std::string validate_snapshot(const Snapshot& snap) {
  const size_t n = snap.radius.size();
  if (snap.positions.size() != 3 * n)
    return "snapshot: " + std::to_string(snap.positions.size()) + " position values for " +
           std::to_string(n) + " particles (expected 3 per particle)";
  if (!snap.scalar.empty() && snap.scalar.size() != n)
    return "snapshot: scalar has " + std::to_string(snap.scalar.size()) + " values for " +
           std::to_string(n) + " particles";
  if (!snap.contact.empty() && snap.contact.size() != n)
    return "snapshot: contact has " + std::to_string(snap.contact.size()) + " values for " +
           std::to_string(n) + " particles";
  for (const WallMesh* m : {&snap.wall, &snap.part}) {
    const std::string what = m == &snap.wall ? "wall" : "moving part";
    if (m->vertices.size() % 3 != 0) return "snapshot: " + what + " vertex array is not x,y,z triples";
    if (m->indices.size() % 3 != 0) return "snapshot: " + what + " index array is not triangles";
    const size_t nv = m->vertices.size() / 3;
    for (size_t i = 0; i < m->indices.size(); ++i)
      if (m->indices[i] >= nv)
        return "snapshot: " + what + " triangle " + std::to_string(i / 3) + " refers to vertex " +
               std::to_string(m->indices[i]) + " of " + std::to_string(nv);
  }
  return {};
}

Bounds compute_bounds(const Snapshot& snap) {
  Bounds b;
  float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (const WallMesh* m : {&snap.wall, &snap.part})
    for (size_t i = 0; i + 2 < m->vertices.size(); i += 3)
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], m->vertices[i + k]);
        hi[k] = std::max(hi[k], m->vertices[i + k]);
      }
  for (size_t i = 0; i < snap.radius.size() && 3 * i + 2 < snap.positions.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      const float p = snap.positions[3 * i + k], r = snap.radius[i];
      if (!std::isfinite(p)) continue;
      lo[k] = std::min(lo[k], p - r);
      hi[k] = std::max(hi[k], p + r);
    }
  for (int k = 0; k < 3; ++k) {
    b.lo[k] = lo[k];
    b.hi[k] = hi[k];
  }
  return b;
}

}  // namespace collido::render
