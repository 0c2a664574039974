// Every method and traversal against the exact double-precision reference.
#include "sim/detect.h"

#include <gtest/gtest.h>

#include <cmath>
#include <iterator>
#include <map>
#include <string>

#include "sim/accuracy.h"
#include "sim/exact_distance.h"
#include "sim/narrow_phase.h"
#include "sim/octree.h"
#include "sim/particles.h"
#include "sim/shapes.h"
#include "tests/sim/gpu_suite.h"
#include "tests/sim/wall_shape.h"

namespace collido::sim {
namespace {

const std::string kData = COLLIDO_TEST_DATA;

struct Combo {
  Method method;
  Traversal traversal;
};
const Combo kCombos[] = {
    {Method::kBin, Traversal::kParticle},          {Method::kBin, Traversal::kWall},
    {Method::kGravity, Traversal::kParticle},      {Method::kGravity, Traversal::kWall},
    {Method::kCircumcircle, Traversal::kParticle}, {Method::kCircumcircle, Traversal::kWall},
    {Method::kMidpoint4, Traversal::kParticle},    {Method::kMidpoint4, Traversal::kWall},
    {Method::kBvh, Traversal::kParticle},          {Method::kOctree, Traversal::kParticle}};

// The octree's ways of dealing out a frame's particles (sim/detect.h).
struct OctreeWay {
  const char* name;
  uint32_t runs_below;
  float flat_cost;
  void apply(DetectConfig& c) const { c.octree_runs_below = runs_below, c.octree_flat_cost = flat_cost; }
};
const OctreeWay kOctreeWays[] = {{" in chunks", 0u, 1.8f},
                                 {" in runs, leaf by leaf", UINT32_MAX, INFINITY},
                                 {" in runs, flattened", UINT32_MAX, 0.f}};

DetectResult run(const TriangleMesh& mesh, const Particles& p, DetectConfig cfg) {
  auto det = Detector::create(mesh, cfg, p.size());
  EXPECT_TRUE(det) << det.status().message();
  if (!det) return {};
  DetectResult r;
  Status s = (*det)->set_particles(p);
  EXPECT_TRUE(s) << s.message();
  s = (*det)->detect(&r);
  EXPECT_TRUE(s) << s.message();
  return r;
}

// Exact distance from particle i to the triangle with source id `tri`.
double exact_distance(const TriangleMesh& mesh, const Particles& p, uint32_t i, uint32_t tri) {
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    if (mesh.source_ids[t] == tri)
      return std::sqrt(point_triangle_dist2(Vec3d{p.x[i], p.y[i], p.z[i]}, mesh.corner(t, 0), mesh.corner(t, 1),
                                            mesh.corner(t, 2)));
  ADD_FAILURE() << "no triangle with id " << tri;
  return 0;
}

// The accuracy contract: exactly the reference's contact set, no tolerance
// band (sim/exact_distance.h); distances to float precision.
void expect_same_contacts(const TriangleMesh& mesh, const Particles& p, const DetectResult& ref,
                          const DetectResult& got, double r_max, const std::string& what) {
  std::map<std::pair<uint32_t, uint32_t>, double> a, b;
  for (const auto& c : ref.contacts) a[{c.particle, c.triangle}] = c.distance;
  for (const auto& c : got.contacts) b[{c.particle, c.triangle}] = c.distance;
  int missed = 0, invented = 0;
  for (const auto& [key, d] : a) {
    auto it = b.find(key);
    if (it == b.end()) {
      if (++missed <= 5)
        ADD_FAILURE() << what << ": missed particle " << key.first << " triangle " << key.second
                      << " d=" << d << " r=" << p.r[key.first];
    } else {
      EXPECT_NEAR(it->second, d, 2e-5 * std::max(1.0, r_max)) << what;
    }
  }
  for (const auto& [key, d] : b) {
    if (a.count(key)) continue;
    if (++invented <= 5)
      ADD_FAILURE() << what << ": invented particle " << key.first << " triangle " << key.second
                    << " exact d=" << exact_distance(mesh, p, key.first, key.second)
                    << " r=" << p.r[key.first];
  }
  EXPECT_EQ(missed, 0) << what;
  EXPECT_EQ(invented, 0) << what;
  // Counts per particle agree with the contact list.
  std::vector<uint32_t> counts(p.size(), 0);
  for (const auto& c : got.contacts) ++counts[c.particle];
  EXPECT_EQ(counts, got.counts) << what;
  EXPECT_EQ(got.contact_count, got.contacts.size()) << what;
  // Sorted by particle, then triangle, no duplicates.
  for (size_t k = 1; k < got.contacts.size(); ++k) {
    const auto& u = got.contacts[k - 1];
    const auto& v = got.contacts[k];
    ASSERT_TRUE(u.particle < v.particle || (u.particle == v.particle && u.triangle < v.triangle)) << what;
  }
}

// Particles near the surface (within 2 r of a random surface point) and uniform in the box.
Particles scene_near(const TriangleMesh& mesh, size_t n, double r_lo, double r_hi, uint64_t seed) {
  SplitMix64 rng(seed);
  Bounds3d box = mesh_bounds(mesh);
  Particles p;
  p.resize(n);
  for (size_t i = 0; i < n; ++i) {
    Vec3d c;
    const double r = rng.uniform(r_lo, r_hi);
    if (i % 2) {
      c = {rng.uniform(box.lo.x, box.hi.x), rng.uniform(box.lo.y, box.hi.y), rng.uniform(box.lo.z, box.hi.z)};
    } else {
      const size_t t = rng.next() % mesh.triangles.size();
      double u = rng.uniform(), v = rng.uniform();
      if (u + v > 1) u = 1 - u, v = 1 - v;
      const Vec3d a = mesh.corner(t, 0), b = mesh.corner(t, 1), cc = mesh.corner(t, 2);
      const Vec3d on = a + (b - a) * u + (cc - a) * v;
      Vec3d dir{rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)};
      dir = dir * (1.0 / std::max(1e-9, length(dir)));
      c = on + dir * rng.uniform(0, 2 * r);
    }
    p.x[i] = c.x, p.y[i] = c.y, p.z[i] = c.z, p.r[i] = r;
  }
  return p;
}


void check_all_methods(const TriangleMesh& mesh, const Particles& p, const std::string& what,
                       uint64_t max_dense_cells = 1ull << 24, double grid_length = 0) {
  DetectConfig cfg;
  cfg.backend = backend_under_test();
  cfg.r_max = max_radius(p);
  cfg.max_dense_cells = max_dense_cells;
  cfg.grid_length = grid_length;
  DetectConfig rc = cfg;
  rc.method = Method::kReference;
  rc.backend = Backend::kCpu;
  const DetectResult ref = run(mesh, p, rc);
  ASSERT_EQ(ref.contact_count, ref.contacts.size());
  for (const Combo& c : kCombos) {
    // The octree deals its particles out in chunks of a leaf or in runs, a
    // run leaf by leaf or its pairs flattened: every way.
    const bool octree = c.method == Method::kOctree;
    for (size_t way = 0; way < (octree ? std::size(kOctreeWays) : 1u); ++way) {
      DetectConfig mc = cfg;
      mc.method = c.method;
      mc.traversal = c.traversal;
      if (octree) kOctreeWays[way].apply(mc);
      const std::string label = what + " " + to_string(c.method) + "/" + to_string(c.traversal) +
                                (octree ? kOctreeWays[way].name : "") + " on " +
                                to_string(cfg.backend);
      const DetectResult got = run(mesh, p, mc);
      expect_same_contacts(mesh, p, ref, got, cfg.r_max, label);
      // Counting alone gives the same counts as collecting.
      mc.collect_contacts = false;
      const DetectResult counted = run(mesh, p, mc);
      EXPECT_EQ(counted.counts, got.counts) << label;
    }
  }
}

void twenty_random_scenes() {
  auto teapot = load_stl(kData + "/meshes/teapot_trimesh.stl");
  ASSERT_TRUE(teapot);
  const TriangleMesh walls[] = {make_cylinder(50, 100, 40), make_wall2(), make_sphere(10, 2),
                                make_box(20, 30, 10), *teapot};
  const double radius_hi[] = {3, 4, 1, 1.5, 0.4};
  int scenes = 0;
  for (int w = 0; w < 5; ++w) {
    for (int k = 0; k < 4; ++k) {
      const double hi = radius_hi[w] * (k % 2 ? 1.0 : 0.5);
      const double lo = k < 2 ? hi : hi * 0.3;
      Particles p = scene_near(walls[w], 1500, lo, hi, 100 + 10 * w + k);
      check_all_methods(walls[w], p, "wall " + std::to_string(w) + " scene " + std::to_string(k));
      ++scenes;
    }
  }
  EXPECT_EQ(scenes, 20);
}

// Particles centred on vertices and edges shared by several triangles, and at
// r (1 +- 1e-6) from faces, edges and corners.
void adversarial_placements() {
  const TriangleMesh wall = make_cylinder(10, 20, 16);  // fan caps: one vertex shared by 14+ triangles
  Particles p;
  auto add = [&](Vec3d c, double r) {
    p.x.push_back(c.x), p.y.push_back(c.y), p.z.push_back(c.z), p.r.push_back(r);
  };
  for (const Vec3d& v : wall.vertices) add(v, 1.0);
  for (size_t t = 0; t < wall.triangles.size(); ++t) {
    const Vec3d a = wall.corner(t, 0), b = wall.corner(t, 1), c = wall.corner(t, 2);
    add((a + b) * 0.5, 0.7);
    const Vec3d n = cross(b - a, c - a) * (1.0 / length(cross(b - a, c - a)));
    const Vec3d centroid = (a + b + c) * (1.0 / 3.0);
    for (double s : {1 - 1e-6, 1 + 1e-6, 1 - 1e-4, 1 + 1e-4}) {
      add(centroid + n * s, 1.0);   // face, outside
      add(centroid - n * s, 1.0);   // face, inside
      const Vec3d out_of_edge = (a + b) * 0.5 + (((a + b) * 0.5 - c) * (1.0 / length((a + b) * 0.5 - c))) * s;
      add(out_of_edge, 1.0);
      const Vec3d beyond_corner = a + ((a - centroid) * (1.0 / length(a - centroid))) * s;
      add(beyond_corner, 1.0);
    }
  }
  check_all_methods(wall, p, "adversarial");
  // Exactly-on-vertex particles touch every triangle around the vertex: one contact each.
  DetectConfig rc;
  rc.method = Method::kReference;
  rc.r_max = 1.0;
  const DetectResult ref = run(wall, p, rc);
  EXPECT_GE(ref.counts[0], 3u);
}

void slivers_and_zero_area() {
  // A fan of needles (slivers) plus degenerate triangles that loading drops.
  std::vector<std::array<Vec3d, 3>> soup;
  for (int i = 0; i < 40; ++i) {
    const double a0 = 1e-3 * i, a1 = 1e-3 * (i + 1);
    soup.push_back({Vec3d{0, 0, 0}, Vec3d{30 * std::cos(a0), 30 * std::sin(a0), 0},
                    Vec3d{30 * std::cos(a1), 30 * std::sin(a1), 0}});
    if (i % 10 == 0) soup.push_back({Vec3d{1, 1, 1}, Vec3d{2, 2, 2}, Vec3d{3, 3, 3}});  // collinear
  }
  MeshReport rep;
  const TriangleMesh mesh = weld_soup(soup, {}, 0.0, &rep);
  EXPECT_EQ(rep.dropped_zero_area, 4u);
  EXPECT_EQ(mesh.triangles.size(), 40u);
  Particles p = scene_near(mesh, 800, 0.2, 0.5, 5);
  check_all_methods(mesh, p, "slivers");
  // Contacts name the input file's triangle indices, which skip the dropped ones.
  DetectConfig cfg;
  cfg.r_max = max_radius(p);
  cfg.backend = backend_under_test();
  const DetectResult r = run(mesh, p, cfg);
  for (const auto& c : r.contacts) EXPECT_NE(c.triangle % 11, 1u) << "a dropped triangle's id was reported";
}

// Grids the engine cannot number, or that would have each particle walk
// hundreds of thousands of cells, are refused with the reason (a cell count
// past 64 bits once wrapped to a dense table of no buckets; a reach past int
// walked no cells on the CPU and every cell on the GPU).
TEST(Detect, GridsTooFineToNumberOrWalkAreRefused) {
  const std::vector<std::array<Vec3d, 3>> soup = {
      {Vec3d{0, 0, 0}, Vec3d{1, 0, 0}, Vec3d{0, 1, 0}},
      {Vec3d{4194300.5, 2097148.5, 2097148.5}, Vec3d{4194301.5, 2097148.5, 2097148.5},
       Vec3d{4194300.5, 2097149.5, 2097148.5}}};
  const TriangleMesh sparse = weld_soup(soup, {}, 0.0, nullptr);
  DetectConfig cfg;
  cfg.method = Method::kBin;
  cfg.r_max = 0.5;
  auto refused = Detector::create(sparse, cfg, 10);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.status().message().find("cells over this wall's box"), std::string::npos)
      << refused.status().message();
  cfg.method = Method::kGravity;
  cfg.r_max = 1;
  cfg.grid_length = 0.05;  // the pieces' reach is about 40 cells
  auto fine = Detector::create(make_cylinder(50, 100, 40), cfg, 10);
  ASSERT_FALSE(fine);
  EXPECT_NE(fine.status().message().find("times below the pieces' reach"), std::string::npos)
      << fine.status().message();
  cfg.grid_length = 0.5;  // half the radius: a reach of 4, allowed
  EXPECT_TRUE(Detector::create(make_cylinder(50, 100, 40), cfg, 10));
}

void far_from_origin() {
  TriangleMesh wall = make_cylinder(10, 20, 24);
  translate(wall, {1e4, -1e4, 1e4});
  Particles p = scene_near(wall, 3000, 1.0, 1.0, 9);
  check_all_methods(wall, p, "far");
}

void hashed_grid() {
  const TriangleMesh wall = make_wall2();
  Particles p = scene_near(wall, 3000, 1, 2, 21);
  check_all_methods(wall, p, "hashed", /*max_dense_cells=*/1);
}

void other_grid_lengths() {
  const TriangleMesh wall = make_sphere(10, 2);
  Particles p = scene_near(wall, 2000, 0.5, 1, 33);
  check_all_methods(wall, p, "grid 0.7", 1ull << 24, 0.7);  // smaller than 2 r_max: wider neighbourhoods
  check_all_methods(wall, p, "grid 5", 1ull << 24, 5.0);
}

void outside_and_empty() {
  const TriangleMesh wall = make_box(10, 10, 10);
  Particles p;
  for (double x : {-1e6, 0.0, 1e6}) p.x.push_back(x), p.y.push_back(0), p.z.push_back(0), p.r.push_back(1);
  check_all_methods(wall, p, "outside");
  DetectConfig cfg;
  cfg.r_max = 1;
  cfg.backend = backend_under_test();
  auto det = Detector::create(wall, cfg, 10);
  ASSERT_TRUE(det);
  DetectResult r;
  ASSERT_TRUE((*det)->set_particles(Particles{}));
  ASSERT_TRUE((*det)->detect(&r));
  EXPECT_EQ(r.contact_count, 0u);
}

// Every mesh under tests/data with particles within 1e-6 r and 1e-4 r of
// touching, off faces, edges and vertices: the study's adversarial placement.
void third_party_meshes_near_touching() {
  for (const std::string name :
       {"3dsmax_export_assimp.stl", "plate_holes_trimesh_binary_solid_header.stl",
        "sphere_with_hole_assimp.stl", "teapot_trimesh.stl", "triangle_with_two_solids_assimp.stl",
        "wuson_assimp.stl"}) {
    auto mesh = load_stl(kData + "/meshes/" + name);
    ASSERT_TRUE(mesh) << name;
    const double r = 0.03 * length(mesh_bounds(*mesh).extent());
    for (double rel : {1e-6, 1e-4})
      check_all_methods(*mesh, particles_touching(*mesh, 600, 0.5 * r, r, rel, 7), name);
  }
}

// Float precision is the failure the filter closes: within 1e-6 r of touching
// it misses and invents contacts, and the band counter says how many pairs it
// decided in doubt (every wrong one among them); exact re-decides those.
void float_precision_flags_its_doubts() {
  const TriangleMesh wall = make_cylinder(50, 100, 40);  // wall1
  const Particles p = particles_touching(wall, 3000, 1, 1, 1e-6, 3);
  DetectConfig cfg;
  cfg.backend = backend_under_test();
  cfg.r_max = 1;
  DetectConfig rc = cfg;
  rc.method = Method::kReference;
  rc.backend = Backend::kCpu;
  const DetectResult ref = run(wall, p, rc);
  for (const Combo& c :
       {Combo{Method::kBin, Traversal::kParticle}, Combo{Method::kCircumcircle, Traversal::kWall},
        Combo{Method::kBvh, Traversal::kParticle}, Combo{Method::kOctree, Traversal::kParticle}}) {
    DetectConfig mc = cfg;
    mc.method = c.method, mc.traversal = c.traversal, mc.precision = Precision::kFloat;
    const DetectResult fl = run(wall, p, mc);
    const ContactDiff diff = compare_contacts(wall, p, ref.contacts, fl.contacts, 0.0);
    EXPECT_GT(diff.missed + diff.invented, 0u) << to_string(c.method);
    EXPECT_GE(fl.band_pairs, diff.missed + diff.invented) << to_string(c.method);
    mc.precision = Precision::kExact;
    const DetectResult ex = run(wall, p, mc);
    EXPECT_GT(ex.band_pairs, 0u);
    EXPECT_EQ(ex.band_pairs, fl.band_pairs) << "both precisions see the same band";
    // More than the octree's first room for them: its frame grows it and runs again.
    if (c.method == Method::kOctree) {
      EXPECT_GT(ex.band_pairs, kOctreeFirstDoubts);
    }
    const ContactDiff none = compare_contacts(wall, p, ref.contacts, ex.contacts, 0.0);
    EXPECT_EQ(none.missed + none.invented + none.borderline, 0u) << to_string(c.method);
  }
}

// The octree's contacts on `mesh` in every way of dealing out the particles
// (kOctreeWays), against the reference, which must find more than
// `min_contacts`; returns the octree's preparation, as said.
PrepareInfo octree_ways_match_the_reference(const TriangleMesh& mesh, const Particles& p,
                                            size_t min_contacts, const std::string& what) {
  DetectConfig cfg;
  cfg.backend = backend_under_test();
  cfg.r_max = max_radius(p);
  DetectConfig rc = cfg;
  rc.method = Method::kReference;
  rc.backend = Backend::kCpu;
  const DetectResult ref = run(mesh, p, rc);
  EXPECT_GT(ref.contact_count, min_contacts) << what;
  cfg.method = Method::kOctree;
  auto det = Detector::create(mesh, cfg, p.size());
  EXPECT_TRUE(det) << det.status().message();
  if (!det) return {};
  for (const OctreeWay& way : kOctreeWays) {
    way.apply(cfg);
    expect_same_contacts(mesh, p, ref, run(mesh, p, cfg), cfg.r_max, what + way.name);
  }
  return (*det)->info();
}

// The octree's leaves whose triangles lie more than 65,535 slots apart list
// whole slots (sim/octree.h): a row of 140,000 small triangles along x and a
// long sliver over it, listed with the row's triangles by every leaf; the
// sliver's slot lies 2/3 of the way along, so the leaves near the row's ends
// are wide and those between are not.
void octree_wide_leaves() {
  const double s = 5e-4;  // a triangle's size: the row 70 long keeps float's distances to 1e-5
  const TriangleMesh row = triangle_row_under_a_sliver(140000, s);
  const Particles p = scene_near(row, 1500, 2 * s, 4 * s, 11);
  const PrepareInfo info = octree_ways_match_the_reference(row, p, 1500, "wide leaves");
  EXPECT_GT(info.octree_wide_entries, 1000u);
  EXPECT_LT(info.octree_wide_entries, info.octree_entries / 2);
}

// The octree's long lists (the fine ball's leaves) and short ones (the
// box's) in one frame, the particles a few a leaf: in runs, the long lists'
// chunks are items of their own ahead of the runs (sim/detect_pipeline.h).
void octree_long_and_short_lists() {
  const Particles p = scene_near(crowded_wall(), 4000, 0.15, 0.3, 13);
  const PrepareInfo info =
      octree_ways_match_the_reference(crowded_wall(), p, 2000, "long and short lists");
  EXPECT_GT(info.octree_long_leaves, 100u);
  EXPECT_GT(info.octree_leaves - info.octree_long_leaves, 100u);
}

// A frame whose candidate pairs pass the most a frame may hold fails with a
// clear error instead of a wrong count; counting alone (bin, bvh) holds no pairs, the
// octree's only those in float's error band.
void more_pairs_than_a_frame_may_hold() {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  const Particles p = particles_touching(wall, 600, 1, 1, 1e-3, 4);
  for (const Combo& c : kCombos) {
    DetectConfig cfg;
    cfg.r_max = 1, cfg.method = c.method, cfg.traversal = c.traversal, cfg.max_frame_pairs = 100;
    cfg.backend = backend_under_test();
    auto det = Detector::create(wall, cfg, p.size());
    ASSERT_TRUE(det) << det.status().message();
    ASSERT_TRUE((*det)->set_particles(p));
    DetectResult r;
    const Status s = (*det)->detect(&r);
    ASSERT_FALSE(s) << to_string(c.method) << "/" << to_string(c.traversal);
    EXPECT_EQ(s.code(), ErrorCode::kResourceExhausted);
    EXPECT_NE(s.message().find("more than 100 candidate"), std::string::npos) << s.message();
    // The detector stays usable: the next frame is judged afresh.
    EXPECT_FALSE((*det)->detect(&r));
    if ((c.method == Method::kBin || c.method == Method::kBvh) &&
        c.traversal == Traversal::kParticle) {
      (*det)->set_frame_options(/*collect_contacts=*/false, false);
      ASSERT_TRUE((*det)->detect(&r)) << "counting alone holds no pairs";
      EXPECT_GT(r.contact_count, 100u);
    }
    if (c.method == Method::kOctree) {
      // The octree's count holds the pairs in float's band for their double
      // pass, and these particles lie within a hair of touching.
      (*det)->set_frame_options(/*collect_contacts=*/false, false);
      const Status counted = (*det)->detect(&r);
      ASSERT_FALSE(counted);
      EXPECT_EQ(counted.code(), ErrorCode::kResourceExhausted);
      EXPECT_NE(counted.message().find("in float's error band"), std::string::npos)
          << counted.message();
    }
  }
}

// The float distance never strays from the exact one by more than a quarter
// of the band the filter trusts it outside of: slivers, far from the origin,
// a large wall, a third-party mesh, particles near and exactly near touching.
TEST(Detect, FloatErrorStaysInsideTheBand) {
  std::vector<std::pair<std::string, TriangleMesh>> walls;
  walls.emplace_back("wall1", make_cylinder(50, 100, 40));
  TriangleMesh far = make_cylinder(10, 20, 24);
  translate(far, {1e4, -1e4, 1e4});
  walls.emplace_back("far", far);
  std::vector<std::array<Vec3d, 3>> soup;
  for (int i = 0; i < 40; ++i)
    soup.push_back({Vec3d{0, 0, 0}, Vec3d{30 * std::cos(1e-3 * i), 30 * std::sin(1e-3 * i), 0},
                    Vec3d{30 * std::cos(1e-3 * (i + 1)), 30 * std::sin(1e-3 * (i + 1)), 0}});
  walls.emplace_back("slivers", weld_soup(soup, {}, 0.0, nullptr));
  auto teapot = load_stl(kData + "/meshes/teapot_trimesh.stl");
  ASSERT_TRUE(teapot);
  walls.emplace_back("teapot", *teapot);
  for (const auto& [name, wall] : walls) {
    const Vec3d origin = mesh_bounds(wall).center();
    const float scale = wall_band_scale(wall, origin);
    const double r = name == "teapot" ? 0.3 : 1.0;
    Particles p = particles_touching(wall, 1500, r, r, 1e-3, 11);
    double worst = 0;
    for (size_t i = 0; i < p.size(); ++i) {
      const Vec3d c{p.x[i], p.y[i], p.z[i]};
      const Vec3f f = cast3<float>(c - origin);
      const float band = float_band(f.x, f.y, f.z, float(r), scale);
      for (size_t t = 0; t < wall.triangles.size(); ++t) {
        const TriangleD tri{wall.corner(t, 0), wall.corner(t, 1), wall.corner(t, 2)};
        const double de = std::sqrt(exact_dist2(c, tri));
        if (de > 3 * r) continue;
        const PlanarTriangle pt = make_planar(tri.a, tri.b, tri.c, origin);
        const double df = std::sqrt(double(point_triangle_dist2(f, pt)));
        worst = std::max(worst, std::fabs(df - de) / band);
      }
    }
    std::printf("%s: worst float error %.3g of the band\n", name.c_str(), worst);
    EXPECT_LT(worst, 0.25) << name;
  }
}

TEST(Detect, ThirdPartyMeshesNearTouchingMatchTheReference) { third_party_meshes_near_touching(); }
TEST(Detect, FloatPrecisionFlagsItsDoubts) { float_precision_flags_its_doubts(); }
TEST(Detect, OctreeLeavesListingWholeSlotsMatchTheReference) {
  octree_wide_leaves();
}
TEST(Detect, OctreeLongAndShortListsMatchTheReference) {
  octree_long_and_short_lists();
}
TEST(Detect, AFrameWithMorePairsThanItMayHoldIsRefused) { more_pairs_than_a_frame_may_hold(); }
TEST(Detect, TwentyRandomScenesMatchTheReference) { twenty_random_scenes(); }
TEST(Detect, AdversarialPlacementsMatchTheReference) { adversarial_placements(); }
TEST(Detect, SliversAndZeroAreaTrianglesInTheInput) { slivers_and_zero_area(); }
TEST(Detect, FarFromTheOrigin) { far_from_origin(); }
TEST(Detect, HashedGridGivesTheSameContacts) { hashed_grid(); }
TEST(Detect, OtherGridLengthsStayExact) { other_grid_lengths(); }
TEST(Detect, ParticlesOutsideTheGridAndEmptyFrames) { outside_and_empty(); }

// The same scenes on the GPU: identical contact sets to the reference (and so
// to the CPU) under the accuracy contract. Skipped where no GPU is usable.
class DetectCuda : public GpuSuite {};
TEST_F(DetectCuda, TwentyRandomScenesMatchTheReference) { twenty_random_scenes(); }
TEST_F(DetectCuda, AdversarialPlacementsMatchTheReference) { adversarial_placements(); }
TEST_F(DetectCuda, SliversAndZeroAreaTrianglesInTheInput) { slivers_and_zero_area(); }
TEST_F(DetectCuda, FarFromTheOrigin) { far_from_origin(); }
TEST_F(DetectCuda, HashedGridGivesTheSameContacts) { hashed_grid(); }
TEST_F(DetectCuda, OtherGridLengthsStayExact) { other_grid_lengths(); }
TEST_F(DetectCuda, ParticlesOutsideTheGridAndEmptyFrames) { outside_and_empty(); }
TEST_F(DetectCuda, ThirdPartyMeshesNearTouchingMatchTheReference) { third_party_meshes_near_touching(); }
TEST_F(DetectCuda, FloatPrecisionFlagsItsDoubts) { float_precision_flags_its_doubts(); }
TEST_F(DetectCuda, OctreeLeavesListingWholeSlotsMatchTheReference) {
  octree_wide_leaves();
}
TEST_F(DetectCuda, OctreeLongAndShortListsMatchTheReference) {
  octree_long_and_short_lists();
}
TEST_F(DetectCuda, AFrameWithMorePairsThanItMayHoldIsRefused) { more_pairs_than_a_frame_may_hold(); }

TEST_F(DetectCuda, GpuAndCpuCountsAgreeOnALargeScene) {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  Particles p = random_particles(200000, mesh_bounds(wall), 0.5, 1, 77);
  for (const Combo& c : kCombos) {
    DetectConfig cfg;
    cfg.r_max = 1;
    cfg.method = c.method;
    cfg.traversal = c.traversal;
    cfg.collect_contacts = false;
    if (c.method == Method::kMidpoint4) continue;  // 2.6M pieces: covered by the smaller scenes
    const DetectResult cpu = run(wall, p, cfg);
    cfg.backend = Backend::kCuda;
    const DetectResult gpu = run(wall, p, cfg);
    EXPECT_EQ(cpu.contact_count, gpu.contact_count) << to_string(c.method) << "/" << to_string(c.traversal);
    size_t differ = 0;
    for (size_t i = 0; i < p.size(); ++i) differ += cpu.counts[i] != gpu.counts[i];
    EXPECT_EQ(differ, 0u);
  }
}

TEST(Detect, CudaBackendIsReportedAbsentClearly) {
  std::string why;
  if (cuda_available(&why)) GTEST_SKIP() << "a GPU is present";
  EXPECT_FALSE(why.empty());
  DetectConfig cfg;
  cfg.r_max = 1;
  cfg.backend = Backend::kCuda;
  auto det = Detector::create(make_box(1, 1, 1), cfg, 10);
  ASSERT_FALSE(det);
  EXPECT_EQ(det.status().code(), ErrorCode::kBackend);
}

TEST(Detect, BadInputsAreClearErrors) {
  const TriangleMesh wall = make_box(10, 10, 10);
  DetectConfig cfg;
  cfg.r_max = 0;
  EXPECT_FALSE(Detector::create(wall, cfg, 10));
  cfg.r_max = 1;
  EXPECT_FALSE(Detector::create(TriangleMesh{}, cfg, 10));
  cfg.grid_length = 1e-9;
  auto tiny = Detector::create(wall, cfg, 10);
  ASSERT_FALSE(tiny);
  EXPECT_NE(tiny.status().message().find("grid length"), std::string::npos);
  cfg.grid_length = 0;
  auto det = Detector::create(wall, cfg, 2);
  ASSERT_TRUE(det);
  Particles big;
  big.x = {0}, big.y = {0}, big.z = {0}, big.r = {2};
  Status s = (*det)->set_particles(big);
  ASSERT_FALSE(s);
  EXPECT_NE(s.message().find("r_max"), std::string::npos);
  Particles many = random_particles(3, mesh_bounds(wall), 0.5, 0.5, 1);
  EXPECT_FALSE((*det)->set_particles(many));
  // Division that would explode is refused, not attempted.
  DetectConfig huge;
  huge.method = Method::kGravity;
  huge.r_max = 1e-4;
  auto refused = Detector::create(make_cylinder(50, 100, 40), huge, 10);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.status().message().find("bin"), std::string::npos);
}

}  // namespace
}  // namespace collido::sim
