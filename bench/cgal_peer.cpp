// The CPU peer of `bench detect` on large meshes: CGAL's AABB tree (Debian's
// libcgal-dev, double precision, one thread) answering the same question for
// the same particles: how many triangles lie within each sphere's radius.
// Built only when CGAL is found, and only here: the engine never links it.
// Usage: cgal_peer WALL.stl PARTICLES NEAR_FRACTION R_LO R_HI SEED
// Prints one line: triangles, particles, build ms, query ms, contacts.
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "sim/accuracy.h"
#include "sim/mesh.h"

namespace {

using K = CGAL::Simple_cartesian<double>;
using Iterator = std::vector<K::Triangle_3>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<K, Iterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;

// A sphere query through the tree's own traversal: boxes within r of the
// centre are opened, triangles counted when strictly closer than r (the
// engine's contact predicate).
struct SphereCount {
  double r2 = 0;
  uint64_t count = 0;
  bool go_further() const { return true; }
  void intersection(const K::Point_3& p, const Primitive& prim) {
    if (CGAL::squared_distance(p, prim.datum()) < r2) ++count;
  }
  template <class Node>
  bool do_intersect(const K::Point_3& p, const Node& node) const {
    const CGAL::Bbox_3& b = node.bbox();
    double d2 = 0;
    const double c[3] = {p.x(), p.y(), p.z()};
    for (int a = 0; a < 3; ++a) {
      const double lo = b.min(a), hi = b.max(a);
      const double d = c[a] < lo ? lo - c[a] : (c[a] > hi ? c[a] - hi : 0.0);
      d2 += d * d;
    }
    return d2 <= r2;
  }
};

double ms_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 7) {
    std::fprintf(stderr, "usage: cgal_peer WALL.stl PARTICLES NEAR_FRACTION R_LO R_HI SEED\n");
    return 2;
  }
  auto mesh = collido::sim::load_stl(argv[1]);
  if (!mesh) {
    std::fprintf(stderr, "cgal_peer: %s\n", mesh.status().message().c_str());
    return 1;
  }
  const size_t n = std::strtoull(argv[2], nullptr, 10);
  const double near = std::atof(argv[3]), r_lo = std::atof(argv[4]), r_hi = std::atof(argv[5]);
  // The same particles as `collidoscope bench detect` with these settings.
  const collido::sim::Particles p = collido::sim::particles_near_surface(
      *mesh, n, r_lo, r_hi, near, 1.5 * r_hi, std::strtoull(argv[6], nullptr, 10));
  std::vector<K::Triangle_3> tris;
  tris.reserve(mesh->triangles.size());
  for (size_t t = 0; t < mesh->triangles.size(); ++t) {
    auto pt = [&](int k) {
      const auto v = mesh->corner(t, k);
      return K::Point_3(v.x, v.y, v.z);
    };
    tris.emplace_back(pt(0), pt(1), pt(2));
  }
  auto t0 = std::chrono::steady_clock::now();
  Tree tree(tris.cbegin(), tris.cend());
  tree.build();
  const double build_ms = ms_since(t0);
  t0 = std::chrono::steady_clock::now();
  uint64_t contacts = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    SphereCount q;
    q.r2 = p.r[i] * p.r[i];
    tree.traversal(K::Point_3(p.x[i], p.y[i], p.z[i]), q);
    contacts += q.count;
  }
  const double query_ms = ms_since(t0);
  std::printf("cgal_peer: %zu triangles, %zu particles, build %.1f ms, query %.1f ms, %llu contacts\n",
              mesh->triangles.size(), p.size(), build_ms, query_ms,
              static_cast<unsigned long long>(contacts));
  return 0;
}
