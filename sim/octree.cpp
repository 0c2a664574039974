#include "sim/octree.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <utility>

#include "sim/narrow_phase.h"
#include "sim/parallel.h"

namespace collido::sim {

namespace {

using Corners = std::array<Vec3d, 3>;

// Whether triangle c may come within `grow` of the cube at lo with side s:
// it meets the cube grown by `grow` on every side (thirteen separating axes),
// and its distance from the cube's centre is at most grow plus the
// half-diagonal (the grown cube's corners lie farther than `grow`).
bool near_cube(const Corners& c, Vec3d lo, double s, double grow) {
  const double h = 0.5 * s;
  const Vec3d centre{lo.x + h, lo.y + h, lo.z + h};
  if (!triangle_box_overlap<double>(c[0], c[1], c[2], centre, Vec3d{h + grow, h + grow, h + grow}))
    return false;
  const double reach = grow + h * std::sqrt(3.0);
  return point_triangle_dist2<double>(centre, c[0], c[1], c[2]) <= reach * reach;
}

// The nodes of some top cells, numbered from 0 within this part; merged
// into the whole build in the cells' order, so the result does not depend on
// how the cells were shared among threads.
struct Part {
  std::vector<int32_t> top;  // a node per top cell of the part
  std::vector<int32_t> inner;
  std::vector<uint32_t> leaf_start{0};
  std::vector<uint32_t> leaf_tri;
  uint64_t splits = 0;
  uint32_t longest = 0;

  // The node of the cube at lo, side s, `depth` levels below the top, which
  // lists `mine` (already tested against it).
  int32_t make(const std::vector<Corners>& tri, const std::vector<uint32_t>& mine, Vec3d lo,
               double s, int depth, double grow, uint32_t split_above, int max_depth) {
    if (mine.empty()) return kOctreeEmpty;
    if (mine.size() > split_above && depth < max_depth) {
      const uint32_t children = uint32_t(inner.size());
      inner.resize(inner.size() + 8, kOctreeEmpty);
      ++splits;
      const double half = 0.5 * s;
      std::vector<uint32_t> sub;
      for (int o = 0; o < 8; ++o) {
        const Vec3d at{lo.x + (o & 1) * half, lo.y + ((o >> 1) & 1) * half,
                       lo.z + ((o >> 2) & 1) * half};
        sub.clear();
        for (uint32_t t : mine)
          if (near_cube(tri[t], at, half, grow)) sub.push_back(t);
        const int32_t child = make(tri, sub, at, half, depth + 1, grow, split_above, max_depth);
        inner[children + uint32_t(o)] = child;
      }
      return octree_inner_node(children);
    }
    const int32_t leaf = int32_t(leaf_start.size() - 1);
    leaf_tri.insert(leaf_tri.end(), mine.begin(), mine.end());
    leaf_start.push_back(uint32_t(leaf_tri.size()));
    longest = std::max(longest, uint32_t(mine.size()));
    return leaf;
  }
};

// Sorts v on the pool: pieces sorted side by side, then merged two by two,
// round after round. v's elements must be unique (or equal ones alike), so
// the result does not depend on the pool's size.
template <class T>
void parallel_sort(std::vector<T>& v, ThreadPool& threads) {
  const size_t pieces =
      std::min<size_t>(2 * size_t(threads.size()), std::max<size_t>(v.size() / 4096, 1));
  std::vector<size_t> at(pieces + 1);
  for (size_t i = 0; i <= pieces; ++i) at[i] = v.size() * i / pieces;
  threads.run_items(pieces, [&](size_t i) { std::sort(v.begin() + at[i], v.begin() + at[i + 1]); });
  if (pieces == 1) return;
  std::vector<T> merged(v.size());
  for (size_t width = 1; width < pieces; width *= 2) {
    threads.run_items((pieces + 2 * width - 1) / (2 * width), [&](size_t g) {
      const size_t lo = at[g * 2 * width], mid = at[std::min(pieces, g * 2 * width + width)],
                   hi = at[std::min(pieces, g * 2 * width + 2 * width)];
      std::merge(v.begin() + lo, v.begin() + mid, v.begin() + mid, v.begin() + hi,
                 merged.begin() + lo);
    });
    v.swap(merged);
  }
}

// 21 bits of v spread to every third bit.
uint64_t spread3(uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffull;
  v = (v | v << 16) & 0x1f0000ff0000ffull;
  v = (v | v << 8) & 0x100f00f00f00f00full;
  v = (v | v << 4) & 0x10c30c30c30c30c3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}

}  // namespace

OctreeLists pack_octree_lists(const TriangleMesh& mesh, const OctreeBuild& built,
                              ThreadPool* pool) {
  OctreeLists out;
  ThreadPool& threads = pool ? *pool : default_pool();
  const size_t m = mesh.triangles.size();
  // The triangles' centres along a Morton curve over the mesh's box.
  const Bounds3d box = mesh_bounds(mesh);
  const Vec3d e = box.extent();
  const double scale = double((1u << 21) - 1) / std::max({e.x, e.y, e.z, 1e-300});
  std::vector<std::pair<uint64_t, uint32_t>> keyed(m);
  for (size_t t = 0; t < m; ++t) {
    const Vec3d c =
        (mesh.corner(t, 0) + mesh.corner(t, 1) + mesh.corner(t, 2)) * (1.0 / 3) - box.lo;
    auto bits = [&](double v) { return spread3(uint64_t(std::clamp(v * scale, 0.0, 2097151.0))); };
    keyed[t] = {bits(c.x) | bits(c.y) << 1 | bits(c.z) << 2, uint32_t(t)};
  }
  parallel_sort(keyed, threads);
  std::vector<uint32_t> slot(m);
  out.order.resize(m);
  for (size_t k = 0; k < m; ++k)
    out.order[k] = keyed[k].second, slot[keyed[k].second] = uint32_t(k);
  // Each leaf's lowest slot, or kOctreeWide where its slots lie farther
  // apart than 16 bits reach; then where its words begin (a wide leaf's
  // slots from an even word); then the words, the leaves shared among threads.
  const size_t leaves = built.leaves();
  out.leaf_base.resize(leaves);
  threads.run_chunks(leaves, 4096, [&](size_t begin, size_t end) {
    for (size_t l = begin; l < end; ++l) {
      uint32_t lo = ~0u, hi = 0;
      for (uint32_t k = built.leaf_start[l]; k < built.leaf_start[l + 1]; ++k)
        lo = std::min(lo, slot[built.leaf_tri[k]]), hi = std::max(hi, slot[built.leaf_tri[k]]);
      out.leaf_base[l] = lo > hi ? 0u : (hi - lo > kOctreeSpan ? kOctreeWide : lo);
    }
  });
  out.leaf_start.resize(leaves + 1);
  uint64_t words = 0;
  for (size_t l = 0; l < leaves; ++l) {
    const uint32_t n = built.leaf_start[l + 1] - built.leaf_start[l];
    const bool wide = out.leaf_base[l] == kOctreeWide;
    out.leaf_start[l] = uint32_t(words);
    words += wide ? (words % 2) + 2 * uint64_t(n) : n;
    if (wide) out.wide_entries += n;
  }
  out.leaf_start[leaves] = uint32_t(words);
  out.leaf_entry.assign(words, 0);
  threads.run_chunks(leaves, 4096, [&](size_t begin, size_t end) {
    std::vector<uint32_t> mine;
    for (size_t l = begin; l < end; ++l) {
      // A leaf's slots ascending, so neighbouring lanes read neighbouring
      // triangles (no difference measured on the H200 or here, 2026-11-30).
      mine.clear();
      for (uint32_t k = built.leaf_start[l]; k < built.leaf_start[l + 1]; ++k)
        mine.push_back(slot[built.leaf_tri[k]]);
      std::sort(mine.begin(), mine.end());
      const uint32_t base = out.leaf_base[l];
      if (base == kOctreeWide) {
        // As the device reads them back: a 32-bit slot from an even word.
        std::memcpy(&out.leaf_entry[(out.leaf_start[l] + 1) / 2 * 2], mine.data(),
                    mine.size() * sizeof(uint32_t));
      } else {
        uint16_t* to = &out.leaf_entry[out.leaf_start[l]];
        for (const uint32_t s : mine) *to++ = uint16_t(s - base);
      }
    }
  });
  return out;
}

OctreeBuild build_octree(const TriangleMesh& mesh, Vec3d origin, const GridSpec& grid, double grow,
                         uint32_t split_above, int max_depth, ThreadPool* pool) {
  OctreeBuild out;
  ThreadPool& threads = pool ? *pool : default_pool();
  max_depth = std::clamp(max_depth, 0, kOctreeDeepest);
  const size_t m = mesh.triangles.size();
  std::vector<Corners> tri(m);
  for (size_t t = 0; t < m; ++t)
    for (int k = 0; k < 3; ++k) tri[t][k] = mesh.corner(t, k) - origin;
  // The grid's cells in double, as the float grid places them.
  const Vec3d o{grid.origin.x, grid.origin.y, grid.origin.z};
  const double cell = grid.cell;
  const int n[3] = {grid.nx, grid.ny, grid.nz};

  // (top cell, triangle) for every cell a triangle's box grown by `grow`
  // reaches and the triangle may come within `grow` of; then in cell order.
  // Made in blocks of 256 triangles side by side, a block a claim (slivers
  // reach many cells), then copied into one array at each block's place.
  constexpr size_t kTrianglesABlock = 256;
  std::vector<std::vector<std::pair<uint64_t, uint32_t>>> blocks((m + kTrianglesABlock - 1) /
                                                                 kTrianglesABlock);
  threads.run_items(blocks.size(), [&](size_t b) {
    for (size_t t = b * kTrianglesABlock; t < std::min(m, (b + 1) * kTrianglesABlock); ++t) {
      int lo[3], hi[3];
      for (int a = 0; a < 3; ++a) {
        auto axis = [a](Vec3d v) { return a == 0 ? v.x : (a == 1 ? v.y : v.z); };
        double mn = axis(tri[t][0]), mx = mn;
        for (int k = 1; k < 3; ++k)
          mn = std::min(mn, axis(tri[t][k])), mx = std::max(mx, axis(tri[t][k]));
        const double oa = axis(o);
        lo[a] = std::clamp(int(std::floor((mn - grow - oa) / cell)), 0, n[a] - 1);
        hi[a] = std::clamp(int(std::floor((mx + grow - oa) / cell)), 0, n[a] - 1);
      }
      for (int z = lo[2]; z <= hi[2]; ++z)
        for (int y = lo[1]; y <= hi[1]; ++y)
          for (int x = lo[0]; x <= hi[0]; ++x)
            if (near_cube(tri[t], Vec3d{o.x + x * cell, o.y + y * cell, o.z + z * cell}, cell,
                          grow))
              blocks[b].push_back({grid.linear(x, y, z), uint32_t(t)});
    }
  });
  std::vector<size_t> block_at(blocks.size() + 1, 0);
  for (size_t b = 0; b < blocks.size(); ++b) block_at[b + 1] = block_at[b] + blocks[b].size();
  std::vector<std::pair<uint64_t, uint32_t>> pairs(block_at.back());
  threads.run_chunks(blocks.size(), 64, [&](size_t first, size_t last) {
    for (size_t b = first; b < last; ++b) {
      std::copy(blocks[b].begin(), blocks[b].end(), pairs.begin() + block_at[b]);
      std::vector<std::pair<uint64_t, uint32_t>>().swap(blocks[b]);
    }
  });
  parallel_sort(pairs, threads);

  // The listed top cells: where each one's run of pairs begins.
  std::vector<size_t> runs;
  for (size_t i = 0; i < pairs.size(); ++i)
    if (i == 0 || pairs[i].first != pairs[i - 1].first) runs.push_back(i);
  runs.push_back(pairs.size());
  const size_t cells = runs.size() - 1;
  // Each top cell's node, built in parts of consecutive cells on the pool, a
  // part a claim (the crowded cells lie side by side).
  constexpr size_t kCellsAPart = 16;
  std::vector<Part> parts((cells + kCellsAPart - 1) / kCellsAPart);
  threads.run_items(parts.size(), [&](size_t p) {
    std::vector<uint32_t> list;
    Part& part = parts[p];
    for (size_t c = p * kCellsAPart; c < std::min(cells, (p + 1) * kCellsAPart); ++c) {
      list.clear();
      for (size_t i = runs[c]; i < runs[c + 1]; ++i) list.push_back(pairs[i].second);
      int x = 0, y = 0, z = 0;
      grid.unlinear(pairs[runs[c]].first, x, y, z);
      const Vec3d lo{o.x + x * cell, o.y + y * cell, o.z + z * cell};
      part.top.push_back(part.make(tri, list, lo, cell, 0, grow, split_above, max_depth));
    }
  });
  // The parts in order, their nodes renumbered into the whole, the leaves
  // listing over kOctreeLongList numbered first, each kind in the parts'
  // order (neighbouring leaves share triangles): where each part's nodes, top
  // cells and leaves of each kind begin, then each part copied to its place
  // on the pool.
  struct Offsets {
    size_t inner = 0, top = 0;
    size_t leaf[2] = {0, 0}, entry[2] = {0, 0};  // [1]: the long lists', [0]: the others'
  };
  auto is_long = [](const Part& part, size_t l) {
    return part.leaf_start[l + 1] - part.leaf_start[l] > kOctreeLongList;
  };
  std::vector<Offsets> at(parts.size() + 1);
  for (size_t p = 0; p < parts.size(); ++p) {
    const Part& part = parts[p];
    Offsets& next = at[p + 1];
    next = at[p];
    next.inner += part.inner.size(), next.top += part.top.size();
    for (size_t l = 0; l + 1 < part.leaf_start.size(); ++l) {
      const bool longer = is_long(part, l);
      next.leaf[longer] += 1, next.entry[longer] += part.leaf_start[l + 1] - part.leaf_start[l];
    }
    out.splits += part.splits;
    out.longest = std::max(out.longest, part.longest);
  }
  const Offsets total = at.back();
  out.long_leaves = uint32_t(total.leaf[1]);
  for (Offsets& a : at)  // the other leaves after every long one
    a.leaf[0] += total.leaf[1], a.entry[0] += total.entry[1];
  out.inner.resize(total.inner);
  out.leaf_start.resize(total.leaf[0] + total.leaf[1] + 1);
  out.leaf_start.back() = uint32_t(total.entry[0] + total.entry[1]);
  out.leaf_tri.resize(out.leaf_start.back());
  std::vector<std::pair<uint64_t, int32_t>> tops(cells);  // (cell, node)
  threads.run_chunks(parts.size(), 1, [&](size_t first, size_t last) {
    std::vector<int32_t> leaf_of;  // a part's leaves' numbers in the whole
    for (size_t p = first; p < last; ++p) {
      Part& part = parts[p];
      Offsets a = at[p];
      leaf_of.resize(part.leaf_start.size() - 1);
      for (size_t l = 0; l < leaf_of.size(); ++l) {
        const bool longer = is_long(part, l);
        size_t &leaf = a.leaf[longer], &entry = a.entry[longer];
        leaf_of[l] = int32_t(leaf);
        out.leaf_start[leaf] = uint32_t(entry);
        std::copy(part.leaf_tri.begin() + part.leaf_start[l],
                  part.leaf_tri.begin() + part.leaf_start[l + 1], out.leaf_tri.begin() + entry);
        leaf += 1, entry += part.leaf_start[l + 1] - part.leaf_start[l];
      }
      auto renumber = [&](int32_t node) {
        return node >= 0 ? leaf_of[size_t(node)]
               : octree_is_inner(node)
                   ? octree_inner_node(octree_children(node) + uint32_t(a.inner))
                   : node;
      };
      for (size_t k = 0; k < part.inner.size(); ++k)
        out.inner[a.inner + k] = renumber(part.inner[k]);
      for (size_t k = 0; k < part.top.size(); ++k)
        tops[a.top + k] = {pairs[runs[a.top + k]].first, renumber(part.top[k])};
      part = Part{};  // copied: the tiling's parts hold 0.5 GB
    }
  });
  // The tops are in cell order (the pairs were sorted by cell, the parts
  // merged in order). A dense grid marks its listed cells in words of 32.
  if (!grid.hashed) {
    out.cell_word.resize(size_t((uint64_t(grid.buckets) + 31) / 32));
    for (const auto& top : tops) out.cell_word[top.first >> 5].bits |= 1u << (top.first & 31);
    uint32_t before = 0;
    for (OctreeWord& w : out.cell_word) {
      w.before = before;
      before += uint32_t(__builtin_popcount(w.bits));
    }
    for (const auto& top : tops) out.cell_node.push_back(top.second);
    return out;
  }
  // A hashed grid's table holds about one listed cell a bucket (bin's table
  // is sized for its entries: on the large icosphere 16.8 million buckets,
  // 67 MB, for 2.1 million listed cells); grouped by bucket (CSR).
  GridSpec table = grid;
  table.buckets = 1;
  while (table.buckets < tops.size() && table.buckets < (1u << 31)) table.buckets <<= 1;
  out.buckets = table.buckets;
  std::stable_sort(tops.begin(), tops.end(), [&](const auto& a, const auto& b) {
    return table.bucket(a.first) < table.bucket(b.first);
  });
  out.cell_start.assign(size_t(table.buckets) + 1, 0);
  for (const auto& top : tops) ++out.cell_start[table.bucket(top.first) + 1];
  for (size_t k = 1; k < out.cell_start.size(); ++k) out.cell_start[k] += out.cell_start[k - 1];
  out.cell_key.reserve(tops.size());
  out.cell_node.reserve(tops.size());
  for (const auto& [l, node] : tops) out.cell_key.push_back(l), out.cell_node.push_back(node);
  return out;
}

}  // namespace collido::sim
