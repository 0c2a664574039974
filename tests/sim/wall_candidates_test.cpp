// The dynamics' wall lookup: the candidates a particle's cell offers, and the
// cheap cull before the exact distance, never lose a triangle within reach.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "sim/backend_cpu.h"
#include "sim/contact_force.h"
#include "sim/shapes.h"
#include "sim/wall_index.h"
#include "tests/sim/wall_shape.h"

namespace collido::sim {
namespace {

// The squared distance with no reach to cull by.
double exact_d2(Vec3d p, const PlanarTriangleD& t, double reach2 = INFINITY) {
  Vec3d q;
  double h = 0, aside = 0;
  return closest_point_planar(p, t, reach2, &q, &h, &aside);
}

// Whether the cull in closest_point_planar keeps t for p: the height, then out_of_reach.
bool kept_by_cull(Vec3d p, const PlanarTriangleD& t, double reach2) {
  const Vec3d ap = p - t.a;
  const double h = dot(ap, t.n), left = reach2 - h * h;
  return left > 0 && !out_of_reach(dot(ap, t.e1), dot(ap, cross(t.n, t.e1)), left, t, reach2);
}

// A point at `dist` from a random point of t, in a random direction.
Vec3d point_near(const PlanarTriangleD& t, double dist, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u01(0, 1);
  double s = u01(rng), w = u01(rng);
  if (s + w > 1) s = 1 - s, w = 1 - w;
  const Vec3d e2 = cross(t.n, t.e1);
  const Vec3d on = t.a + t.e1 * (s * t.b1 + w * t.c1) + e2 * (w * t.c2);
  std::normal_distribution<double> g(0, 1);
  Vec3d dir{g(rng), g(rng), g(rng)};
  return on + dir * (dist / length(dir));
}

// Triangles of every shape the walls give: wide, slivers, needles, one a segment.
std::vector<PlanarTriangleD> odd_triangles(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<PlanarTriangleD> out;
  const Vec3d far{3e4, -2e4, 1e4};
  for (int i = 0; i < 400; ++i) {
    const double scale = std::pow(10.0, 3 * u(rng));  // 1e-3 .. 1e3 of the radius
    const Vec3d base = (i % 4 == 0 ? far : Vec3d{0, 0, 0}) + Vec3d{u(rng), u(rng), u(rng)};
    Vec3d a = base, b = base + Vec3d{u(rng), u(rng), u(rng)} * scale;
    Vec3d c = base + Vec3d{u(rng), u(rng), u(rng)} * scale;
    if (i % 5 == 1) c = a + (b - a) * 0.5 + Vec3d{1e-7, 0, 1e-7} * scale;  // a sliver
    if (i % 7 == 2) b = a + Vec3d{u(rng), u(rng), u(rng)} * 1e-4 * scale;  // a needle
    if (i % 11 == 3) c = a + (b - a) * 0.25;                               // a segment
    out.push_back(make_planar<double>(a, b, c, Vec3d{0, 0, 0}));
  }
  return out;
}

TEST(WallLookup, TheCullNeverRejectsATriangleWithinReach) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u01(0, 1);
  size_t touching = 0, clear = 0, culled = 0, tried = 0;
  for (const PlanarTriangleD& t : odd_triangles(rng)) {
    for (int k = 0; k < 200; ++k) {
      const double r = 1.0;
      // Touching by a hair, missing by a hair, and well clear.
      const double dist = k % 3 == 0 ? r * (1 - 1e-9 * u01(rng))
                          : k % 3 == 1 ? r * (1 + 1e-9 * u01(rng))
                                       : r * 3 * u01(rng);
      const Vec3d p = point_near(t, dist, rng);
      const bool within = exact_d2(p, t) < r * r;
      const bool kept = kept_by_cull(p, t, r * r);
      // With the cull inside it, the closest point decides as without.
      ASSERT_EQ(exact_d2(p, t, r * r) < r * r, within);
      ++tried;
      touching += within;
      clear += dist > 1.5 * r;
      culled += !kept;
      ASSERT_TRUE(kept || !within) << "a triangle within reach was culled";
    }
  }
  // Not vacuous: many points touch, and the cull rejects more than those well clear.
  EXPECT_GT(touching, tried / 4);
  EXPECT_GT(culled, clear);
}

// A centre over a triangle's edge has its foot on the edge: the in-plane
// distance the closest point gives is the coordinates' rounding alone, far
// under the 1e-18 r^2 below which the dynamics pushes along the face's normal
// (the total less h^2 carries h^2's rounding, about 1e-17 r^2: a sideways
// push that walked a resting ball off a cup's bottom on the GPU). Elsewhere
// the in-plane part and the height make up the total.
TEST(WallLookup, AnEdgesFootLiesInThePlaneWithoutTheHeightsRounding) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u01(0, 1);
  size_t over_edges = 0;
  for (const PlanarTriangleD& t : odd_triangles(rng)) {
    const double r = 1.0, r2 = r * r;
    const double size = std::sqrt(t.b1 * t.b1 + t.c1 * t.c1 + t.c2 * t.c2);
    if (!(t.c2 > 1e-3 * size) || size < 1e-2 || size > 1e2) continue;  // no slivers, a ball's size
    const Vec3d e2 = cross(t.n, t.e1);
    const Vec3d corner[3] = {t.a, t.a + t.e1 * t.b1, t.a + t.e1 * t.c1 + e2 * t.c2};
    for (int k = 0; k < 30; ++k) {
      const int e = k % 3;
      const double s = 0.2 + 0.6 * u01(rng), height = r * (0.3 + 0.6 * u01(rng));
      const Vec3d foot = corner[e] + (corner[(e + 1) % 3] - corner[e]) * s;
      const Vec3d p = foot + t.n * height;
      Vec3d q;
      double h = 0, aside = -1;
      const double d2 = closest_point_planar(p, t, r2, &q, &h, &aside);
      ASSERT_LT(d2, r2);
      const double scale = std::max({std::fabs(p.x), std::fabs(p.y), std::fabs(p.z), size});
      EXPECT_LE(aside, 1e-28 * scale * scale) << "over edge " << e;
      ++over_edges;
      // A point beside the face: the parts add up to the total.
      const Vec3d off = p + (foot - (corner[(e + 2) % 3])) * (0.1 * u01(rng));
      const double d2_off = closest_point_planar(off, t, INFINITY, &q, &h, &aside);
      EXPECT_NEAR(aside + h * h, d2_off, 1e-12 * d2_off);
    }
  }
  EXPECT_GT(over_edges, 1000u);
}

// Every prepared triangle or piece within r_max of a point is among the
// candidates its cell offers, on the divided walls (a cube of cells around the
// point) and bin; dense and hashed grids, far from the origin too.
TEST(WallLookup, EveryTriangleWithinReachIsACandidate) {
  TriangleMesh far = shape("sphere:r=10,subdivisions=2");
  translate(far, {1e4, -3e3, 2e3});
  struct Case {
    TriangleMesh mesh;
    double r;
  };
  const Case cases[] = {{shape("wall1"), 2.5},
                        {shape("wall2"), 4.6},
                        {shape("box:x=20,y=20,z=20"), 0.23},
                        {shape("cone:r1=20,r2=5,h=30,segments=32"), 0.4},
                        {std::move(far), 0.9}};
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u01(0, 1);
  for (const Case& c : cases) {
    for (Method method : {Method::kGravity, Method::kCircumcircle, Method::kMidpoint4, Method::kBin}) {
      for (uint64_t dense : {uint64_t(1) << 20, uint64_t(500)}) {
        CpuBackend backend;
        WallIndex<CpuBackend> wall;
        PrepareInfo info;
        // The dynamics' cell: twice the largest radius.
        ASSERT_TRUE(wall.prepare(backend, c.mesh, method, c.r, 2 * c.r, dense, 200, &info, true).ok());
        const WallView view = wall.view();
        const size_t m = wall.tris_d.size();
        ASSERT_GT(m, 0u);
        // Each triangle's reach from its corner a, to skip the far ones quickly.
        std::vector<double> extent(m);
        for (size_t k = 0; k < m; ++k) {
          const PlanarTriangleD& t = wall.tris_d.data()[k];
          extent[k] = std::max(t.b1, std::sqrt(t.c1 * t.c1 + t.c2 * t.c2));
        }
        std::vector<char> offered(m);
        size_t points_touching = 0;
        for (int s = 0; s < 150; ++s) {
          const PlanarTriangleD& t = wall.tris_d.data()[size_t(u01(rng) * double(m)) % m];
          const double dist = s % 2 ? c.r * (1 - 1e-7) : c.r * 1.5 * u01(rng);
          const Vec3d p = point_near(t, dist, rng);
          std::fill(offered.begin(), offered.end(), 0);
          view.for_each_candidate(cast3<float>(p), [&](uint32_t k, uint32_t) { offered[k] = 1; });
          bool any = false;
          for (uint32_t k = 0; k < m; ++k) {
            const PlanarTriangleD& t = wall.tris_d.data()[k];
            if (length(p - t.a) > extent[k] + 2 * c.r) continue;  // far: cannot touch
            if (!(exact_d2(p, t) < c.r * c.r)) continue;
            any = true;
            ASSERT_TRUE(offered[k])
                << to_string(method) << " r = " << c.r << (dense < 1000 ? " hashed" : "")
                << ": triangle " << k << " within reach was not offered";
          }
          points_touching += any;
        }
        EXPECT_GT(points_touching, 50u);
      }
    }
  }
}

}  // namespace
}  // namespace collido::sim
