#include "sim/shapes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "sim/winding_field.h"

namespace collido::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

void expect_closed_outward(const TriangleMesh& m, const std::string& what) {
  EXPECT_TRUE(is_closed_manifold(m)) << what;
  EXPECT_GT(signed_volume(m), 0) << what << ": normals point inward";
}

TEST(Shapes, Wall1IsThePapers156TriangleCylinder) {
  auto m = make_shape("cylinder:r=50,h=100,segments=40");
  ASSERT_TRUE(m) << m.status().message();
  EXPECT_EQ(m->triangles.size(), 156u);
  expect_closed_outward(*m, "wall1");
  // Volume of the inscribed 40-gon prism.
  const double polygon = 0.5 * 40 * 50 * 50 * std::sin(2 * kPi / 40);
  EXPECT_NEAR(signed_volume(*m), polygon * 100, 1e-6 * polygon * 100);
  auto alias = make_shape("wall1");
  ASSERT_TRUE(alias);
  EXPECT_EQ(alias->triangles.size(), 156u);
}

TEST(Shapes, PrimitivesAreClosedWithOutwardNormals) {
  expect_closed_outward(make_box(2, 3, 4), "box");
  EXPECT_NEAR(signed_volume(make_box(2, 3, 4)), 24, 1e-9);
  TriangleMesh s = make_sphere(5, 3);
  EXPECT_EQ(s.triangles.size(), 20u * 64u);
  expect_closed_outward(s, "sphere");
  EXPECT_NEAR(signed_volume(s), 4.0 / 3.0 * kPi * 125, 0.02 * 4.0 / 3.0 * kPi * 125);
  expect_closed_outward(make_cone(10, 0, 20, 32), "cone");
  expect_closed_outward(make_cone(10, 4, 20, 32), "frustum");
  expect_closed_outward(make_cylinder(1, 2, 3), "triangular prism");
}

TEST(Shapes, Wall2IsAClosedCompositeVesselOfAbout1600Triangles) {
  TriangleMesh w = make_wall2();
  EXPECT_GT(w.triangles.size(), 1400u);
  EXPECT_LT(w.triangles.size(), 1800u);
  expect_closed_outward(w, "wall2");
  std::printf("wall2: %zu triangles (paper: about 1600)\n", w.triangles.size());
}

TEST(Shapes, UnionsAndOffsets) {
  auto m = make_shape("box:x=1,y=1,z=1+sphere:r=1,subdivisions=1,dz=5");
  ASSERT_TRUE(m) << m.status().message();
  EXPECT_EQ(m->triangles.size(), 12u + 80u);
  Bounds3d b = mesh_bounds(*m);
  EXPECT_NEAR(b.hi.z, 7, 1e-9);
  for (size_t i = 0; i < m->source_ids.size(); ++i) EXPECT_EQ(m->source_ids[i], i);
}

// A drum on its side: the lathed shapes turn to lie along x or y, still closed
// and facing out; a wrong axis is an error.
TEST(Shapes, LathedShapesLieAlongTheAxisAsked) {
  for (const char* axis : {"x", "y"}) {
    auto m = make_shape(std::string("cylinder:r=5,h=2,segments=32,axis=") + axis + ",dz=7");
    ASSERT_TRUE(m) << m.status().message();
    expect_closed_outward(*m, axis);
    const Bounds3d b = mesh_bounds(*m);
    const double along = axis[0] == 'x' ? b.hi.x - b.lo.x : b.hi.y - b.lo.y;
    EXPECT_NEAR(along, 2, 1e-9) << axis;
    EXPECT_NEAR(b.hi.z - b.lo.z, 10, 1e-9) << axis;
    EXPECT_NEAR(0.5 * (b.hi.z + b.lo.z), 7, 1e-9) << axis;
  }
  auto bad = make_shape("cylinder:axis=w");
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.status().message().find("axis"), std::string::npos);
  EXPECT_FALSE(make_shape("box:axis=y"));  // a box has no axis
}

TEST(Shapes, BadSpecsNameTheProblem) {
  struct Case {
    const char* spec;
    const char* says;
  } cases[] = {{"cylinder:r=-1", "r must be"},       {"cylinder:segments=2", "segments"},
               {"cylinder:radius=5", "unknown parameter 'radius'"}, {"teacup:r=1", "unknown shape"},
               {"box:x=abc", "finite number"},       {"sphere:subdivisions=12", "subdivisions"},
               {"cylinder:r=5,caps=maybe", "caps"},  {"cone:r1=0,r2=0", "radii"},
               {"cylinder:r", "key=value"},          {"box:dx=1e20", "dx must lie within"}};
  for (const auto& c : cases) {
    auto m = make_shape(c.spec);
    ASSERT_FALSE(m) << c.spec;
    EXPECT_NE(m.status().message().find(c.says), std::string::npos) << c.spec << ": " << m.status().message();
  }
}

TEST(Shapes, OpenCapsAreOpen) {
  auto m = make_shape("funnel:r1=10,r2=40,h=30,segments=64");
  ASSERT_TRUE(m);
  EXPECT_FALSE(is_closed_manifold(*m));
  EXPECT_EQ(m->triangles.size(), 128u);
}

// The winding number as the plain sum of each triangle's solid angle, the
// definition that winding_number computes with one atan2 instead of one a triangle.
double winding_by_sum(const TriangleMesh& mesh, Vec3d p) {
  double sum = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Vec3d a = mesh.corner(t, 0) - p, b = mesh.corner(t, 1) - p, c = mesh.corner(t, 2) - p;
    const double la = length(a), lb = length(b), lc = length(c);
    const double num = dot(a, cross(b, c));
    const double den = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb;
    sum += 2 * std::atan2(num, den);
  }
  return sum / (4 * kPi);
}

// Points to ask a wall's winding number at: 300 in and around its box (a
// fifth of its size beyond each face), its vertices, edges' midpoints and
// faces' centroids, and the box's centre.
std::vector<Vec3d> winding_probes(const TriangleMesh& m, std::mt19937_64& rng) {
  Bounds3d box;
  for (const Vec3d& v : m.vertices) box.grow(v);
  const Vec3d size = box.hi - box.lo;
  std::uniform_real_distribution<double> u(-0.2, 1.2);
  std::vector<Vec3d> points;
  for (int i = 0; i < 300; ++i)
    points.push_back(box.lo + Vec3d{u(rng) * size.x, u(rng) * size.y, u(rng) * size.z});
  for (size_t t = 0; t < m.triangles.size(); t += 1 + m.triangles.size() / 60) {
    points.push_back(m.corner(t, 0));
    points.push_back((m.corner(t, 0) + m.corner(t, 1)) * 0.5);
    points.push_back((m.corner(t, 0) + m.corner(t, 1) + m.corner(t, 2)) * (1.0 / 3.0));
  }
  points.push_back((box.lo + box.hi) * 0.5);
  return points;
}

TriangleMesh test_mesh(const std::string& name) {
  auto m = load_stl(std::string(COLLIDO_TEST_DATA) + "/meshes/" + name);
  EXPECT_TRUE(m) << m.status().message();
  return m ? std::move(*m) : TriangleMesh{};
}

TEST(Shapes, WindingNumbersAreTheSumOfTheSolidAngles) {
  std::vector<TriangleMesh> walls;
  for (const char* spec : {"sphere:r=10,subdivisions=3", "funnel:r1=10,r2=40,h=30,segments=64",
                           "box:x=2,y=2,z=2", "wall2"})
    walls.push_back(*make_shape(spec));
  walls.push_back(test_mesh("3dsmax_export_assimp.stl"));
  std::mt19937_64 rng(5);
  size_t inside = 0, outside = 0, fractional = 0;
  for (const TriangleMesh& m : walls) {
    for (const Vec3d& p : winding_probes(m, rng)) {
      const double w = winding_number(m, p), ref = winding_by_sum(m, p);
      ASSERT_NEAR(w, ref, 1e-9) << "at " << p.x << ", " << p.y << ", " << p.z;
      inside += std::fabs(w - 1) < 1e-6;
      outside += std::fabs(w) < 1e-6;
      fractional += std::fabs(w) > 0.05 && std::fabs(w - 1) > 0.05;
    }
  }
  // Not vacuous: whole turns inside the closed walls, none outside, fractions near the open ones.
  EXPECT_GT(inside, 100u);
  EXPECT_GT(outside, 300u);
  EXPECT_GT(fractional, 100u);
}

// The field gives the plain sum's number on closed walls, open ones (a cup,
// a funnel, CAD exports with holes and slits), one whose faces are wound
// every which way, and a plate with holes; at points in the open, on faces,
// edges and vertices, and on the cap's plane (a cup's rim). And it does less
// work than the plain sum: most points settle from the tree and the cap.
TEST(Shapes, AWindingFieldGivesThePlainSum) {
  std::vector<TriangleMesh> walls;
  for (const char* spec : {"sphere:r=10,subdivisions=3", "funnel:r1=10,r2=40,h=30,segments=64",
                           "cylinder:r=10,h=20,segments=48,caps=bottom", "box:x=2,y=2,z=2", "wall2"})
    walls.push_back(*make_shape(spec));
  for (const char* name : {"3dsmax_export_assimp.stl", "sphere_with_hole_assimp.stl",
                           "plate_holes_trimesh_binary_solid_header.stl", "teapot_trimesh.stl",
                           "counter_unitsmm_trimesh_83750tri.stl"})
    walls.push_back(test_mesh(name));
  TriangleMesh mixed = *make_shape("sphere:r=5,subdivisions=2");
  for (size_t t = 0; t < mixed.triangles.size(); t += 3) std::swap(mixed.triangles[t][1], mixed.triangles[t][2]);
  walls.push_back(std::move(mixed));
  std::mt19937_64 rng(9);
  size_t fractional = 0, whole = 0;
  for (const TriangleMesh& m : walls) {
    const WindingField field(m);
    std::vector<Vec3d> points = winding_probes(m, rng);
    // Just off the faces, where the near triangles' dipoles would be poor.
    for (size_t t = 0; t < m.triangles.size(); t += 1 + m.triangles.size() / 60) {
      const Vec3d a = m.corner(t, 0), b = m.corner(t, 1), c = m.corner(t, 2);
      const Vec3d n = cross(b - a, c - a);
      const double size = std::sqrt(length(n));
      if (!(size > 0)) continue;
      for (double off : {-1e-2, -1e-5, 1e-5, 1e-2})
        points.push_back((a + b + c) * (1.0 / 3.0) + n * (off * size / length(n)));
    }
    // The cup's rim plane, where its cap lies (the cone over a level rim is flat).
    if (m.triangles.size() == 142) {
      double top = -INFINITY;
      for (const Vec3d& v : m.vertices) top = std::max(top, v.z);
      for (int i = 0; i < 40; ++i) points.push_back({-12 + 0.6 * i, 0.3 * i - 6, top});
    }
    WindingField::Work work;
    for (const Vec3d& p : points) {
      const double w = field.at(p, &work), ref = winding_number(m, p);
      ASSERT_NEAR(w, ref, 1e-11) << m.triangles.size() << " triangles, at " << p.x << ", " << p.y
                                 << ", " << p.z;
      fractional += std::fabs(w - std::nearbyint(w)) > 0.05;
      whole += std::fabs(w - std::nearbyint(w)) < 1e-9;
    }
    if (m.triangles.size() > 1000) {
      // Work per point against the plain sum's pass over every triangle: the
      // plain sum only for the points on the wall (its vertices, edges and
      // faces, 180 of about 720), the tree's exact triangles half or less.
      ASSERT_FALSE(field.plain());
      EXPECT_LT(double(work.plain), 0.45 * double(work.points)) << m.triangles.size();
      EXPECT_LT(double(work.exact_triangles), 0.5 * double(m.triangles.size() * work.points))
          << m.triangles.size() << " triangles";
      EXPECT_GT(work.far_nodes, work.points) << m.triangles.size();
    }
  }
  EXPECT_GT(fractional, 200u);
  EXPECT_GT(whole, 1000u);
}

// A union that would take a worker minutes to build (found by fuzz_wall_spec)
// is refused: too many parts, or more triangles than a wall spec may make.
TEST(Shapes, HugeUnionsAreRefused) {
  ASSERT_TRUE(make_shape("sphere:r=1,subdivisions=8"));  // 1.3 million triangles: fine
  const std::string big = "sphere:r=1,subdivisions=8+sphere:r=1,subdivisions=8,dz=3";
  auto m = make_shape(big);
  ASSERT_FALSE(m);
  EXPECT_NE(m.status().message().find("triangles"), std::string::npos) << m.status().message();
  std::string many = "box:x=1,y=1,z=1";
  for (int i = 0; i < 64; ++i) many += "+box:x=1,y=1,z=1";
  auto n = make_shape(many);
  ASSERT_FALSE(n);
  EXPECT_NE(n.status().message().find("union of more than 64"), std::string::npos);
}

}  // namespace
}  // namespace collido::sim
