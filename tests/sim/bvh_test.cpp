// The bvh method's tree (sim/bvh.h): every triangle in one leaf, every box
// holding what lies below it, paths short enough for the walk's stack on any
// input, and a walk that visits every triangle within its reach. Exactness
// of the detection built on it is in detect_test (the method is in every
// scene there) and below on the large CAD mesh it was made for.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <set>
#include <string>
#include <vector>

#include "sim/accuracy.h"
#include "sim/bvh.h"
#include "sim/detect.h"
#include "sim/parallel.h"
#include "sim/particles.h"
#include "sim/shapes.h"
#include "gpu_suite.h"

namespace collido::sim {
namespace {

const std::string kData = COLLIDO_TEST_DATA;

struct Walked {
  std::vector<int> seen;  // per triangle slot: leaves holding it
  int depth = 0;
};

// A node's children as the checks read them, from the binary or the wide tree.
struct Child {
  uint32_t code;
  float lo[3], hi[3];
};
std::vector<Child> children(const BvhBuild& b, bool wide, uint32_t node) {
  std::vector<Child> out;
  if (wide) {
    const BvhWideNode& n = b.wide[node];
    for (int c = 0; c < 4; ++c)
      out.push_back({n.child[c], {n.lo_x[c], n.lo_y[c], n.lo_z[c]}, {n.hi_x[c], n.hi_y[c], n.hi_z[c]}});
  } else {
    const BvhNode& n = b.nodes[node];
    out.push_back({n.child0, {n.lo0x, n.lo0y, n.lo0z}, {n.hi0x, n.hi0y, n.hi0z}});
    out.push_back({n.child1, {n.lo1x, n.lo1y, n.lo1z}, {n.hi1x, n.hi1y, n.hi1z}});
  }
  return out;
}

// Walks every node of the binary or the wide tree, checking that each
// child's box holds the triangles below it.
void walk(const TriangleMesh& mesh, Vec3d origin, const BvhBuild& b, bool wide, uint32_t node,
          int depth, Walked* w, std::vector<uint32_t>* below) {
  ASSERT_LT(node, wide ? b.wide.size() : b.nodes.size());
  ASSERT_LT(depth, kBvhStackDepth);
  w->depth = std::max(w->depth, depth);
  const std::vector<Child> kids = children(b, wide, node);
  for (size_t c = 0; c < kids.size(); ++c) {
    const Child& ch = kids[c];
    if (ch.lo[0] > ch.hi[0]) continue;  // an empty slot (a one-leaf tree, a wide node not full)
    std::vector<uint32_t> slots;
    if (ch.code & kBvhLeafBit) {
      const uint32_t first = (ch.code & ~kBvhLeafBit) >> kBvhLeafCountBits;
      const uint32_t count = (ch.code & (kBvhMaxLeaf - 1)) + 1;
      ASSERT_LE(first + count, b.order.size());
      for (uint32_t k = first; k < first + count; ++k) slots.push_back(k), ++w->seen[k];
    } else {
      walk(mesh, origin, b, wide, ch.code, depth + 1, w, &slots);
    }
    for (uint32_t k : slots) {
      for (int v = 0; v < 3; ++v) {
        const Vec3d p = mesh.corner(b.order[k], v) - origin;
        const double q[3] = {p.x, p.y, p.z};
        for (int a = 0; a < 3; ++a) {
          ASSERT_LE(ch.lo[a], q[a]) << (wide ? "wide " : "") << "node " << node << " child " << c;
          ASSERT_GE(ch.hi[a], q[a]) << (wide ? "wide " : "") << "node " << node << " child " << c;
        }
      }
    }
    if (below) below->insert(below->end(), slots.begin(), slots.end());
  }
}

// Checks the tree built for `mesh` in the frame at `origin` and returns it.
BvhBuild expect_sound_tree_at(const TriangleMesh& mesh, Vec3d origin, double reach,
                              const std::string& what) {
  BvhBuild b = build_bvh(mesh, origin, reach, 0.0);
  EXPECT_EQ(b.order.size(), mesh.triangles.size()) << what;
  if (b.order.size() != mesh.triangles.size()) return b;
  std::vector<uint32_t> sorted = b.order;
  std::sort(sorted.begin(), sorted.end());
  for (size_t k = 0; k < sorted.size(); ++k) EXPECT_EQ(sorted[k], k) << what << ": not a permutation";
  Walked w;
  w.seen.assign(mesh.triangles.size(), 0);
  walk(mesh, origin, b, /*wide=*/false, 0, 0, &w, nullptr);
  for (size_t k = 0; k < w.seen.size(); ++k) EXPECT_EQ(w.seen[k], 1) << what << ": slot " << k;
  EXPECT_LE(b.depth, w.depth + 1) << what;  // leaves sit one level below their node
  EXPECT_LT(b.depth, kBvhStackDepth) << what;
  // The wide tree holds the same leaves, in fewer levels.
  Walked ww;
  ww.seen.assign(mesh.triangles.size(), 0);
  walk(mesh, origin, b, /*wide=*/true, 0, 0, &ww, nullptr);
  for (size_t k = 0; k < ww.seen.size(); ++k) EXPECT_EQ(ww.seen[k], 1) << what << ": wide, slot " << k;
  EXPECT_LE(b.wide_depth, std::max(b.depth, 1)) << what;  // a one-leaf tree still has a root
  EXPECT_LE(b.wide.size(), b.nodes.size()) << what;
  return b;
}
// The same in the frame the engine uses, centred at the wall's box.
BvhBuild expect_sound_tree(const TriangleMesh& mesh, double reach, const std::string& what) {
  return expect_sound_tree_at(mesh, mesh_bounds(mesh).center(), reach, what);
}

TEST(Bvh, EveryTriangleInOneLeafUnderBoxesThatHoldIt) {
  auto teapot = load_stl(kData + "/meshes/teapot_trimesh.stl");
  ASSERT_TRUE(teapot);
  expect_sound_tree(*teapot, 0.3, "teapot");
  expect_sound_tree(make_sphere(10, 4), 0.5, "icosphere");
  expect_sound_tree(make_cylinder(50, 100, 400), 1.0, "cylinder of slivers");
  expect_sound_tree(make_box(1, 1, 1), 10.0, "a box smaller than the reach: one leaf");
  TriangleMesh one;
  one.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  one.triangles = {{0, 1, 2}};
  one.source_ids = {0};
  expect_sound_tree(one, 1.0, "one triangle");
}

// A mesh large enough that subtrees are built on the pool: sound, and the
// same tree whatever the threads.
TEST(Bvh, SubtreesBuiltInParallelGiveOneTree) {
  auto counter = load_stl(kData + "/meshes/counter_unitsmm_trimesh_83750tri.stl");
  ASSERT_TRUE(counter);
  expect_sound_tree(*counter, 1.0, "counter");
  const Vec3d origin = mesh_bounds(*counter).center();
  ThreadPool one(1), three(3);
  const BvhBuild a = build_bvh(*counter, origin, 1.0, 1e-3, &one);
  const BvhBuild b = build_bvh(*counter, origin, 1.0, 1e-3, &three);
  EXPECT_EQ(a.order, b.order);
  ASSERT_EQ(a.nodes.size(), b.nodes.size());
  EXPECT_EQ(std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(BvhNode)), 0);
  ASSERT_EQ(a.wide.size(), b.wide.size());
  EXPECT_EQ(std::memcmp(a.wide.data(), b.wide.data(), a.wide.size() * sizeof(BvhWideNode)), 0);
  EXPECT_EQ(a.depth, b.depth);
  EXPECT_EQ(a.leaves, b.leaves);
}

// Inputs that defeat the surface-area heuristic: thousands of triangles with
// one centre (no plane separates them) and a chain of ever smaller triangles
// (the heuristic peels off the largest, level after level, past the depth
// where object medians take over) still give paths the stack holds.
TEST(Bvh, DegenerateInputsKeepPathsWithinTheStack) {
  TriangleMesh same;
  for (int i = 0; i < 5000; ++i) {
    const uint32_t v = static_cast<uint32_t>(same.vertices.size());
    const double s = 1 + 1e-3 * i;
    same.vertices.push_back({-s, -s, 0});
    same.vertices.push_back({s, -s, 0});
    same.vertices.push_back({0, 2 * s, 0});
    same.triangles.push_back({v, v + 1, v + 2});
    same.source_ids.push_back(static_cast<uint32_t>(i));
  }
  expect_sound_tree(same, 0.1, "5000 triangles about one centre");
  TriangleMesh chain;
  double x = 0;
  for (int i = 0; i < 2000; ++i) {
    const double s = std::pow(0.9, i);
    const uint32_t v = static_cast<uint32_t>(chain.vertices.size());
    chain.vertices.push_back({x, 0, 0});
    chain.vertices.push_back({x + s, 0, 0});
    chain.vertices.push_back({x, s, 0});
    chain.triangles.push_back({v, v + 1, v + 2});
    chain.source_ids.push_back(static_cast<uint32_t>(i));
    x += s;
  }
  // Built about the chain's first corner, the tiniest triangles keep their own
  // coordinates and the heuristic peels them one by one, past the guard.
  EXPECT_GT(expect_sound_tree_at(chain, {0, 0, 0}, 1e-3, "a chain of shrinking triangles").depth,
            kBvhSahDepth)
      << "the guard was not reached";
}

// The walk visits every triangle whose box lies within its reach of the point.
TEST(Bvh, WalkVisitsEveryTriangleWithinReach) {
  auto teapot = load_stl(kData + "/meshes/teapot_trimesh.stl");
  ASSERT_TRUE(teapot);
  const TriangleMesh& mesh = *teapot;
  const Vec3d origin = mesh_bounds(mesh).center();
  const float reach = 0.25f;
  const BvhBuild b = build_bvh(mesh, origin, reach, 0.0);
  const Particles probe = particles_near_surface(mesh, 3000, 0.1, 0.1, 0.7, 0.5, 11);
  for (size_t i = 0; i < probe.size(); ++i) {
    const Vec3f p = cast3<float>(Vec3d{probe.x[i], probe.y[i], probe.z[i]} - origin);
    std::set<uint32_t> walked;
    bvh_for_each_near(b.wide.data(), p, reach, [&](uint32_t k) {
      EXPECT_TRUE(walked.insert(b.order[k]).second) << "a triangle visited twice";
    });
    for (size_t t = 0; t < mesh.triangles.size(); ++t) {
      Vec3d lo = mesh.corner(t, 0) - origin, hi = lo;
      for (int v = 1; v < 3; ++v) {
        const Vec3d c = mesh.corner(t, v) - origin;
        lo = {std::min(lo.x, c.x), std::min(lo.y, c.y), std::min(lo.z, c.z)};
        hi = {std::max(hi.x, c.x), std::max(hi.y, c.y), std::max(hi.z, c.z)};
      }
      const double d2 = box_dist2(p, float(lo.x), float(lo.y), float(lo.z), float(hi.x),
                                  float(hi.y), float(hi.z));
      if (d2 < 0.99 * reach * reach) {
        EXPECT_TRUE(walked.count(uint32_t(t))) << "particle " << i << " triangle " << t;
      }
    }
  }
}

TEST(Bvh, MortonKeysFollowTheCurveAndMarkOutsiders) {
  MortonFrame f;
  f.lo = {0, 0, 0}, f.hi = {1, 1, 1}, f.scale = 1024.f;
  EXPECT_EQ(f.key({0, 0, 0}), 0u);
  EXPECT_EQ(f.key({1, 1, 1}), (1u << 30) - 1);  // the upper face lands in the last cell
  EXPECT_EQ(f.key({0, 0, 1.0f / 1024}), 1u);    // z is the lowest bit
  EXPECT_EQ(f.key({1.0f / 1024, 0, 0}), 4u);
  EXPECT_EQ(f.key({-1e-3f, 0.5f, 0.5f}), kInvalidMorton);
  EXPECT_EQ(f.key({0.5f, 2.f, 0.5f}), kInvalidMorton);
  EXPECT_EQ(f.key({NAN, 0.5f, 0.5f}), kInvalidMorton);
}

// The large CAD export the method is for: 83,750 triangles whose areas span
// five decades. Particles within 1e-6 r of touching faces, edges and
// vertices, and near the surface: the reference's contact set, on both backends.
void counter_mesh_matches_the_reference() {
  auto mesh = load_stl(kData + "/meshes/counter_unitsmm_trimesh_83750tri.stl");
  ASSERT_TRUE(mesh) << mesh.status().message();
  for (int scene = 0; scene < 2; ++scene) {
    const Particles p = scene == 0 ? particles_touching(*mesh, 4000, 0.5, 1.0, 1e-6, 5)
                                   : particles_near_surface(*mesh, 4000, 0.5, 1.0, 0.5, 1.5, 6);
    DetectConfig cfg;
    cfg.r_max = 1.0;
    cfg.method = Method::kReference;
    auto ref = Detector::create(*mesh, cfg, p.size());
    ASSERT_TRUE(ref);
    DetectResult rr;
    ASSERT_TRUE((*ref)->set_particles(p));
    ASSERT_TRUE((*ref)->detect(&rr));
    EXPECT_GT(rr.contact_count, 1000u);
    for (Method m : {Method::kBvh, Method::kBin, Method::kOctree}) {
      cfg.method = m;
      cfg.backend = backend_under_test();
      auto det = Detector::create(*mesh, cfg, p.size());
      ASSERT_TRUE(det) << det.status().message();
      DetectResult got;
      ASSERT_TRUE((*det)->set_particles(p));
      ASSERT_TRUE((*det)->detect(&got));
      const ContactDiff d = compare_contacts(*mesh, p, rr.contacts, got.contacts, 0.0);
      EXPECT_EQ(d.missed + d.invented + d.borderline, 0u)
          << to_string(m) << " scene " << scene << ": " << d.missed << " missed, " << d.invented
          << " invented";
      EXPECT_EQ(got.contact_count, rr.contact_count) << to_string(m);
      if (m == Method::kBvh) {
        EXPECT_GT((*det)->info().bvh_nodes, 0u);
        EXPECT_LT((*det)->info().bvh_depth, kBvhStackDepth);
      }
    }
  }
}

TEST(Bvh, CounterMeshMatchesTheReference) { counter_mesh_matches_the_reference(); }

class BvhCuda : public GpuSuite {};
TEST_F(BvhCuda, CounterMeshMatchesTheReference) { counter_mesh_matches_the_reference(); }

TEST(Bvh, WallTraversalIsRefusedClearly) {
  DetectConfig cfg;
  cfg.r_max = 1;
  cfg.method = Method::kBvh;
  cfg.traversal = Traversal::kWall;
  auto det = Detector::create(make_box(10, 10, 10), cfg, 10);
  ASSERT_FALSE(det);
  EXPECT_NE(det.status().message().find("particle traversal"), std::string::npos);
}

}  // namespace
}  // namespace collido::sim
