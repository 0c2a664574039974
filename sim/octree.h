// The `octree` method's wall: a grid of cells (2 r_max by default) over the
// wall's box, each cell that lists more than kOctreeSplitAbove triangles split
// into eight, and those again, up to kOctreeMaxDepth levels. Every leaf lists
// the ORIGINAL triangles that come within r_max of some point of its box, so a
// particle tests its own leaf's list, once, as `bin` tests its cell's.
//
// Why: real CAD exports mix long slivers with tiny facets (areas over five
// decades). A uniform grid's cell over a patch of tiny facets lists hundreds
// of them, which every particle there tests; a tree adapts to the mesh but a
// particle's walk waits on a chain of dependent node reads. Here the cells
// shrink only where the triangles crowd, and a particle finds its leaf in one
// to three dependent reads. A detection frame groups the particles by leaf,
// so the threads of a warp read the same list (sim/detect_pipeline.h). A
// detection method for now: the dynamics' wall lists do not read it. Measured
// in docs/benchmarks.md ("The octree method").
#pragma once

#include <cstdint>
#include <vector>

#include "sim/grid.h"
#include "sim/hd.h"
#include "sim/mesh.h"

namespace collido::sim {

class ThreadPool;  // sim/parallel.h

// A node: >= 0 a leaf (an index into the leaves), kOctreeEmpty when nothing
// lies within reach of its box, <= -2 an inner node whose eight children are
// inner[octree_children(node) + octant], octant = x + 2 y + 4 z (0: lower half).
inline constexpr int32_t kOctreeEmpty = -1;
// A cell is split when it lists more triangles than this and is above the
// deepest level (docs/benchmarks.md: on the counter mesh, 16 and 2 levels
// gave the fastest frames of the settings tried).
inline constexpr uint32_t kOctreeSplitAbove = 16;
inline constexpr int kOctreeMaxDepth = 2;
inline constexpr int kOctreeDeepest = 4;  // the most levels any build may have
// Leaves listing more than this many triangles are numbered first (their
// particles then sort first, and a frame deals them out in chunks of their
// own: sim/detect_pipeline.h's octree_traversal).
inline constexpr uint32_t kOctreeLongList = 32;
// The pairs in float's error band a detector's first frame has room for
// (precision exact decides them in double after the float pass).
inline constexpr uint32_t kOctreeFirstDoubts = 1024;

// A leaf whose triangles lie more than 65,535 slots apart (the triangles in
// Morton order: 1.2 % of the large icosphere's entries, none of the counter
// mesh's) lists whole slots, two 16-bit words each, from an even word.
inline constexpr uint32_t kOctreeWide = 0xFFFFFFFFu;
inline constexpr uint32_t kOctreeSpan = 0xFFFFu;

COLLIDO_HD COLLIDO_FORCEINLINE bool octree_is_inner(int32_t node) {
  return node <= -2;
}
COLLIDO_HD COLLIDO_FORCEINLINE uint32_t octree_children(int32_t node) {
  return uint32_t(-(node + 2));
}
inline int32_t octree_inner_node(uint32_t children) {
  return -int32_t(children) - 2;
}

// A dense grid's top cells, 32 a word: which of them list something (bits)
// and how many listed cells come before the word's first (before), so a
// listed cell's node is cell_node[before + the set bits below its own]. Eight
// bytes per 32 cells where a start per cell took 128 (the counter mesh's
// tiling: 4.8 million cells, 19 MB -> 1.2 MB).
struct alignas(8) OctreeWord {
  uint32_t bits = 0, before = 0;
};

// What a kernel reads; plain pointers, copied by value.
struct OctreeView {
  GridSpec grid;  // the top cells; a hashed grid's buckets are the octree's own
  const OctreeWord* cell_word = nullptr;  // dense grids: (cells + 31) / 32 words
  const uint32_t* cell_start = nullptr;   // hashed grids: buckets + 1, each bucket's listed cells
  const uint64_t* cell_key = nullptr;     // hashed grids: their cell numbers
  const int32_t* cell_node = nullptr;     // the listed cells' nodes (dense: in cell order)
  const int32_t* inner = nullptr;         // eight children an inner node
  const uint32_t* leaf_start = nullptr;   // leaves + 1: each leaf's run of leaf_entry
  const uint32_t* leaf_base = nullptr;    // each leaf's first triangle slot, or kOctreeWide
  const uint16_t* leaf_entry = nullptr;   // slots above the leaf's base (wide: slots, 2 words each)
  uint32_t long_leaves = 0;               // leaves [0, long_leaves) list over kOctreeLongList

  // Leaf `leaf`'s list, and its k-th triangle slot.
  struct List {
    uint32_t start, count, base;
  };
  COLLIDO_HD COLLIDO_FORCEINLINE List list(uint32_t leaf) const {
    const uint32_t start = leaf_start[leaf], base = leaf_base[leaf];
    return {start, (leaf_start[leaf + 1] - start) >> (base == kOctreeWide), base};
  }
  COLLIDO_HD COLLIDO_FORCEINLINE uint32_t slot(const List& l, uint32_t k) const {
    // A wide run starts at its first even word (its length is 2 count, or one more).
    if (l.base == kOctreeWide)
      return reinterpret_cast<const uint32_t*>(leaf_entry)[(l.start + 1) / 2 + k];
    return l.base + leaf_entry[l.start + k];
  }

  // The node of top cell (x, y, z); kOctreeEmpty when it lists nothing.
  COLLIDO_HD COLLIDO_FORCEINLINE int32_t top(int x, int y, int z) const {
    const uint64_t l = grid.linear(x, y, z);
    if (!grid.hashed) {
      const OctreeWord w = cell_word[l >> 5];
      const uint32_t bit = uint32_t(l) & 31u;
      if (!((w.bits >> bit) & 1u)) return kOctreeEmpty;
      return cell_node[w.before + hd_popcount(w.bits & ((1u << bit) - 1u))];
    }
    const uint32_t b = grid.bucket(l);
    for (uint32_t k = cell_start[b], e = cell_start[b + 1]; k < e; ++k)
      if (cell_key[k] == l) return cell_node[k];
    return kOctreeEmpty;
  }

  // The leaf whose box holds p (as float rounds it), or kOctreeEmpty.
  COLLIDO_HD COLLIDO_FORCEINLINE int32_t leaf_of(Vec3f p) const {
    int x = 0, y = 0, z = 0;
    if (!grid.cell_of(p, x, y, z)) return kOctreeEmpty;
    int32_t node = top(x, y, z);
    if (!octree_is_inner(node)) return node;
    // p's place in its cell, in [0, 1) an axis (cell_of may have clamped it).
    auto frac = [](float f, int i) {
      const float u = f - float(i);
      return u < 0.f ? 0.f : (u < 1.f ? u : 0.99999994f);
    };
    float u = frac((p.x - grid.origin.x) * grid.inv_cell, x);
    float v = frac((p.y - grid.origin.y) * grid.inv_cell, y);
    float w = frac((p.z - grid.origin.z) * grid.inv_cell, z);
    do {
      u += u, v += v, w += w;
      const int ox = u >= 1.f, oy = v >= 1.f, oz = w >= 1.f;
      u -= float(ox), v -= float(oy), w -= float(oz);
      node = inner[octree_children(node) + uint32_t(ox + 2 * oy + 4 * oz)];
    } while (octree_is_inner(node));
    return node;
  }
};

// The structure as the host builds it (mesh triangle indices, local frame).
struct OctreeBuild {
  std::vector<OctreeWord> cell_word;  // dense grids
  uint32_t buckets = 0;              // hashed grids: the table's size, about a bucket a listed cell
  std::vector<uint32_t> cell_start;  // hashed grids: buckets + 1
  std::vector<uint64_t> cell_key;    // hashed grids
  std::vector<int32_t> cell_node;
  std::vector<int32_t> inner;
  std::vector<uint32_t> leaf_start{0};  // leaves + 1
  std::vector<uint32_t> leaf_tri;
  uint64_t splits = 0;       // inner nodes
  uint32_t longest = 0;      // the longest leaf list
  uint32_t long_leaves = 0;  // the leaves listing over kOctreeLongList, numbered first
  size_t leaves() const { return leaf_start.size() - 1; }
};

// The device's form of the leaves' lists: the triangles in slots along a
// Morton curve (neighbouring triangles in neighbouring slots), so a leaf's
// list is a base slot and 16-bit steps above it, half the bytes of mesh
// indices (the counter mesh: 44 -> 22 MB). The curve, not the file's order:
// a file's order may be anything (shuffled, every list would be wide); on
// the H200 the two draw level on the counter and its tiling, while on the
// CPU the counter's own order is faster (165 against 185 ms a frame), which
// says more about that file than about the curve (docs/benchmarks.md).
struct OctreeLists {
  std::vector<uint32_t> order;  // slot -> mesh triangle index
  std::vector<uint32_t> leaf_start{0};
  std::vector<uint32_t> leaf_base;
  std::vector<uint16_t> leaf_entry;
  uint64_t wide_entries = 0;  // listed by wide leaves
};
// The leaves are shared among `pool`'s threads (nullptr: default_pool()); the
// result does not depend on them.
OctreeLists pack_octree_lists(const TriangleMesh& mesh, const OctreeBuild& built,
                              ThreadPool* pool = nullptr);

// Builds the lists for `grid` (the wall's local frame, origin at `origin`):
// a leaf lists each triangle of `mesh` that comes within `grow` of its box
// (tested in double: the triangle against the box grown by `grow` a side,
// and its distance from the box's centre), so with `grow` at least r_max
// plus float's rounding of a particle's place (bin_layout's pad) no contact
// is lost. A cell is split while it lists more than `split_above` and lies
// above `max_depth` levels (at most kOctreeDeepest). The triangles and the
// top cells are shared among `pool`'s threads (nullptr: default_pool()); the
// build does not depend on them.
OctreeBuild build_octree(const TriangleMesh& mesh, Vec3d origin, const GridSpec& grid, double grow,
                         uint32_t split_above = kOctreeSplitAbove, int max_depth = kOctreeMaxDepth,
                         ThreadPool* pool = nullptr);

}  // namespace collido::sim
