#include "sim/shapes.h"

#include <gtest/gtest.h>

#include <cmath>

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
               {"cylinder:r", "key=value"}};
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
