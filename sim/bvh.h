// The `bvh` method's wall: a bounding volume hierarchy over the ORIGINAL
// triangles, built once on the host and walked per particle by both backends
// from the same source. Real CAD exports mix long slivers with tiny facets
// (areas over five decades); a uniform grid copies a large triangle into
// every cell it reaches and division cuts it into particle-size pieces,
// while a tree adapts its boxes to the mesh (docs/benchmarks.md, "Large meshes").
//
// Layout: the tree is built binary (each node holds both children's boxes,
// Aila and Laine's layout) and then collapsed into a 4-wide tree whose node
// holds its four children's boxes as arrays (112 bytes, seven 16-byte loads):
// half the levels, so a walk waits on half as many dependent loads. A child
// is an inner node's index or, with the top bit set, a leaf: a run of up to
// kBvhMaxLeaf triangles in the reordered triangle array.
#pragma once

#include <cstdint>
#include <vector>

#include "sim/hd.h"
#include "sim/mesh.h"

namespace collido::sim {

class ThreadPool;  // sim/parallel.h

inline constexpr uint32_t kBvhLeafBit = 0x80000000u;
inline constexpr int kBvhLeafCountBits = 4;
inline constexpr uint32_t kBvhMaxLeaf = 1u << kBvhLeafCountBits;  // triangles per leaf, at most
inline constexpr uint32_t kBvhMaxTriangles = 1u << (31 - kBvhLeafCountBits);
// The builder keeps every path under this many levels, so the walk's stack
// (three entries a level, kBvhWideStackDepth) never overflows: splits below
// kBvhSahDepth are object medians, which halve the count, so no path grows
// past kBvhSahDepth + log2(kBvhMaxTriangles) levels.
inline constexpr int kBvhStackDepth = 64;
inline constexpr int kBvhSahDepth = 32;
static_assert(kBvhSahDepth + 31 - kBvhLeafCountBits < kBvhStackDepth,
              "the stack must hold the deepest path");

// The built form: a binary node with both children's boxes.
struct alignas(16) BvhNode {
  float lo0x, lo0y, lo0z, hi0x;
  float hi0y, hi0z, lo1x, lo1y;
  float lo1z, hi1x, hi1y, hi1z;
  uint32_t child0, child1, pad0, pad1;
};
static_assert(sizeof(BvhNode) == 64, "a node is four 16-byte loads");

// The walked form: four children a node; an empty slot has an inverted box.
struct alignas(16) BvhWideNode {
  float lo_x[4], lo_y[4], lo_z[4], hi_x[4], hi_y[4], hi_z[4];
  uint32_t child[4];
};
static_assert(sizeof(BvhWideNode) == 112, "a wide node is seven 16-byte loads");
// A wide walk pushes at most three entries a level.
inline constexpr int kBvhWideStackDepth = 3 * kBvhStackDepth;

COLLIDO_HD COLLIDO_FORCEINLINE uint32_t bvh_leaf(uint32_t first, uint32_t count) {
  return kBvhLeafBit | (first << kBvhLeafCountBits) | (count - 1);
}

// Squared distance from p to the box [lo, hi] (0 inside).
COLLIDO_HD COLLIDO_FORCEINLINE float box_dist2(Vec3f p, float lox, float loy, float loz, float hix,
                                               float hiy, float hiz) {
  const float dx = hd_max(hd_max(lox - p.x, p.x - hix), 0.f);
  const float dy = hd_max(hd_max(loy - p.y, p.y - hiy), 0.f);
  const float dz = hd_max(hd_max(loz - p.z, p.z - hiz), 0.f);
  return dx * dx + dy * dy + dz * dz;
}

// Calls f(k) for every triangle slot k of a leaf whose box lies within `reach`
// of p (boxes are closed: a box exactly at `reach` is visited). A superset of
// the triangles within `reach`; the caller tests distance.
// The walk descends through inner nodes until it holds a leaf, and only then
// tests the leaf's triangles (Aila and Laine's "while-while"): the threads of
// a GPU warp reach their leaves' loops together instead of idling while one
// of them tests triangles. The stack holds inner nodes and leaves, at most
// one entry per level.
template <class F>
COLLIDO_HD COLLIDO_FORCEINLINE void bvh_for_each_near(const BvhWideNode* nodes, Vec3f p,
                                                      float reach, F&& f) {
  uint32_t stack[kBvhWideStackDepth];
  int top = 0;
  const float reach2 = reach * reach;
  uint32_t item = 0;  // the root, an inner node
  for (;;) {
    while (!(item & kBvhLeafBit)) {
      const BvhWideNode n = nodes[item];
      uint32_t next = 0;
      bool have = false;  // next holds the first child in reach
#if defined(__CUDA_ARCH__)
#pragma unroll
#endif
      for (int c = 0; c < 4; ++c) {
        if (box_dist2(p, n.lo_x[c], n.lo_y[c], n.lo_z[c], n.hi_x[c], n.hi_y[c], n.hi_z[c]) > reach2)
          continue;
        if (!have)
          next = n.child[c], have = true;
        else
          stack[top++] = n.child[c];
      }
      if (!have) {
        if (top == 0) return;
        next = stack[--top];
      }
      item = next;
    }
    const uint32_t first = (item & ~kBvhLeafBit) >> kBvhLeafCountBits;
    const uint32_t end = first + (item & (kBvhMaxLeaf - 1)) + 1;
    for (uint32_t k = first; k < end; ++k) f(k);
    if (top == 0) return;
    item = stack[--top];
  }
}

// A 30-bit Morton code of p's place in a box (10 bits an axis): particles
// sorted by it lie along a space-filling curve, so neighbouring threads walk
// the same nodes. Points outside the box, or not finite, get kInvalidMorton.
inline constexpr uint32_t kInvalidMorton = 0xFFFFFFFFu;
struct MortonFrame {
  Vec3f lo{0, 0, 0};
  float scale = 0;  // 1024 / the box's largest extent
  Vec3f hi{0, 0, 0};

  COLLIDO_HD COLLIDO_FORCEINLINE static uint32_t spread(uint32_t v) {
    v = (v | (v << 16)) & 0x030000FFu;
    v = (v | (v << 8)) & 0x0300F00Fu;
    v = (v | (v << 4)) & 0x030C30C3u;
    v = (v | (v << 2)) & 0x09249249u;
    return v;
  }
  COLLIDO_HD COLLIDO_FORCEINLINE uint32_t key(Vec3f p) const {
    if (!(p.x >= lo.x && p.y >= lo.y && p.z >= lo.z && p.x <= hi.x && p.y <= hi.y && p.z <= hi.z))
      return kInvalidMorton;
    auto q = [&](float v, float o) {
      const float t = (v - o) * scale;
      return uint32_t(t < 1023.f ? t : 1023.f);
    };
    return (spread(q(p.x, lo.x)) << 2) | (spread(q(p.y, lo.y)) << 1) | spread(q(p.z, lo.z));
  }
};

// The tree over a wall's triangles, in the wall's local frame.
struct BvhBuild {
  std::vector<BvhNode> nodes;      // binary, nodes[0] is the root
  std::vector<BvhWideNode> wide;   // the same tree four-wide, wide[0] is the root: what walks read
  std::vector<uint32_t> order;     // triangle slot -> mesh triangle index
  int depth = 0;                   // levels of the deepest leaf (binary)
  int wide_depth = 0;              // the same in the wide tree
  uint32_t leaves = 0;
};

// Builds the tree over `mesh` shifted by -origin. Splits minimise the
// expected work of a query of radius `reach` (binned surface-area heuristic,
// with each box's measure taken as the volume a sphere of that radius sweeps
// around it, Steiner's formula, since a particle visits a node when its centre
// lies within `reach` of the box). Boxes are rounded outward to float and
// grown by `margin`, so a float walk never misses a triangle within `reach`.
// Subtrees below the top levels are built on `pool` (nullptr: default_pool());
// the tree does not depend on the threads.
BvhBuild build_bvh(const TriangleMesh& mesh, Vec3d origin, double reach, double margin,
                   ThreadPool* pool = nullptr);

}  // namespace collido::sim
