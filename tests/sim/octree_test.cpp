// The octree method's wall (sim/octree.h): a point's leaf lists every triangle
// within r_max of it, and cells split where the triangles crowd. The contact
// sets against the reference are detect_test's and bvh_test's.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <vector>

#include "sim/backend_cpu.h"
#include "sim/contact_force.h"
#include "sim/mesh.h"
#include "sim/octree.h"
#include "sim/parallel.h"
#include "sim/wall_index.h"
#include "tests/sim/wall_shape.h"

namespace collido::sim {
namespace {

double exact_d2(Vec3d p, const PlanarTriangleD& t) {
  Vec3d q;
  double h = 0, aside = 0;
  return closest_point_planar(p, t, INFINITY, &q, &h, &aside);
}

// A point at up to `reach` from a random point of a random triangle.
Vec3d point_near_wall(const TriangleMesh& m, double reach, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u01(0, 1);
  const size_t t = size_t(u01(rng) * double(m.triangles.size())) % m.triangles.size();
  double s = u01(rng), w = u01(rng);
  if (s + w > 1) s = 1 - s, w = 1 - w;
  const Vec3d a = m.corner(t, 0), b = m.corner(t, 1), c = m.corner(t, 2);
  std::normal_distribution<double> g(0, 1);
  Vec3d dir{g(rng), g(rng), g(rng)};
  return a + (b - a) * s + (c - a) * w + dir * (reach * u01(rng) / length(dir));
}

TEST(Octree, APointsLeafListsEveryTriangleWithinReach) {
  const TriangleMesh wall = crowded_wall();
  const double r = 0.3;
  std::mt19937_64 rng(5);
  for (uint64_t dense : {uint64_t(1) << 24, uint64_t(64)}) {
    CpuBackend backend;
    WallIndex<CpuBackend> index;
    PrepareInfo info;
    ASSERT_TRUE(
        index.prepare(backend, wall, Method::kOctree, r, 2 * r, dense, 1000, &info, true).ok());
    EXPECT_EQ(info.hashed, dense < 1000);
    EXPECT_GT(info.octree_splits, 100u) << "the ball's cells are split";
    const OctreeView view = index.octree_view();
    const size_t m = wall.triangles.size();
    size_t touching = 0;
    for (int k = 0; k < 3000; ++k) {
      const Vec3d p = point_near_wall(wall, 1.5 * r, rng);
      const Vec3f local = cast3<float>(p - index.origin);
      std::set<uint32_t> listed;
      const int32_t leaf = view.leaf_of(local);
      if (leaf >= 0) {
        const OctreeView::List list = view.list(uint32_t(leaf));
        for (uint32_t k = 0; k < list.count; ++k) listed.insert(view.slot(list, k));
      }
      for (uint32_t t = 0; t < m; ++t) {  // the triangles' slots (tris_d is in their order)
        const PlanarTriangleD& td = index.tris_d.data()[t];
        if (!(exact_d2(p - index.origin, td) < r * r)) continue;
        ++touching;
        ASSERT_TRUE(listed.count(t))
            << "triangle " << t << " within reach is not in the leaf of " << p.x << ", " << p.y
            << ", " << p.z << (dense < 1000 ? " (hashed)" : "");
      }
    }
    EXPECT_GT(touching, 3000u);
  }
}

// Splitting is what the method is for: the crowded ball's cells list far
// fewer triangles once split, and every list stays complete (above).
TEST(Octree, CrowdedCellsAreSplitUntilTheirListsAreShort) {
  const TriangleMesh wall = crowded_wall();
  const double r = 0.3;
  CpuBackend backend;
  WallIndex<CpuBackend> index;
  PrepareInfo info;
  ASSERT_TRUE(index.prepare(backend, wall, Method::kBin, r, 2 * r, 1ull << 24, 1000, &info).ok());
  const Vec3d origin = index.origin;
  const OctreeBuild flat = build_octree(wall, origin, index.grid, r * 1.001, kOctreeSplitAbove, 0);
  const OctreeBuild split = build_octree(wall, origin, index.grid, r * 1.001);
  EXPECT_EQ(flat.splits, 0u);
  EXPECT_GT(split.splits, 100u);
  EXPECT_GT(flat.longest, 200u);
  EXPECT_LT(split.longest, flat.longest / 2);
  EXPECT_GT(split.leaves(), 4 * flat.leaves());
  // The leaves listing over kOctreeLongList triangles come first.
  EXPECT_GT(split.long_leaves, 100u);
  EXPECT_GT(split.leaves() - split.long_leaves, 100u);
  for (size_t l = 0; l < split.leaves(); ++l)
    ASSERT_EQ(split.leaf_start[l + 1] - split.leaf_start[l] > kOctreeLongList,
              l < split.long_leaves)
        << "leaf " << l;
  // Each leaf's list is sorted (by triangle) and without repeats.
  for (size_t l = 0; l < split.leaves(); ++l)
    for (uint32_t k = split.leaf_start[l] + 1; k < split.leaf_start[l + 1]; ++k)
      ASSERT_LT(split.leaf_tri[k - 1], split.leaf_tri[k]);
  // The same build on one thread and on two is the same structure.
  ThreadPool one(1), two(2);
  const OctreeBuild a =
      build_octree(wall, origin, index.grid, r * 1.001, kOctreeSplitAbove, kOctreeMaxDepth, &one);
  const OctreeBuild b =
      build_octree(wall, origin, index.grid, r * 1.001, kOctreeSplitAbove, kOctreeMaxDepth, &two);
  EXPECT_EQ(a.leaf_tri, split.leaf_tri);
  EXPECT_EQ(b.leaf_tri, split.leaf_tri);
  EXPECT_EQ(b.leaf_start, split.leaf_start);
  EXPECT_EQ(b.inner, split.inner);
  EXPECT_EQ(b.cell_node, split.cell_node);
  EXPECT_EQ(b.cell_key, split.cell_key);
}

// Every leaf of `built` gives back its own triangles through the device's
// view of `lists` (the first leaf that does not is reported).
void expect_lists_give_back_every_triangle(const OctreeBuild& built, const OctreeLists& lists) {
  OctreeView view;
  view.leaf_start = lists.leaf_start.data();
  view.leaf_base = lists.leaf_base.data();
  view.leaf_entry = lists.leaf_entry.data();
  for (uint32_t leaf = 0; leaf < built.leaves(); ++leaf) {
    const OctreeView::List list = view.list(leaf);
    std::multiset<uint32_t> got, want;
    for (uint32_t k = 0; k < list.count; ++k) got.insert(lists.order[view.slot(list, k)]);
    want.insert(built.leaf_tri.begin() + built.leaf_start[leaf],
                built.leaf_tri.begin() + built.leaf_start[leaf + 1]);
    ASSERT_EQ(got, want) << "leaf " << leaf;
  }
}

// The device's lists: a base slot and 16-bit steps, or whole slots for a
// leaf whose triangles lie farther apart along the Morton curve. A row of
// 70,000 small triangles along x (their slots follow x) and a long sliver
// beside it: a leaf listing both ends of the row spans more than 65,535 slots.
TEST(Octree, ListsPackedBySlotGiveBackEveryTriangle) {
  const uint32_t n = 70000;
  const TriangleMesh row = triangle_row_under_a_sliver(n, 0.1);
  OctreeBuild built;  // three leaves, by hand
  built.leaf_tri = {0, 1, 2, n - 1, 30000, 30001, 69998, 69999, n};
  built.leaf_start = {0, 4, 6, 9};
  const OctreeLists lists = pack_octree_lists(row, built);
  ASSERT_EQ(lists.order.size(), size_t(n) + 1);
  std::vector<uint32_t> slot(n + 1);
  for (uint32_t k = 0; k <= n; ++k) slot[lists.order[k]] = k;
  for (uint32_t k = 1; k < n; ++k) ASSERT_LT(slot[k - 1], slot[k]) << "the row's slots follow x";
  EXPECT_EQ(lists.leaf_base[0], kOctreeWide);
  EXPECT_NE(lists.leaf_base[1], kOctreeWide);
  EXPECT_EQ(lists.wide_entries, 4u);
  expect_lists_give_back_every_triangle(built, lists);
}

// Packed on one thread and on three: the same words, and every leaf gives
// back its triangles. 20,000 leaves by hand (the packing shares them out
// 4,096 at a time), narrow and wide ones mixed at random (a third listing
// both ends of the row), so wide leaves begin at odd and even words on both
// sides of the threads' shares.
TEST(Octree, ListsPackedOnSeveralThreadsAreTheSame) {
  const uint32_t n = 70000;
  const TriangleMesh row = triangle_row_under_a_sliver(n, 0.1);
  OctreeBuild built;
  std::mt19937 rng(7);
  for (uint32_t leaf = 0; leaf < 20000; ++leaf) {
    const uint32_t count = 1 + rng() % 5, first = rng() % (n - 100);
    const bool wide = rng() % 3 == 0;
    std::set<uint32_t> mine;
    if (wide) mine = {0u, n - 1};  // the row's two ends: 70,000 slots apart
    while (mine.size() < count + 2 * wide) mine.insert(first + rng() % 100);
    built.leaf_tri.insert(built.leaf_tri.end(), mine.begin(), mine.end());
    built.leaf_start.push_back(uint32_t(built.leaf_tri.size()));
  }
  ThreadPool one(1), three(3);
  const OctreeLists a = pack_octree_lists(row, built, &one);
  const OctreeLists b = pack_octree_lists(row, built, &three);
  EXPECT_EQ(a.order, b.order);
  EXPECT_EQ(a.leaf_start, b.leaf_start);
  EXPECT_EQ(a.leaf_base, b.leaf_base);
  EXPECT_EQ(a.leaf_entry, b.leaf_entry);
  EXPECT_EQ(a.wide_entries, b.wide_entries);
  EXPECT_GT(b.wide_entries, 0u);
  expect_lists_give_back_every_triangle(built, b);
}

}  // namespace
}  // namespace collido::sim
