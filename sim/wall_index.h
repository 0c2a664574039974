// The wall as the engine's traversals read it, prepared once per run and
// shared by detection (sim/detect_pipeline.h) and dynamics
// (sim/dynamics_pipeline.h): either the ORIGINAL triangles binned into every
// grid cell they come within r_max of (`bin`), or the paper's divided pieces
// hashed by bounding-sphere centre and sorted by cell (Table 2).
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include "sim/bvh.h"
#include "sim/contact_force.h"
#include "sim/detect.h"
#include "sim/divide.h"
#include "sim/exact_distance.h"
#include "sim/grid.h"
#include "sim/narrow_phase.h"
#include "sim/octree.h"

namespace collido::sim {

// The most cells a grid may have (their 64-bit keys, x + nx (y + ny z), stay unique).
inline constexpr double kMaxGridCells = 4e18;
// The most cells a divided wall's particle looks out in each direction.
inline constexpr double kMaxReach = 8;

// Neighbour cells a particle traversal visits: reach cells in each direction.
inline int neighbour_reach(double search_radius, double cell) {
  // Contacts need centre distances strictly below search_radius; a distance
  // of exactly one cell still lands in the adjacent cell, hence the slack.
  int k = static_cast<int>(std::ceil(search_radius / cell - 1e-6));
  return std::max(k, 1);
}

// Local-frame grid over [lo, hi] with the given cell edge; hashed when too many cells.
inline GridSpec make_grid(Vec3d lo, Vec3d hi, double cell, uint64_t max_dense_cells,
                          uint64_t elements, uint64_t* cells_out) {
  GridSpec g;
  g.origin = cast3<float>(lo);
  g.cell = static_cast<float>(cell);
  g.inv_cell = static_cast<float>(1.0 / cell);
  const Vec3d ext = hi - lo;
  auto dim = [&](double e) {
    double n = std::floor(e / cell) + 1;
    return static_cast<int>(std::min(n, 1e9));
  };
  g.nx = dim(ext.x), g.ny = dim(ext.y), g.nz = dim(ext.z);
  // In double first: three dimensions of up to 1e9 overflow 64 bits, and a
  // count that wrapped to a few would have made a dense table far too small.
  const double product = double(g.nx) * double(g.ny) * double(g.nz);
  const uint64_t cells =
      product < 1.8e19 ? uint64_t(g.nx) * uint64_t(g.ny) * uint64_t(g.nz) : UINT64_MAX;
  *cells_out = cells;
  if (cells <= max_dense_cells) {
    g.buckets = static_cast<uint32_t>(cells);
    g.hashed = 0;
  } else {
    uint64_t want = std::max<uint64_t>(2 * elements, 1u << 16);
    uint64_t b = 1;
    while (b < want && b < (1ull << 31)) b <<= 1;
    g.buckets = static_cast<uint32_t>(b);
    g.hashed = 1;
  }
  return g;
}

// The bin method's grid, in the wall's local frame (origin at its box's centre):
// cells of edge `cell` over the box grown by r_max and a cell, hashed past
// max_dense_cells; a triangle goes into every cell that its distance r_max
// reaches, with `grow` padded for float rounding so no contact is missed: the
// particle's cell, the cells' centres and the triangles' corners are floats in
// the local frame, each off by up to about 6e-8 of the largest coordinate, so
// the pad holds a millionth of that beside the radius's own (padded by the
// radius and the cell alone, a wall 10^4 radii across could leave a particle
// that touched by a hair at a cell's face without that triangle in its list).
// Shared by the preparation and by the footprint a run is priced with.
struct BinLayout {
  GridSpec grid;
  double grow = 0;
  uint64_t cells = 0;
};
inline BinLayout bin_layout(const Bounds3d& box, Vec3d origin, double r_max, double cell,
                            uint64_t max_dense_cells, size_t triangles, size_t particles) {
  BinLayout b;
  const double coordinate =
      std::max({std::fabs(box.lo.x - origin.x), std::fabs(box.hi.x - origin.x),
                std::fabs(box.lo.y - origin.y), std::fabs(box.hi.y - origin.y),
                std::fabs(box.lo.z - origin.z), std::fabs(box.hi.z - origin.z)}) +
      2 * (r_max + cell);
  b.grow = r_max * (1 + 1e-5) + 1e-6 * cell + 1e-6 * coordinate;
  const Vec3d pad{b.grow + cell, b.grow + cell, b.grow + cell};
  b.grid = make_grid(box.lo - origin - pad, box.hi - origin + pad, cell, max_dense_cells,
                     4 * uint64_t(triangles) + particles, &b.cells);
  return b;
}

// The cells [lo, hi] (inclusive, per axis) of the box around triangle t grown by `grow`.
COLLIDO_HD inline void bin_cell_range(const GridSpec& g, const TriangleF& t, float grow, int lo[3],
                                      int hi[3]) {
  const float tl[3] = {fminf(t.a.x, fminf(t.b.x, t.c.x)) - grow,
                       fminf(t.a.y, fminf(t.b.y, t.c.y)) - grow,
                       fminf(t.a.z, fminf(t.b.z, t.c.z)) - grow};
  const float th[3] = {fmaxf(t.a.x, fmaxf(t.b.x, t.c.x)) + grow,
                       fmaxf(t.a.y, fmaxf(t.b.y, t.c.y)) + grow,
                       fmaxf(t.a.z, fmaxf(t.b.z, t.c.z)) + grow};
  const float o[3] = {g.origin.x, g.origin.y, g.origin.z};
  const int n[3] = {g.nx, g.ny, g.nz};
  auto clampi = [](int v, int n) { return v < 0 ? 0 : (v >= n ? n - 1 : v); };
  for (int a = 0; a < 3; ++a) {
    lo[a] = clampi(int(floorf((tl[a] - o[a]) * g.inv_cell)), n[a]);
    hi[a] = clampi(int(floorf((th[a] - o[a]) * g.inv_cell)), n[a]);
  }
}

// Calls f(linear cell) for each cell whose box grown by `grow` overlaps the triangle.
template <class F>
COLLIDO_HD void for_each_bin_cell(const GridSpec& g, const TriangleF& t, float grow, F&& f) {
  int lo[3], hi[3];
  bin_cell_range(g, t, grow, lo, hi);
  const float h = 0.5f * g.cell + grow;
  for (int z = lo[2]; z <= hi[2]; ++z)
    for (int y = lo[1]; y <= hi[1]; ++y)
      for (int x = lo[0]; x <= hi[0]; ++x) {
        const Vec3f centre{g.origin.x + (x + 0.5f) * g.cell, g.origin.y + (y + 0.5f) * g.cell,
                           g.origin.z + (z + 0.5f) * g.cell};
        if (triangle_box_overlap(t.a, t.b, t.c, centre, Vec3f{h, h, h})) f(g.linear(x, y, z));
      }
}

// What a kernel needs to walk the wall near a point; plain pointers, copied by value.
struct WallView {
  GridSpec g;
  int reach = 0;
  float piece_search = 0;  // pieces: how far a piece's sphere centre may lie from a touching centre
  bool bin = true;
  const BvhWideNode* bvh = nullptr;  // bvh: the tree (the other layouts: null)
  float bvh_reach = 0;           // bvh: how far from a centre boxes are visited
  const PlanarTriangle* tris = nullptr;
  const uint32_t* original = nullptr;  // pieces: original triangle (mesh index) of each piece
  const uint64_t* tri_cell = nullptr;  // pieces: cell of each piece
  const uint32_t* tri_start = nullptr;
  const uint32_t* tri_end = nullptr;
  const uint32_t* bin_start = nullptr;  // bin: CSR over buckets
  const uint32_t* bin_tri = nullptr;
  const uint64_t* bin_cell = nullptr;

  // Calls f(k, original mesh index) for every triangle or piece k (an index
  // into the prepared arrays) that may lie within r_max of p: a superset of
  // the contacts, the caller tests distance.
  template <class F>
  COLLIDO_HD COLLIDO_FORCEINLINE void for_each_candidate(Vec3f p, F&& f) const {
    if (bvh) {
      bvh_for_each_near(bvh, p, bvh_reach, [&](uint32_t k) { f(k, original[k]); });
      return;
    }
    int x = 0, y = 0, z = 0;
    if (!g.cell_of(p, x, y, z)) return;
    if (bin) {
      const uint64_t l = g.linear(x, y, z);
      const uint32_t b = g.bucket(l);
      for (uint32_t k = bin_start[b], e = bin_start[b + 1]; k < e; ++k) {
        if (g.hashed && bin_cell[k] != l) continue;
        const uint32_t t = bin_tri[k];
        f(t, t);
      }
      return;
    }
    // Pieces: those of the cells the cube of half-side piece_search around p
    // overlaps (8 to 27 of the 27 around its cell, with the usual cell of
    // 2 r_max), the cube grown by far more than float's rounding of p and of
    // the pieces' centres when they were binned.
    const float pad = 1e-6f * (hd_max(hd_abs(p.x), hd_max(hd_abs(p.y), hd_abs(p.z))) +
                               hd_max(hd_abs(g.origin.x), hd_max(hd_abs(g.origin.y), hd_abs(g.origin.z))) +
                               g.cell);
    int lo[3], hi[3];
    if (cube_cells(p, piece_search + pad, lo, hi))
      for_each_listed(lo, hi, 0, [&](uint32_t k) { f(k, original[k]); });
  }

  // The original mesh index of prepared triangle or piece k.
  COLLIDO_HD COLLIDO_FORCEINLINE uint32_t original_of(uint32_t k) const {
    return bin ? k : original[k];
  }

  // Calls f(k) for every k that for_each_candidate gives at some point within
  // e of p (0 <= e < one cell); f may see a k more than once. A grid's
  // candidates depend only on the point's cell, and the cells of the points in
  // the cube [p - e, p + e] are those between its corners' (float rounding is
  // monotonic); the tree is walked with its reach grown by e.
  template <class F>
  COLLIDO_HD void for_each_candidate_near(Vec3f p, float e, F&& f) const {
    if (bvh) {
      bvh_for_each_near(bvh, p, bvh_reach + e, f);
      return;
    }
    int lo[3], hi[3];
    if (!cube_cells(p, e, lo, hi)) return;
    for_each_listed(lo, hi, bin ? 0 : reach, f);  // pieces: the cells within reach of each of those
  }

  // The cells [lo, hi] of the grid that the cube [p - e, p + e] overlaps,
  // clamped to the grid; false when the cube misses it.
  COLLIDO_HD COLLIDO_FORCEINLINE bool cube_cells(Vec3f p, float e, int lo[3], int hi[3]) const {
    const float pc[3] = {p.x, p.y, p.z}, oc[3] = {g.origin.x, g.origin.y, g.origin.z};
    const int n[3] = {g.nx, g.ny, g.nz};
    for (int a = 0; a < 3; ++a) {
      const float f0 = (pc[a] - e - oc[a]) * g.inv_cell, f1 = (pc[a] + e - oc[a]) * g.inv_cell;
      if (!(f1 >= 0.f) || !(f0 < float(n[a]))) return false;
      lo[a] = f0 < 0.f ? 0 : (int(f0) < n[a] ? int(f0) : n[a] - 1);
      hi[a] = int(f1) < n[a] ? int(f1) : n[a] - 1;
    }
    return true;
  }

  // Calls f(k) for each triangle (bin) or piece listed in the cells [lo, hi]
  // grown by `grow` cells each way, inside the grid.
  template <class F>
  COLLIDO_HD COLLIDO_FORCEINLINE void for_each_listed(const int lo[3], const int hi[3], int grow,
                                                      F&& f) const {
    for (int z = lo[2] - grow; z <= hi[2] + grow; ++z)
      for (int y = lo[1] - grow; y <= hi[1] + grow; ++y)
        for (int x = lo[0] - grow; x <= hi[0] + grow; ++x) {
          if (!g.inside(x, y, z)) continue;
          const uint64_t l = g.linear(x, y, z);
          const uint32_t b = g.bucket(l);
          if (bin) {
            for (uint32_t k = bin_start[b], end = bin_start[b + 1]; k < end; ++k)
              if (!g.hashed || bin_cell[k] == l) f(bin_tri[k]);
          } else {
            for (uint32_t k = tri_start[b], end = tri_end[b]; k < end; ++k)
              if (!g.hashed || tri_cell[k] == l) f(k);
          }
        }
  }
};

template <class B>
class WallIndex {
  template <class T>
  using Buf = typename B::template Buffer<T>;

 public:
  // Prepares `mesh` for particles of radius <= r_max with cells of edge `cell`
  // (world units); `particles` sizes a hashed table. Fills the wall part of *info.
  // double_triangles: also keep the triangles in double (tris_d) for contact forces.
  Status prepare(B& backend, const TriangleMesh& mesh, Method method, double r_max, double cell,
                 uint64_t max_dense_cells, size_t particles, PrepareInfo* info,
                 bool double_triangles = false) {
    double_ = double_triangles;
    method_ = method;
    r_max_ = r_max;
    max_dense_cells_ = max_dense_cells;
    particles_ = particles;
    const Bounds3d box = mesh_bounds(mesh);
    // Grids whose cells a 64-bit key cannot number (a few hundred thousand
    // cells per axis of a sparse wall reach it) are refused here, for
    // detection and dynamics alike.
    if (method != Method::kBvh) {
      const Vec3d ext = box.extent();
      const double span = 2 * (r_max + 2 * cell);
      const double cells = (ext.x / cell + span / cell + 1) * (ext.y / cell + span / cell + 1) *
                           (ext.z / cell + span / cell + 1);
      if (!(cells < kMaxGridCells))
        return invalid_argument("a grid length of " + std::to_string(cell) + " makes " +
                                std::to_string(cells) + " cells over this wall's box, more than " +
                                std::to_string(kMaxGridCells) + "; use a longer grid length");
    }
    // The local frame's origin at the wall's centre keeps float precision for
    // walls far from the world origin (coordinates near 1e4 with r = 1).
    origin = box.center();
    band_scale = wall_band_scale(mesh, origin);
    info->triangles_original = mesh.triangles.size();
    if (method == Method::kBvh) return prepare_bvh(backend, mesh, box, info);
    if (method == Method::kOctree) return prepare_octree(backend, mesh, box, cell, info);
    return method == Method::kBin ? prepare_bin(backend, mesh, box, cell, info)
                                  : prepare_pieces(backend, mesh, cell, info);
  }

  WallView view() const {
    WallView v;
    v.g = grid;
    v.reach = reach;
    v.piece_search = piece_search;
    v.bin = method_ == Method::kBin;
    v.tris = tris.data();
    if (method_ == Method::kBvh) {
      v.bin = false;
      v.bvh = bvh_nodes.data(), v.bvh_reach = bvh_reach, v.original = tri_original.data();
    } else if (v.bin) {
      v.bin_start = bin_start.data(), v.bin_tri = bin_tri.data(), v.bin_cell = bin_cell.data();
    } else {
      v.original = tri_original.data(), v.tri_cell = tri_cell.data();
      v.tri_start = tri_start.data(), v.tri_end = tri_end.data();
    }
    return v;
  }

  // nvcc's extended lambdas may not live in private member functions, so the
  // preparation steps are public; callers use prepare() and view().
  Status prepare_pieces(B& backend, const TriangleMesh& mesh, double cell, PrepareInfo* info) {
    const DivisionMethod dm = division_of(method_);
    // Division is bounded by area / r_max^2; refuse absurd requests before allocating.
    const double estimate = 8 * mesh_area(mesh) / (r_max_ * r_max_) + mesh.triangles.size();
    if (estimate > 4e8)
      return invalid_argument("dividing this wall for r_max = " + std::to_string(r_max_) +
                              " would make about " + std::to_string(estimate) +
                              " triangles; use --method bin");
    DividedMesh dv = divide(mesh, dm, r_max_);
    info->triangles_used = dv.pieces.size();
    info->max_sphere_radius = dv.max_sphere_radius;
    info->area_error = division_area_error(mesh, dv);
    const size_t m = dv.pieces.size();
    // Pad the reach for float rounding of centres and positions.
    const double search = (r_max_ + dv.max_sphere_radius) * (1 + 1e-6) + 1e-6 * r_max_;
    // Each particle visits (2 reach + 1)^3 cells: a grid length far below the
    // radius made that hundreds of thousands a step (and past int, wrong).
    if (!(search / cell <= kMaxReach))
      return invalid_argument(
          "a grid length of " + std::to_string(cell) + " is more than " +
          std::to_string(kMaxReach) + " times below the pieces' reach (" + std::to_string(search) +
          "): each particle would visit too many cells; use a longer grid length");
    reach = neighbour_reach(search, cell);
    piece_search = static_cast<float>(search);
    info->reach = reach;

    Bounds3d cb;
    for (const auto& c : dv.sphere_centre) cb.grow(c - origin);
    const double pad = (reach + 1) * cell;
    grid = make_grid(cb.lo - Vec3d{pad, pad, pad}, cb.hi + Vec3d{pad, pad, pad}, cell,
                     max_dense_cells_, m + particles_, &info->cells);
    info->buckets = grid.buckets;
    info->hashed = grid.hashed != 0;

    // Hash the pieces by bounding-sphere centre and sort them by cell (paper Table 2).
    std::vector<PlanarTriangle> host_tris(m);
    std::vector<PlanarTriangleD> host_tris_d(double_ ? m : 0);
    std::vector<uint32_t> key(m), idx(m);
    std::vector<uint64_t> cellkey(m);
    for (size_t i = 0; i < m; ++i) {
      const auto& p = dv.pieces[i];
      host_tris[i] = make_planar(p[0], p[1], p[2], origin);
      if (double_) host_tris_d[i] = make_planar<double>(p[0], p[1], p[2], origin);
      int x = 0, y = 0, z = 0;
      Vec3f c = cast3<float>(dv.sphere_centre[i] - origin);
      if (!grid.cell_of(c, x, y, z))
        return Status(ErrorCode::kBackend, "piece centre outside its grid");
      cellkey[i] = grid.linear(x, y, z);
      key[i] = grid.bucket(cellkey[i]);
      idx[i] = static_cast<uint32_t>(i);
    }
    std::stable_sort(idx.begin(), idx.end(),
                     [&](uint32_t a, uint32_t b) { return key[a] < key[b]; });
    std::vector<PlanarTriangle> tris_sorted(m);
    std::vector<PlanarTriangleD> tris_d_sorted(double_ ? m : 0);
    std::vector<uint32_t> orig_sorted(m);
    std::vector<uint64_t> cell_sorted(m);
    std::vector<uint32_t> start(grid.buckets, 0), end(grid.buckets, 0);
    for (size_t j = 0; j < m; ++j) {
      tris_sorted[j] = host_tris[idx[j]];
      if (double_) tris_d_sorted[j] = host_tris_d[idx[j]];
      orig_sorted[j] = dv.original[idx[j]];
      cell_sorted[j] = cellkey[idx[j]];
      const uint32_t k = key[idx[j]];
      if (j == 0 || key[idx[j - 1]] != k) start[k] = static_cast<uint32_t>(j);
      end[k] = static_cast<uint32_t>(j + 1);
    }
    upload(backend, tris, tris_sorted);
    if (double_) upload(backend, tris_d, tris_d_sorted);
    upload(backend, tri_original, orig_sorted);
    upload(backend, tri_cell, cell_sorted);
    upload(backend, tri_start, start);
    upload(backend, tri_end, end);
    return Status::ok();
  }

  // bvh: the tree over the original triangles (sim/bvh.h), built on the host;
  // the triangles stored in leaf order with their mesh index. A grid over the
  // wall's box (cells of 2 r_max) is kept only to say where particles may
  // touch: the Morton frame that orders a frame's particles covers it.
  Status prepare_bvh(B& backend, const TriangleMesh& mesh, const Bounds3d& box, PrepareInfo* info) {
    const size_t m = mesh.triangles.size();
    if (m > kBvhMaxTriangles)
      return invalid_argument("the bvh method holds at most " + std::to_string(kBvhMaxTriangles) +
                              " triangles; this wall has " + std::to_string(m));
    info->triangles_used = m;
    reach = 0;
    // Boxes grow by far more than float's rounding of a box distance in the
    // local frame, and queries reach past r_max by far more than twice float's
    // error band of the narrow phase there (sim/exact_distance.h: 8 ulps of
    // the coordinates and the wall's scale), so the walk never loses a pair
    // the decision would take.
    const Vec3d ext = box.extent();
    const double size = std::fabs(ext.x) + std::fabs(ext.y) + std::fabs(ext.z) + r_max_ +
                        band_scale;
    const double margin = 1e-6 * size;
    bvh_reach = static_cast<float>(r_max_ * (1 + 1e-5) + 1e-5 * size);
    BvhBuild built = build_bvh(mesh, origin, r_max_, margin);
    info->bvh_nodes = built.wide.size();
    info->bvh_depth = built.wide_depth;
    upload_in_order(backend, mesh, built.order);
    upload(backend, bvh_nodes, built.wide);
    // Particles farther than the reach from the wall's box touch nothing.
    const double pad = bvh_reach + margin;
    morton.lo = cast3<float>(box.lo - origin - Vec3d{pad, pad, pad});
    morton.hi = cast3<float>(box.hi - origin + Vec3d{pad, pad, pad});
    const Vec3f e = morton.hi - morton.lo;
    morton.scale = 1024.f / hd_max(hd_max(e.x, e.y), hd_max(e.z, 1e-30f));
    info->cells = 0;
    info->grid_length = 0;  // no grid
    return Status::ok();
  }

  // bin's grid over the wall's m triangles (bin and octree), said in *info.
  BinLayout lay_bin_grid(const Bounds3d& box, double cell, size_t m, PrepareInfo* info) {
    info->triangles_used = m;
    reach = 0;
    const BinLayout layout = bin_layout(box, origin, r_max_, cell, max_dense_cells_, m, particles_);
    grid = layout.grid;
    info->cells = layout.cells;
    info->buckets = grid.buckets;
    info->hashed = grid.hashed != 0;
    return layout;
  }

  // octree: bin's grid (the same cells and pad for float rounding), its cells
  // split where triangles crowd (sim/octree.h), built on the host; the
  // triangles in the lists' slots (sim/octree.h, pack_octree_lists).
  Status prepare_octree(B& backend, const TriangleMesh& mesh, const Bounds3d& box, double cell,
                        PrepareInfo* info) {
    const size_t m = mesh.triangles.size();
    const BinLayout layout = lay_bin_grid(box, cell, m, info);
    const OctreeBuild built = build_octree(mesh, origin, grid, layout.grow);
    // The device's list words are numbered in 32 bits, and a wide leaf takes two a slot.
    if (built.leaf_tri.size() >= (1ull << 30))
      return invalid_argument("the octree method would store " +
                              std::to_string(built.leaf_tri.size()) +
                              " (leaf, triangle) pairs; raise --grid-length");
    // The triangles in the lists' slots (along a Morton curve), each slot's
    // mesh index beside them, as the tree keeps its own order.
    const OctreeLists lists = pack_octree_lists(mesh, built);
    upload_in_order(backend, mesh, lists.order);
    info->octree_leaves = built.leaves();
    info->octree_entries = built.leaf_tri.size();
    info->octree_splits = built.splits;
    info->octree_wide_entries = lists.wide_entries;
    info->octree_long_leaves = built.long_leaves;
    oct_long_leaves = built.long_leaves;
    if (grid.hashed) {
      grid.buckets = built.buckets;  // the octree's own table (the grid serves no other method)
      info->buckets = grid.buckets;
      upload(backend, oct_cell_start, built.cell_start);
      upload(backend, oct_cell_key, built.cell_key);
    } else {
      upload(backend, oct_cell_word, built.cell_word);
    }
    upload(backend, oct_cell_node, built.cell_node);
    upload(backend, oct_inner, built.inner);
    upload(backend, oct_leaf_start, lists.leaf_start);
    upload(backend, oct_leaf_base, lists.leaf_base);
    upload(backend, oct_leaf_entry, lists.leaf_entry);
    return Status::ok();
  }

  OctreeView octree_view() const {
    OctreeView o;
    o.grid = grid;
    o.cell_word = oct_cell_word.data();
    o.cell_start = oct_cell_start.data(), o.cell_key = oct_cell_key.data();
    o.cell_node = oct_cell_node.data(), o.inner = oct_inner.data();
    o.leaf_start = oct_leaf_start.data(), o.leaf_base = oct_leaf_base.data();
    o.leaf_entry = oct_leaf_entry.data();
    o.long_leaves = oct_long_leaves;
    return o;
  }

  Status prepare_bin(B& backend, const TriangleMesh& mesh, const Bounds3d& box, double cell,
                     PrepareInfo* info) {
    const size_t m = mesh.triangles.size();
    const BinLayout layout = lay_bin_grid(box, cell, m, info);
    const double grow = layout.grow;

    std::vector<TriangleF> host_corners(m);
    std::vector<PlanarTriangle> host_tris(m);
    std::vector<PlanarTriangleD> host_tris_d(double_ ? m : 0);
    for (size_t t = 0; t < m; ++t) {
      host_corners[t] = {cast3<float>(mesh.corner(t, 0) - origin),
                         cast3<float>(mesh.corner(t, 1) - origin),
                         cast3<float>(mesh.corner(t, 2) - origin)};
      set_planar(mesh, t, t, host_tris, host_tris_d);
    }
    upload(backend, tris, host_tris);
    if (double_) upload(backend, tris_d, host_tris_d);
    upload(backend, corners, host_corners);

    // CSR build on the backend: count (cell, triangle) overlaps, scan, fill.
    Buf<uint32_t> bin_count;
    backend.resize(bin_count, size_t(grid.buckets) + 1);
    backend.fill(bin_count.data(), size_t(grid.buckets) + 1, 0u);
    const GridSpec g = grid;
    const TriangleF* T = corners.data();
    const float fgrow = static_cast<float>(grow);
    uint32_t* count = bin_count.data();
    backend.parallel_for(m, [=] COLLIDO_HD(uint32_t t) {
      for_each_bin_cell(g, T[t], fgrow,
                        [&](uint64_t l) { atomic_add_u32(&count[g.bucket(l)], 1u); });
    });
    const uint64_t total = backend.exclusive_scan(count, size_t(grid.buckets) + 1);
    if (total > (1ull << 31))
      return invalid_argument("the bin method would store " + std::to_string(total) +
                              " (cell, triangle) pairs; raise --grid-length");
    info->bin_entries = total;
    backend.resize(bin_start, size_t(grid.buckets) + 1);
    backend.copy(bin_start.data(), count, (size_t(grid.buckets) + 1) * sizeof(uint32_t));
    backend.resize(bin_tri, std::max<uint64_t>(total, 1));
    backend.resize(bin_cell, std::max<uint64_t>(total, 1));
    uint32_t* cursor = count;  // reuse the scanned counts as fill cursors
    uint32_t* bt = bin_tri.data();
    uint64_t* bc = bin_cell.data();
    backend.parallel_for(m, [=] COLLIDO_HD(uint32_t t) {
      for_each_bin_cell(g, T[t], fgrow, [&](uint64_t l) {
        const uint32_t slot = atomic_add_u32(&cursor[g.bucket(l)], 1u);
        bt[slot] = t;
        bc[slot] = l;
      });
    });
    // Fixed order inside each cell (by triangle) makes runs repeatable.
    backend.sort_segments(bin_tri.data(), bin_cell.data(), bin_start.data(), grid.buckets, total);
    return Status::ok();
  }

  // Mesh triangle t in narrow-phase form at `slot`, and in double too when kept.
  void set_planar(const TriangleMesh& mesh, size_t t, size_t slot, std::vector<PlanarTriangle>& f,
                  std::vector<PlanarTriangleD>& d) const {
    const Vec3d a = mesh.corner(t, 0), b = mesh.corner(t, 1), c = mesh.corner(t, 2);
    f[slot] = make_planar(a, b, c, origin);
    if (double_) d[slot] = make_planar<double>(a, b, c, origin);
  }

  // The triangles in slots of the method's own order (slot -> mesh index),
  // and each slot's mesh index: the tree's and the octree's.
  void upload_in_order(B& backend, const TriangleMesh& mesh, const std::vector<uint32_t>& order) {
    const size_t m = order.size();
    std::vector<PlanarTriangle> host_tris(m);
    std::vector<PlanarTriangleD> host_tris_d(double_ ? m : 0);
    for (size_t k = 0; k < m; ++k) set_planar(mesh, order[k], k, host_tris, host_tris_d);
    upload(backend, tris, host_tris);
    if (double_) upload(backend, tris_d, host_tris_d);
    upload(backend, tri_original, order);
  }

  template <class T>
  static void upload(B& backend, Buf<T>& dst, const std::vector<T>& src) {
    backend.resize(dst, std::max<size_t>(src.size(), 1));
    if (!src.empty()) backend.to_device(dst.data(), src.data(), src.size() * sizeof(T));
  }

  GridSpec grid;
  int reach = 1;
  float piece_search = 0;  // pieces: r_max plus the largest piece's sphere, padded
  Vec3d origin{0, 0, 0};
  float band_scale = 0;  // the wall's wall_band_scale in this frame: sizes float's error band
  Buf<PlanarTriangle> tris;     // narrow-phase form
  Buf<PlanarTriangleD> tris_d;  // the same in double, for contact forces (when asked for)
  Buf<TriangleF> corners;       // bin preparation only
  Buf<uint32_t> tri_original, tri_start, tri_end;
  Buf<uint64_t> tri_cell;
  Buf<uint32_t> bin_start, bin_tri;
  Buf<uint64_t> bin_cell;
  Buf<BvhWideNode> bvh_nodes;  // the four-wide tree
  float bvh_reach = 0;
  MortonFrame morton;  // bvh: orders a frame's particles along the wall
  // octree (sim/octree.h): the listed top cells (dense: in words; hashed: by
  // bucket), the inner nodes, the leaves' lists
  Buf<OctreeWord> oct_cell_word;  // dense grids only
  Buf<uint32_t> oct_cell_start;   // hashed grids only
  Buf<uint64_t> oct_cell_key;     // hashed grids only
  Buf<uint32_t> oct_leaf_start, oct_leaf_base;
  Buf<uint16_t> oct_leaf_entry;
  uint32_t oct_long_leaves = 0;
  Buf<int32_t> oct_cell_node, oct_inner;
  uint32_t octree_leaves() const {
    return oct_leaf_start.size() ? static_cast<uint32_t>(oct_leaf_start.size() - 1) : 0u;
  }

 private:
  Method method_ = Method::kBin;
  bool double_ = false;
  double r_max_ = 0;
  uint64_t max_dense_cells_ = 0;
  size_t particles_ = 0;
};

}  // namespace collido::sim
