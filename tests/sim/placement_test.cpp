// Placement: fills lie inside the vessel, clear of the wall and of each other;
// inlets release streams whose particles never overlap; bad requests say what fits.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <set>
#include <string>
#include <vector>

#include "sim/mesh.h"
#include "sim/parallel.h"
#include "sim/narrow_phase.h"
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

// When a pour's first particles reach the wall: falling straight from the
// inlet to the first triangle under it (less their radius), from rest at the
// inlet's speed along gravity. What has no straight fall to the wall says -1.
TEST(Placement, APoursFirstContactIsItsFallToTheWall) {
  const TriangleMesh box = make_box(20, 20, 40);  // floor at z = 0, open top
  ParticleSpec ps;
  ps.count = 50;
  ps.r_min = ps.r_max = 0.5;
  PlacementSpec pl;
  pl.kind = PlacementKind::kPour;
  pl.has_inlet = true;
  pl.inlet = {0, 0, 30};
  pl.inlet_radius = 4;
  pl.velocity = {0, 0, -2};
  const Vec3d g{0, 0, -9.81};
  auto plan = plan_release(box, ps, pl, g);
  ASSERT_TRUE(plan) << plan.status().message();
  // 29.5 m = 2 t + 9.81 t^2 / 2.
  const double t = (-2 + std::sqrt(4 + 2 * 9.81 * 29.5)) / 9.81;
  EXPECT_NEAR(plan->first_contact, t, 1e-9 * t);
  // A shelf under part of the inlet is met first.
  TriangleMesh shelved = box;
  const uint32_t v0 = uint32_t(shelved.vertices.size());
  for (const Vec3d v :
       {Vec3d{-10, -10, 10}, Vec3d{0, -10, 10}, Vec3d{0, 10, 10}, Vec3d{-10, 10, 10}})
    shelved.vertices.push_back(v);
  shelved.triangles.push_back({v0, v0 + 1, v0 + 2});
  shelved.triangles.push_back({v0, v0 + 2, v0 + 3});
  auto shelf = plan_release(shelved, ps, pl, g);
  ASSERT_TRUE(shelf);
  const double t_shelf = (-2 + std::sqrt(4 + 2 * 9.81 * 19.5)) / 9.81;
  EXPECT_NEAR(shelf->first_contact, t_shelf, 1e-9 * t_shelf);
  // A jet across gravity, no gravity, a fill: not known.
  PlacementSpec jet = pl;
  jet.kind = PlacementKind::kJet;
  jet.velocity = {3, 0, 0};
  EXPECT_EQ(plan_release(box, ps, jet, g)->first_contact, -1);
  EXPECT_EQ(plan_release(box, ps, pl, {0, 0, 0})->first_contact, -1);
  PlacementSpec fill;
  fill.kind = PlacementKind::kFill;
  EXPECT_EQ(plan_release(box, ps, fill, g)->first_contact, -1);
  // Nothing under the inlet (beside the box): never.
  PlacementSpec beside = pl;
  beside.inlet = {40, 0, 30};
  EXPECT_EQ(plan_release(box, ps, beside, g)->first_contact, -1);
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
  // Filled from the bottom up, the first layer on the floor (a lattice a
  // radius from the box's faces left that layer out, as touching the floor).
  EXPECT_LT(p->z.front(), p->z.back());
  EXPECT_LT(*std::min_element(p->z.begin(), p->z.end()), 1.2 * ps.r_max);
  // The same seed gives the same set.
  auto q = place_particles(wall, ps, PlacementSpec{}, {0, 0, -9.81}, 3);
  ASSERT_TRUE(q);
  EXPECT_EQ(p->x, q->x);
  EXPECT_EQ(p->r, q->r);
}

// An open vessel: a cup (no lid) and a funnel over it, filled from their box,
// take particles inside only (their generalized winding number 1/2 or more),
// none in the box's corners beside the cup; a floor, which holds nothing,
// takes every clear site above it.
TEST(Placement, OpenVesselsFillInsideAndAFloorAbove) {
  ParticleSpec ps;
  ps.count = 300;
  ps.r_min = ps.r_max = 0.5;
  for (const char* spec : {"cylinder:r=5,h=10,segments=48,caps=bottom",
                           "funnel:r1=2,r2=8,h=8,segments=48,dz=12+cylinder:r=5,h=10,segments=48,caps=bottom"}) {
    auto wall = make_shape(spec);
    ASSERT_TRUE(wall);
    auto p = place_particles(*wall, ps, PlacementSpec{}, {0, 0, -9.81}, 3);
    ASSERT_TRUE(p) << p.status().message();
    ASSERT_EQ(p->size(), 300u);
    for (size_t i = 0; i < p->size(); ++i) {
      EXPECT_LT(std::hypot(p->x[i], p->y[i]) + 0.5, 5 * std::cos(M_PI / 48)) << spec;
      EXPECT_GT(p->z[i] - 0.5, 0) << spec;
    }
  }
  TriangleMesh plate;
  plate.vertices = {{-5, -5, 0}, {5, -5, 0}, {5, 5, 0}, {-5, 5, 0}};
  plate.triangles = {{0, 1, 2}, {0, 2, 3}};
  plate.source_ids = {0, 1};
  PlacementSpec above;
  above.has_region = true;
  above.region_lo = {-4, -4, 0};
  above.region_hi = {4, 4, 5};
  ps.count = 100;
  auto q = place_particles(plate, ps, above, {0, 0, -9.81}, 3);
  ASSERT_TRUE(q) << q.status().message();
  EXPECT_EQ(q->size(), 100u);
}

// An open vessel of many triangles is filled inside it too: a ball of 81,920
// triangles with a hole at its top and 5,000 particles pass the 4e8 solid
// angles that plain sums a site would take (then every clear site of the box
// was kept, its corners included); the winding-number field's work a site is a
// few hundred.
TEST(Placement, AnOpenVesselOfManyTrianglesIsFilledInside) {
  TriangleMesh ball = *make_shape("sphere:r=5,subdivisions=6");
  const Vec3d centre = mesh_bounds(ball).center();
  TriangleMesh open;
  open.vertices = ball.vertices;
  for (size_t t = 0; t < ball.triangles.size(); ++t)
    if ((ball.corner(t, 0).z + ball.corner(t, 1).z + ball.corner(t, 2).z) / 3 < centre.z + 4.8) {
      open.triangles.push_back(ball.triangles[t]);
      open.source_ids.push_back(ball.source_ids[t]);
    }
  ASSERT_FALSE(is_closed_manifold(open));
  ASSERT_GT(double(open.triangles.size()) * 5'000, 4e8);
  ParticleSpec ps;
  ps.count = 5'000;
  ps.r_min = ps.r_max = 0.15;
  auto p = place_particles(open, ps, PlacementSpec{}, {0, 0, -9.81}, 3);
  ASSERT_TRUE(p) << p.status().message();
  ASSERT_EQ(p->size(), 5'000u);
  for (size_t i = 0; i < p->size(); i += 17) {
    const Vec3d c{p->x[i], p->y[i], p->z[i]};
    EXPECT_GE(std::fabs(winding_number(open, c)), 0.5) << "outside the ball at " << i;
    EXPECT_LT(length(c - centre) + 0.15, 5.0) << i;
  }
}

// Inside is decided once per connected group of sites (sim/placement.cpp,
// SideOfWall): two closed boxes apart, and a solid block inside one of them,
// take particles in both cavities and none between them, in the block or
// clear of its faces; every particle placed lies inside, as a winding number
// of its own says, and the lattice fills each cavity as a box alone fills.
TEST(Placement, FillFindsEveryCavityOfAClosedWall) {
  auto moved = [](TriangleMesh m, Vec3d d) {
    for (Vec3d& v : m.vertices) v = v + d;
    return m;
  };
  auto add = [](TriangleMesh* to, const TriangleMesh& m) {
    const uint32_t base = uint32_t(to->vertices.size());
    to->vertices.insert(to->vertices.end(), m.vertices.begin(), m.vertices.end());
    for (auto t : m.triangles) to->triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  };
  const TriangleMesh left = make_box(10, 10, 10), right = moved(make_box(10, 10, 10), {14, 0, 0});
  TriangleMesh block = moved(make_box(4, 4, 4), {14, 0, 3});
  for (auto& t : block.triangles) std::swap(t[1], t[2]);  // a solid inside the right box
  TriangleMesh wall;
  add(&wall, left);
  add(&wall, right);
  add(&wall, block);
  for (size_t i = 0; i < wall.triangles.size(); ++i) wall.source_ids.push_back(uint32_t(i));
  ASSERT_TRUE(is_closed_manifold(wall));
  ParticleSpec ps;
  ps.count = 100000;  // more than fit: the error says how many do
  ps.r_min = ps.r_max = 0.45;
  PlacementSpec pl;
  pl.has_region = true;
  pl.region_lo = {-5, -5, 0}, pl.region_hi = {19, 5, 10};
  auto refused = place_particles(wall, ps, pl, {0, 0, -9.81}, 5);
  ASSERT_FALSE(refused);
  const std::string msg = refused.status().message();
  const size_t at = msg.find("holds only ");
  ASSERT_NE(at, std::string::npos) << msg;
  const size_t fit = std::stoul(msg.substr(at + 11));
  ps.count = fit;
  auto p = place_particles(wall, ps, pl, {0, 0, -9.81}, 5);
  ASSERT_TRUE(p) << p.status().message();
  size_t in_left = 0, in_right = 0;
  for (size_t i = 0; i < p->size(); ++i) {
    const Vec3d c{p->x[i], p->y[i], p->z[i]};
    EXPECT_GT(std::fabs(winding_number(wall, c)), 0.5) << "particle " << i;
    EXPECT_FALSE(c.x > 4.5 && c.x < 9.5) << "between the boxes: " << c.x;
    // The block spans [12, 16] x [-2, 2] x [3, 7]: no centre within a radius of it.
    const double dx = std::max(std::fabs(c.x - 14) - 2, 0.0), dy = std::max(std::fabs(c.y) - 2, 0.0),
                 dz = std::max({3 - c.z, c.z - 7, 0.0});
    EXPECT_GE(std::sqrt(dx * dx + dy * dy + dz * dz), 0.45)
        << "in or on the block: " << c.x << ", " << c.y << ", " << c.z;
    (c.x < 7 ? in_left : in_right) += 1;
  }
  EXPECT_GT(in_left, 100u);
  EXPECT_GT(in_right, 100u);
  EXPECT_GT(in_left, in_right);  // the block takes room on the right
}

// A closed vessel whose triangles wind inward fills exactly as the same vessel wound outward.
TEST(Placement, InwardWoundVesselFillsLikeOutward) {
  const TriangleMesh out = make_cylinder(10, 20, 40);
  TriangleMesh in = out;
  for (auto& t : in.triangles) std::swap(t[1], t[2]);
  ASSERT_LT(winding_number(in, {0, 0, 10}), -0.5);
  ParticleSpec ps;
  ps.count = 500;
  ps.r_min = 0.4, ps.r_max = 0.6;
  auto a = place_particles(out, ps, PlacementSpec{}, {0, 0, -9.81}, 3);
  auto b = place_particles(in, ps, PlacementSpec{}, {0, 0, -9.81}, 3);
  ASSERT_TRUE(a) << a.status().message();
  ASSERT_TRUE(b) << b.status().message();
  EXPECT_EQ(a->x, b->x);
  EXPECT_EQ(a->y, b->y);
  EXPECT_EQ(a->z, b->z);
  EXPECT_EQ(a->r, b->r);
}

TEST(Placement, FillRefusesWhatDoesNotFitAndSaysHowManyDo) {
  const TriangleMesh wall = make_box(4, 4, 4);
  ParticleSpec ps;
  ps.count = 1000;
  ps.r_min = ps.r_max = 0.5;
  auto p = place_particles(wall, ps, PlacementSpec{}, {0, 0, -9.81}, 1);
  ASSERT_FALSE(p);
  EXPECT_NE(p.status().message().find("holds only"), std::string::npos) << p.status().message();
  // An inverted region is refused for itself, even for one particle that would fit.
  ps.count = 1;
  PlacementSpec region;
  region.has_region = true;
  region.region_lo = {1, 1, 1}, region.region_hi = {0, 2, 2};
  auto inverted = place_particles(wall, ps, region, {0, 0, -9.81}, 1);
  ASSERT_FALSE(inverted);
  EXPECT_EQ(inverted.status().message().rfind("placement.region", 0), 0u)
      << inverted.status().message();
  // Ten tiny particles in a large box: a layer of millions of sites (gigabytes)
  // is refused before anything is allocated for it, saying why.
  const TriangleMesh big = make_box(100, 100, 10);
  ps.count = 10;
  ps.r_min = ps.r_max = 0.01;
  auto tiny = place_particles(big, ps, PlacementSpec{}, {0, 0, -9.81}, 1);
  ASSERT_FALSE(tiny);
  EXPECT_NE(tiny.status().message().find("too large for 10 particles"), std::string::npos)
      << tiny.status().message();
  ps.count = 100000;  // as many sites are worth their memory when the particles need them
  ps.r_min = ps.r_max = 0.1;
  EXPECT_TRUE(place_particles(big, ps, PlacementSpec{}, {0, 0, -9.81}, 1));
}

TEST(Placement, PourReleasesAStreamThatNeverOverlaps) {
  const TriangleMesh wall = make_cylinder(20, 60, 40);
  ParticleSpec ps;
  ps.count = 500;
  ps.r_min = ps.r_max = 1;
  PlacementSpec pl;
  pl.kind = PlacementKind::kPour;
  const Vec3d g{0, 0, -9.81};
  auto p = place_particles(wall, ps, pl, g, 2);
  ASSERT_TRUE(p) << p.status().message();
  std::set<double> release_times;
  for (size_t i = 0; i < p->size(); ++i) {
    EXPECT_GE(p->release[i], 0);
    EXPECT_LT(p->vz[i], 0);  // leaving downwards, along gravity
    release_times.insert(p->release[i]);
  }
  // A stream: particles leave one by one, not as layers that all leave at once.
  EXPECT_GT(release_times.size(), p->size() / 2);
  // When a particle leaves, no particle already in flight (free fall from its own
  // release) is within a diameter of it.
  auto at = [&](size_t i, double t) {
    const double s = t - p->release[i];
    return Vec3d{p->x[i] + p->vx[i] * s + 0.5 * g.x * s * s,
                 p->y[i] + p->vy[i] * s + 0.5 * g.y * s * s,
                 p->z[i] + p->vz[i] * s + 0.5 * g.z * s * s};
  };
  double closest = 1e300;
  for (size_t j = 0; j < p->size(); ++j)
    for (size_t i = 0; i < p->size(); ++i) {
      if (i == j || p->release[i] > p->release[j]) continue;
      const Vec3d d = at(i, p->release[j]) - at(j, p->release[j]);
      closest = std::min(closest, length(d));
    }
  EXPECT_GT(closest, 2.0 * ps.r_max);
}

std::string refusal(const TriangleMesh& wall, const ParticleSpec& ps, const PlacementSpec& pl,
                    Vec3d gravity);

// The distance from p to the nearest of the wall's triangles.
double wall_distance(const TriangleMesh& wall, Vec3d p) {
  double best = 1e300;
  for (const auto& t : wall.triangles)
    best = std::min(best, length(p - closest_point_on_triangle(p, wall.vertices[t[0]],
                                                               wall.vertices[t[1]],
                                                               wall.vertices[t[2]])));
  return best;
}

// An inlet never starts a particle in the wall or within 1.1 r of it, and the
// default inlet (3 r under the top of a ball, where its disc is wider than the
// ball) starts them inside the vessel only: the disc's places past the ball's
// side used to release there, and a pour of 300 lost 40 at up to 700 m/s.
// A given inlet keeps its places outside (a pour may start beside a wall),
// and one with no place clear of the wall is refused.
// A cup modelled as a solid, as CAD and 3D printing export one: the profile
// (0, 0) (5, 0) (5, 10) (4, 10) (4, 1) (0, 1) turned about z, 48 segments; a
// closed wall whose inside is the cup's material (1 thick), its hollow outside.
// seam_open: the last segment's far edge 1e-6 off the first's near one (a slit
// the export left, so the wall is not closed).
TriangleMesh solid_cup(bool seam_open = false) {
  const double prof[6][2] = {{0, 0}, {5, 0}, {5, 10}, {4, 10}, {4, 1}, {0, 1}};
  constexpr int n = 48;
  auto at = [&](const double* rz, int k) {
    const double a = 2 * M_PI * (k % n) / n;
    const double slit = seam_open && k == n && rz[0] > 0 ? 1e-6 : 0.0;
    return Vec3d{rz[0] * std::cos(a), rz[0] * std::sin(a) + slit, rz[1]};
  };
  std::vector<std::array<Vec3d, 3>> soup;
  for (int i = 0; i + 1 < 6; ++i)
    for (int k = 0; k < n; ++k) {
      const Vec3d a = at(prof[i], k), b = at(prof[i], k + 1), c = at(prof[i + 1], k + 1),
                  d = at(prof[i + 1], k);
      if (prof[i][0] > 0) soup.push_back({a, b, c});
      if (prof[i + 1][0] > 0) soup.push_back({a, c, d});
    }
  return weld_soup(soup, std::vector<uint32_t>(soup.size(), 0), 1e-9, nullptr);
}

// Particles go into a solid cup's hollow, never into its material (its inside
// as a closed wall) nor beside it in its box: a fill, and a pour with its
// default inlet (refused before, no place of its disc being inside the wall);
// the same with a slit left in its seam (an open wall that encloses nothing
// by its winding number: its fill took every clear site, in the base too).
// A ball stays a shell: filled inside (APourIntoABall..., FillIsInside...).
TEST(Placement, ASolidCupIsFilledInItsHollow) {
  ParticleSpec ps;
  ps.count = 200;
  ps.r_min = ps.r_max = 0.3;
  for (const bool seam_open : {false, true}) {
    SCOPED_TRACE(seam_open ? "seam open" : "closed");
    const TriangleMesh cup = solid_cup(seam_open);
    ASSERT_EQ(is_closed_manifold(cup), !seam_open);
    for (const PlacementKind kind : {PlacementKind::kFill, PlacementKind::kPour}) {
      PlacementSpec pl;
      pl.kind = kind;
      pl.rate = 200;
      auto p = place_particles(cup, ps, pl, {0, 0, -9.81}, 5);
      ASSERT_TRUE(p) << p.status().message();
      ASSERT_EQ(p->size(), 200u);
      for (size_t i = 0; i < p->size(); ++i) {
        const Vec3d c{p->x[i], p->y[i], p->z[i]};
        EXPECT_LT(std::fabs(winding_number(cup, c)), 0.5) << "in the material at " << i;
        EXPECT_LT(std::hypot(c.x, c.y) + 0.3, 4.0) << i;  // within the hollow's side
        EXPECT_GT(c.z - 0.3, 1.0) << i;                   // over its floor
      }
    }
  }
}

// An open wall's places are looked at on the job's pool a chunk at a time;
// the set is the same as on one thread, whatever the pool's size (by winding
// numbers: an open cup, a funnel over it; by rays: a solid cup with its seam open).
TEST(Placement, AnOpenWallsFillIsTheSameOnAPool) {
  ParticleSpec ps;
  ps.count = 700;
  ps.r_min = 0.2, ps.r_max = 0.3;
  std::vector<TriangleMesh> walls;
  for (const char* spec : {"cylinder:r=5,h=10,segments=48,caps=bottom",
                           "funnel:r1=2,r2=8,h=8,segments=48,dz=12+cylinder:r=5,h=10,segments=48,caps=bottom"})
    walls.push_back(*make_shape(spec));
  walls.push_back(solid_cup(true));
  ThreadPool two(2), five(5);
  for (const TriangleMesh& wall : walls) {
    ASSERT_FALSE(is_closed_manifold(wall));
    auto alone = place_particles(wall, ps, PlacementSpec{}, {0, 0, -9.81}, 4);
    ASSERT_TRUE(alone) << alone.status().message();
    ASSERT_EQ(alone->size(), ps.count);
    for (ThreadPool* pool : {&two, &five}) {
      auto shared = place_particles(wall, ps, PlacementSpec{}, {0, 0, -9.81}, 4, pool);
      ASSERT_TRUE(shared) << shared.status().message();
      ASSERT_EQ(shared->size(), alone->size());
      for (size_t i = 0; i < alone->size(); ++i) {
        ASSERT_EQ(shared->x[i], alone->x[i]) << i;
        ASSERT_EQ(shared->y[i], alone->y[i]) << i;
        ASSERT_EQ(shared->z[i], alone->z[i]) << i;
        ASSERT_EQ(shared->r[i], alone->r[i]) << i;
      }
    }
  }
}

// A fill's region over a closed solid (a plate), holding no point inside it,
// takes the room outside it: a heap dropped onto the plate (refused before,
// the region holding no site inside the wall).
TEST(Placement, AFillOverASolidTakesTheRoomAboveIt) {
  const TriangleMesh plate = make_box(10, 10, 1);
  ParticleSpec ps;
  ps.count = 150;
  ps.r_min = ps.r_max = 0.4;
  PlacementSpec pl;
  pl.has_region = true;
  pl.region_lo = {-4, -4, 1.5}, pl.region_hi = {4, 4, 5};
  auto p = place_particles(plate, ps, pl, {0, 0, -9.81}, 5);
  ASSERT_TRUE(p) << p.status().message();
  ASSERT_EQ(p->size(), 150u);
  for (size_t i = 0; i < p->size(); ++i) EXPECT_GT(p->z[i] - 0.4, 1.5) << i;
}

TEST(Placement, APourIntoABallStartsInsideAndClearOfIt) {
  auto ball = make_shape("sphere:r=10,subdivisions=3");
  ASSERT_TRUE(ball);
  ParticleSpec ps;
  ps.count = 300;
  ps.r_min = ps.r_max = 0.3;
  PlacementSpec pl;
  pl.kind = PlacementKind::kPour;
  auto p = place_particles(*ball, ps, pl, {0, 0, -9.81}, 1);
  ASSERT_TRUE(p) << p.status().message();
  std::vector<Vec3d> places;  // where particles start, each once (within the jitter)
  for (size_t i = 0; i < p->size(); ++i) {
    const Vec3d at{p->x[i], p->y[i], p->z[i]};
    EXPECT_GE(std::fabs(winding_number(*ball, at)), 0.5) << i;
    EXPECT_GE(wall_distance(*ball, at), 1.1 * 0.3 - 0.02 * 0.3) << i;  // less the jitter
    if (std::none_of(places.begin(), places.end(), [&](Vec3d q) { return length(q - at) < 0.1; }))
      places.push_back(at);
  }
  auto plan = plan_release(*ball, ps, pl, {0, 0, -9.81});
  ASSERT_TRUE(plan) << plan.status().message();
  EXPECT_EQ(plan->slots, places.size());  // the plan counts the places the pour uses

  // An open vessel narrowing to its top (no lid): the disc reaches past its side
  // there too, and each place is judged by its own winding number.
  auto narrowing = make_shape("cone:r1=8,r2=2,h=10,segments=48,caps=bottom");
  ASSERT_TRUE(narrowing);
  ASSERT_FALSE(is_closed_manifold(*narrowing));
  auto o = place_particles(*narrowing, ps, pl, {0, 0, -9.81}, 1);
  ASSERT_TRUE(o) << o.status().message();
  for (size_t i = 0; i < o->size(); ++i) {
    const Vec3d at{o->x[i], o->y[i], o->z[i]};
    EXPECT_GE(std::fabs(winding_number(*narrowing, at)), 0.5) << i;
    EXPECT_GE(wall_distance(*narrowing, at), 1.1 * 0.3 - 0.02 * 0.3) << i;
  }

  // A given inlet across a closed cylinder's side: no start within 1.1 r of it,
  // some outside.
  const TriangleMesh can = make_cylinder(20, 60, 40);
  ps.r_min = ps.r_max = 1;
  ps.count = 400;
  pl.has_inlet = true;
  pl.inlet = {0, 0, 40};
  pl.inlet_radius = 26;
  auto q = place_particles(can, ps, pl, {0, 0, -9.81}, 1);
  ASSERT_TRUE(q) << q.status().message();
  size_t outside = 0;
  for (size_t i = 0; i < q->size(); ++i) {
    const Vec3d at{q->x[i], q->y[i], q->z[i]};
    EXPECT_GE(wall_distance(can, at), 1.1 - 0.02) << i;
    outside += std::fabs(winding_number(can, at)) < 0.5;
  }
  EXPECT_GT(outside, 0u);

  // An inlet in a floor's plane has no place clear of it.
  TriangleMesh floor;
  floor.vertices = {{-5, -5, 0}, {5, -5, 0}, {5, 5, 0}, {-5, 5, 0}};
  floor.triangles = {{0, 1, 2}, {0, 2, 3}};
  floor.source_ids = {0, 1};
  pl.inlet = {0, 0, 0};
  pl.inlet_radius = 3;
  const std::string why = refusal(floor, ps, pl, {0, 0, -9.81});
  EXPECT_NE(why.find("no place in the inlet's disc"), std::string::npos) << why;
  EXPECT_NE(why.find("clear of the wall"), std::string::npos) << why;
}

// A pour's and a jet's released particles counted against rate x time from the
// first quarter second to the last particle: within 2 % (the inlet's phases are spread evenly, so the
// count is exact to a particle or two); a rate the inlet cannot carry is refused
// with the radius that would, and that radius carries it.
std::string refusal(const TriangleMesh& wall, const ParticleSpec& ps, const PlacementSpec& pl,
                    Vec3d gravity);
TEST(Placement, PourAndJetDeliverTheirRateFromTheStart) {
  struct Case {
    const char* what;
    TriangleMesh wall;
    PlacementKind kind;
    Vec3d inlet, velocity;
    double inlet_radius, rate, r_min, r_max;
    uint64_t count;
  };
  const Case cases[] = {
      {"wall1 pour", make_cylinder(50, 100, 40), PlacementKind::kPour, {0, 0, 60}, {0, 0, -2}, 25,
       800, 1, 1, 3000},
      {"funnel jet", make_cone(5, 30, 40, 64, Caps::kNone), PlacementKind::kJet, {-20, 0, 45},
       {8, 0, 0}, 8, 600, 0.4, 0.6, 3000},
      // About 1,140 slots: a last layer of a third of them, which used to leave
      // over a whole period, at a third of the rate.
      {"wide pour", make_cylinder(50, 100, 40), PlacementKind::kPour, {0, 0, 60}, {0, 0, -2}, 40,
       1500, 1, 1, 1500},
  };
  for (const Case& c : cases) {
    ParticleSpec ps;
    ps.count = c.count;
    ps.r_min = c.r_min, ps.r_max = c.r_max;
    PlacementSpec pl;
    pl.kind = c.kind;
    pl.has_inlet = true;
    pl.inlet = c.inlet;
    pl.inlet_radius = c.inlet_radius;
    pl.velocity = c.velocity;
    pl.rate = c.rate;
    auto p = place_particles(c.wall, ps, pl, {0, 0, -9.81}, 3);
    ASSERT_TRUE(p) << c.what << ": " << p.status().message();
    const double all_out = double(c.count) / c.rate;  // when the last should leave
    for (double t : {0.25, 0.5, 1.0, 2.0, 2.5, 0.8 * all_out, 0.9 * all_out, 0.97 * all_out}) {
      const size_t released = size_t(std::count_if(p->release.begin(), p->release.end(),
                                                   [&](double r) { return r <= t; }));
      const double expected = std::min(double(c.count), c.rate * t);
      EXPECT_NEAR(double(released), expected, 0.02 * expected) << c.what << " at " << t << " s";
    }
    // Twice the rate is more than this inlet carries: refused, naming the radius that would.
    pl.rate = 2 * c.rate;
    const std::string why = refusal(c.wall, ps, pl, {0, 0, -9.81});
    EXPECT_EQ(why.rfind("placement.rate", 0), 0u) << why;
    const size_t at = why.find("widen inlet_radius to about ");
    ASSERT_NE(at, std::string::npos) << why;
    pl.inlet_radius = std::stod(why.substr(at + 28));
    EXPECT_EQ(refusal(c.wall, ps, pl, {0, 0, -9.81}), "") << c.what;
  }
}

// The message a refused placement gives ("" when it was not refused).
std::string refusal(const TriangleMesh& wall, const ParticleSpec& ps, const PlacementSpec& pl,
                    Vec3d gravity) {
  auto p = place_particles(wall, ps, pl, gravity, 1);
  return p ? "" : p.status().message();
}

// Each refusal names its own cause, so a case cannot pass on another one's error.
TEST(Placement, JetNeedsVelocityAndInletsNeedRoom) {
  const TriangleMesh wall = make_cylinder(20, 60, 40);
  ParticleSpec ps;
  ps.count = 10;
  PlacementSpec pl;
  pl.kind = PlacementKind::kJet;
  EXPECT_FALSE(place_particles(wall, ps, pl, {0, 0, -9.81}, 1));
  EXPECT_NE(refusal(wall, ps, pl, {0, 0, -9.81}).find("a jet needs a non-zero velocity"),
            std::string::npos);
  pl.velocity = {10, 0, 0};
  pl.has_inlet = true;
  pl.inlet = {-15, 0, 30};
  pl.inlet_radius = 2;
  auto p = place_particles(wall, ps, pl, {0, 0, -9.81}, 1);
  ASSERT_TRUE(p) << p.status().message();
  // Each at the jet's speed, within its spray of 3 degrees (tangent 0.05), not all along one line.
  double widest = 0;
  for (size_t i = 0; i < p->size(); ++i) {
    EXPECT_NEAR(std::hypot(p->vx[i], p->vy[i], p->vz[i]), 10, 1e-12);
    const double across = std::hypot(p->vy[i], p->vz[i]) / p->vx[i];
    EXPECT_LE(across, 0.05 * (1 + 1e-12));
    widest = std::max(widest, across);
  }
  EXPECT_GT(widest, 0.01);
  pl.inlet_radius = 0.1;  // smaller than one particle
  EXPECT_FALSE(place_particles(wall, ps, pl, {0, 0, -9.81}, 1));
  EXPECT_EQ(refusal(wall, ps, pl, {0, 0, -9.81}).rfind("placement.inlet_radius", 0), 0u);
  // An inlet 10^12 spacings across: refused before the slot count is cast to
  // int (UBSan caught the overflow) or the disc fills memory.
  pl.inlet_radius = 1e12;
  EXPECT_NE(refusal(wall, ps, pl, {0, 0, -9.81}).find("particle spacings"), std::string::npos);
  // A jet straight up too slow to climb one layer's spacing against gravity.
  pl.inlet_radius = 2;
  pl.velocity = {0, 0, 0.1};
  EXPECT_FALSE(place_particles(wall, ps, pl, {0, 0, -9.81}, 1));
  EXPECT_NE(refusal(wall, ps, pl, {0, 0, -9.81}).find("too slow against gravity"),
            std::string::npos);
  // A pour with neither gravity nor a velocity has nowhere to go.
  PlacementSpec pour;
  pour.kind = PlacementKind::kPour;
  EXPECT_FALSE(place_particles(wall, ps, pour, {0, 0, 0}, 1));
  EXPECT_NE(refusal(wall, ps, pour, {0, 0, 0}).find("a pour without gravity needs a velocity"),
            std::string::npos);
}

}  // namespace
}  // namespace collido::sim
