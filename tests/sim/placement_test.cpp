// Placement: fills lie inside the vessel, clear of the wall and of each other;
// inlets release layers that never overlap; bad requests say what fits.
#include <gtest/gtest.h>

#include <cmath>

#include "sim/placement.h"
#include "sim/shapes.h"

namespace collido::sim {
namespace {

double closest_pair(const ParticleSet& p, const std::vector<size_t>& idx) {
  double best = 1e300;
  for (size_t a = 0; a < idx.size(); ++a)
    for (size_t b = a + 1; b < idx.size(); ++b) {
      const size_t i = idx[a], j = idx[b];
      const double d =
          std::sqrt((p.x[i] - p.x[j]) * (p.x[i] - p.x[j]) + (p.y[i] - p.y[j]) * (p.y[i] - p.y[j]) +
                    (p.z[i] - p.z[j]) * (p.z[i] - p.z[j]));
      best = std::min(best, d - p.r[i] - p.r[j]);
    }
  return best;
}

TEST(Placement, FillIsInsideClearAndWithoutOverlaps) {
  const TriangleMesh wall = make_cylinder(10, 20, 40);
  ParticleSpec ps;
  ps.count = 800;
  ps.r_min = 0.4, ps.r_max = 0.6;
  auto p = place_particles(wall, ps, PlacementSpec{}, {0, 0, -9.81}, 3);
  ASSERT_TRUE(p) << p.status().message();
  ASSERT_EQ(p->size(), 800u);
  std::vector<size_t> all(p->size());
  for (size_t i = 0; i < all.size(); ++i) {
    all[i] = i;
    EXPECT_GT(winding_number(wall, {p->x[i], p->y[i], p->z[i]}), 0.5);
    EXPECT_GE(p->r[i], 0.4);
    EXPECT_LE(p->r[i], 0.6);
    EXPECT_EQ(p->release[i], 0);
    // Clear of the side (radius 10 polygon: inscribed radius 10 cos(pi/40)) and the floor.
    EXPECT_LT(std::hypot(p->x[i], p->y[i]) + p->r[i], 10 * std::cos(M_PI / 40));
    EXPECT_GT(p->z[i] - p->r[i], 0);
  }
  EXPECT_GT(closest_pair(*p, all), 0);
  // Filled from the bottom up.
  EXPECT_LT(p->z.front(), p->z.back());
  // The same seed gives the same set.
  auto q = place_particles(wall, ps, PlacementSpec{}, {0, 0, -9.81}, 3);
  ASSERT_TRUE(q);
  EXPECT_EQ(p->x, q->x);
  EXPECT_EQ(p->r, q->r);
}

TEST(Placement, FillRefusesWhatDoesNotFitAndSaysHowManyDo) {
  const TriangleMesh wall = make_box(4, 4, 4);
  ParticleSpec ps;
  ps.count = 1000;
  ps.r_min = ps.r_max = 0.5;
  auto p = place_particles(wall, ps, PlacementSpec{}, {0, 0, -9.81}, 1);
  ASSERT_FALSE(p);
  EXPECT_NE(p.status().message().find("holds only"), std::string::npos) << p.status().message();
  PlacementSpec region;
  region.has_region = true;
  region.region_lo = {1, 1, 1}, region.region_hi = {0, 2, 2};
  EXPECT_FALSE(place_particles(wall, ps, region, {0, 0, -9.81}, 1));
}

TEST(Placement, PourReleasesLayersThatNeverOverlap) {
  const TriangleMesh wall = make_cylinder(20, 60, 40);
  ParticleSpec ps;
  ps.count = 500;
  ps.r_min = ps.r_max = 1;
  PlacementSpec pl;
  pl.kind = PlacementKind::kPour;
  auto p = place_particles(wall, ps, pl, {0, 0, -9.81}, 2);
  ASSERT_TRUE(p) << p.status().message();
  // Within one layer (same release) particles are apart; later layers start later.
  std::vector<size_t> first_layer;
  for (size_t i = 0; i < p->size(); ++i) {
    if (p->release[i] == 0) first_layer.push_back(i);
    if (i) {
      EXPECT_GE(p->release[i], p->release[i - 1]);
    }
    EXPECT_LT(p->vz[i], 0);  // leaving downwards, along gravity
  }
  ASSERT_GT(first_layer.size(), 1u);
  EXPECT_GT(closest_pair(*p, first_layer), 0);
  EXPECT_GT(p->release.back(), 0);
  // When a layer is released, the one before has fallen more than a diameter.
  const double tau = [&] {
    for (size_t i = 0; i < p->size(); ++i)
      if (p->release[i] > 0) return p->release[i];
    return 0.0;
  }();
  EXPECT_GT(1.0 * tau + 0.5 * 9.81 * tau * tau, 2 * 1.0);
}

TEST(Placement, JetNeedsVelocityAndInletsNeedRoom) {
  const TriangleMesh wall = make_cylinder(20, 60, 40);
  ParticleSpec ps;
  ps.count = 10;
  PlacementSpec pl;
  pl.kind = PlacementKind::kJet;
  EXPECT_FALSE(place_particles(wall, ps, pl, {0, 0, -9.81}, 1));
  pl.velocity = {10, 0, 0};
  pl.has_inlet = true;
  pl.inlet = {-15, 0, 30};
  pl.inlet_radius = 2;
  auto p = place_particles(wall, ps, pl, {0, 0, -9.81}, 1);
  ASSERT_TRUE(p) << p.status().message();
  EXPECT_DOUBLE_EQ(p->vx[0], 10);
  pl.inlet_radius = 0.1;  // smaller than one particle
  EXPECT_FALSE(place_particles(wall, ps, pl, {0, 0, -9.81}, 1));
  // A jet straight up too slow to climb one layer's spacing against gravity.
  pl.inlet_radius = 2;
  pl.velocity = {0, 0, 0.1};
  EXPECT_FALSE(place_particles(wall, ps, pl, {0, 0, -9.81}, 1));
  // A pour with neither gravity nor a velocity has nowhere to go.
  PlacementSpec pour;
  pour.kind = PlacementKind::kPour;
  EXPECT_FALSE(place_particles(wall, ps, pour, {0, 0, 0}, 1));
}

}  // namespace
}  // namespace collido::sim
