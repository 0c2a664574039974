// The detection pipeline, written once and instantiated for each backend
// (sim/detect_cpu.cpp, sim/detect_cuda.cu). A backend B supplies buffers,
// parallel_for, scan, radix sort and copies; every loop body here is a
// COLLIDO_HD lambda that runs unchanged on CPU threads or GPU threads.
//
// Stages of a frame (paper Fig. 3): hash particles -> sort by cell -> cell
// start/end -> traversal (narrow phase) -> contacts deduplicated per
// (particle, original triangle). The `bin` method skips the first three in its
// particle traversal: every original triangle is stored in each cell it comes
// within r_max of, so a particle reads its own cell's list, once.
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <vector>

#include "sim/detect.h"
#include "sim/divide.h"
#include "sim/grid.h"
#include "sim/narrow_phase.h"

namespace collido::sim {

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
  const uint64_t cells = uint64_t(g.nx) * uint64_t(g.ny) * uint64_t(g.nz);
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

template <class B>
class GridDetector final : public Detector {
  template <class T>
  using Buf = typename B::template Buffer<T>;

 public:
  static Expected<std::unique_ptr<Detector>> make(const TriangleMesh& mesh, const DetectConfig& cfg,
                                                  size_t max_particles) {
    auto d = std::unique_ptr<GridDetector>(new GridDetector(cfg, max_particles));
    Status s = d->prepare(mesh);
    if (!s) return s;
    return std::unique_ptr<Detector>(std::move(d));
  }

  void set_frame_options(bool collect_contacts, bool time_stages) override {
    cfg_.collect_contacts = collect_contacts;
    cfg_.time_stages = time_stages;
  }
  const PrepareInfo& info() const override { return info_; }
  const DetectConfig& config() const override { return cfg_; }

  Status set_particles(const Particles& p) override {
    const size_t n = p.size();
    if (n > capacity_)
      return invalid_argument("frame has " + std::to_string(n) + " particles, detector was made for " +
                              std::to_string(capacity_));
    std::vector<PackedParticle>& host = staging_;
    host.resize(n);
    const float rmax = static_cast<float>(cfg_.r_max);
    for (size_t i = 0; i < n; ++i) {
      host[i] = {static_cast<float>(p.x[i] - origin_.x), static_cast<float>(p.y[i] - origin_.y),
                 static_cast<float>(p.z[i] - origin_.z), static_cast<float>(p.r[i])};
      if (!(p.r[i] > 0) || host[i].r > rmax * (1 + 1e-6f))
        return invalid_argument("particle " + std::to_string(i) + " has radius " + std::to_string(p.r[i]) +
                                ", outside (0, r_max = " + std::to_string(cfg_.r_max) + "]");
    }
    n_ = n;
    if (n) backend_.to_device(particles_.data(), host.data(), n * sizeof(PackedParticle));
    return Status::ok();
  }

  Status detect(DetectResult* out) override {
    *out = DetectResult{};
    const auto t_frame = clock();
    lap_start_ = t_frame;
    const bool bin = cfg_.method == Method::kBin;
    const bool wall = cfg_.traversal == Traversal::kWall;
    if (bin && !wall) {
      if (cfg_.collect_contacts) {
        for (bool fits = false; !fits; fits = pairs_fit()) {
          reset_pairs();
          bin_particle_traversal(true);
        }
      } else {
        bin_particle_traversal(false);
      }
      lap(out->times.traverse_ms);
    } else {
      hash_and_sort(out);
      for (bool fits = false; !fits; fits = pairs_fit()) {
        reset_pairs();
        if (bin)
          bin_wall_traversal();
        else if (wall)
          pieces_wall_traversal();
        else
          pieces_particle_traversal();
      }
      lap(out->times.traverse_ms);
    }
    // Contacts as (particle, original) pairs, deduplicated with the smallest distance.
    const bool from_pairs = !(bin && !wall);
    uint32_t unique = 0;
    if (from_pairs || cfg_.collect_contacts) {
      unique = backend_.dedup_min(pair_key_.data(), pair_dist_.data(), pair_count_host_,
                                  pair_key2_.data(), pair_dist2_.data());
      if (from_pairs) counts_from_pairs(unique);
      lap(out->times.finalize_ms);
    }
    backend_.sync();
    out->times.frame_ms = ms(t_frame, clock());
    if (Status e = backend_.status(); !e) return e;
    // Results for the caller: outside the frame's time.
    const auto t = clock();
    download(unique, out);
    out->times.download_ms = ms(t, clock());
    return backend_.status();
  }

 private:
  GridDetector(const DetectConfig& cfg, size_t cap) : cfg_(cfg), capacity_(cap) {}

  using Clock = std::chrono::steady_clock;
  // Adds the time since the previous lap to `slot` (with a device sync) when stages are timed.
  void lap(double& slot) {
    if (!cfg_.time_stages) return;
    backend_.sync();
    const auto now = clock();
    slot += ms(lap_start_, now);
    lap_start_ = now;
  }
  Clock::time_point lap_start_;
  static Clock::time_point clock() { return Clock::now(); }
  static double ms(Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  }

  // --- preparation -------------------------------------------------------------------------
 public:

  Status prepare(const TriangleMesh& mesh) {
    const auto t0 = clock();
    if (!(cfg_.r_max > 0) || !std::isfinite(cfg_.r_max))
      return invalid_argument("r_max must be a positive radius, got " + std::to_string(cfg_.r_max));
    if (mesh.triangles.empty()) return invalid_argument("the wall has no triangles");
    if (cfg_.grid_length < 0 || !std::isfinite(cfg_.grid_length))
      return invalid_argument("grid length must be positive, got " + std::to_string(cfg_.grid_length));
    const Bounds3d box = mesh_bounds(mesh);
    // The local frame's origin at the wall's centre keeps float precision for
    // walls far from the world origin (coordinates near 1e4 with r = 1).
    origin_ = box.center();
    source_ids_ = mesh.source_ids;
    info_.triangles_original = mesh.triangles.size();
    const double cell = cfg_.grid_length > 0 ? cfg_.grid_length : 2 * cfg_.r_max;
    info_.grid_length = cell;
    const double extent = length(box.extent());
    if (extent / cell > 1e7)
      return invalid_argument("grid length " + std::to_string(cell) + " is absurdly small for a wall " +
                              std::to_string(extent) + " across");

    backend_.resize(particles_, capacity_);
    backend_.resize(counts_, std::max<size_t>(capacity_, 1));
    Status s = cfg_.method == Method::kBin ? prepare_bin(mesh, box, cell) : prepare_pieces(mesh, cell);
    if (!s) return s;
    if (cfg_.traversal == Traversal::kWall || cfg_.method != Method::kBin) {
      backend_.resize(p_key_, capacity_);
      backend_.resize(p_idx_, capacity_);
      backend_.resize(p_key_sorted_, capacity_);
      backend_.resize(p_idx_sorted_, capacity_);
      backend_.resize(sorted_particles_, capacity_);
      if (cfg_.traversal == Traversal::kWall) {
        backend_.resize(p_cell_start_, grid_.buckets);
        backend_.resize(p_cell_end_, grid_.buckets);
      }
    }
    grow_pairs(std::max<size_t>(capacity_ / 4, 4096));
    backend_.resize(pair_counter_, 1);
    backend_.sync();
    if (Status e = backend_.status(); !e) return e;
    info_.prepare_ms = ms(t0, clock());
    info_.device_bytes = backend_.bytes_held();
    return Status::ok();
  }

  Status prepare_pieces(const TriangleMesh& mesh, double cell) {
    const DivisionMethod dm = cfg_.method == Method::kGravity        ? DivisionMethod::kGravity
                              : cfg_.method == Method::kCircumcircle ? DivisionMethod::kCircumcircle
                                                                     : DivisionMethod::kMidpoint4;
    // Division is bounded by area / r_max^2; refuse absurd requests before allocating.
    const double estimate = 8 * mesh_area(mesh) / (cfg_.r_max * cfg_.r_max) + mesh.triangles.size();
    if (estimate > 4e8)
      return invalid_argument("dividing this wall for r_max = " + std::to_string(cfg_.r_max) +
                              " would make about " + std::to_string(estimate) + " triangles; use --method bin");
    DividedMesh dv = divide(mesh, dm, cfg_.r_max);
    info_.triangles_used = dv.pieces.size();
    info_.max_sphere_radius = dv.max_sphere_radius;
    info_.area_error = division_area_error(mesh, dv);
    const size_t m = dv.pieces.size();
    // Pad the reach for float rounding of centres and positions.
    const double search = (cfg_.r_max + dv.max_sphere_radius) * (1 + 1e-6) + 1e-6 * cfg_.r_max;
    reach_ = neighbour_reach(search, cell);
    info_.reach = reach_;

    Bounds3d cb;
    for (const auto& c : dv.sphere_centre) cb.grow(c - origin_);
    const double pad = (reach_ + 1) * cell;
    grid_ = make_grid(cb.lo - Vec3d{pad, pad, pad}, cb.hi + Vec3d{pad, pad, pad}, cell,
                      cfg_.max_dense_cells, m + capacity_, &info_.cells);
    info_.buckets = grid_.buckets;
    info_.hashed = grid_.hashed != 0;

    // Hash the pieces by bounding-sphere centre and sort them by cell (paper Table 2).
    std::vector<PlanarTriangle> tris(m);
    std::vector<uint32_t> orig(m), key(m), idx(m);
    std::vector<uint64_t> cellkey(m);
    for (size_t i = 0; i < m; ++i) {
      const auto& p = dv.pieces[i];
      tris[i] = make_planar(p[0], p[1], p[2], origin_);
      int x = 0, y = 0, z = 0;
      Vec3f c = cast3<float>(dv.sphere_centre[i] - origin_);
      if (!grid_.cell_of(c, x, y, z)) return Status(ErrorCode::kBackend, "piece centre outside its grid");
      cellkey[i] = grid_.linear(x, y, z);
      key[i] = grid_.bucket(cellkey[i]);
      idx[i] = static_cast<uint32_t>(i);
    }
    std::stable_sort(idx.begin(), idx.end(), [&](uint32_t a, uint32_t b) { return key[a] < key[b]; });
    std::vector<PlanarTriangle> tris_sorted(m);
    std::vector<uint32_t> orig_sorted(m);
    std::vector<uint64_t> cell_sorted(m);
    std::vector<uint32_t> start(grid_.buckets, 0), end(grid_.buckets, 0);
    for (size_t j = 0; j < m; ++j) {
      tris_sorted[j] = tris[idx[j]];
      orig_sorted[j] = dv.original[idx[j]];
      cell_sorted[j] = cellkey[idx[j]];
      const uint32_t k = key[idx[j]];
      if (j == 0 || key[idx[j - 1]] != k) start[k] = static_cast<uint32_t>(j);
      end[k] = static_cast<uint32_t>(j + 1);
    }
    upload(tris_, tris_sorted);
    upload(tri_original_, orig_sorted);
    upload(tri_cell_, cell_sorted);
    upload(tri_start_, start);
    upload(tri_end_, end);
    return Status::ok();
  }

  Status prepare_bin(const TriangleMesh& mesh, const Bounds3d& box, double cell) {
    const size_t m = mesh.triangles.size();
    info_.triangles_used = m;
    reach_ = 0;
    // A particle in a cell can touch a triangle only if the triangle meets the
    // cell grown by r_max; pad for float rounding so no contact is ever missed.
    const double grow = cfg_.r_max * (1 + 1e-5) + 1e-6 * cell;
    const Vec3d pad{grow + cell, grow + cell, grow + cell};
    grid_ = make_grid(box.lo - origin_ - pad, box.hi - origin_ + pad, cell, cfg_.max_dense_cells,
                      4 * m + capacity_, &info_.cells);
    info_.buckets = grid_.buckets;
    info_.hashed = grid_.hashed != 0;

    std::vector<TriangleF> corners(m);
    std::vector<PlanarTriangle> tris(m);
    for (size_t t = 0; t < m; ++t) {
      corners[t] = {cast3<float>(mesh.corner(t, 0) - origin_), cast3<float>(mesh.corner(t, 1) - origin_),
                    cast3<float>(mesh.corner(t, 2) - origin_)};
      tris[t] = make_planar(mesh.corner(t, 0), mesh.corner(t, 1), mesh.corner(t, 2), origin_);
    }
    upload(tris_, tris);
    upload(corners_, corners);

    // CSR build on the backend: count (cell, triangle) overlaps, scan, fill.
    Buf<uint32_t> bin_count;
    backend_.resize(bin_count, size_t(grid_.buckets) + 1);
    backend_.fill(bin_count.data(), size_t(grid_.buckets) + 1, 0u);
    const GridSpec g = grid_;
    const TriangleF* T = corners_.data();
    const float fgrow = static_cast<float>(grow);
    uint32_t* count = bin_count.data();
    backend_.parallel_for(m, [=] COLLIDO_HD(uint32_t t) {
      for_each_bin_cell(g, T[t], fgrow, [&](uint64_t l) { atomic_add_u32(&count[g.bucket(l)], 1u); });
    });
    const uint64_t total = backend_.exclusive_scan(count, size_t(grid_.buckets) + 1);
    if (total > (1ull << 31))
      return invalid_argument("the bin method would store " + std::to_string(total) +
                              " (cell, triangle) pairs; raise --grid-length");
    info_.bin_entries = total;
    backend_.resize(bin_start_, size_t(grid_.buckets) + 1);
    backend_.copy(bin_start_.data(), count, (size_t(grid_.buckets) + 1) * sizeof(uint32_t));
    backend_.resize(bin_tri_, std::max<uint64_t>(total, 1));
    backend_.resize(bin_cell_, std::max<uint64_t>(total, 1));
    uint32_t* cursor = count;  // reuse the scanned counts as fill cursors
    uint32_t* bt = bin_tri_.data();
    uint64_t* bc = bin_cell_.data();
    backend_.parallel_for(m, [=] COLLIDO_HD(uint32_t t) {
      for_each_bin_cell(g, T[t], fgrow, [&](uint64_t l) {
        const uint32_t slot = atomic_add_u32(&cursor[g.bucket(l)], 1u);
        bt[slot] = t;
        bc[slot] = l;
      });
    });
    // Fixed order inside each cell (by triangle) makes runs repeatable.
    backend_.sort_segments(bin_tri_.data(), bin_cell_.data(), bin_start_.data(), grid_.buckets, total);
    return Status::ok();
  }

  // Calls f(linear cell) for each cell whose box grown by `grow` overlaps the triangle.
  template <class F>
  COLLIDO_HD static void for_each_bin_cell(const GridSpec& g, const TriangleF& t, float grow, F&& f) {
    const float lox = fminf(t.a.x, fminf(t.b.x, t.c.x)) - grow, hix = fmaxf(t.a.x, fmaxf(t.b.x, t.c.x)) + grow;
    const float loy = fminf(t.a.y, fminf(t.b.y, t.c.y)) - grow, hiy = fmaxf(t.a.y, fmaxf(t.b.y, t.c.y)) + grow;
    const float loz = fminf(t.a.z, fminf(t.b.z, t.c.z)) - grow, hiz = fmaxf(t.a.z, fmaxf(t.b.z, t.c.z)) + grow;
    auto clampi = [](int v, int n) { return v < 0 ? 0 : (v >= n ? n - 1 : v); };
    const int x0 = clampi(int(floorf((lox - g.origin.x) * g.inv_cell)), g.nx),
              x1 = clampi(int(floorf((hix - g.origin.x) * g.inv_cell)), g.nx);
    const int y0 = clampi(int(floorf((loy - g.origin.y) * g.inv_cell)), g.ny),
              y1 = clampi(int(floorf((hiy - g.origin.y) * g.inv_cell)), g.ny);
    const int z0 = clampi(int(floorf((loz - g.origin.z) * g.inv_cell)), g.nz),
              z1 = clampi(int(floorf((hiz - g.origin.z) * g.inv_cell)), g.nz);
    const float h = 0.5f * g.cell + grow;
    for (int z = z0; z <= z1; ++z)
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) {
          const Vec3f centre{g.origin.x + (x + 0.5f) * g.cell, g.origin.y + (y + 0.5f) * g.cell,
                             g.origin.z + (z + 0.5f) * g.cell};
          if (triangle_box_overlap(t.a, t.b, t.c, centre, Vec3f{h, h, h})) f(g.linear(x, y, z));
        }
  }

  template <class T>
  void upload(Buf<T>& dst, const std::vector<T>& src) {
    backend_.resize(dst, std::max<size_t>(src.size(), 1));
    if (!src.empty()) backend_.to_device(dst.data(), src.data(), src.size() * sizeof(T));
  }

  // --- frame stages -------------------------------------------------------------------------
  // Public only because nvcc's extended (host/device) lambdas may not live in
  // private member functions; nothing outside this class calls them.
 public:

  void hash_and_sort(DetectResult* out) {
    const GridSpec g = grid_;
    const PackedParticle* P = particles_.data();
    uint32_t* key = p_key_.data();
    uint32_t* idx = p_idx_.data();
    backend_.parallel_for(n_, [=] COLLIDO_HD(uint32_t i) {
      int x = 0, y = 0, z = 0;
      key[i] = g.cell_of(position(P[i]), x, y, z) ? g.bucket(g.linear(x, y, z)) : kInvalidBucket;
      idx[i] = i;
    });
    lap(out->times.hash_ms);
    backend_.sort_pairs(key, idx, p_key_sorted_.data(), p_idx_sorted_.data(), n_);
    // Reorder the particles by cell so neighbouring threads read neighbouring memory.
    const uint32_t* sidx = p_idx_sorted_.data();
    PackedParticle* SP = sorted_particles_.data();
    backend_.parallel_for(n_, [=] COLLIDO_HD(uint32_t j) { SP[j] = P[sidx[j]]; });
    lap(out->times.sort_ms);
    if (cfg_.traversal == Traversal::kWall) {
      uint32_t* start = p_cell_start_.data();
      uint32_t* end = p_cell_end_.data();
      const uint32_t* skey = p_key_sorted_.data();
      const uint32_t n = static_cast<uint32_t>(n_);
      backend_.fill(start, grid_.buckets, 0u);
      backend_.fill(end, grid_.buckets, 0u);
      backend_.parallel_for(n_, [=] COLLIDO_HD(uint32_t j) {
        const uint32_t k = skey[j];
        if (k == kInvalidBucket) return;
        if (j == 0 || skey[j - 1] != k) start[k] = j;
        if (j + 1 == n || skey[j + 1] != k) end[k] = j + 1;
      });
      lap(out->times.cells_ms);
    }
  }

  void reset_pairs() {
    backend_.fill(pair_counter_.data(), 1, 0u);
  }
  bool pairs_fit() {
    uint32_t c = 0;
    backend_.to_host(&c, pair_counter_.data(), sizeof c);
    pair_count_host_ = c;
    if (c <= pair_capacity_) return true;
    grow_pairs(size_t(c) + c / 4);
    return false;
  }
  void grow_pairs(size_t cap) {
    pair_capacity_ = cap;
    backend_.resize(pair_key_, cap);
    backend_.resize(pair_dist_, cap);
    backend_.resize(pair_key2_, cap);
    backend_.resize(pair_dist2_, cap);
  }

  // Appends (particle, original triangle, distance) to the pair buffer if it has room.
  struct PairSink {
    uint64_t* key;
    float* dist;
    uint32_t* counter;
    uint32_t capacity;
    COLLIDO_HD COLLIDO_FORCEINLINE void push(uint32_t particle, uint32_t tri, float d) const {
      const uint32_t slot = atomic_add_u32(counter, 1u);
      if (slot < capacity) {
        key[slot] = (uint64_t(particle) << 32) | tri;
        dist[slot] = d;
      }
    }
  };
  PairSink sink() {
    return {pair_key_.data(), pair_dist_.data(), pair_counter_.data(), static_cast<uint32_t>(pair_capacity_)};
  }

  // bin, particle traversal: a thread per particle reads its own cell's list.
  void bin_particle_traversal(bool collect) {
    const GridSpec g = grid_;
    const PackedParticle* P = particles_.data();
    const PlanarTriangle* T = tris_.data();
    const uint32_t* start = bin_start_.data();
    const uint32_t* tri = bin_tri_.data();
    const uint64_t* cellk = bin_cell_.data();
    uint32_t* counts = counts_.data();
    const PairSink out = sink();
    backend_.parallel_for(n_, [=] COLLIDO_HD(uint32_t i) {
      const PackedParticle p = P[i];
      int x = 0, y = 0, z = 0;
      uint32_t n = 0;
      if (g.cell_of(position(p), x, y, z)) {
        const uint64_t l = g.linear(x, y, z);
        const uint32_t b = g.bucket(l);
        const float r2 = p.r * p.r;
        for (uint32_t k = start[b], e = start[b + 1]; k < e; ++k) {
          if (g.hashed && cellk[k] != l) continue;
          const uint32_t t = tri[k];
          const float d2 = point_triangle_dist2(position(p), T[t]);
          if (d2 < r2) {
            ++n;
            if (collect) out.push(i, t, sqrtf(d2));
          }
        }
      }
      counts[i] = n;
    });
  }

  // bin, wall traversal: a thread per (cell, triangle) entry loops over the
  // particles of that cell. Each pair is met once, so no deduplication is needed.
  void bin_wall_traversal() {
    const GridSpec g = grid_;
    const PackedParticle* SP = sorted_particles_.data();
    const uint32_t* sidx = p_idx_sorted_.data();
    const PlanarTriangle* T = tris_.data();
    const uint32_t* tri = bin_tri_.data();
    const uint64_t* cellk = bin_cell_.data();
    const uint32_t* pstart = p_cell_start_.data();
    const uint32_t* pend = p_cell_end_.data();
    const PairSink out = sink();
    backend_.parallel_for(info_.bin_entries, [=] COLLIDO_HD(uint32_t k) {
      const uint64_t l = cellk[k];
      const uint32_t b = g.bucket(l);
      const uint32_t t = tri[k];
      const PlanarTriangle tr = T[t];
      for (uint32_t j = pstart[b], e = pend[b]; j < e; ++j) {
        const PackedParticle p = SP[j];
        if (g.hashed && !g.holds(position(p), l)) continue;
        const float d2 = point_triangle_dist2(position(p), tr);
        if (d2 < p.r * p.r) out.push(sidx[j], t, sqrtf(d2));
      }
    });
  }

  // Divided pieces, particle traversal (paper 3.6): a thread per particle
  // loops over the pieces of its neighbouring cells and emits every hit.
  // Several pieces of one original may touch the particle; the pairs are
  // deduplicated afterwards, as for the wall traversal, which keeps the
  // smallest distance and needs no per-thread memory however many originals meet.
  void pieces_particle_traversal() {
    const GridSpec g = grid_;
    const int reach = reach_;
    const PackedParticle* SP = sorted_particles_.data();
    const uint32_t* skey = p_key_sorted_.data();
    const uint32_t* sidx = p_idx_sorted_.data();
    const PlanarTriangle* T = tris_.data();
    const uint32_t* orig = tri_original_.data();
    const uint64_t* tcell = tri_cell_.data();
    const uint32_t* tstart = tri_start_.data();
    const uint32_t* tend = tri_end_.data();
    const PairSink out = sink();
    backend_.parallel_for(n_, [=] COLLIDO_HD(uint32_t j) {
      if (skey[j] == kInvalidBucket) return;
      const uint32_t i = sidx[j];
      const PackedParticle p = SP[j];
      const Vec3f c = position(p);
      const float r2 = p.r * p.r;
      int cx = 0, cy = 0, cz = 0;
      g.cell_of(c, cx, cy, cz);
      g.for_each_neighbour(cx, cy, cz, reach, [&](uint64_t l, uint32_t b) {
        for (uint32_t k = tstart[b], e = tend[b]; k < e; ++k) {
          if (g.hashed && tcell[k] != l) continue;
          const float d2 = point_triangle_dist2(c, T[k]);
          if (d2 < r2) out.push(i, orig[k], sqrtf(d2));
        }
      });
    });
  }

  // Divided pieces, wall traversal: a thread per piece loops over the
  // particles of its neighbouring cells and emits every hit; pieces of one
  // original meet the same particle, so the pairs are deduplicated afterwards.
  void pieces_wall_traversal() {
    const GridSpec g = grid_;
    const int reach = reach_;
    const PackedParticle* SP = sorted_particles_.data();
    const uint32_t* sidx = p_idx_sorted_.data();
    const PlanarTriangle* T = tris_.data();
    const uint32_t* orig = tri_original_.data();
    const uint64_t* tcell = tri_cell_.data();
    const uint32_t* pstart = p_cell_start_.data();
    const uint32_t* pend = p_cell_end_.data();
    const PairSink out = sink();
    backend_.parallel_for(info_.triangles_used, [=] COLLIDO_HD(uint32_t k) {
      const PlanarTriangle& tr = T[k];
      const uint32_t o = orig[k];
      int cx = 0, cy = 0, cz = 0;
      g.unlinear(tcell[k], cx, cy, cz);
      g.for_each_neighbour(cx, cy, cz, reach, [&](uint64_t l, uint32_t b) {
        for (uint32_t j = pstart[b], e = pend[b]; j < e; ++j) {
          const PackedParticle p = SP[j];
          if (g.hashed && !g.holds(position(p), l)) continue;
          const float d2 = point_triangle_dist2(position(p), tr);
          if (d2 < p.r * p.r) out.push(sidx[j], o, sqrtf(d2));
        }
      });
    });
  }

  void counts_from_pairs(uint32_t unique) {
    uint32_t* counts = counts_.data();
    const uint64_t* key = pair_key2_.data();
    backend_.fill(counts, n_, 0u);
    backend_.parallel_for(unique, [=] COLLIDO_HD(uint32_t k) { atomic_add_u32(&counts[key[k] >> 32], 1u); });
  }

  void download(uint32_t unique, DetectResult* out) {
    out->counts.resize(n_);
    if (n_) backend_.to_host(out->counts.data(), counts_.data(), n_ * sizeof(uint32_t));
    for (uint32_t c : out->counts) {
      out->contact_count += c;
      out->colliding_particles += c != 0;
    }
    if (!cfg_.collect_contacts) return;
    std::vector<uint64_t> keys(unique);
    std::vector<float> dist(unique);
    if (unique) {
      backend_.to_host(keys.data(), pair_key2_.data(), unique * sizeof(uint64_t));
      backend_.to_host(dist.data(), pair_dist2_.data(), unique * sizeof(float));
    }
    out->contacts.resize(unique);
    for (uint32_t k = 0; k < unique; ++k)
      out->contacts[k] = {static_cast<uint32_t>(keys[k] >> 32), source_ids_[keys[k] & 0xFFFFFFFFu], dist[k]};
    // Source ids follow the input file's order, which welding and dropping may
    // have permuted relative to mesh indices: sort by the ids the user sees.
    std::sort(out->contacts.begin(), out->contacts.end(), [](const Contact& a, const Contact& b) {
      return a.particle != b.particle ? a.particle < b.particle : a.triangle < b.triangle;
    });
  }

  B backend_;
  DetectConfig cfg_;
  PrepareInfo info_;
  size_t capacity_ = 0, n_ = 0;
  Vec3d origin_{0, 0, 0};
  std::vector<uint32_t> source_ids_;
  std::vector<PackedParticle> staging_;  // host copy of a frame's particles, reused
  GridSpec grid_;
  int reach_ = 1;

  Buf<PlanarTriangle> tris_;  // narrow-phase form
  Buf<TriangleF> corners_;    // bin preparation only
  Buf<uint32_t> tri_original_, tri_start_, tri_end_;
  Buf<uint64_t> tri_cell_;
  Buf<uint32_t> bin_start_, bin_tri_;
  Buf<uint64_t> bin_cell_;

  Buf<PackedParticle> particles_, sorted_particles_;
  Buf<uint32_t> p_key_, p_idx_, p_key_sorted_, p_idx_sorted_, p_cell_start_, p_cell_end_, counts_;

  Buf<uint64_t> pair_key_, pair_key2_;
  Buf<float> pair_dist_, pair_dist2_;
  Buf<uint32_t> pair_counter_;
  size_t pair_capacity_ = 0;
  uint32_t pair_count_host_ = 0;
};

}  // namespace collido::sim
