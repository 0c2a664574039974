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

#include "sim/cell_ranges.h"
#include "sim/detect.h"
#include "sim/exact_distance.h"
#include "sim/wall_index.h"

namespace collido::sim {

// Largest particle radius or grid cell, as a multiple of the wall's size.
inline constexpr double kMaxScaleOverWall = 1e4;

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

  Status set_particles(const Particles& p) override {
    const size_t n = p.size();
    if (n > capacity_)
      return invalid_argument("frame has " + std::to_string(n) +
                              " particles, detector was made for " + std::to_string(capacity_));
    std::vector<PackedParticle>& host = staging_;
    host.resize(n);
    const float rmax = static_cast<float>(cfg_.r_max);
    for (size_t i = 0; i < n; ++i) {
      host[i] = {static_cast<float>(p.x[i] - wall_.origin.x),
                 static_cast<float>(p.y[i] - wall_.origin.y),
                 static_cast<float>(p.z[i] - wall_.origin.z), static_cast<float>(p.r[i])};
      if (!(p.r[i] > 0) || host[i].r > rmax * (1 + 1e-6f))
        return invalid_argument("particle " + std::to_string(i) + " has radius " +
                                std::to_string(p.r[i]) +
                                ", outside (0, r_max = " + std::to_string(cfg_.r_max) + "]");
    }
    n_ = n;
    if (n) backend_.to_device(particles_.data(), host.data(), n * sizeof(PackedParticle));
    if (created_precision_ == Precision::kExact && n) {
      ParticleD* direct = backend_.host_pointer(particles_d_);
      std::vector<ParticleD>& hd = staging_d_;
      if (!direct) hd.resize(n);
      ParticleD* to = direct ? direct : hd.data();
      for (size_t i = 0; i < n; ++i) to[i] = {p.x[i], p.y[i], p.z[i], p.r[i]};
      if (!direct) backend_.to_device(particles_d_.data(), hd.data(), n * sizeof(ParticleD));
    }
    return Status::ok();
  }

  Status detect(DetectResult* out) override {
    *out = DetectResult{};
    const auto t_frame = clock();
    lap_start_ = t_frame;
    const bool bin = cfg_.method == Method::kBin;
    const bool bvh = cfg_.method == Method::kBvh;
    const bool octree = cfg_.method == Method::kOctree;
    const bool wall = cfg_.traversal == Traversal::kWall;
    if (bvh || octree || (bin && !wall)) {
      // The walks that count per particle themselves (no sort for bin: a particle reads its cell).
      if (bvh) hash_and_sort(out);
      if (octree) octree_group(out);
      auto walk = [&](bool collect) {
        if (bvh)
          bvh_particle_traversal(collect);
        else if (octree) {
          octree_traversal(collect);
          if (exact()) octree_doubts(collect);
        } else
          bin_particle_traversal(collect);
      };
      if (cfg_.collect_contacts) {
        for (bool fits = false; !fits; fits = pairs_fit()) {
          reset_pairs();
          walk(true);
        }
      } else {
        reset_pairs();
        walk(false);
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
    if (pair_overflow_) {
      pair_overflow_ = false;
      return resource_exhausted(
          "this frame has more than " + std::to_string(pair_limit()) +
          " candidate (particle, triangle) pairs, the most a frame may hold (24 bytes each): "
          "use the bin or bvh method, or fewer or smaller particles");
    }
    // Contacts as (particle, original) pairs, deduplicated with the smallest distance.
    const bool from_pairs = !(bin && !wall) && !bvh && !octree;
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
    uint32_t counters[4] = {0, 0, 0, 0};  // [1] the band's pairs, [3] the octree's doubts
    backend_.to_host(counters, pair_counter_.data(), sizeof counters);
    const uint32_t band = counters[1], doubts = counters[3];
    if (octree && exact()) {
      if (doubts > pair_limit())
        return resource_exhausted("this frame has more than " + std::to_string(pair_limit()) +
                                  " (particle, triangle) pairs in float's error band, the most a "
                                  "frame may hold: use the bin or bvh method");
      if (doubts > doubt_capacity_) {  // some were dropped: again, with room for them all
        grow_doubts(size_t(doubts) + doubts / 4);
        return detect(out);
      }
    }
    out->band_pairs = band;
    download(unique, out);
    out->times.download_ms = ms(t, clock());
    return backend_.status();
  }

 private:
  GridDetector(const DetectConfig& cfg, size_t cap) : Detector(cfg), capacity_(cap) {
    backend_.set_pool(cfg.pool);
  }

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
      return invalid_argument("grid length must be positive, got " +
                              std::to_string(cfg_.grid_length));
    const Bounds3d box = mesh_bounds(mesh);
    source_ids_ = mesh.source_ids;
    const double cell = cfg_.grid_length > 0 ? cfg_.grid_length : 2 * cfg_.r_max;
    info_.grid_length = cell;
    const double extent = length(box.extent());
    if (extent / cell > 1e7)
      return invalid_argument("grid length " + std::to_string(cell) +
                              " is absurdly small for a wall " + std::to_string(extent) +
                              " across");
    // The engine works in float relative to the wall: a radius or cell that
    // dwarfs the wall by more than this cannot be placed exactly against it.
    const double largest = std::max(extent, 1e-300) * kMaxScaleOverWall;
    if (cfg_.r_max > largest || cell > largest)
      return invalid_argument("a radius of " + std::to_string(cfg_.r_max) + " or grid length of " +
                              std::to_string(cell) + " is more than " +
                              std::to_string(int(kMaxScaleOverWall)) + " times the wall (" +
                              std::to_string(extent) + " across)");

    backend_.resize(particles_, capacity_);
    backend_.resize(counts_, std::max<size_t>(capacity_, 1));
    Status s = wall_.prepare(backend_, mesh, cfg_.method, cfg_.r_max, cell, cfg_.max_dense_cells,
                             capacity_, &info_);
    if (!s) return s;
    if (cfg_.traversal == Traversal::kWall || cfg_.method != Method::kBin) {
      if (cfg_.method != Method::kOctree) {  // the octree groups without them (octree_group)
        backend_.resize(p_key_, capacity_);
        backend_.resize(p_idx_, capacity_);
      }
      backend_.resize(p_key_sorted_, capacity_);
      backend_.resize(p_idx_sorted_, capacity_);
      const bool walks = cfg_.method == Method::kBvh || cfg_.method == Method::kOctree;
      if (!walks || B::kWalksReadReorderedCopy) backend_.resize(sorted_particles_, capacity_);
      if (cfg_.traversal == Traversal::kWall) {
        backend_.resize(p_cell_start_, wall_.grid.buckets);
        backend_.resize(p_cell_end_, wall_.grid.buckets);
      }
    }
    if (cfg_.method == Method::kOctree) {
      // The leaves' starts, then the particles located, the chunks, the test
      // stage's next item and the chunks of long lists (octree_traversal).
      backend_.resize(leaf_pos_, size_t(wall_.octree_leaves()) + 4);
      backend_.resize(octree_chunk_, capacity_);
      // The pairs in float's band (about 3 in 10^3 contacts on the counter
      // mesh): room for a few at first; a frame that finds more grows it.
      if (exact()) grow_doubts(kOctreeFirstDoubts);
    }
    if (created_precision_ == Precision::kExact) prepare_exact(mesh);
    // bvh counts without pairs: its buffer grows when a frame first collects them.
    grow_pairs(std::min<size_t>(cfg_.method == Method::kBvh || cfg_.method == Method::kOctree
                                    ? 4096
                                    : std::max<size_t>(capacity_ / 4, 4096),
                                pair_limit()));
    backend_.resize(pair_counter_, 4);
    backend_.sync();
    if (Status e = backend_.status(); !e) return e;
    info_.prepare_ms = ms(t0, clock());
    info_.device_bytes = backend_.bytes_held();
    return Status::ok();
  }

  // The exact filter's data: the wall as the mesh holds it, world double
  // vertices and each triangle's three indices (the same corners as 72-byte
  // triangles, in about a third of the memory: vertices are shared; only
  // pairs in the band read them).
  void prepare_exact(const TriangleMesh& mesh) {
    WallIndex<B>::upload(backend_, vertices_exact_, mesh.vertices);
    std::vector<uint32_t> corners(3 * mesh.triangles.size());
    for (size_t t = 0; t < mesh.triangles.size(); ++t)
      for (int k = 0; k < 3; ++k) corners[3 * t + k] = mesh.triangles[t][k];
    WallIndex<B>::upload(backend_, corners_exact_, corners);
    // The octree reads the particles' double copy only in its pass over the
    // pairs in doubt (a few in 10^3), so it lies in host memory the device
    // reads (32 bytes a particle of device memory saved); the other methods
    // decide their band's pairs inside the traversal, whose warps would wait
    // on the bus.
    if (cfg_.method == Method::kOctree)
      backend_.resize_host_visible(particles_d_, std::max<size_t>(capacity_, 1));
    else
      backend_.resize(particles_d_, std::max<size_t>(capacity_, 1));
  }
  bool exact() const { return cfg_.precision == Precision::kExact; }

  // Decides a float candidate pair (particle i at p, the candidate t whose
  // original triangle is `orig`) from their float distance: outside float's
  // error band the float answer stands; inside it, precision exact asks the
  // contract's double predicate. Returns the contact and its distance in *dist.
  struct Narrow {
    const ParticleD* pd;
    const Vec3d* vd;     // world double vertices
    const uint32_t* cd;  // three vertex indices per original triangle
    float wall_scale;
    bool exact;
    // The float distance's verdict: out, in, or in doubt (precision exact
    // only; in the band, where float cannot tell). Counts the band's pairs.
    enum Verdict { kOut, kIn, kDoubt };
    COLLIDO_HD COLLIDO_FORCEINLINE Verdict judge(const PackedParticle& p, const PlanarTriangle& t,
                                                 float* dist, uint32_t* band) const {
      const float delta = float_band(p.x, p.y, p.z, p.r, wall_scale);
      const float hi = p.r + delta;
      const float d2 = point_triangle_dist2(position(p), t, hi * hi);
      if (!(d2 < hi * hi)) return kOut;
      const float lo = p.r - delta;
      if (lo > 0.f && d2 < lo * lo) {
        *dist = sqrtf(d2);
        return kIn;
      }
      ++*band;
      if (!exact) {
        *dist = sqrtf(d2);
        return d2 < p.r * p.r ? kIn : kOut;
      }
      return kDoubt;
    }
    COLLIDO_HD COLLIDO_FORCEINLINE bool decide(const PackedParticle& p, const PlanarTriangle& t,
                                               uint32_t i, uint32_t orig, float* dist,
                                               uint32_t* band) const {
      const Verdict v = judge(p, t, dist, band);
      return v == kDoubt ? decide_exactly(i, orig, dist) : v == kIn;
    }
    // A pair in doubt, in double: the contract's predicate.
    COLLIDO_HD COLLIDO_FORCEINLINE bool decide_exactly(uint32_t i, uint32_t orig,
                                                       float* dist) const {
      double e2 = 0;
      const TriangleD world{vd[cd[3 * orig]], vd[cd[3 * orig + 1]], vd[cd[3 * orig + 2]]};
      if (!exact_touch(pd[i], world, &e2)) return false;
      *dist = static_cast<float>(sqrt(e2));
      return true;
    }
  };
  Narrow narrow() {
    // Both precisions size the error band (float counts the pairs it decides in it).
    return {particles_d_.data(), vertices_exact_.data(), corners_exact_.data(), wall_.band_scale,
            exact()};
  }
  uint32_t* band_counter() { return pair_counter_.data() + 1; }

  // --- frame stages -------------------------------------------------------------------------
  // Public only because nvcc's extended (host/device) lambdas may not live in
  // private member functions; nothing outside this class calls them.
 public:
  void hash_and_sort(DetectResult* out) {
    const GridSpec g = wall_.grid;
    const PackedParticle* P = particles_.data();
    uint32_t* key = p_key_.data();
    uint32_t* idx = p_idx_.data();
    if (cfg_.method == Method::kBvh) {
      // Along a space-filling curve: neighbouring threads walk the same nodes.
      const MortonFrame mf = wall_.morton;
      backend_.parallel_for(n_, [=] COLLIDO_HD(uint32_t i) {
        key[i] = mf.key(position(P[i]));
        idx[i] = i;
      });
    } else {
      backend_.parallel_for(n_, [=] COLLIDO_HD(uint32_t i) {
        int x = 0, y = 0, z = 0;
        key[i] = g.cell_of(position(P[i]), x, y, z) ? g.bucket(g.linear(x, y, z)) : kInvalidBucket;
        idx[i] = i;
      });
    }
    lap(out->times.hash_ms);
    backend_.sort_pairs(key, idx, p_key_sorted_.data(), p_idx_sorted_.data(), n_);
    // The tree's walk reads each particle once: through the sorted index where
    // the backend hides scattered reads, else from a reordered copy.
    if (cfg_.method == Method::kBvh && !B::kWalksReadReorderedCopy) {
      lap(out->times.sort_ms);
      return;
    }
    // Reorder the particles by cell so neighbouring threads read neighbouring memory.
    const uint32_t* sidx = p_idx_sorted_.data();
    PackedParticle* SP = sorted_particles_.data();
    backend_.parallel_for(n_, [=] COLLIDO_HD(uint32_t j) { SP[j] = P[sidx[j]]; });
    lap(out->times.sort_ms);
    if (cfg_.traversal == Traversal::kWall) {
      build_cell_ranges(backend_, p_key_sorted_.data(), n_, p_cell_start_.data(),
                        p_cell_end_.data(), wall_.grid.buckets, kInvalidBucket);
      lap(out->times.cells_ms);
    }
  }

  // The pair counter, the band counter, the overflow flag and the octree's doubts.
  void reset_pairs() { backend_.fill(pair_counter_.data(), 4, 0u); }
  // The most pairs a frame may hold: the config's, within the 32-bit counter's
  // half range (a counter that passed it is flagged before it could wrap).
  uint32_t pair_limit() const {
    return static_cast<uint32_t>(std::min<uint64_t>(cfg_.max_frame_pairs, 1ull << 31));
  }
  // True when the frame's pairs fit (or overflowed: pair_overflow_, the frame
  // fails); else the buffer grows and the traversal must run again.
  bool pairs_fit() {
    uint32_t c[3] = {0, 0, 0};
    backend_.to_host(c, pair_counter_.data(), sizeof c);
    pair_count_host_ = c[0];
    if (c[2] || c[0] > pair_limit()) {
      pair_overflow_ = true;
      pair_count_host_ = 0;
      return true;
    }
    if (c[0] <= pair_capacity_) return true;
    grow_pairs(std::min<size_t>(size_t(c[0]) + c[0] / 4, pair_limit()));
    return false;
  }
  void grow_doubts(size_t cap) {
    doubt_capacity_ = std::min<size_t>(cap, UINT32_MAX);
    backend_.resize(doubt_key_, doubt_capacity_);
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
    uint32_t* counter;  // [0] pairs offered, [2] set when they passed the limit
    uint32_t capacity, limit;
    COLLIDO_HD COLLIDO_FORCEINLINE void push(uint32_t particle, uint32_t tri, float d) const {
      const uint32_t slot = atomic_add_u32(counter, 1u);
      if (slot < capacity) {
        key[slot] = (uint64_t(particle) << 32) | tri;
        dist[slot] = d;
      } else if (slot >= limit) {
        counter[2] = 1u;  // every value up to the wrap passes here first
      }
    }
  };
  PairSink sink() {
    return {pair_key_.data(), pair_dist_.data(), pair_counter_.data(),
            static_cast<uint32_t>(pair_capacity_), pair_limit()};
  }
  // Appends a (particle, triangle) pair in doubt for the octree's double pass;
  // counts every offer (pair_counter_[3]), keeps those that fit.
  struct DoubtSink {
    uint64_t* key;
    uint32_t* counter;
    uint32_t capacity;
    COLLIDO_HD COLLIDO_FORCEINLINE void push(uint32_t particle, uint32_t tri) const {
      const uint32_t slot = atomic_add_u32(counter, 1u);
      if (slot < capacity) key[slot] = (uint64_t(particle) << 32) | tri;
    }
  };
  DoubtSink doubt_sink() {
    return {doubt_key_.data(), pair_counter_.data() + 3, static_cast<uint32_t>(doubt_capacity_)};
  }

  // bin, particle traversal: a thread per particle reads its own cell's list.
  void bin_particle_traversal(bool collect) {
    const GridSpec g = wall_.grid;
    const PackedParticle* P = particles_.data();
    const PlanarTriangle* T = wall_.tris.data();
    const uint32_t* start = wall_.bin_start.data();
    const uint32_t* tri = wall_.bin_tri.data();
    const uint64_t* cellk = wall_.bin_cell.data();
    uint32_t* counts = counts_.data();
    const PairSink out = sink();
    const Narrow nw = narrow();
    uint32_t* band_total = band_counter();
    backend_.parallel_for(n_, [=] COLLIDO_HD(uint32_t i) {
      const PackedParticle p = P[i];
      int x = 0, y = 0, z = 0;
      uint32_t n = 0, band = 0;
      if (g.cell_of(position(p), x, y, z)) {
        const uint64_t l = g.linear(x, y, z);
        const uint32_t b = g.bucket(l);
        for (uint32_t k = start[b], e = start[b + 1]; k < e; ++k) {
          if (g.hashed && cellk[k] != l) continue;
          const uint32_t t = tri[k];
          float d = 0;
          if (nw.decide(p, T[t], i, t, &d, &band)) {
            ++n;
            if (collect) out.push(i, t, d);
          }
        }
      }
      counts[i] = n;
      if (band) atomic_add_u32(band_total, band);
    });
  }

  // bvh: a thread per particle, in Morton order, walks the tree; each
  // original triangle sits in one leaf, so every pair is met once.
  void bvh_particle_traversal(bool collect) {
    constexpr bool copy = B::kWalksReadReorderedCopy;
    const PackedParticle* P = copy ? sorted_particles_.data() : particles_.data();
    const uint32_t* skey = p_key_sorted_.data();
    const uint32_t* sidx = p_idx_sorted_.data();
    const BvhWideNode* nodes = wall_.bvh_nodes.data();
    const PlanarTriangle* T = wall_.tris.data();
    const uint32_t* orig = wall_.tri_original.data();
    // Float's error band around the radius, at most (particles farther out have no key).
    const float extra = wall_.bvh_reach - static_cast<float>(cfg_.r_max);
    uint32_t* counts = counts_.data();
    const PairSink out = sink();
    const Narrow nw = narrow();
    uint32_t* band_total = band_counter();
    backend_.parallel_for_walk(n_, [=] COLLIDO_HD(uint32_t j) {
      const uint32_t i = sidx[j];
      uint32_t n = 0, band = 0;
      if (skey[j] != kInvalidMorton) {
        const PackedParticle p = P[copy ? j : i];
        const Vec3f c = position(p);
        bvh_for_each_near(nodes, c, p.r + extra, [&](uint32_t k) {
          float d = 0;
          if (nw.decide(p, T[k], i, orig[k], &d, &band)) {
            ++n;
            if (collect) out.push(i, orig[k], d);
          }
        });
      }
      counts[i] = n;
      if (band) atomic_add_u32(band_total, band);
    });
  }

  // octree, first half of a frame: the particles grouped by leaf (a counting
  // sort: each particle's leaf and its rank among the leaf's, the leaves'
  // starts by a scan, then the sorted index), so the threads that test one
  // leaf's list read it together. A leaf's particles form chunks of up to 32,
  // the test stage's items, listed in leaf order by selecting the sorted
  // places that start one. The particles in no leaf touch nothing. How many
  // particles lie in leaves (pos[leaves]) and how many chunks there are
  // (pos[leaves + 1]) stay on the device. The frame's per-particle scratch is
  // four words: the leaf and rank live in the chunk list and the counts until
  // the sorted index and the leaf of each sorted place are written (8 bytes a
  // particle fewer than two arrays of their own).
  void octree_group(DetectResult* out) {
    const OctreeView ov = wall_.octree_view();
    const PackedParticle* P = particles_.data();
    uint32_t* leaf_of = octree_chunk_.data();
    uint32_t* rank = counts_.data();
    uint32_t* pos = leaf_pos_.data();
    const size_t leaves = wall_.octree_leaves();
    const uint32_t long_leaves = ov.long_leaves;
    backend_.fill(pos, leaves + 4, 0u);
    backend_.parallel_for(n_, [=] COLLIDO_HD(uint32_t i) {
      const int32_t leaf = ov.leaf_of(position(P[i]));
      leaf_of[i] = uint32_t(leaf);
      if (leaf >= 0) rank[i] = atomic_add_u32(&pos[leaf], 1u);
    });
    lap(out->times.hash_ms);
    backend_.exclusive_scan_on_device(pos, leaves + 1);
    // The test stage reads the particles through the sorted index where the
    // backend hides scattered reads, else from a reordered copy (as the tree's).
    constexpr bool copy = B::kWalksReadReorderedCopy;
    PackedParticle* SP = sorted_particles_.data();
    uint32_t* sid = p_idx_sorted_.data();
    uint32_t* sleaf = p_key_sorted_.data();
    uint32_t* long_chunks = pos + leaves + 3;
    backend_.parallel_for(n_, [=] COLLIDO_HD(uint32_t i) {
      const uint32_t leaf = leaf_of[i];
      if (leaf == uint32_t(kOctreeEmpty)) return;
      const uint32_t at = pos[leaf] + rank[i];
      if (copy) SP[at] = P[i];
      sid[at] = i;
      sleaf[at] = leaf;
      if (leaf < long_leaves && rank[i] % kOctreeChunk == 0) atomic_add_u32(long_chunks, 1u);
    });
    // The chunks in leaf order (neighbouring warps then read neighbouring
    // leaves, which share triangles: the counter mesh's frame 0.32 -> 0.28 ms
    // against numbering them as they come).
    const uint32_t* located = pos + leaves;
    backend_.select_indices(
        n_,
        [=] COLLIDO_HD(uint32_t j) {
          return j < *located && (j - pos[sleaf[j]]) % kOctreeChunk == 0;
        },
        octree_chunk_.data(), pos + leaves + 1);
    lap(out->times.sort_ms);
  }
  static constexpr uint32_t kOctreeChunk = 32;  // a warp's lanes

  // octree, second half: a warp an item (one thread on the CPU), whose number
  // stays on the device. On the GPU each warp claims its next item from a
  // counter when it is done with one, and the long lists' items come first:
  // striding over them in a fixed order (warp w took items w, w + W, ...)
  // left the tiling's test stage at 20 % occupancy, its warps waiting on the
  // few that drew runs in long lists (465 -> 132 µs, docs/benchmarks.md). An item is a
  // chunk of one leaf's particles, or, where the chunks are small, a run of 32
  // grouped particles whose leaves it takes in turn. Its particles are read
  // one a lane in one coalesced read and handed round by shuffles. A leaf's
  // list longer than half a warp is tested a triangle a lane while its
  // particles pass; a shorter one 32 / T particles at a time, a lane a pair.
  // The lane that holds a particle sums its hits and writes its count: each
  // particle lies in one item. Each pair is met once; the pairs in float's
  // band wait for octree_doubts.
  void octree_traversal(bool collect) {
    const OctreeView ov = wall_.octree_view();
    const PackedParticle* SP = sorted_particles_.data();
    const PackedParticle* P = particles_.data();
    const uint32_t* sid = p_idx_sorted_.data();
    const uint32_t* sleaf = p_key_sorted_.data();
    const uint32_t* pos = leaf_pos_.data();
    const uint32_t* chunk = octree_chunk_.data();
    const uint32_t* chunks = pos + wall_.octree_leaves() + 1;
    const PlanarTriangle* T = wall_.tris.data();  // in the lists' slots
    const uint32_t* orig = wall_.tri_original.data();
    uint32_t* counts = counts_.data();
    const PairSink out = sink();
    const DoubtSink doubts = doubt_sink();
    const Narrow nw = narrow();
    uint32_t* band_total = band_counter();
    backend_.fill(counts, n_, 0u);
    constexpr bool copied = B::kWalksReadReorderedCopy;
    constexpr bool claims = !B::kHostThreads;  // the CPU's threads share items by chunks
    const uint32_t stride = backend_.strided_items(n_, kOctreeChunk);
    const uint32_t* located = pos + wall_.octree_leaves();
    uint32_t* next_item = leaf_pos_.data() + wall_.octree_leaves() + 2;
    const uint32_t* long_chunks = pos + wall_.octree_leaves() + 3;
    const uint32_t long_leaves = ov.long_leaves;
    if (claims) backend_.fill(next_item, 1, 0u);
    const uint64_t runs_below = cfg_.octree_runs_below;
    const float flat_cost = cfg_.octree_flat_cost;
    auto body = [=] COLLIDO_HD(uint32_t u, LaneGroup g) {
      uint32_t band = 0;
      // Chunks hold one leaf's particles each; where they hold few (the leaves are
      // many and small), runs of 32 in leaf order instead, a run's leaves in
      // turn. Not the long lists' leaves, which come first (sim/octree.h): their
      // chunks stay items of their own, the first ones, so a run of 32
      // particles in 32 long lists does not keep one warp busy while the others
      // have finished (the tiling's test stage at 20 % occupancy).
      const bool runs = *located < runs_below * *chunks;
      const uint32_t first_chunks = runs ? *long_chunks : *chunks;
      const uint32_t runs_from = runs ? pos[long_leaves] : 0u;  // the short lists' particles
      const uint32_t items =
          first_chunks + (runs ? (*located - runs_from + kOctreeChunk - 1) / kOctreeChunk : 0u);
      // Every lane shuffles (lane 0 claims for the warp).
      auto claim = [&] { return g.from(0, g.lane == 0 ? atomic_add_u32(next_item, 1u) : 0u); };
      for (uint32_t c = claims ? claim() : u; c < items; c = claims ? claim() : c + stride) {
        const bool run = c >= first_chunks;
        const uint32_t j0 = run ? runs_from + (c - first_chunks) * kOctreeChunk : chunk[c];
        const uint32_t jend = run ? hd_min(*located, j0 + kOctreeChunk)
                                  : hd_min(pos[sleaf[j0] + 1], j0 + kOctreeChunk);
        for (uint32_t jb = j0; jb < jend; jb += g.size) {  // once on the GPU
          const uint32_t m = hd_min(g.size, jend - jb);
          // This lane's particle, then particle k's from lane k (one lane: k == 0).
          const bool holds = g.lane < m;
          const uint32_t mine_i = holds ? sid[jb + g.lane] : 0u;
          PackedParticle mine{};
          if (holds) mine = copied ? SP[jb + g.lane] : P[mine_i];
          auto particle = [&](uint32_t k) {
            return PackedParticle{g.from(k, mine.x), g.from(k, mine.y), g.from(k, mine.z),
                                  g.from(k, mine.r)};
          };
          uint32_t mine_hits = 0;
          // A run's leaves hold a particle or two: their pairs may be flattened,
          // each lane a pair in turn (pair q's particle is the first lane whose
          // lists end past q), so that no lane idles on a short leaf. Lane k
          // holds its particle's list, and where its pairs begin and end.
          const uint32_t mine_leaf = run && holds ? sleaf[jb + g.lane] : ~0u;
          const OctreeView::List mine_list =
              run && holds ? ov.list(mine_leaf) : OctreeView::List{0, 0, 0};
          uint32_t ends = 0, begins = 0, pairs = 0;
          bool flat = false;
          if (run) {  // and the rounds leaf by leaf, counted by each leaf's first lane
            ends = g.scan(mine_list.count), begins = ends - mine_list.count;
            pairs = g.from(g.size - 1, ends);
            const uint32_t before_leaf = g.from(g.lane ? g.lane - 1 : 0u, mine_leaf);
            const bool first = holds && (g.lane == 0 || before_leaf != mine_leaf);
            const uint32_t firsts = g.bits(first), nt = mine_list.count;
            const uint32_t after = firsts & ~((2u << g.lane) - 1u);
            const uint32_t k = (after ? LaneGroup::lowest(after) : m) - g.lane;
            const uint32_t rounds = !first || nt == 0 ? 0u
                                    : 2 * nt > g.size
                                        ? (nt + g.size - 1) / g.size * k
                                        : (k + g.size / nt - 1) / (g.size / nt);
            flat = flat_cost * float((pairs + g.size - 1) / g.size) < float(g.sum(rounds));
          }
          if (flat) {
            for (uint32_t qb = 0; qb < pairs; qb += g.size) {
              const uint32_t q = qb + g.lane;
              uint32_t k = 0;
              for (uint32_t step = g.size >> 1; step > 0; step >>= 1)
                if (g.from(k + step - 1, ends) <= q) k += step;
              const bool pair = q < pairs;
              k = hd_min(k, g.size - 1);
              // Every lane shuffles: a shuffle in a branch that some lanes skip
              // is undefined (it failed every such frame on the H200).
              const OctreeView::List list{g.from(k, mine_list.start), 0u, g.from(k, mine_list.base)};
              const uint32_t its_begin = g.from(k, begins);
              const uint32_t t = pair ? ov.slot(list, q - its_begin) : 0u;
              const PackedParticle p = particle(k);
              const uint32_t i = g.from(k, mine_i);
              const PlanarTriangle tri = T[t];
              float d = 0;
              const auto v = pair ? nw.judge(p, tri, &d, &band) : Narrow::kOut;
              if (v == Narrow::kIn && collect) out.push(i, orig[t], d);
              if (v == Narrow::kDoubt) doubts.push(i, t);
              // This lane's particle's pairs in the round: lanes [lo, hi).
              const uint32_t bits = g.bits(v == Narrow::kIn);
              if (ends > qb && begins < qb + g.size) {
                const uint32_t lo = hd_max(begins, qb) - qb, hi = hd_min(ends, qb + g.size) - qb;
                const uint32_t below_hi = hi >= 32 ? ~0u : (1u << hi) - 1u;
                mine_hits += hd_popcount(bits & below_hi & ~((1u << lo) - 1u));
              }
            }
          } else {
            // The batch's particles by leaf: lanes k0 .. k1 - 1 hold one leaf's.
            for (uint32_t k0 = 0; k0 < m;) {
              const uint32_t leaf = sleaf[jb + k0];
              const uint32_t k1 = hd_min(m, pos[leaf + 1] - jb);
              const OctreeView::List list = ov.list(leaf);
              const uint32_t nt = list.count;
              if (2 * nt > g.size || nt == 0) {
                for (uint32_t tb = 0; tb < nt; tb += g.size) {
                  const uint32_t ti = tb + g.lane;
                  const bool have = ti < nt;
                  const uint32_t t = have ? ov.slot(list, ti) : 0u;
                  const PlanarTriangle tri = T[t];
                  for (uint32_t k = k0; k < k1; ++k) {
                    const PackedParticle p = particle(k);
                    const uint32_t i = g.from(k, mine_i);
                    float d = 0;
                    const auto v = have ? nw.judge(p, tri, &d, &band) : Narrow::kOut;
                    if (v == Narrow::kIn && collect) out.push(i, orig[t], d);
                    if (v == Narrow::kDoubt) doubts.push(i, t);
                    const uint32_t hits = g.count(v == Narrow::kIn);
                    if (g.lane == k) mine_hits += hits;
                  }
                }
              } else {
                const uint32_t per = g.size / nt, group = g.lane / nt, ti = g.lane - group * nt;
                const bool have = group < per;
                const uint32_t t = have ? ov.slot(list, ti) : 0u;
                const PlanarTriangle tri = T[t];
                for (uint32_t kb = k0; kb < k1; kb += per) {
                  const uint32_t k = kb + group;
                  const bool pair = have && k < k1;
                  const PackedParticle p = particle(pair ? k : 0u);
                  const uint32_t i = g.from(pair ? k : 0u, mine_i);
                  float d = 0;
                  const auto v = pair ? nw.judge(p, tri, &d, &band) : Narrow::kOut;
                  if (v == Narrow::kIn && collect) out.push(i, orig[t], d);
                  if (v == Narrow::kDoubt) doubts.push(i, t);
                  // The lane that holds particle kb + q counts group q's hits.
                  const uint32_t bits = g.bits(v == Narrow::kIn);
                  if (g.lane >= kb && g.lane < kb + per)
                    mine_hits += hd_popcount((bits >> ((g.lane - kb) * nt)) & ((1u << nt) - 1u));
                }
              }
              k0 = k1;
            }
          }
          if (holds && mine_hits) counts[mine_i] = mine_hits;
        }
      }
      if (band) atomic_add_u32(band_total, band);
    };
    // 58-66 registers a thread: capped at 64, four blocks an SM instead of three
    // (the counter's frame 0.32 -> 0.30 ms, the small icosphere's 0.37 -> 0.33).
    backend_.parallel_for_lanes_light(stride, kOctreeChunk, body);
  }

  // octree, the pairs the test stage left in doubt, each in double (apart so
  // that the test stage's threads do not carry the double path's registers:
  // 128 with it, 56 without). Their count stays on the device; a frame whose
  // doubts passed the buffer runs again with a larger one (detect()).
  void octree_doubts(bool collect) {
    const uint64_t* key = doubt_key_.data();  // particle << 32 | the triangle's slot
    const uint32_t* orig = wall_.tri_original.data();
    const uint32_t* held = pair_counter_.data() + 3;
    uint32_t* counts = counts_.data();
    const PairSink out = sink();
    const Narrow nw = narrow();
    backend_.parallel_for(doubt_capacity_, [=] COLLIDO_HD(uint32_t j) {
      if (j >= *held) return;
      const uint32_t i = uint32_t(key[j] >> 32), t = orig[uint32_t(key[j])];
      float d = 0;
      if (!nw.decide_exactly(i, t, &d)) return;
      atomic_add_u32(&counts[i], 1u);
      if (collect) out.push(i, t, d);
    });
  }

  // bin, wall traversal: a thread per (cell, triangle) entry loops over the
  // particles of that cell. Each pair is met once, so no deduplication is needed.
  void bin_wall_traversal() {
    const GridSpec g = wall_.grid;
    const PackedParticle* SP = sorted_particles_.data();
    const uint32_t* sidx = p_idx_sorted_.data();
    const PlanarTriangle* T = wall_.tris.data();
    const uint32_t* tri = wall_.bin_tri.data();
    const uint64_t* cellk = wall_.bin_cell.data();
    const uint32_t* pstart = p_cell_start_.data();
    const uint32_t* pend = p_cell_end_.data();
    const PairSink out = sink();
    const Narrow nw = narrow();
    uint32_t* band_total = band_counter();
    backend_.parallel_for(info_.bin_entries, [=] COLLIDO_HD(uint32_t k) {
      const uint64_t l = cellk[k];
      const uint32_t b = g.bucket(l);
      const uint32_t t = tri[k];
      const PlanarTriangle tr = T[t];
      uint32_t band = 0;
      for (uint32_t j = pstart[b], e = pend[b]; j < e; ++j) {
        const PackedParticle p = SP[j];
        if (g.hashed && !g.holds(position(p), l)) continue;
        float d = 0;
        if (nw.decide(p, tr, sidx[j], t, &d, &band)) out.push(sidx[j], t, d);
      }
      if (band) atomic_add_u32(band_total, band);
    });
  }

  // Divided pieces, particle traversal (paper 3.6): a thread per particle
  // loops over the pieces of its neighbouring cells and emits every hit.
  // Several pieces of one original may touch the particle; the pairs are
  // deduplicated afterwards, as for the wall traversal, which keeps the
  // smallest distance and needs no per-thread memory however many originals meet.
  void pieces_particle_traversal() {
    const GridSpec g = wall_.grid;
    const int reach = wall_.reach;
    const PackedParticle* SP = sorted_particles_.data();
    const uint32_t* skey = p_key_sorted_.data();
    const uint32_t* sidx = p_idx_sorted_.data();
    const PlanarTriangle* T = wall_.tris.data();
    const uint32_t* orig = wall_.tri_original.data();
    const uint64_t* tcell = wall_.tri_cell.data();
    const uint32_t* tstart = wall_.tri_start.data();
    const uint32_t* tend = wall_.tri_end.data();
    const PairSink out = sink();
    const Narrow nw = narrow();
    uint32_t* band_total = band_counter();
    backend_.parallel_for(n_, [=] COLLIDO_HD(uint32_t j) {
      if (skey[j] == kInvalidBucket) return;
      const uint32_t i = sidx[j];
      const PackedParticle p = SP[j];
      const Vec3f c = position(p);
      uint32_t band = 0;
      int cx = 0, cy = 0, cz = 0;
      g.cell_of(c, cx, cy, cz);
      g.for_each_neighbour(cx, cy, cz, reach, [&](uint64_t l, uint32_t b) {
        for (uint32_t k = tstart[b], e = tend[b]; k < e; ++k) {
          if (g.hashed && tcell[k] != l) continue;
          float d = 0;
          if (nw.decide(p, T[k], i, orig[k], &d, &band)) out.push(i, orig[k], d);
        }
      });
      if (band) atomic_add_u32(band_total, band);
    });
  }

  // Divided pieces, wall traversal: a thread per piece loops over the
  // particles of its neighbouring cells and emits every hit; pieces of one
  // original meet the same particle, so the pairs are deduplicated afterwards.
  void pieces_wall_traversal() {
    const GridSpec g = wall_.grid;
    const int reach = wall_.reach;
    const PackedParticle* SP = sorted_particles_.data();
    const uint32_t* sidx = p_idx_sorted_.data();
    const PlanarTriangle* T = wall_.tris.data();
    const uint32_t* orig = wall_.tri_original.data();
    const uint64_t* tcell = wall_.tri_cell.data();
    const uint32_t* pstart = p_cell_start_.data();
    const uint32_t* pend = p_cell_end_.data();
    const PairSink out = sink();
    const Narrow nw = narrow();
    uint32_t* band_total = band_counter();
    backend_.parallel_for(info_.triangles_used, [=] COLLIDO_HD(uint32_t k) {
      const PlanarTriangle& tr = T[k];
      const uint32_t o = orig[k];
      uint32_t band = 0;
      int cx = 0, cy = 0, cz = 0;
      g.unlinear(tcell[k], cx, cy, cz);
      g.for_each_neighbour(cx, cy, cz, reach, [&](uint64_t l, uint32_t b) {
        for (uint32_t j = pstart[b], e = pend[b]; j < e; ++j) {
          const PackedParticle p = SP[j];
          if (g.hashed && !g.holds(position(p), l)) continue;
          float d = 0;
          if (nw.decide(p, tr, sidx[j], o, &d, &band)) out.push(sidx[j], o, d);
        }
      });
      if (band) atomic_add_u32(band_total, band);
    });
  }

  void counts_from_pairs(uint32_t unique) {
    uint32_t* counts = counts_.data();
    const uint64_t* key = pair_key2_.data();
    backend_.fill(counts, n_, 0u);
    backend_.parallel_for(
        unique, [=] COLLIDO_HD(uint32_t k) { atomic_add_u32(&counts[key[k] >> 32], 1u); });
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
      out->contacts[k] = {static_cast<uint32_t>(keys[k] >> 32), source_ids_[keys[k] & 0xFFFFFFFFu],
                          dist[k]};
    // Source ids follow the input file's order, which welding and dropping may
    // have permuted relative to mesh indices: sort by the ids the user sees.
    std::sort(out->contacts.begin(), out->contacts.end(), [](const Contact& a, const Contact& b) {
      return a.particle != b.particle ? a.particle < b.particle : a.triangle < b.triangle;
    });
  }

  B backend_;
  size_t capacity_ = 0, n_ = 0;
  std::vector<uint32_t> source_ids_;
  std::vector<PackedParticle> staging_;  // host copy of a frame's particles, reused
  std::vector<ParticleD> staging_d_;     // the same in world double (precision exact)
  Buf<ParticleD> particles_d_;
  Buf<Vec3d> vertices_exact_;    // the mesh's vertices, world double
  Buf<uint32_t> corners_exact_;  // three vertex indices per triangle, mesh order

  WallIndex<B> wall_;

  Buf<PackedParticle> particles_, sorted_particles_;
  Buf<uint32_t> p_key_, p_idx_, p_key_sorted_, p_idx_sorted_, p_cell_start_, p_cell_end_, counts_;
  // octree: each particle's leaf, then each chunk's first sorted place
  Buf<uint32_t> octree_chunk_;
  // octree: the leaves' particle counts, then their starts (leaves + 1); the chunks' count
  Buf<uint32_t> leaf_pos_;

  Buf<uint64_t> pair_key_, pair_key2_;
  Buf<float> pair_dist_, pair_dist2_;
  Buf<uint32_t> pair_counter_;
  Buf<uint64_t> doubt_key_;  // octree: the pairs in doubt, particle << 32 | the triangle's slot
  size_t doubt_capacity_ = 0;
  size_t pair_capacity_ = 0;
  uint32_t pair_count_host_ = 0;
  bool pair_overflow_ = false;  // the frame's pairs passed pair_limit()
};

}  // namespace collido::sim
