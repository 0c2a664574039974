// The footprint a job is priced with against what the preparation builds.
#include "sim/wall_footprint.h"

#include <gtest/gtest.h>

#include <string>

#include "sim/shapes.h"
#include "tests/sim/wall_shape.h"

namespace collido::sim {
namespace {

// The CPU preparation's figures for `mesh` (the GPU's share the code).
PrepareInfo prepared(const TriangleMesh& mesh, Method method, double r_max,
                     uint64_t max_dense_cells, size_t particles) {
  DetectConfig c;
  c.method = method;
  c.r_max = r_max;
  c.max_dense_cells = max_dense_cells;
  auto d = Detector::create(mesh, c, particles);
  EXPECT_TRUE(d.has_value()) << d.status().message();
  return d ? (*d)->info() : PrepareInfo{};
}

TEST(WallFootprint, BinEntriesAndBucketsAreThoseThePreparationStores) {
  TriangleMesh far = shape("sphere:r=10,subdivisions=2");
  translate(far, {1e4, -3e3, 2e3});  // float's frame at the wall's centre
  const std::pair<TriangleMesh, double> cases[] = {
      {shape("wall1"), 0.7},         {shape("wall2"), 1.297},
      {shape("wall2"), 4.6},         {shape("cone:r1=20,r2=5,h=30,segments=32"), 0.4},
      {shape("box:x=20,y=20,z=20"), 0.23}, {far, 0.9}};
  for (const auto& [mesh, r] : cases) {
    for (const uint64_t dense : {uint64_t(1) << 24, uint64_t(2000)}) {  // dense, then hashed
      const PrepareInfo info = prepared(mesh, Method::kBin, r, dense, 500);
      const WallFootprint f = wall_footprint(mesh, Method::kBin, r, 2 * r, dense, 500, 0);
      EXPECT_FALSE(f.sampled);
      EXPECT_EQ(f.bin_entries, double(info.bin_entries)) << "r " << r << " dense " << dense;
      EXPECT_EQ(f.buckets, info.buckets) << "r " << r << " dense " << dense;
      EXPECT_GT(f.bin_entries, 0);
    }
  }
}

// The entries are remembered per wall and grid, the particles' table is not:
// asked again with other counts, or for a wall that differs by one vertex,
// each answer is still the preparation's.
TEST(WallFootprint, AWallPricedAgainAnswersAsItsPreparation) {
  TriangleMesh mesh = shape("cone:r1=20,r2=5,h=30,segments=32");
  const double r = 0.45;
  for (int round = 0; round < 2; ++round) {
    for (const size_t particles : {size_t(500), size_t(200000), size_t(500)}) {
      const PrepareInfo info = prepared(mesh, Method::kBin, r, 2000, particles);
      const WallFootprint f = wall_footprint(mesh, Method::kBin, r, 2 * r, 2000, particles, 0);
      EXPECT_EQ(f.bin_entries, double(info.bin_entries)) << "round " << round << ", " << particles;
      EXPECT_EQ(f.buckets, info.buckets) << "round " << round << ", " << particles;
    }
    mesh.vertices[0] = mesh.vertices[0] + Vec3d{0, 0, 7.5};  // a spike: more cells
  }
}

TEST(WallFootprint, ASampleOfALargeWallEstimatesItsEntries) {
  const TriangleMesh mesh = shape("sphere:r=10,subdivisions=5");  // 20,480 triangles
  const double r = 0.05;
  const WallFootprint exact = wall_footprint(mesh, Method::kBin, r, 2 * r, 1ull << 24, 0, 0, 1e12);
  const WallFootprint sample = wall_footprint(mesh, Method::kBin, r, 2 * r, 1ull << 24, 0, 0, 2e4);
  ASSERT_FALSE(exact.sampled);
  EXPECT_TRUE(sample.sampled);
  EXPECT_NEAR(sample.bin_entries / exact.bin_entries, 1.0, 0.03);
  EXPECT_EQ(sample.buckets, exact.buckets);
}

TEST(WallFootprint, DividedWallsGridTheirPiecesNearTheWallsBox) {
  const TriangleMesh mesh = shape("cylinder:r=10,h=30,segments=24");
  for (Method m : {Method::kGravity, Method::kCircumcircle, Method::kMidpoint4}) {
    const double r = 0.6;
    const PrepareInfo info = prepared(mesh, m, r, 1ull << 24, 1000);
    const WallFootprint f =
        wall_footprint(mesh, m, r, 2 * r, 1ull << 24, 1000, double(info.triangles_used));
    EXPECT_EQ(f.bin_entries, 0);
    EXPECT_NEAR(double(f.buckets) / double(info.buckets), 1.0, 0.1) << to_string(m);
  }
  EXPECT_EQ(wall_footprint(mesh, Method::kBvh, 0.6, 1.2, 1ull << 24, 1000, 92).buckets, 0u);
}

}  // namespace
}  // namespace collido::sim
