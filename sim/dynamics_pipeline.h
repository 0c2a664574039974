// The dynamics, written once and instantiated for each backend
// (sim/dynamics.cpp for the CPU, sim/dynamics_cuda.cu for the GPU). Every loop
// body is a COLLIDO_HD lambda; the state stays on the backend for the whole
// run and only per-frame statistics (a few reductions) come back.
//
// A step: release waiting particles -> (Verlet) half kick and drift ->
// particle grid (only with particle-particle contacts) -> forces (wall
// contacts one per feature, particle pairs, gravity) -> kick (and, for
// symplectic Euler, drift) -> finite and domain checks.
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <type_traits>
#include <vector>

#include "sim/cell_ranges.h"
#include "sim/contact_force.h"
#include "sim/dynamics.h"
#include "sim/pair_batch.h"
#include "sim/wall_index.h"

namespace collido::sim {

// Wall contacts kept per particle per step (a sphere in the corner of a box touches three).
inline constexpr int kMaxWallContacts = 4;
// Friction springs remembered per particle: one per wall contact, and up to
// kPairSlots neighbours (a settled pile has about six; more are counted as overflow).
inline constexpr int kWallSlots = kMaxWallContacts;
inline constexpr int kPairSlots = 8;
// Waiting particles the neighbour lists hold at least, past the live ones (see list_cover).
inline constexpr size_t kCoverAhead = 64;
// The listed pairs of a batch of the CPU's vector pair pass (see batch_end).
inline constexpr uint32_t kBatchPairs = 48;
// An automatic skin grows when a list lived fewer steps than this, up to this
// share of the smallest radius (the bound of the automatic choice; grow_skin_after).
inline constexpr uint64_t kShortListSteps = 3;
inline constexpr double kMaxSkinShare = 0.5;

// Per-particle statistics columns filled by a measuring pass, reduced per frame.
enum StatColumn : size_t {
  kStatElasticWall,
  kStatElasticPair,
  kStatOverlapWall,
  kStatOverlapPair,
  kStatWallContacts,
  kStatPairContacts,
  kStatTouching,
  kStatOverflowWall,
  kStatOverflowPair,
  kStatKinetic,
  kStatPotential,
  kStatSpeed,
  kStatWaiting,
  kStatHeld,  // due by the releases decided, waiting for its place (see takes_place)
  kStatActive,
  kStatEscaped,
  kStatInvalid,
  kStatColumns
};

// reorder_by_cell moves the widest per-particle record through the statistics scratch.
static_assert(kPairSlots * sizeof(FrictionSlot) <= kStatColumns * sizeof(double) &&
                  kWallSlots * sizeof(FrictionSlot) <= kStatColumns * sizeof(double) &&
                  sizeof(Vec3d) <= kStatColumns * sizeof(double),
              "a particle's record must fit its statistics scratch");

template <class B>
class DynamicsPipeline final : public Simulation {
  template <class T>
  using Buf = typename B::template Buffer<T>;

 public:
  static Expected<std::unique_ptr<Simulation>> make(const TriangleMesh& mesh,
                                                    const DynamicsConfig& cfg,
                                                    const ParticleSet& particles,
                                                    const TimeStepInfo& ts, Vec3d domain_lo,
                                                    Vec3d domain_hi) {
    auto s = std::unique_ptr<DynamicsPipeline>(new DynamicsPipeline(cfg, ts));
    if (Status e = s->init(mesh, particles, domain_lo, domain_hi); !e) return e;
    return std::unique_ptr<Simulation>(std::move(s));
  }

  const TimeStepInfo& time_step_info() const override { return ts_; }
  void set_stage_timing(bool on) override {
    timing_ = on;
    times_ = StepTimes{};
  }
  const StepTimes& stage_times() const override { return times_; }
  const PrepareInfo& wall_info() const override { return info_; }
  double time() const override { return time_; }
  uint64_t steps_taken() const override { return steps_; }
  uint64_t device_bytes() const override { return backend_.bytes_held(); }
  int step_threads() const override { return backend_.threads(); }

  Status step(uint64_t steps, double dt) override {
    if (!(dt > 0) || !std::isfinite(dt))
      return invalid_argument("time step must be positive, got " + std::to_string(dt));
    const uint64_t last = steps_ + steps;
    do {
      while (steps_ < last) {
        one_step(dt);
        if (window_.size() >= window_steps()) settle_window();
      }
    } while (settle_window());  // a step voided by a build is taken again
    close_pending_step();
    backend_.sync();
    return backend_.status();
  }

  Status advance(double duration, FrameStats* stats) override {
    if (!(duration > 0) || !std::isfinite(duration))
      return invalid_argument("frame duration must be positive, got " + std::to_string(duration));
    const double end = time_ + duration;
    const uint64_t first = steps_;
    double dt_min = 1e300, dt_max = 0, dt = 0, travel = 0, fastest = 0;
    bool checked = false;
    uint64_t checked_at = 0;
    // The fastest speed is read every few steps: it sizes the automatic step
    // and, with a fixed one, tells how far a step carries a particle.
    const auto speed_check_due = [&] {
      return !checked || steps_ - checked_at >= uint64_t(kSpeedCheckInterval);
    };
    // A step taken again after a build (settle_window) starts where the first
    // try did, so it is given the same length: the steps do not depend on
    // whether they ran ahead.
    for (;;) {
      if (!(time_ < end * (1 - 1e-15) && end - time_ > 1e-300)) {
        if (settle_window()) continue;
        break;
      }
      if (speed_check_due()) {
        double vmax = 0;
        if (settle_window_and_fastest(&vmax)) continue;
        dt = ts_.explicit_step > 0 ? ts_.explicit_step : automatic_step(vmax);
        if (ts_.r_min > 0) travel = std::max(travel, vmax * dt / ts_.r_min);
        fastest = std::max(fastest, vmax);
        checked = true, checked_at = steps_;
      }
      const double remaining = end - time_;
      // Land exactly on the frame's end: split what remains into equal steps.
      const double steps_left = std::ceil(remaining / dt * (1 - 1e-12));
      const double h = steps_left <= 1 ? remaining : remaining / steps_left;
      if (!one_step(h)) continue;  // stepped back: the steps from there again
      // A full window is settled now, unless the speed check comes next: it
      // settles the window in the same wait (settle_window_and_fastest).
      if (window_.size() >= window_steps() && !speed_check_due()) settle_window();
      dt_min = std::min(dt_min, h), dt_max = std::max(dt_max, h);
      if (Status e = backend_.status(); !e) return e;
    }
    const uint64_t substeps = steps_ - first;
    if (Status e = measure(stats); !e) return e;
    stats->substeps = substeps;
    stats->dt_min = substeps ? dt_min : 0;
    stats->dt_max = dt_max;
    stats->peak_travel = travel;
    stats->peak_speed = std::max(fastest, stats->max_speed);
    return Status::ok();
  }

  Status measure(FrameStats* st) override {
    close_pending_step();
    *st = FrameStats{};
    st->time = time_;
    if (n_ == 0) return backend_.status();
    // Candidates as the positions are now (symplectic Euler drifted after the last step's).
    update_candidates();
    forces(0.0, /*measure=*/true, time_);
    kinematics_stats();
    // The columns and, last, the deepest wall overlap of any step since the
    // last measure, in one reduction.
    const double* columns[kStatColumns + 1];
    for (size_t c = 0; c < kStatColumns; ++c) columns[c] = scratch_.data() + c * n_;
    columns[kStatColumns] = peak_overlap_.data();
    const unsigned long long largest = (1ull << kStatOverlapWall) | (1ull << kStatOverlapPair) |
                                       (1ull << kStatSpeed) | (1ull << kStatColumns);
    double col[kStatColumns + 1];
    backend_.reduce_columns(columns, kStatColumns + 1, live_, largest, col);
    col[kStatWaiting] += double(n_ - live_);  // beyond the live prefix every particle waits
    // Every particle is out once none is due after the releases decided and none due waits.
    if (!all_released_ && released_to_ >= last_release_ && col[kStatHeld] < 0.5)
      all_released_ = true;
    st->elastic = col[kStatElasticWall] + col[kStatElasticPair];
    st->max_overlap = std::max(col[kStatOverlapWall], col[kStatOverlapPair]);
    st->wall_contacts = static_cast<uint64_t>(col[kStatWallContacts] + 0.5);
    st->particle_contacts =
        static_cast<uint64_t>(col[kStatPairContacts] * 0.5 + 0.5);  // each pair seen twice
    st->touching_wall = static_cast<uint64_t>(col[kStatTouching] + 0.5);
    st->kinetic = col[kStatKinetic];
    st->potential = col[kStatPotential];
    st->max_speed = col[kStatSpeed];
    st->waiting = static_cast<uint64_t>(col[kStatWaiting] + 0.5);
    st->held = static_cast<uint64_t>(col[kStatHeld] + 0.5);
    st->active = static_cast<uint64_t>(col[kStatActive] + 0.5);
    st->escaped = static_cast<uint64_t>(col[kStatEscaped] + 0.5);
    st->invalid = static_cast<uint64_t>(col[kStatInvalid] + 0.5);
    st->history_overflow =
        static_cast<uint64_t>(col[kStatOverflowWall] + col[kStatOverflowPair] + 0.5);
    // The deepest wall overlap of any step since the last measure, then a fresh start.
    st->peak_wall_overlap = std::max(col[kStatOverlapWall], col[kStatColumns]);
    backend_.fill(peak_overlap_.data(), live_, 0.0);
    return backend_.status();
  }

  Status save_state(SimState* out) override {
    close_pending_step();
    out->particles = n_;
    out->time = time_;
    out->steps = steps_;
    out->all_released = all_released_;
    out->arrays.clear();
    state_arrays([&](auto& buf, size_t count) {
      std::vector<uint8_t> bytes(count * sizeof(*buf.data()));
      if (count) backend_.to_host(bytes.data(), buf.data(), bytes.size());
      out->arrays.push_back(std::move(bytes));
      return true;
    });
    save_lists(&out->lists);
    return backend_.status();
  }

  Status restore_state(const SimState& in) override {
    if (in.particles != n_)
      return invalid_argument("checkpoint holds " + std::to_string(in.particles) +
                              " particles, the run has " + std::to_string(n_));
    size_t k = 0;
    const bool fits = state_arrays([&](auto& buf, size_t count) {
      if (k >= in.arrays.size() || in.arrays[k].size() != count * sizeof(*buf.data()))
        return false;
      if (count) backend_.to_device(buf.data(), in.arrays[k].data(), in.arrays[k].size());
      ++k;
      return true;
    });
    if (!fits || k != in.arrays.size())
      return invalid_argument("checkpoint does not match this run's settings (friction, particle "
                              "contacts or integrator differ)");
    // The constant arrays in the restored numbering.
    const std::vector<uint32_t> order = host_order();
    for (uint32_t i : order)
      if (i >= n_) return invalid_argument("checkpoint holds a particle order that is not one");
    upload_in_order(order);
    // Every particle the saved run released was due by its time; a checkpoint
    // numbered otherwise than by release (an older one) just keeps a longer prefix.
    live_ = 0;
    grow_live(in.time);
    time_ = in.time;
    steps_ = in.steps;
    all_released_ = in.all_released;
    // Unknown: held particles count from the next step's releases on.
    released_to_ = -std::numeric_limits<double>::infinity();
    close_pending_ = false;  // the restored state is a whole step's
    disp_fresh_ = false;
    restore_lists(in.lists);
    backend_.sync();
    return backend_.status();
  }

  Status download(ParticleSet* out, std::vector<uint8_t>* flags) override {
    close_pending_step();
    std::vector<Vec3d> p(n_), v(n_);
    const std::vector<uint32_t> order = host_order();
    if (n_) {
      backend_.to_host(p.data(), pos_.data(), n_ * sizeof(Vec3d));
      backend_.to_host(v.data(), vel_.data(), n_ * sizeof(Vec3d));
    }
    // In the caller's numbering (the engine's follows the cells, see reorder_by_cell).
    out->resize(n_);
    for (size_t k = 0; k < n_; ++k) {
      const size_t i = order[k];
      out->x[i] = p[k].x + wall_.origin.x, out->y[i] = p[k].y + wall_.origin.y,
      out->z[i] = p[k].z + wall_.origin.z;
      out->vx[i] = v[k].x, out->vy[i] = v[k].y, out->vz[i] = v[k].z;
      out->r[i] = radius_host_[i];
      out->release[i] = release_host_[i];
    }
    if (flags) {
      std::vector<uint8_t> f(n_);
      if (n_) backend_.to_host(f.data(), flags_.data(), n_);
      flags->resize(n_);
      for (size_t k = 0; k < n_; ++k) (*flags)[order[k]] = f[k];
    }
    return backend_.status();
  }

 private:
  DynamicsPipeline(const DynamicsConfig& cfg, const TimeStepInfo& ts) : cfg_(cfg), ts_(ts) {
    backend_.set_pool(cfg.pool);
  }

  // --- set-up ---------------------------------------------------------------------------------
 public:  // nvcc's extended lambdas may not live in private member functions
  Status init(const TriangleMesh& mesh, const ParticleSet& ps, Vec3d domain_lo, Vec3d domain_hi) {
    n_ = ps.size();
    const double cell = cfg_.grid_length > 0 ? cfg_.grid_length : 2 * ts_.r_max;
    info_.grid_length = cell;
    // A moving part gets an index of its own, in its own frame; the rest stands still.
    const WallMotion& wm = cfg_.wall_motion;
    part_ = wm.moves_part();
    const TriangleMesh still =
        part_ ? mesh_range(mesh, wm.part_begin, wm.part_end, false) : TriangleMesh{};
    if (Status e = wall_.prepare(backend_, part_ ? still : mesh, cfg_.method, ts_.r_max, cell,
                                 cfg_.max_dense_cells, n_, &info_,
                                 /*double_triangles=*/true);
        !e)
      return e;
    if (part_) {
      PrepareInfo pi;
      if (Status e = mover_.prepare(backend_, mesh_range(mesh, wm.part_begin, wm.part_end, true),
                                    cfg_.method, ts_.r_max, cell, cfg_.max_dense_cells, n_, &pi,
                                    /*double_triangles=*/true);
          !e)
        return e;
      info_.triangles_original += pi.triangles_original;
      info_.triangles_used += pi.triangles_used;
      info_.cells += pi.cells;
      info_.buckets += pi.buckets;
      info_.bin_entries += pi.bin_entries;
      info_.bvh_nodes += pi.bvh_nodes;
      info_.max_sphere_radius = std::max(info_.max_sphere_radius, pi.max_sphere_radius);
      shift_ = wall_.origin - mover_.origin;
    }
    // A step of a small scene is a few microseconds a pass: a second thread's
    // share of it costs more in moving the particles' data between the cores
    // than it saves (a block of 1,000 with pairs, 2-core VM: 0.054 ms a step on
    // one thread, 0.064-0.067 on two; 2,000: 0.115 against 0.088), and when the
    // second core is busy with another process every pass waits for it (a pour
    // of 323: 1.67 s on one thread, 2.6-3.3 s on two). The wall's preparation
    // above keeps the caller's threads.
    if (B::kHostThreads && n_ < cfg_.one_thread_below) {
      one_thread_ = std::make_unique<ThreadPool>(1);
      backend_.set_pool(one_thread_.get());
    }
    lo_ = domain_lo - wall_.origin, hi_ = domain_hi - wall_.origin;
    pair_law_ = ts_.pair_law;
    wall_law_ = ts_.wall_law;
    // Spins are followed once any contact has friction (rolling resistance acts on them).
    rotation_ = wall_law_.mu > 0 || (cfg_.particle_contacts && pair_law_.mu > 0);

    radius_host_ = ps.r;
    release_host_ = ps.release;
    last_release_ = n_ ? *std::max_element(ps.release.begin(), ps.release.end()) : 0.0;
    all_released_ = !(last_release_ > 0);  // every particle moves from the start
    // Numbered in the order of release, so the released particles are a
    // prefix: the passes of a step skip those still waiting at an inlet (a
    // pour spent a quarter of its time on them) and releasing extends the prefix.
    std::vector<uint32_t> order(n_);
    for (size_t i = 0; i < n_; ++i) order[i] = uint32_t(i);
    std::stable_sort(order.begin(), order.end(),
                     [&](uint32_t a, uint32_t b) { return ps.release[a] < ps.release[b]; });
    std::vector<Vec3d> p(n_), v(n_);
    std::vector<uint8_t> state(n_);
    for (size_t k = 0; k < n_; ++k) {
      const size_t i = order[k];
      p[k] = Vec3d{ps.x[i], ps.y[i], ps.z[i]} - wall_.origin;
      v[k] = {ps.vx[i], ps.vy[i], ps.vz[i]};
      state[k] = ps.release[i] > 0 ? kWaiting : kActive;
    }
    upload(pos_, p);
    upload(vel_, v);
    upload(state_, state);
    upload(order_, order);
    upload_in_order(order);
    backend_.resize(flags_, std::max<size_t>(n_, 1));
    backend_.fill(flags_.data(), n_, uint8_t(0));
    backend_.resize(acc_, std::max<size_t>(n_, 1));
    backend_.fill(acc_.data(), n_, Vec3d{0, 0, 0});
    backend_.resize(speed_, std::max<size_t>(n_, 1));
    backend_.fill(speed_.data(), n_, 0.0);  // saved with the state, waiting ones too
    backend_.resize(peak_overlap_, std::max<size_t>(n_, 1));
    backend_.fill(peak_overlap_.data(), std::max<size_t>(n_, 1), 0.0);
    backend_.resize(scratch_, std::max<size_t>(n_ * kStatColumns, 1));
    backend_.fill(scratch_.data(), n_ * kStatColumns,
                  0.0);  // pair columns stay 0 without pair contacts
    if (rotation_) {
      backend_.resize(omega_, std::max<size_t>(n_, 1));
      backend_.resize(alpha_, std::max<size_t>(n_, 1));
      backend_.fill(omega_.data(), n_, Vec3d{0, 0, 0});
      backend_.fill(alpha_.data(), n_, Vec3d{0, 0, 0});
      for (int k = 0; k < 2; ++k) {
        backend_.resize(wall_hist_[k], std::max<size_t>(n_ * kWallSlots, 1));
        backend_.fill(wall_hist_[k].data(), n_ * kWallSlots, FrictionSlot{kNoKey, 0, 0, 0});
        if (!cfg_.particle_contacts) continue;
        backend_.resize(pair_hist_[k], std::max<size_t>(n_ * kPairSlots, 1));
        backend_.fill(pair_hist_[k].data(), n_ * kPairSlots, FrictionSlot{kNoKey, 0, 0, 0});
      }
    }
    // Candidates kept in lists with a skin: the particle pairs, and the
    // wall's triangles where the wall stands still (a moving wall moves under
    // particles that stand still, so its candidates are searched every step).
    skin_ = ts_.neighbour_skin;
    wall_list_ = skin_ > 0 && !cfg_.wall_motion.moving() &&
                 (cfg_.particle_contacts || wall_lists_without_pairs(cfg_));
    nlist_ = cfg_.particle_contacts && skin_ > 0;
    lists_ = nlist_ || wall_list_;
    if (lists_) backend_.resize(x_ref_, std::max<size_t>(n_, 1));
    if (wall_list_) {
      backend_.resize(wl_start_, n_ + 1);
      backend_.resize(wl_count_, std::max<size_t>(n_, 1));
    }
    if (cfg_.particle_contacts) {
      make_particle_grid();
      if (nlist_) {
        once_ = cfg_.pairs_once < 0 ? B::kPairForcesOncePerPair : cfg_.pairs_once == 1;
        backend_.resize(nl_start_, n_ + 1);
        backend_.resize(lo_start_, n_ + 1);
      }
      backend_.resize(p_key_, std::max<size_t>(n_, 1));
      backend_.resize(p_idx_, std::max<size_t>(n_, 1));
      backend_.resize(p_key_sorted_, std::max<size_t>(n_, 1));
      backend_.resize(p_idx_sorted_, std::max<size_t>(n_, 1));
      backend_.resize(sorted_, std::max<size_t>(n_, 1));
      // Float filter slack: rounding of coordinates up to the domain's size, and of the radii.
      const Vec3d ext = hi_ - lo_;
      filter_slack_ =
          float(4e-7 * (std::fabs(lo_.x) + std::fabs(lo_.y) + std::fabs(lo_.z) + length(ext)) +
                1e-5 * ts_.r_max);
    }
    // Forces of the initial state, so the first Verlet half kick has them.
    grow_live(0.0);
    update_candidates();
    forces(0.0, false, 0.0);
    if (rotation_) swap_history();
    speeds();
    backend_.sync();
    return backend_.status();
  }

  // The particle grid for cells of 2 r_max + the skin: its buckets, their ranges'
  // buffers and the radix sort's key bits. Only particle contacts have one.
  void make_particle_grid() {
    if (!cfg_.particle_contacts) return;
    uint64_t cells = 0;
    // A dense table up to a few cells per particle: hashed buckets cost a filter on every read.
    pgrid_ = make_grid(lo_, hi_, 2 * ts_.r_max + skin_,
                       std::max<uint64_t>(cfg_.max_dense_cells, 8 * uint64_t(n_)), n_, &cells);
    backend_.resize(cell_start_, pgrid_.buckets);
    backend_.resize(cell_end_, pgrid_.buckets);
    backend_.fill(cell_start_.data(), pgrid_.buckets, 0u);  // then cleared bucket by bucket
    backend_.fill(cell_end_.data(), pgrid_.buckets, 0u);
    grid_keys_ = 0;
    // Radix passes over the bits a bucket number (or the `none` key, buckets) needs.
    pkey_bits_ = 1;
    while (pkey_bits_ < 32 && (uint64_t(1) << pkey_bits_) <= pgrid_.buckets) ++pkey_bits_;
  }

  // An automatic skin doubles (up to kMaxSkinShare of the smallest radius, the
  // grid's cells growing with it) when a list lived fewer than kShortListSteps
  // steps: particles faster than the scene's expected impacts (a jet piling up,
  // a particle thrown off a deep overlap) moved half of it every step, and each
  // build cost more than the list saved. A skin given in the scene stays.
  void grow_skin_after(uint64_t list_steps) {
    if (!(cfg_.neighbour_skin < 0) || list_steps >= kShortListSteps) return;
    const double cap = kMaxSkinShare * ts_.r_min;
    if (!(skin_ < cap)) return;
    skin_ = std::min(2 * skin_, cap);
    ts_.neighbour_skin = skin_;
    make_particle_grid();
  }

  // Calls f(buffer, element count) for every buffer of the changing state, in
  // one fixed order (save_state and restore_state walk it alike); stops at the
  // first f that returns false and says whether all were visited.
  template <class F>
  bool state_arrays(F&& f) {
    bool ok = f(pos_, n_) && f(vel_, n_) && f(acc_, n_) && f(state_, n_) && f(flags_, n_) &&
              f(speed_, n_) && f(order_, n_);
    if (ok && rotation_) {
      ok = f(omega_, n_) && f(alpha_, n_) && f(wall_hist_[hist_in_], n_ * kWallSlots);
      if (ok && cfg_.particle_contacts) ok = f(pair_hist_[hist_in_], n_ * kPairSlots);
    }
    return ok;
  }

  // What a list build leaves besides the lists, saved with them.
  struct ListScalars {
    uint64_t valid, cover, built_step, pair_builds;
    double skin, per_particle, wall_per_particle, built_at, life;
  };

  // Calls f(buffer, element count) for each buffer of the lists as built, in
  // one fixed order (see state_arrays); counts from the saved scalars.
  template <class F>
  bool list_arrays(const ListScalars& s, uint64_t up, uint64_t lo, uint64_t wall, F&& f) {
    const size_t c = size_t(s.cover);
    bool ok = !nlist_ || (f(nl_start_, c + 1) && f(nl_list_, up) && f(lo_start_, c + 1) &&
                          f(lo_j_, lo) && (!once_ || f(lo_rec_, lo)));
    ok = ok && f(x_ref_, c);
    if (ok && wall_list_) ok = f(wl_start_, c + 1) && f(wl_count_, c) && f(wl_list_, wall);
    return ok;
  }

  // The lists into *out: their scalars, then list_arrays' buffers (none when
  // they are not built), the entry counts first.
  void save_lists(std::vector<std::vector<uint8_t>>* out) {
    out->clear();
    if (!lists_) return;
    const ListScalars s{nl_valid_,        nl_cover_,        nl_built_step_,
                        pair_builds_,     skin_,            nl_per_particle_,
                        wl_per_particle_, nl_built_at_,     nl_life_};
    auto bytes_of = [](const void* p, size_t n) {
      const auto* b = static_cast<const uint8_t*>(p);
      return std::vector<uint8_t>(b, b + n);
    };
    out->push_back(bytes_of(&s, sizeof s));
    if (!nl_valid_) return;
    // The upper, lower and wall entries: each scan's total, after its last particle.
    auto total = [&](const Buf<uint32_t>& start) {
      uint32_t t = 0;
      backend_.to_host(&t, start.data() + nl_cover_, sizeof t);
      return uint64_t(t);
    };
    const uint64_t counts[3] = {nlist_ ? total(nl_start_) : 0, nlist_ ? total(lo_start_) : 0,
                                wall_list_ ? total(wl_start_) : 0};
    out->push_back(bytes_of(counts, sizeof counts));
    list_arrays(s, counts[0], counts[1], counts[2], [&](auto& buf, size_t count) {
      std::vector<uint8_t> b(count * sizeof(*buf.data()));
      if (count) backend_.to_host(b.data(), buf.data(), b.size());
      out->push_back(std::move(b));
      return true;
    });
  }

  // The lists save_lists gave, in place of a build; given none, or lists of
  // another layout (a checkpoint of the other backend: the CPU keeps each
  // pair's record place, the GPU none), a build at the next step.
  void restore_lists(const std::vector<std::vector<uint8_t>>& in) {
    nl_valid_ = false;
    if (in.empty() || !lists_) return;
    ListScalars s{};
    if (in[0].size() != sizeof s) return;
    std::memcpy(&s, in[0].data(), sizeof s);
    if (s.cover > n_ || !(s.skin > 0) || !std::isfinite(s.skin)) return;
    if (s.skin != skin_) {  // it grew in the saved run: the grid's cells with it
      skin_ = s.skin;
      ts_.neighbour_skin = skin_;
      make_particle_grid();
    }
    nl_built_step_ = s.built_step, pair_builds_ = s.pair_builds;
    nl_per_particle_ = s.per_particle, wl_per_particle_ = s.wall_per_particle;
    nl_built_at_ = s.built_at, nl_life_ = s.life;
    if (!s.valid) return;
    uint64_t counts[3];
    if (in.size() < 2 || in[1].size() != sizeof counts) return;
    std::memcpy(counts, in[1].data(), sizeof counts);
    size_t k = 2;
    const bool fits = list_arrays(s, counts[0], counts[1], counts[2], [&](auto& buf, size_t count) {
      using T = std::remove_reference_t<decltype(*buf.data())>;
      if (k >= in.size() || in[k].size() != count * sizeof(T)) return false;
      if (count > buf.size()) backend_.resize(buf, count);
      if (count) backend_.to_device(buf.data(), in[k].data(), in[k].size());
      ++k;
      return true;
    });
    if (!fits || k != in.size()) return;  // some buffers overwritten: the build replaces them
    if (keeps_records() && counts[0] > rec_f_.size()) {  // the records of every listed pair
      backend_.resize(rec_f_, size_t(counts[0]));
      backend_.resize(rec_touched_, size_t(counts[0]));
      if (rotation_) backend_.resize(rec_torque_, size_t(counts[0]));
      if (rotation_ && pair_law_.mu_roll > 0) backend_.resize(rec_roll_, size_t(counts[0]));
    }
    nl_cover_ = size_t(s.cover);
    nl_valid_ = true;
  }

  // The per-particle arrays as plain pointers, for the loop bodies to capture by value.
  struct ParticleArrays {
    Vec3d *x, *v, *w, *acc, *alpha;  // position (local frame), velocity, spin, accelerations
    double *r, *mass;
    uint8_t *state, *flags;
  };
  ParticleArrays arrays() {
    return {pos_.data(),    vel_.data(),      omega_.data(), acc_.data(),  alpha_.data(),
            radius_.data(), mass_.data(), state_.data(), flags_.data()};
  }

  template <class T>
  void upload(Buf<T>& dst, const std::vector<T>& src) {
    backend_.resize(dst, std::max<size_t>(src.size(), 1));
    if (!src.empty()) backend_.to_device(dst.data(), src.data(), src.size() * sizeof(T));
  }

  // The engine's numbering: order_[k] is the caller's index of the particle held at k.
  std::vector<uint32_t> host_order() {
    std::vector<uint32_t> order(n_);
    if (n_) backend_.to_host(order.data(), order_.data(), n_ * sizeof(uint32_t));
    return order;
  }
  // The particles' constant arrays (radius, mass, release time) in that numbering.
  void upload_in_order(const std::vector<uint32_t>& order) {
    std::vector<double> r(n_), mass(n_), release(n_);
    for (size_t k = 0; k < n_; ++k) {
      const double ri = radius_host_[order[k]];
      r[k] = ri;
      mass[k] = cfg_.material.density * 4.0 / 3.0 * M_PI * ri * ri * ri;
      release[k] = release_host_[order[k]];
    }
    upload(radius_, r);
    upload(mass_, mass);
    upload(release_, release);
    // The earliest release at or after each place of the numbering.
    due_from_.assign(n_, 0.0);
    for (size_t k = n_; k-- > 0;)
      due_from_[k] = k + 1 < n_ ? std::min(release[k], due_from_[k + 1]) : release[k];
  }

  // Grows the live prefix to hold every particle due by t: past it, each
  // place's earliest release lies after t. It only grows, and renumbering
  // moves particles within it only, so the places past it keep their values.
  void grow_live(double t) { live_ = std::max(live_, due_by(t)); }
  // How many particles are due by time t (they are numbered by release).
  size_t due_by(double t) const {
    return size_t(std::upper_bound(due_from_.begin(), due_from_.end(), t) - due_from_.begin());
  }

  // Renumbers the live particles in the order of their cells (the grid just
  // built over them: p_idx_sorted_, waiting and gone particles last in their
  // old order), so that neighbours sit near each other in memory; those past
  // the live prefix stay where they are. Every per-particle array moves;
  // friction springs move with their particle and take their partners' new
  // numbers; hand_over_springs then gives each to its pair's new owner.
  // No memory of its own: the moves go through the statistics scratch (free
  // between frames' measures, 136 bytes a particle) and the inverse through
  // the particle grid's unsorted indices (free once sorted).
  void reorder_by_cell() {
    const uint32_t* perm = p_idx_sorted_.data();  // new k holds old perm[k]
    uint32_t* iv = p_idx_.data();
    backend_.parallel_for(live_, [=] COLLIDO_HD(uint32_t k) { iv[perm[k]] = k; });
    move_by(pos_, 1, perm), move_by(vel_, 1, perm), move_by(acc_, 1, perm);
    move_by(state_, 1, perm), move_by(flags_, 1, perm), move_by(speed_, 1, perm);
    move_by(peak_overlap_, 1, perm), move_by(order_, 1, perm);
    move_by(radius_, 1, perm), move_by(mass_, 1, perm), move_by(release_, 1, perm);
    if (rotation_) {
      move_by(omega_, 1, perm), move_by(alpha_, 1, perm);
      move_by(wall_hist_[hist_in_], kWallSlots, perm);
      if (cfg_.particle_contacts) {
        move_by(pair_hist_[hist_in_], kPairSlots, perm);
        // Springs are held by live particles, with live partners only.
        FrictionSlot* slots = pair_hist_[hist_in_].data();
        backend_.parallel_for(live_ * kPairSlots, [=] COLLIDO_HD(uint32_t q) {
          if (slots[q].key != kNoKey) slots[q].key = iv[slots[q].key];
        });
      }
    }
  }

  // Whether consecutively numbered particles lie, on average, more than
  // kScatteredCells cells apart (each distance counted up to 64 cells): a
  // numbering that follows space (a lattice, a fresh renumbering) stays, one
  // that a pour has stirred is renumbered. Through the statistics scratch.
  bool numbering_scattered() {
    const size_t n = live_;
    if (n < 2) return false;
    const Vec3d* x = pos_.data();
    const double inv_cell = 1.0 / double(pgrid_.cell);
    double* d = scratch_.data();
    backend_.parallel_for(n - 1, [=] COLLIDO_HD(uint32_t k) {
      d[k] = hd_min(length(x[k + 1] - x[k]) * inv_cell, 64.0);
    });
    return backend_.reduce_sum(d, n - 1) > kScatteredCells * double(n - 1);
  }

  // buf[k * width + s] = old buf[perm[k] * width + s] for the live prefix,
  // through the statistics scratch.
  template <class T>
  void move_by(Buf<T>& buf, size_t width, const uint32_t* perm) {
    static_assert(alignof(T) <= alignof(double), "the scratch is an array of doubles");
    const size_t bytes = live_ * width * sizeof(T);
    T* dst = reinterpret_cast<T*>(scratch_.data());
    const T* src = buf.data();
    backend_.parallel_for(live_, [=] COLLIDO_HD(uint32_t k) {
      for (size_t s = 0; s < width; ++s) dst[k * width + s] = src[size_t(perm[k]) * width + s];
    });
    backend_.copy(buf.data(), dst, bytes);
  }

  // --- one step -------------------------------------------------------------------------------
  // Velocity Verlet's closing half kick and checks are left pending at the end
  // of a step and done in the next step's first pass (one pass over the
  // particles instead of two), or by close_pending_step() before anything
  // reads the state.
  // One step of length dt; false when it was not taken (a step launched
  // before it was voided: the state is that step's, taken again).
  bool one_step(double dt) {
    if (timing_) lap_ = std::chrono::steady_clock::now();
    const bool releasing = !all_released_;
    const bool verlet = cfg_.integrator == Integrator::kVelocityVerlet;
    // Releases are decided where the positions (and the candidates found for
    // them) are those of a step boundary: Verlet's step end, after its drift,
    // or symplectic Euler's step start. Either way a particle starts moving at
    // the first boundary at or after its release time. The forces are
    // evaluated there too, in the pass that takes the decisions.
    const double release_at = verlet ? time_ + dt : time_;
    const size_t live = releasing ? std::max(live_, due_by(release_at)) : live_;
    // On the GPU the device takes the lists' check itself and the host goes on
    // launching steps without reading it (see settle_window; the wait for the
    // number cost 17-19 us a step on the H200, docs/benchmarks.md), unless the
    // particles due now reach past the lists' cover (a build the host calls).
    // The releases themselves are decided on the device (decide_releases).
    const bool ahead =
        B::kRunsAhead && !timing_ && verlet && lists_ && nl_valid_ && live <= nl_cover_;
    // A step that looks must see the steps launched before it stand; when one
    // of them called a build, the caller takes the steps from there again.
    if (!ahead && settle_window()) return false;
    live_ = live;
    if (ahead)
      window_.push_back(
          WindowStep{steps_, time_, dt, hist_in_, live_, released_to_, all_released_});
    if (verlet) open_step(dt, ahead);
    if (releasing && !cfg_.particle_contacts) all_released_ = time_ >= last_release_;
    lap(times_.drift_ms);
    if (!ahead) update_candidates();  // nothing to do without lists or particle contacts
    lap(times_.grid_ms);
    // Forces where the positions now are: after Verlet's drift, at the step's end.
    forces_and_end(dt, release_at, releasing, verlet);
    return true;
  }

  // A step's forces where the positions now are, and its host side after them.
  void forces_and_end(double dt, double release_at, bool releasing, bool verlet) {
    forces(dt, false, release_at, releasing);
    if (releasing) released_to_ = release_at;
    end_step(dt, verlet);
  }

  // A step's host side after its forces: the springs' generations turn, and
  // Verlet's close waits for the next pass.
  void end_step(double dt, bool verlet) {
    if (rotation_) swap_history();
    if (verlet) {
      close_pending_ = true, pending_dt_ = dt;
    } else {
      finish_step(dt, false, wall_pose(time_ + dt));
    }
    lap(times_.kick_ms);
    times_.steps += timing_;
    time_ += dt;
    ++steps_;
  }

  // How many steps the host launches before it reads the lists' check: the
  // scene's count (run_ahead), or a quarter of the last lists' life, 1 to 32
  // (kFirstWindowSteps before it is known). A look costs a wait for the
  // device (17-19 us on the H200); a build voids the steps launched after the
  // one that called it, on average half a window, whose launches are lost: at
  // 10^4 particles with a build every 3 steps, windows of 8 launched 799 steps
  // again in 400 (docs/benchmarks.md).
  size_t window_steps() const {
    if (cfg_.run_ahead > 0) return size_t(cfg_.run_ahead);
    if (nl_life_steps_ == 0) return kFirstWindowSteps;
    return size_t(std::clamp<uint64_t>(nl_life_steps_ / 4, 1, 32));
  }

  // The window before the lists have lasted once: as many steps as advance
  // takes between two reads of the fastest speed (kSpeedCheckInterval), so
  // that in advance the window ends at the speed check and one wait reads both
  // (settle_window_and_fastest).
  static constexpr size_t kFirstWindowSteps = kSpeedCheckInterval;

  // A step launched ahead of the lists' check (one_step): where it started.
  struct WindowStep {
    uint64_t steps;
    double time, dt;
    int hist_in;
    size_t live;         // the live prefix the step ran over
    double released_to;  // the releases' state before it
    bool all_released;
  };

  // Reads the lists' check of the steps launched ahead. When one of them found
  // a particle past half the skin, the device did nothing from its forces on
  // (every later loop returned at once), so the state is that step's after
  // its first pass: the host steps back to it, builds the lists there and
  // makes its forces, as a look before them would have. Returns whether it
  // stepped back (the caller takes the later steps again).
  bool settle_window() {
    if (window_.empty()) return false;
    ++times_.waits;
    unsigned long long mark = 0;
    if constexpr (B::kRunsAhead) mark = backend_.halt();
    return step_back_to(mark);
  }

  // settle_window, then the pending step closed and the fastest speed read
  // (*vmax), where the steps run ahead in one wait for the device instead of
  // two. When it steps back, *vmax is void and the caller asks again.
  bool settle_window_and_fastest(double* vmax) {
    ++times_.waits;
    if constexpr (B::kRunsAhead) {
      if (!window_.empty()) {
        close_pending_step();  // voided by a halt, as the window's steps are
        return step_back_to(backend_.halt_and_max(speed_.data(), live_, vmax));
      }
    }
    close_pending_step();  // nothing was launched ahead
    *vmax = fastest_speed();
    return false;
  }

  // The window's end (see settle_window): `mark` is the halt word read back,
  // 0 when every step of the window stands.
  bool step_back_to(unsigned long long mark) {
    // A set mark names a step of the window (the device marks only those).
    const auto at = std::find_if(window_.begin(), window_.end(),
                                 [&](const WindowStep& w) { return mark && w.steps + 1 == mark; });
    const bool back = at != window_.end();
    const WindowStep from = back ? *at : WindowStep{};
    times_.steps_retaken += uint64_t(window_.end() - at);
    window_.clear();  // keeps its capacity for the next window
    if (!back) return false;
    steps_ = from.steps, time_ = from.time, hist_in_ = from.hist_in;
    live_ = from.live, released_to_ = from.released_to, all_released_ = from.all_released;
    close_pending_ = false;  // the step's first pass closed the one before it
    disp_fresh_ = false;
    // The rest of the step as one_step takes it (only Verlet runs ahead).
    const bool releasing = !all_released_;
    const double release_at = time_ + from.dt;
    if (releasing && !cfg_.particle_contacts) all_released_ = time_ >= last_release_;
    build_lists();
    forces_and_end(from.dt, release_at, releasing, true);
    return true;
  }

  // Adds the time since the last lap to `slot` (after a sync) when stages are timed.
  void lap(double& slot) {
    if (!timing_) return;
    backend_.sync();
    const auto now = std::chrono::steady_clock::now();
    slot += std::chrono::duration<double, std::milli>(now - lap_).count();
    lap_ = now;
  }

  double fastest_speed() { return backend_.reduce_max(speed_.data(), live_); }
  double automatic_step(double vmax) {
    // Speed may grow under gravity before the next check (bounded inside); a
    // runaway speed must not stall the run (never below a thousandth of the spring step).
    return automatic_step_size(ts_.spring_step, cfg_.motion_fraction, ts_.r_min, vmax,
                               length(cfg_.gravity));
  }

  // A particle's candidate partners as this step found them: its lists (the
  // lower, then the upper, each in ascending index: the same contacts in the
  // same order whenever they were built, so a run resumed from a checkpoint
  // repeats the original bit for bit) or the grid's 27 cells around it.
  struct PairCandidates {
    bool list;
    GridSpec pg;
    const uint32_t *start, *end, *sidx;
    const PackedParticle* sp;
    float slack;
    const uint32_t *nl_start, *nl, *lo_start, *lo_j;
    template <class F>
    COLLIDO_HD COLLIDO_FORCEINLINE void each(uint32_t i, Vec3f xf, float rf, F&& f) const {
      if (list) {
        for (uint32_t k = lo_start[i], e = lo_start[i + 1]; k < e; ++k) f(lo_j[k]);
        for (uint32_t k = nl_start[i], e = nl_start[i + 1]; k < e; ++k) f(nl[k]);
      } else {
        for_each_grid_candidate(pg, start, end, sidx, sp, slack, i, xf, rf, f);
      }
    }
    // With lists, i's candidates by number, in the order of each().
    struct Listed {
      const uint32_t *lo, *up;
      uint32_t n_lo, count;
      COLLIDO_HD COLLIDO_FORCEINLINE uint32_t operator[](uint32_t c) const {
        return c < n_lo ? lo[c] : up[c - n_lo];
      }
    };
    COLLIDO_HD COLLIDO_FORCEINLINE Listed listed(uint32_t i) const {
      const uint32_t l0 = lo_start[i], n_lo = lo_start[i + 1] - l0, u0 = nl_start[i];
      return {lo_j + l0, nl + u0, n_lo, n_lo + (nl_start[i + 1] - u0)};
    }
  };
  PairCandidates pair_candidates() {
    return {nlist_,          pgrid_,          cell_start_.data(), cell_end_.data(),
            p_idx_sorted_.data(), sorted_.data(), filter_slack_,   nl_start_.data(),
            nl_list_.data(), lo_start_.data(), lo_j_.data()};
  }

  // A particle due where another one is (touching it, in double) waits: released
  // into it, it would start deep inside and be fired out at many times the
  // scene's speeds (a jet whose mouth had jammed blew up so). It goes at the
  // first step boundary where nothing touches it. Of two due particles that
  // touch each other (an inlet's slot holds its waiting particles one on
  // another) the one due first goes first, ties by number. Without particle
  // contacts particles pass through one another and every due particle goes.
  // With them the decision is taken in the pair forces' pass, where the
  // candidates are at hand (decide_releases on the CPU's pairs-once path), and
  // marked in flags, unused while a particle waits: kActive = may go. No
  // decision reads another's new state, so the CPU and the GPU decide alike.
  // The release itself is the next pass's (release_marked): Verlet's next
  // opening pass, whose particle then moves from that step; symplectic Euler's
  // closing pass of the same step.

  // Whether j takes due particle i's place: it touches i and is moving, or is due before i.
  COLLIDO_HD static COLLIDO_FORCEINLINE bool takes_place(const ParticleArrays& P,
                                                         const double* rel, uint32_t i,
                                                         uint32_t j) {
    const Vec3d d = P.x[i] - P.x[j];
    const double rs = P.r[i] + P.r[j];
    if (!(dot(d, d) < rs * rs)) return false;
    const uint8_t sj = P.state[j];
    return sj == kActive ||
           (sj == kWaiting && (rel[j] < rel[i] || (rel[j] == rel[i] && j < i)));
  }

  // Whether particle i is waiting and due by t.
  COLLIDO_HD static COLLIDO_FORCEINLINE bool due(const ParticleArrays& P, const double* rel,
                                                 uint32_t i, double t) {
    return P.state[i] == kWaiting && rel[i] <= t;
  }

  // Releases particle i if it was let go (flags) or, without particle
  // contacts, is due by free_t; returns its state.
  COLLIDO_HD static COLLIDO_FORCEINLINE uint8_t release_marked(const ParticleArrays& P,
                                                               const double* rel, uint32_t i,
                                                               double free_t) {
    const uint8_t st = P.state[i];
    if (st == kWaiting && (P.flags[i] == kActive || rel[i] <= free_t))
      return P.state[i] = P.flags[i] = kActive;
    return st;
  }
  // The time by which every due particle goes unasked (no particle contacts), else none.
  double free_release_time() const {
    return cfg_.particle_contacts ? -std::numeric_limits<double>::infinity() : time_;
  }

  // The decisions for the particles due by t, on a pass of their own (the
  // pairs-once path's passes do not walk both lists of a waiting particle).
  void decide_releases(double t) {
    const ParticleArrays P = arrays();
    const double* rel = release_.data();
    const PairCandidates cand = pair_candidates();
    backend_.parallel_for(live_, [=] COLLIDO_HD(uint32_t i) {
      if (due(P, rel, i, t)) decide_release(P, rel, cand, i);
    });
  }
  COLLIDO_HD static COLLIDO_FORCEINLINE void decide_release(const ParticleArrays& P,
                                                            const double* rel,
                                                            const PairCandidates& cand,
                                                            uint32_t i) {
    bool taken = false;
    cand.each(i, cast3<float>(P.x[i]), float(P.r[i]),
              [&](uint32_t j) { taken = taken || takes_place(P, rel, i, j); });
    P.flags[i] = taken ? uint8_t(kWaiting) : uint8_t(kActive);
  }

  // The wall's pose at time t, in the engine's local frame (a still wall's
  // with a moving part: the identity).
  WallPose wall_pose(double t) const {
    return part_ ? WallPose{} : cfg_.wall_motion.pose(t, wall_.origin);
  }
  // The moving part's pose at time t, in its own index's frame.
  WallPose part_pose(double t) const { return cfg_.wall_motion.pose(t, mover_.origin); }

  // The domain the checks keep particles in, with the wall's pose (a
  // translating or oscillating wall carries it along).
  struct Domain {
    Vec3d lo, hi;
  };
  Domain domain_at(const WallPose& pose) const { return {lo_ + pose.d, hi_ + pose.d}; }
  COLLIDO_HD static COLLIDO_FORCEINLINE bool outside(Vec3d x, const Domain& dom) {
    return x.x < dom.lo.x || x.y < dom.lo.y || x.z < dom.lo.z || x.x > dom.hi.x ||
           x.y > dom.hi.y || x.z > dom.hi.z;
  }
  // A particle that leaves the domain escapes: frozen where it left, counted.
  COLLIDO_HD static COLLIDO_FORCEINLINE uint8_t escape(const ParticleArrays& P, uint32_t i,
                                                        double* speed) {
    P.state[i] = kEscaped;
    P.flags[i] = kEscaped;
    if (speed) speed[i] = 0;
    return kEscaped;
  }

  // The end of a step for active particle i: the closing kick (Verlet's second
  // half, or symplectic Euler's whole kick and drift), then the checks.
  // Returns its state afterwards. speed: |v| written for the speed check
  // (nullptr: not written, see OpenStep).
  COLLIDO_HD static COLLIDO_FORCEINLINE uint8_t close_particle(const ParticleArrays& P, uint32_t i,
                                                               double dt, bool verlet, bool rot,
                                                               double* speed, Domain dom) {
    Vec3d vi = P.v[i], xi = P.x[i];
    if (verlet) {
      vi = vi + P.acc[i] * (0.5 * dt);
      if (rot) P.w[i] = P.w[i] + P.alpha[i] * (0.5 * dt);
    } else {
      vi = vi + P.acc[i] * dt;
      xi = xi + vi * dt;
      if (rot) P.w[i] = P.w[i] + P.alpha[i] * dt;
    }
    const double s2 = dot(vi, vi);
    const bool finite = hd_finite(s2) && hd_finite(xi.x) && hd_finite(xi.y) && hd_finite(xi.z);
    if (!finite) {
      // Frozen where it last was finite, counted, never written as NaN.
      P.state[i] = kInvalid;
      P.flags[i] = kInvalid;
      P.v[i] = Vec3d{0, 0, 0};
      if (speed) speed[i] = 0;
      return kInvalid;
    }
    P.v[i] = vi;
    if (!verlet) P.x[i] = xi;  // Verlet moved it in the drift
    if (speed) speed[i] = sqrt(s2);
    return outside(xi, dom) ? escape(P, i, speed) : uint8_t(kActive);
  }

  // What open_step does to one particle; returns its squared move since the
  // lists were built (0 when it is not active or there are no lists).
  struct OpenStep {
    ParticleArrays P;
    bool rot, close, disp;
    double h, dt;  // the pending step's length, this step's
    Domain dom;  // where the pending step ended
    Domain next;  // where this step ends
    const Vec3d* ref;
    const double* rel;
    double free_t;  // see release_marked
    COLLIDO_HD COLLIDO_FORCEINLINE double operator()(uint32_t i) const {
      const bool moved = P.state[i] == kActive;  // in the pending step
      uint8_t st = release_marked(P, rel, i, free_t);
      if (close) {
        // A particle released here did not move in the pending step: no
        // closing kick for it (its acceleration is already gravity's, for its
        // first kick below), only the checks. No speeds: they are read only
        // after close_pending_step, whose pass writes every one (a square
        // root a particle a step saved).
        if (st == kActive) st = close_particle(P, i, moved ? h : 0.0, true, rot, nullptr, dom);
      }
      if (st != kActive) return 0.0;
      const Vec3d v = P.v[i] + P.acc[i] * (0.5 * dt);
      const Vec3d x = P.x[i] + v * dt;
      P.v[i] = v;
      P.x[i] = x;
      if (rot) P.w[i] = P.w[i] + P.alpha[i] * (0.5 * dt);
      // Out of the domain, it escapes here, before this step's forces: the
      // particle grid ends at the domain, so a pair list built before it left
      // would give its partners forces that one built after would not (the
      // forces would hang on when the lists were built).
      if (outside(x, next)) {
        escape(P, i, nullptr);
        return 0.0;
      }
      if (!disp) return 0.0;
      const Vec3d d = x - ref[i];
      return dot(d, d);
    }
  };

  // Velocity Verlet's first pass of a step, particle by particle in the order
  // separate passes would take: the last step's pending close, this step's
  // half kick and drift; with lists, the largest squared move since they were
  // built, for the check that follows.
  // ahead: the device decides whether the lists still hold (see settle_window).
  void open_step(double dt, bool ahead) {
    const bool disp = lists_ && nl_valid_;
    const OpenStep op{arrays(),      rotation_,
                      close_pending_, disp,
                      pending_dt_,   dt,
                      domain_at(wall_pose(time_)),
                      domain_at(wall_pose(time_ + dt)), x_ref_.data(), release_.data(),
                      free_release_time()};
    if (disp && ahead) {
      // moved_half_skin's test, 4 d > skin^2, as d > skin^2 / 4 (the same
      // decision: both scalings by 4 are exact).
      if constexpr (B::kRunsAhead)
        backend_.parallel_max_halting(
            live_, [=] COLLIDO_HD(uint32_t i) { return op(i); }, 0.25 * (skin_ * skin_),
            steps_ + 1);
    } else if (cpu_vectors()) {
      if constexpr (B::kPairRecordsInBatches) {
        const double most = open_groups(op);
        if (disp) disp_max_ = most;
      }
    } else if (disp) {
      disp_max_ = backend_.parallel_max(live_, [=] COLLIDO_HD(uint32_t i) { return op(i); });
    } else {
      backend_.parallel_for(live_, [=] COLLIDO_HD(uint32_t i) { op(i); });
    }
    close_pending_ = false;
    disp_fresh_ = disp && !ahead;  // ahead, the host never holds the number
  }

  // Whether the CPU's AVX2 passes run (cfg simd): the pairs four at a time
  // (pair_batch_forces) and the opening pass (open_groups).
  bool cpu_vectors() const {
    if constexpr (B::kPairRecordsInBatches) {
      return cfg_.simd != 0 && pair_batch_supported();
    } else {
      return false;
    }
  }
  // open_step's pass on the CPU: the groups of four plain particles in
  // vectors (open_plain_groups), the others one at a time, the same bits;
  // returns the largest squared move (0 without lists).
  double open_groups(const OpenStep& op) {
    OpenGroups g;
    g.x = op.P.x, g.v = op.P.v, g.w = op.P.w, g.acc = op.P.acc, g.alpha = op.P.alpha;
    g.state = op.P.state, g.ref = op.ref;
    g.close = op.close, g.rot = op.rot, g.disp = op.disp;
    g.close_half = 0.5 * op.h, g.half_dt = 0.5 * op.dt, g.dt = op.dt;
    g.lo = op.dom.lo, g.hi = op.dom.hi, g.next_lo = op.next.lo, g.next_hi = op.next.hi;
    return backend_.parallel_max_chunks(live_, [&](size_t begin, size_t end) {
      double most = 0;
      for (uint32_t i = uint32_t(begin); i < end;) {
        i = open_plain_groups(g, i, uint32_t(end), &most);
        for (const uint32_t stop = std::min(i + 4, uint32_t(end)); i < stop; ++i)
          most = std::max(most, op(i));
      }
      return most;
    });
  }

  // Closes a step left pending (see one_step) on its own pass.
  void close_pending_step() {
    if (!close_pending_) return;
    finish_step(pending_dt_, true, wall_pose(time_));
    close_pending_ = false;
  }

  // pose: the wall at the step's end.
  void finish_step(double dt, bool verlet, const WallPose& pose) {
    const ParticleArrays P = arrays();
    double* speed = speed_.data();
    const bool rot = rotation_;
    const Domain dom = domain_at(pose);
    const double* rel = release_.data();
    const double free_t = free_release_time();
    backend_.parallel_for(live_, [=] COLLIDO_HD(uint32_t i) {
      const bool moved = P.state[i] == kActive;  // in the step being closed
      if (release_marked(P, rel, i, free_t) != kActive) {
        speed[i] = 0;
        return;
      }
      // Verlet closes a step that a particle released now did not move in
      // (see OpenStep); symplectic Euler's closing pass is its release's step.
      close_particle(P, i, verlet && !moved ? 0.0 : dt, verlet, rot, speed, dom);
    });
  }

  void speeds() {
    const ParticleArrays P = arrays();
    double* speed = speed_.data();
    backend_.parallel_for(live_, [=] COLLIDO_HD(uint32_t i) {
      speed[i] = P.state[i] == kActive ? length(P.v[i]) : 0.0;
    });
  }

  void swap_history() { hist_in_ ^= 1; }

  // Calls f(j) for every particle j != i in the 27 cells around i's whose
  // float distance may lie within r_i + r_j + extra (the grid's sorted float
  // copies; extra covers their rounding, and the skin when a list is built).
  template <class F>
  COLLIDO_HD static COLLIDO_FORCEINLINE void for_each_grid_candidate(
      const GridSpec& pg, const uint32_t* start, const uint32_t* end, const uint32_t* sidx,
      const PackedParticle* sp, float extra, uint32_t i, Vec3f xf, float rf, F&& f) {
    int cx = 0, cy = 0, cz = 0;
    if (!pg.cell_of(xf, cx, cy, cz)) return;
    pg.for_each_neighbour(cx, cy, cz, 1, [&](uint64_t l, uint32_t b) {
      for (uint32_t k = start[b], e = end[b]; k < e; ++k) {
        const PackedParticle q = sp[k];
        const float fx = xf.x - q.x, fy = xf.y - q.y, fz = xf.z - q.z, reach = rf + q.r + extra;
        if (fx * fx + fy * fy + fz * fz >= reach * reach) continue;  // clearly apart (most)
        const uint32_t j = sidx[k];
        if (j == i) continue;
        if (pg.hashed && !pg.holds(position(q), l)) continue;
        f(j);
      }
    });
  }

  // The candidates for this step: the particle grid rebuilt (particle
  // contacts without a list), and the lists (the pairs' and the still wall's,
  // or the wall's alone without particle contacts), rebuilt only when a particle was
  // released that they do not cover or one has moved half the skin (then
  // every pair now touching was within r_i + r_j + skin at the build, and
  // every wall triangle touching a particle within r + skin/2 of it, so they
  // are listed).
  void update_candidates() {
    if (!lists_) {
      // With the particles waiting for their place, which takes_place looks up.
      if (cfg_.particle_contacts) build_particle_grid(live_, /*with_waiting=*/!all_released_);
      return;
    }
    bool rebuild = !nl_valid_ || live_ > nl_cover_;
    if (!rebuild) {
      if (!disp_fresh_) {  // open_step has not measured the moves since the positions changed
        const ParticleArrays P = arrays();
        const Vec3d* ref = x_ref_.data();
        disp_max_ = backend_.parallel_max(live_, [=] COLLIDO_HD(uint32_t i) {
          const Vec3d d = P.x[i] - ref[i];
          return P.state[i] == kActive ? dot(d, d) : 0.0;
        });
      }
      rebuild = moved_half_skin();
    }
    disp_fresh_ = false;
    if (rebuild) build_lists();
  }

  // Whether the largest move since the lists were built (disp_max_, squared)
  // passes half the skin: then a pair now touching may be missing from them.
  bool moved_half_skin() const { return 4 * disp_max_ > skin_ * skin_; }

  // How far the lists reach past the live prefix: the particles due next are
  // listed where they wait, so their release needs no build (a waiting
  // particle does not move; once released, its move since the build is
  // checked like any other's). A pour released one every few steps and built
  // the lists at each. Those due within twice the last list's life (about
  // when the skin would call a build anyway), at most a quarter of the live
  // count past it (at least kCoverAhead): an inlet's slot holds its waiting
  // particles one on another, and each pair of them would be listed.
  size_t list_cover() const {
    const size_t cap = std::min(n_, live_ + std::max<size_t>(kCoverAhead, live_ / 4));
    if (nl_life_ <= 0) return cap;
    const size_t due = size_t(
        std::upper_bound(due_from_.begin(), due_from_.end(), time_ + 2 * nl_life_) -
        due_from_.begin());
    return std::clamp(due, live_, cap);
  }

  // Whether a particle goes into the lists: active, or waiting to be released where it is.
  COLLIDO_HD static COLLIDO_FORCEINLINE bool listed(uint8_t st) {
    return st == kActive || st == kWaiting;
  }

  // Sorts a short list in place (insertion sort: a few dozen entries), moving
  // the values `with` along when given.
  COLLIDO_HD static COLLIDO_FORCEINLINE void sort_short(uint32_t* a, uint32_t n,
                                                        uint32_t* with = nullptr) {
    for (uint32_t k = 1; k < n; ++k) {
      const uint32_t v = a[k], vw = with ? with[k] : 0;
      uint32_t b = k;
      for (; b > 0 && a[b - 1] > v; --b) {
        a[b] = a[b - 1];
        if (with) with[b] = with[b - 1];
      }
      a[b] = v;
      if (with) with[b] = vw;
    }
  }

  // The lists at the current positions, which their check then measures moves from.
  void build_lists() {
    if (nl_valid_) {
      nl_life_ = time_ - nl_built_at_;
      nl_life_steps_ = steps_ - nl_built_step_;
      grow_skin_after(nl_life_steps_);
    }
    nl_built_at_ = time_;
    nl_built_step_ = steps_;
    if (nlist_)
      build_pair_lists();  // sets nl_cover_
    else
      nl_cover_ = list_cover();
    if (wall_list_) build_wall_lists();
    backend_.copy(x_ref_.data(), pos_.data(), nl_cover_ * sizeof(Vec3d));
    nl_valid_ = true;
    ++times_.neighbour_builds;
  }

  // Every active pair within r_i + r_j + skin: per particle the partners whose
  // pair it owns (larger index: the upper list) and those that own their pair
  // with it (the lower list, with where each pair sits in the owner's upper
  // list), both in ascending index.
  // A count pass, two scans, the upper lists' fill pass, and the lower lists
  // filled from the upper ones (each list sorted in place, a few dozen
  // entries). The candidate test is symmetric in i and j (the same float
  // copies, one sum of radii, cells found alike), so the count pass counts
  // every lower entry the upper lists give.
  void build_pair_lists() {
    const int every = cfg_.renumber_every;
    const bool renumber = every < 0   ? numbering_scattered()
                          : every > 0 ? pair_builds_ % uint64_t(every) == 0
                                      : false;
    ++pair_builds_;
    if (renumber) {
      build_particle_grid(live_, /*with_waiting=*/false);
      reorder_by_cell();
    }
    const size_t n = nl_cover_ = list_cover();
    build_particle_grid(n, /*with_waiting=*/true);
    const ParticleArrays P = arrays();
    const GridSpec pg = pgrid_;
    const uint32_t* start = cell_start_.data();
    const uint32_t* end = cell_end_.data();
    const uint32_t* sidx = p_idx_sorted_.data();
    const PackedParticle* sp = sorted_.data();
    const float extra = filter_slack_ + float(skin_) * 1.0001f;
    uint32_t* up_count = nl_start_.data();
    uint32_t* lo_count = lo_start_.data();
    backend_.parallel_for_heavy(n, [=] COLLIDO_HD(uint32_t i) {
      uint32_t up = 0, lo = 0;
      if (listed(P.state[i]))
        for_each_grid_candidate(pg, start, end, sidx, sp, extra, i, cast3<float>(P.x[i]),
                                float(P.r[i]), [&](uint32_t j) { j > i ? ++up : ++lo; });
      up_count[i] = up;
      lo_count[i] = lo;
    });
    backend_.fill(up_count + n, 1, 0u);
    backend_.fill(lo_count + n, 1, 0u);
    const uint64_t up_total = backend_.exclusive_scan(up_count, n + 1);
    const uint64_t lo_total = backend_.exclusive_scan(lo_count, n + 1);
    nl_per_particle_ = n ? double(up_total + lo_total) / double(n) : 0.0;
    if (up_total > nl_list_.size()) {
      const size_t cap = size_t(up_total + up_total / 4 + 16);
      backend_.resize(nl_list_, cap);
      if (keeps_records()) {
        backend_.resize(rec_f_, cap);
        backend_.resize(rec_touched_, cap);
        if (rotation_) backend_.resize(rec_torque_, cap);
        if (rotation_ && pair_law_.mu_roll > 0) backend_.resize(rec_roll_, cap);
      }
    }
    if (lo_total > lo_j_.size()) {
      backend_.resize(lo_j_, size_t(lo_total + lo_total / 4 + 16));
      if (once_) backend_.resize(lo_rec_, lo_j_.size());
    }
    const uint32_t* up_first = nl_start_.data();
    const uint32_t* lo_first = lo_start_.data();
    uint32_t* up_list = nl_list_.data();
    backend_.parallel_for_heavy(n, [=] COLLIDO_HD(uint32_t i) {
      if (!listed(P.state[i])) return;
      uint32_t c = up_first[i];
      for_each_grid_candidate(pg, start, end, sidx, sp, extra, i, cast3<float>(P.x[i]),
                              float(P.r[i]), [&](uint32_t j) {
                                if (j > i) up_list[c++] = j;
                              });
      sort_short(up_list + up_first[i], c - up_first[i]);
    });
    // The lower lists are the upper ones turned around: each upper entry (i, j)
    // goes to j's lower list with its place, through a counter per particle
    // (the unsorted grid keys, free until the next build), then each lower
    // list is sorted. A third walk of the grid cost as much as each of the two
    // above (a pour builds its lists every few dozen steps).
    uint32_t* lo_j = lo_j_.data();
    uint32_t* lo_rec = lo_rec_.data();
    uint32_t* fill = p_key_.data();
    const bool once = once_;  // the records' places are needed only to gather them
    backend_.fill(fill, n, 0u);
    backend_.parallel_for(n, [=] COLLIDO_HD(uint32_t i) {
      for (uint32_t k = up_first[i], e = up_first[i + 1]; k < e; ++k) {
        const uint32_t j = up_list[k];
        const uint32_t a = lo_first[j] + atomic_add_u32(&fill[j], 1u);
        if (a >= lo_first[j + 1]) continue;  // never: the count pass found the same pairs
        lo_j[a] = i;
        if (once) lo_rec[a] = k;
      }
    });
    backend_.parallel_for(n, [=] COLLIDO_HD(uint32_t j) {
      const uint32_t s0 = lo_first[j];
      sort_short(lo_j + s0, lo_first[j + 1] - s0, once ? lo_rec + s0 : nullptr);
    });
    if (renumber && rotation_) hand_over_springs();
  }

  // After a renumbering a pair may have a new owner (its particle of lower
  // index): each particle's springs become those of its upper list's pairs,
  // found in its own slots or, negated, in the partner's (the old owner's).
  void hand_over_springs() {
    const uint32_t* nl_start = nl_start_.data();
    const uint32_t* nl = nl_list_.data();
    const FrictionSlot* hin = pair_hist_[hist_in_].data();
    FrictionSlot* hout = pair_hist_[hist_in_ ^ 1].data();
    const size_t n = nl_cover_;
    backend_.parallel_for(n, [=] COLLIDO_HD(uint32_t i) {
      const FrictionSlot* mine = hin + size_t(i) * kPairSlots;
      FrictionSlot* out = hout + size_t(i) * kPairSlots;
      int c = 0;
      for (uint32_t k = nl_start[i], e = nl_start[i + 1]; k < e && c < kPairSlots; ++k) {
        const uint32_t j = nl[k];
        const FrictionSlot* theirs = hin + size_t(j) * kPairSlots;
        bool found = false;
        for (int s = 0; s < kPairSlots && mine[s].key != kNoKey && !found; ++s)
          if (mine[s].key == j) out[c++] = mine[s], found = true;
        for (int s = 0; s < kPairSlots && theirs[s].key != kNoKey && !found; ++s)
          if (theirs[s].key == i)
            out[c++] = FrictionSlot{j, -theirs[s].sx, -theirs[s].sy, -theirs[s].sz}, found = true;
      }
      if (c < kPairSlots) out[c].key = kNoKey;
    });
    // Back into the current generation (the wall's springs share its index).
    backend_.copy(pair_hist_[hist_in_].data(), hout, n * kPairSlots * sizeof(FrictionSlot));
  }

  // Calls f(k) for each wall triangle or piece k within `reach` of x (repeats
  // included), the candidates within e of x tested in double.
  template <class F>
  COLLIDO_HD static COLLIDO_FORCEINLINE void wall_near(const WallView& wall,
                                                       const PlanarTriangleD* tris_d, Vec3d x,
                                                       double reach, float e, F&& f) {
    wall.for_each_candidate_near(cast3<float>(x), e, [&](uint32_t k) {
      Vec3d q;
      double h = 0, aside = 0;
      const double r2 = reach * reach;
      if (closest_point_planar(x, tris_d[k], r2, &q, &h, &aside) < r2) f(k);
    });
  }

  // Every wall triangle (or piece) within r + skin / 2 of each particle now:
  // until the list is rebuilt no particle moves half the skin, so every
  // contact it can have is listed. Candidates from the cells (or the tree)
  // around the particle's reach, then the exact distance in double; a count
  // pass over-counts repeats, the fill pass keeps each triangle once.
  void build_wall_lists() {
    const ParticleArrays P = arrays();
    const WallView wall = wall_.view();
    const PlanarTriangleD* tris_d = wall_.tris_d.data();
    const double half_skin = 0.5 * skin_ * 1.0001;
    const float e = float(half_skin) * 1.0001f;
    uint32_t* start = wl_start_.data();
    uint32_t* count = wl_count_.data();
    const size_t n = nl_cover_;
    backend_.parallel_for_heavy(n, [=] COLLIDO_HD(uint32_t i) {
      uint32_t c = 0;
      if (listed(P.state[i]))
        wall_near(wall, tris_d, P.x[i], P.r[i] + half_skin, e, [&](uint32_t) { ++c; });
      start[i] = c;
    });
    backend_.fill(start + n, 1, 0u);
    const uint64_t total = backend_.exclusive_scan(start, n + 1);
    wl_per_particle_ = n ? double(total) / double(n) : 0.0;
    if (total > wl_list_.size()) backend_.resize(wl_list_, size_t(total + total / 4 + 16));
    uint32_t* list = wl_list_.data();
    backend_.parallel_for_heavy(n, [=] COLLIDO_HD(uint32_t i) {
      const uint32_t s0 = start[i];
      uint32_t c = s0;
      if (listed(P.state[i]))
        wall_near(wall, tris_d, P.x[i], P.r[i] + half_skin, e, [&](uint32_t k) {
          // In ascending k, each once: the contacts arrive in one order whenever
          // the list was built (the wall's forces are summed in that order).
          uint32_t a = c;
          for (; a > s0 && list[a - 1] > k; --a) {
          }
          if (a > s0 && list[a - 1] == k) return;
          for (uint32_t b = c; b > a; --b) list[b] = list[b - 1];
          list[a] = k;
          ++c;
        });
      count[i] = c - s0;
    });
    // A particle without candidates has no wall contact while the list
    // stands: its spring lists are empty in both generations from now on, so
    // wall_forces need not terminate them every step (a cache line a particle,
    // most of that pass's time where few particles are near the wall).
    if (wall_law_.mu > 0) {
      FrictionSlot* h0 = wall_hist_[0].data();
      FrictionSlot* h1 = wall_hist_[1].data();
      backend_.parallel_for(n, [=] COLLIDO_HD(uint32_t i) {
        if (count[i] == 0) h0[size_t(i) * kWallSlots].key = h1[size_t(i) * kWallSlots].key = kNoKey;
      });
    }
  }

  // The particle grid over the first n particles: the active ones, and with
  // with_waiting those waiting too (the lists cover them, see list_cover).
  void build_particle_grid(size_t n, bool with_waiting) {
    const ParticleArrays P = arrays();
    const GridSpec g = pgrid_;
    const uint32_t none = pgrid_.buckets;  // sorts after every bucket, within the key bits
    uint32_t* key = p_key_.data();
    uint32_t* idx = p_idx_.data();
    backend_.parallel_for(n, [=] COLLIDO_HD(uint32_t i) {
      const uint8_t st = P.state[i];
      int cx = 0, cy = 0, cz = 0;
      key[i] = (st == kActive || (with_waiting && st == kWaiting)) &&
                       g.cell_of(cast3<float>(P.x[i]), cx, cy, cz)
                   ? g.bucket(g.linear(cx, cy, cz))
                   : none;
      idx[i] = i;
    });
    // The last build's buckets cleared (by its sorted keys, before they are
    // overwritten), not the whole table: the table spans the domain for every
    // particle, and clearing it took 40 % of a pour whose lists were built each step.
    clear_cell_ranges(backend_, p_key_sorted_.data(), grid_keys_, cell_start_.data(),
                      cell_end_.data(), none);
    backend_.sort_pairs(key, idx, p_key_sorted_.data(), p_idx_sorted_.data(), n, pkey_bits_);
    set_cell_ranges(backend_, p_key_sorted_.data(), n, cell_start_.data(), cell_end_.data(), none);
    grid_keys_ = n;
    // A float copy of each particle in cell order: the pair loop reads its
    // neighbours' cells as contiguous 16-byte records and goes to the double
    // state only for real contacts.
    PackedParticle* sp = sorted_.data();
    const uint32_t* sidx = p_idx_sorted_.data();
    const uint32_t* skey = p_key_sorted_.data();
    backend_.parallel_for(n, [=] COLLIDO_HD(uint32_t j) {
      if (skey[j] == none) return;
      const uint32_t i = sidx[j];
      sp[j] = PackedParticle{float(P.x[i].x), float(P.x[i].y), float(P.x[i].z), float(P.r[i])};
    });
  }

  // Forces on every active particle, in two passes so each kernel stays
  // small (registers decide how many threads hide the memory latency): pairs
  // with gravity first, then the wall's contacts added on top. measure: write
  // statistics only (no accelerations, no friction memory), so measuring
  // never changes the run.
  // The laps time a step's stages; the measuring pass is not a step.
  // decide: take the release decisions for the particles due by t (see takes_place).
  void forces(double dt, bool measure, double t, bool decide = false) {
    if (cfg_.particle_contacts) {
      if (once_ && !measure) {
        if (decide) decide_releases(t);
        if (sums_in_order()) {
          if (wall_list_) {
            // A listed wall stands still and has no moving part; its pass
            // runs within the pair pass, batch by batch, and its time counts
            // as the pairs'.
            const WallPass wall = wall_pass(dt, false, wall_pose(t), WallPose{});
            pair_forces_in_order(dt, &wall);
            lap(times_.pair_ms);
            return;
          }
          pair_forces_in_order(dt, nullptr);
        } else {
          pair_records(dt);
          pair_gather();
        }
      } else {
        pair_forces(dt, measure, decide ? t : -std::numeric_limits<double>::infinity());
      }
      if (!measure) lap(times_.pair_ms);
    }
    wall_forces(dt, measure, wall_pose(t), part_ ? part_pose(t) : WallPose{});
    if (!measure) lap(times_.wall_ms);
  }

  // Looks up a contact's spring in last step's terminated slot list.
  COLLIDO_HD static COLLIDO_FORCEINLINE Vec3d find_spring(const FrictionSlot* slots, int k,
                                                          uint32_t key) {
    for (int s = 0; s < k && slots[s].key != kNoKey; ++s)
      if (slots[s].key == key) return Vec3d{slots[s].sx, slots[s].sy, slots[s].sz};
    return Vec3d{0, 0, 0};
  }

  // One touching pair as particle i sees it (d = x_i - x_j, |d|^2 = dist2 <
  // rs^2; *spring: the pair's tangential spring as i sees it, in and out).
  // Every quantity is an odd function of the pair's orientation, evaluated so
  // that rounding keeps it odd: j's view of the pair is i's with every vector
  // negated exactly, so evaluating a pair once (pair_records) or from both
  // sides (pair_forces) gives the same bits, and momentum is kept exactly.
  struct PairContact {
    ContactForce cf;  // on i; cf.torque is per metre of lever: i's torque is it times r_i, j's times r_j
    Vec3d roll;       // rolling torque on i (j's is its negative)
  };
  COLLIDO_HD static COLLIDO_FORCEINLINE PairContact pair_contact(
      const ContactLaw& law, bool rot, const ParticleArrays& P, uint32_t i, uint32_t j, Vec3d vi,
      Vec3d wi, double r, double m, Vec3d d, double dist2, double rs, Vec3d* spring, double dt) {
    const double dist = sqrt(dist2);
    // Coincident centres: separate along z, opposite ways for the two.
    const Vec3d nrm = dist > 1e-12 * rs ? d * (1.0 / dist) : Vec3d{0, 0, i < j ? 1.0 : -1.0};
    const double mj = P.mass[j], rj = P.r[j];
    // i's surface point against j's: (v_i - v_j) - (w_i x n r_i + w_j x n r_j).
    Vec3d vrel = vi - P.v[j];
    if (law.mu > 0) vrel = vrel - (cross(wi, nrm * r) + cross(P.w[j], nrm * rj));
    // The contact's radius, for the laws that read it (a division the linear law saves).
    const bool roll = rot && law.mu_roll > 0;
    const double r_eff = law.model == ContactModel::kHertzMindlin || roll ? r * rj / rs : 0.0;
    PairContact out;
    out.cf = contact_force(law, nrm, rs - dist, vrel, m * mj / (m + mj), r_eff, 1.0, spring, dt);
    out.roll = Vec3d{0, 0, 0};
    if (roll) {
      const double ii = 0.4 * m * r * r, ij = 0.4 * mj * rj * rj;
      out.roll = rolling_torque(law, nrm, out.cf.fn, wi - P.w[j], r_eff, ii * ij / (ii + ij), dt);
    }
    return out;
  }

  // A particle that owns pairs, as its pairs read it: velocity, spin (0 when
  // spins are not followed), radius, mass.
  struct Owner {
    Vec3d v, w;
    double r, m;
  };
  // A touching pair as its owner i sees it.
  struct OwnedContact {
    uint32_t k, j;       // the listed pair's record, the partner
    Vec3d d;             // x_i - x_j
    double dist2, rs;    // |d|^2 < rs^2, the radii's sum
    Vec3d spring;        // the pair's spring as last step left it
    FrictionSlot* slot;  // where this step's goes, its key filed (nullptr past the slots)
  };
  // What the passes that record the pairs once read and write.
  struct RecordPass {
    ParticleArrays P;
    ContactLaw law;
    bool rot, rolling;
    const FrictionSlot* hin;  // last step's springs, this step's: null without friction
    FrictionSlot* hout;
    const uint32_t *nl_start, *nl;  // the upper lists
    Vec3d *rec_f, *rec_t, *rec_roll;
    uint8_t* touched;
  };
  RecordPass record_pass() {
    const bool friction = pair_law_.mu > 0;
    return {arrays(),
            pair_law_,
            rotation_,
            rotation_ && pair_law_.mu_roll > 0,
            friction ? pair_hist_[hist_in_].data() : nullptr,
            friction ? pair_hist_[hist_in_ ^ 1].data() : nullptr,
            nl_start_.data(),
            nl_list_.data(),
            rec_f_.data(),
            rec_torque_.data(),
            rec_roll_.data(),
            rec_touched_.data()};
  }

  // Particle i's upper list (the pairs it owns): marks each listed pair
  // touched or not and calls f(owner, contact) for each touching one, in list
  // order. Terminates the new slots. An inactive i touches nothing.
  // kMarks false: touched is left alone (pair_forces_in_order keeps no
  // records; and with no byte stores the compiler keeps the arrays' pointers).
  template <bool kMarks = true, class F>
  COLLIDO_HD static COLLIDO_FORCEINLINE void for_each_owned_contact(const RecordPass& R, uint32_t i,
                                                                    F&& f) {
    const ParticleArrays& P = R.P;
    const uint32_t* nl = R.nl;
    uint8_t* touched = R.touched;
    const Vec3d* x = P.x;
    const double* rad = P.r;
    const uint8_t* state = P.state;
    const bool rot = R.rot;
    const FrictionSlot* hin = R.hin;
    FrictionSlot* hout = R.hout;
    const uint32_t k0 = R.nl_start[i], k1 = R.nl_start[i + 1];
    if (state[i] != kActive) {
      if (kMarks)
        for (uint32_t k = k0; k < k1; ++k) touched[k] = 0;
      return;
    }
    const Owner owner{P.v[i], rot ? P.w[i] : Vec3d{0, 0, 0}, rad[i], P.mass[i]};
    const FrictionSlot* old_slots = hin ? hin + size_t(i) * kPairSlots : nullptr;
    FrictionSlot* new_slots = hout ? hout + size_t(i) * kPairSlots : nullptr;
    const Vec3d xi = x[i];
    uint32_t slots = 0;
    for (uint32_t k = k0; k < k1; ++k) {
      const uint32_t j = nl[k];
      if (kMarks) touched[k] = 0;
      if (state[j] != kActive) continue;
      const Vec3d d = xi - x[j];
      const double rs = owner.r + rad[j];
      const double dist2 = dot(d, d);
      if (!(dist2 < rs * rs)) continue;
      if (kMarks) touched[k] = 1;
      FrictionSlot* slot = nullptr;
      if (new_slots && slots < uint32_t(kPairSlots)) {
        slot = new_slots + slots++;
        slot->key = j;
      }
      const Vec3d spring = old_slots ? find_spring(old_slots, kPairSlots, j) : Vec3d{0, 0, 0};
      f(owner, OwnedContact{k, j, d, dist2, rs, spring, slot});
    }
    if (new_slots && slots < uint32_t(kPairSlots)) new_slots[slots].key = kNoKey;
  }

  // Pair forces once per pair, first pass: each particle evaluates the pairs
  // of its upper list (the pairs it owns) and records, per listed pair,
  // whether it touches and the contact's force, torque per metre and rolling
  // torque as the owner sees them; it keeps the pair's spring.
  void pair_records(double dt) {
    if constexpr (B::kPairRecordsInBatches) {
      if (cpu_vectors()) return pair_records_in_batches(dt);
    }
    const RecordPass R = record_pass();
    backend_.parallel_for_heavy(live_, [=] COLLIDO_HD(uint32_t i) {
      for_each_owned_contact(R, i, [&](const Owner& o, const OwnedContact& c) {
        Vec3d spring = c.spring;
        const PairContact pc = pair_contact(R.law, R.rot, R.P, i, c.j, o.v, o.w, o.r, o.m, c.d,
                                            c.dist2, c.rs, &spring, dt);
        R.rec_f[c.k] = pc.cf.f;
        if (R.rot) R.rec_t[c.k] = pc.cf.torque;
        if (R.rolling) R.rec_roll[c.k] = pc.roll;
        if (c.slot)
          c.slot->sx = float(spring.x), c.slot->sy = float(spring.y), c.slot->sz = float(spring.z);
      });
    });
  }

  // pair_records on the CPU: a chunk of particles finds its touching pairs
  // and their springs one at a time, in the order pair_records does, and
  // computes their forces four at a time (pair_batch_forces); the records and
  // the springs are the same bits.
  void pair_records_in_batches(double dt) {
    const RecordPass R = record_pass();
    backend_.parallel_chunks(live_, kHeavyGrain, [=](size_t begin, size_t end) {
      thread_local PairBatch b;
      for (uint32_t first = uint32_t(begin), last; first < end; first = last) {
        last = batch_end(R, first, uint32_t(end));
        b.reset(R.nl_start[last] - R.nl_start[first]);
        batch_touching_pairs(R, first, last, b);
        pair_batch_forces(R.law, R.rot, dt, b);
        using C = PairBatch;
        const double *fx = b.col(C::kFx), *tx = b.col(C::kTx), *sx = b.col(C::kSxOut);
        const double* rx = b.col(C::kRollX);
        const size_t st = b.stride;
        for (size_t c = 0; c < b.size; ++c) {
          const uint32_t k = b.record[c];
          R.rec_f[k] = Vec3d{fx[c], fx[c + st], fx[c + 2 * st]};
          if (R.rot) R.rec_t[k] = Vec3d{tx[c], tx[c + st], tx[c + 2 * st]};
          if (R.rolling) R.rec_roll[k] = Vec3d{rx[c], rx[c + st], rx[c + 2 * st]};
          if (FrictionSlot* s = b.slot[c])
            s->sx = float(sx[c]), s->sy = float(sx[c + st]), s->sz = float(sx[c + 2 * st]);
        }
      }
    });
  }

  // Whether one thread runs the step's pair pass with the vectors: it then
  // adds each pair's force to its two particles as it goes
  // (pair_forces_in_order), with no records and no gathering pass.
  bool sums_in_order() const {
    if constexpr (B::kPairRecordsInBatches && B::kHostThreads) {
      return cpu_vectors() && backend_.threads() == 1;
    } else {
      return false;
    }
  }

  // Whether the pairs evaluated once go through records (pair_records and
  // pair_gather): their buffers are allocated only then.
  bool keeps_records() const { return once_ && !sums_in_order(); }

  // pair_records_in_batches and pair_gather in one pass, for one thread. The
  // owners come in ascending index and each one's pairs in list order, so a
  // particle j receives its lower partners' forces (negated) in ascending
  // partner index, and then its own pairs' in list order: pair_gather's sums,
  // operation for operation, the same bits (test
  // PairsOnceOrFromBothSidesAgreeBitForBit runs this path, the records and
  // the pairs from both sides). The sums live in acc and alpha until a batch's
  // particles have all their pairs (a particle's lower partners come before
  // it), then become accelerations. Gathering read every listed pair's record
  // twice and branched on whether it touched; this reads the touching ones once.
  // wall (null: none): the wall's pass, run on each batch's particles once
  // they have their accelerations, which it adds to as it does after the
  // pair pass: the same bits, with no second pass over every particle (the
  // batch's particles still in the cache).
  struct WallPass;
  void pair_forces_in_order(double dt, const WallPass* wall) {
    const RecordPass R = record_pass();
    const ParticleArrays P = R.P;
    const Vec3d grav = cfg_.gravity;
    const bool rot = R.rot, rolling = R.rolling;
    const uint32_t live = uint32_t(live_);
    PairBatch& b = ordered_batch_;
    const GroupSums group_sums{P.acc, P.alpha, P.mass, P.r, P.state, rot};
    uint32_t started = 0;  // the sums of particles [0, started) are begun
    const auto start_sums = [&](uint32_t end) {
      for (; started < end; ++started) {
        const uint32_t i = started;
        if (P.state[i] != kActive) continue;
        P.acc[i] = grav * P.mass[i];
        if (rot) P.alpha[i] = Vec3d{0, 0, 0};
        P.flags[i] = uint8_t(kActive);
      }
    };
    using C = PairBatch;
    for (uint32_t first = 0, last; first < live; first = last) {
      last = batch_end(R, first, live);
      b.reset(R.nl_start[last] - R.nl_start[first]);
      batch_touching_pairs<false>(R, first, last, b);
      pair_batch_forces(R.law, rot, dt, b);
      start_sums(last);
      const double *fx = b.col(C::kFx), *tx = b.col(C::kTx), *sx = b.col(C::kSxOut);
      const double* rx = b.col(C::kRollX);
      const size_t st = b.stride;
      for (size_t c = 0; c < b.size; ++c) {
        const uint32_t i = b.owner[c], j = b.partner[c];
        if (j >= started) start_sums(j + 1);
        const Vec3d f{fx[c], fx[c + st], fx[c + 2 * st]};
        P.acc[i] = P.acc[i] + f;
        P.acc[j] = P.acc[j] - f;
        P.flags[i] = P.flags[j] = uint8_t(kActive | kFlagParticleContact);
        if (rot) {
          const Vec3d t{tx[c], tx[c + st], tx[c + 2 * st]};
          P.alpha[i] = P.alpha[i] + t * P.r[i];
          P.alpha[j] = P.alpha[j] + t * P.r[j];
        }
        if (rolling) {
          const Vec3d roll{rx[c], rx[c + st], rx[c + 2 * st]};
          P.alpha[i] = P.alpha[i] + roll;
          P.alpha[j] = P.alpha[j] - roll;
        }
        if (FrictionSlot* s = b.slot[c])
          s->sx = float(sx[c]), s->sy = float(sx[c + st]), s->sz = float(sx[c + 2 * st]);
      }
      // Particles [first, last) have every pair: their sums become
      // accelerations, four at a time where all four are active.
      for (uint32_t i = first; i < last;) {
        i = accelerate_active_groups(group_sums, i, last);
        for (const uint32_t stop = std::min(last, i + 4); i < stop; ++i)
          if (P.state[i] == kActive)
            sums_to_accelerations(P, i, P.acc[i], rot ? P.alpha[i] : Vec3d{0, 0, 0}, rot);
      }
      if (wall)
        for (uint32_t i = first; i < last; ++i) wall->step(i, LaneGroup{});
    }
  }

  // The end of the batch of particles from `first` (before `limit`): whole
  // particles, at least one, whose listed pairs number at most kBatchPairs.
  // A batch's columns stay in the first-level cache: a whole chunk's did
  // not, and its stores took longer than the scalar path's arithmetic. With
  // 34 doubles a pair, 48 pairs against 192 made a step 7 % faster on one
  // thread and 4 % on two (32 and 96 slower than 48); with 15 (stop 57: the
  // particles read from their arrays), 32, 96 and 192 pairs made no
  // difference (docs/benchmarks.md).
  static uint32_t batch_end(const RecordPass& R, uint32_t first, uint32_t limit) {
    const uint32_t most = R.nl_start[first] + kBatchPairs;
    uint32_t last = first + 1;
    while (last < limit && R.nl_start[last + 1] <= most) ++last;
    return last;
  }

  // pair_records_in_batches' first step: particles [first, last) file their
  // touching pairs (owner, partner, where the spring goes, the spring as last
  // step left it) into b, mark them touched, and file their springs' keys into
  // this step's slots, in pair_records' order. The particles' own values
  // pair_batch_forces reads from their arrays (b.src): filing them too, 34
  // doubles a pair, made this the step's costliest pass (docs/benchmarks.md).
  template <bool kMarks = true>
  static void batch_touching_pairs(const RecordPass& R, uint32_t first, uint32_t last,
                                   PairBatch& b) {
    using C = PairBatch;
    double* spring = b.col(C::kSx);
    const size_t st = b.stride;
    size_t c = 0;
    for (uint32_t i = first; i < last; ++i)
      for_each_owned_contact<kMarks>(R, i, [&](const Owner&, const OwnedContact& p) {
        if (kMarks) b.record[c] = p.k;  // the records' place (the records path only)
        b.owner[c] = i;
        b.partner[c] = p.j;
        b.slot[c] = p.slot;
        spring[c] = p.spring.x, spring[st + c] = p.spring.y, spring[2 * st + c] = p.spring.z;
        ++c;
      });
    b.size = c;
    // Spins only where they are followed, as pair_contact reads them.
    b.src = {R.P.x, R.P.v, R.rot ? R.P.w : nullptr, R.P.r, R.P.mass};
  }

  // Second pass: each particle sums its pairs' records with gravity, the lower
  // list's (negated) and then the upper list's, each in ascending index, as
  // pair_forces does, so both ways give the same bits.
  void pair_gather() {
    const ParticleArrays P = arrays();
    const bool rot = rotation_;
    const bool rolling = rot && pair_law_.mu_roll > 0;
    const Vec3d grav = cfg_.gravity;
    const uint32_t* nl_start = nl_start_.data();
    const uint32_t* lo_start = lo_start_.data();
    const uint32_t* lo_rec = lo_rec_.data();
    const Vec3d* rec_f = rec_f_.data();
    const Vec3d* rec_t = rec_torque_.data();
    const Vec3d* rec_roll = rec_roll_.data();
    const uint8_t* touched = rec_touched_.data();
    backend_.parallel_for(live_, [=] COLLIDO_HD(uint32_t i) {
      if (P.state[i] != kActive) return;
      const double r = P.r[i], m = P.mass[i];
      Vec3d f = grav * m, torque{0, 0, 0};
      bool any = false;
      for (uint32_t k = lo_start[i], e = lo_start[i + 1]; k < e; ++k) {
        const uint32_t q = lo_rec[k];
        if (!touched[q]) continue;
        f = f - rec_f[q];
        if (rot) torque = torque + rec_t[q] * r;
        if (rolling) torque = torque - rec_roll[q];
        any = true;
      }
      for (uint32_t q = nl_start[i], e = nl_start[i + 1]; q < e; ++q) {
        if (!touched[q]) continue;
        f = f + rec_f[q];
        if (rot) torque = torque + rec_t[q] * r;
        if (rolling) torque = torque + rec_roll[q];
        any = true;
      }
      P.flags[i] = any ? uint8_t(kActive | kFlagParticleContact) : uint8_t(kActive);
      sums_to_accelerations(P, i, f, torque, rot);
    });
  }

  // A particle's summed force and torque become its accelerations: one
  // expression for pair_gather and pair_forces_in_order, which give the same bits.
  COLLIDO_HD static COLLIDO_FORCEINLINE void sums_to_accelerations(const ParticleArrays& P,
                                                                   uint32_t i, Vec3d f,
                                                                   Vec3d torque, bool rot) {
    const double r = P.r[i], m = P.mass[i];
    P.acc[i] = f * (1.0 / m);
    if (rot) P.alpha[i] = torque * (1.0 / (0.4 * m * r * r));
  }

  // decide_t: the releases due by then are decided on the way (-inf: none).
  void pair_forces(double dt, bool measure, double decide_t) {
    const ParticleArrays P = arrays();
    const ContactLaw law = pair_law_;
    const bool rot = rotation_;
    const Vec3d grav = cfg_.gravity;
    const FrictionSlot* hin = pair_hist_[hist_in_].data();
    FrictionSlot* hout = pair_hist_[hist_in_ ^ 1].data();
    const PairCandidates cand = pair_candidates();
    const double* rel = release_.data();
    double* stats = scratch_.data();
    const size_t n = n_;
    const bool friction = law.mu > 0;
    const bool rolling = rot && law.mu_roll > 0;
    // With lists, a few lanes a particle where the GPU would have idle SMs
    // and the particles have candidates to share: each lane takes every
    // lanes-th candidate, and they file the springs in order.
    const uint32_t lanes = cand.list && !measure ? backend_.lanes_for(live_, nl_per_particle_,
                                                                      uint32_t(cfg_.lanes))
                                                : 1u;
    auto particle = [=] COLLIDO_HD(uint32_t i, LaneGroup g) {
      if (P.state[i] != kActive) {
        if (g.lane != 0) return;
        if (measure)
          stats[kStatElasticPair * n + i] = stats[kStatOverlapPair * n + i] =
              stats[kStatPairContacts * n + i] = stats[kStatOverflowPair * n + i] = 0;
        else if (due(P, rel, i, decide_t))
          decide_release(P, rel, cand, i);
        return;
      }
      const Vec3d xi = P.x[i], vi = P.v[i];
      const Vec3d wi = rot ? P.w[i] : Vec3d{0, 0, 0};
      const double r = P.r[i], m = P.mass[i];
      const Vec3f xf = cast3<float>(xi);
      const float rf = float(r);
      // Gravity first on the first lane, so one lane sums as a single loop does.
      Vec3d f = g.lane == 0 ? grav * m : Vec3d{0, 0, 0}, torque{0, 0, 0};
      double elastic = 0, overlap_max = 0;
      uint32_t npair = 0, slots = 0, overflow = 0;
      // No springs are kept without friction (the buffers are empty): no pointer into them.
      const FrictionSlot* old_slots = friction ? hin + size_t(i) * kPairSlots : nullptr;
      FrictionSlot* new_slots = friction ? hout + size_t(i) * kPairSlots : nullptr;
      // One candidate j: the exact test in double, then the contact's force.
      // owner: i is the pair's particle of lower index (it keeps the spring).
      // Returns whether the spring goes into i's slots (*spring).
      auto touch = [&](uint32_t j, bool owner, Vec3d* spring) {
        const Vec3d d = xi - P.x[j];
        const double rs = r + P.r[j];
        const double dist2 = dot(d, d);
        if (!(dist2 < rs * rs)) return false;
        // The pair's spring is kept by its owner, as that particle sees it.
        *spring = Vec3d{0, 0, 0};
        if (friction)
          *spring = owner ? find_spring(old_slots, kPairSlots, j)
                          : find_spring(hin + size_t(j) * kPairSlots, kPairSlots, i) * -1.0;
        const PairContact c = pair_contact(law, rot, P, i, j, vi, wi, r, m, d, dist2, rs, spring, dt);
        f = f + c.cf.f;
        if (rot) torque = torque + c.cf.torque * r;
        if (rolling) torque = torque + c.roll;
        elastic += 0.5 * c.cf.elastic;  // each side holds half the pair's springs
        overlap_max = hd_max(overlap_max, (rs - sqrt(dist2)) / r);
        ++npair;
        return friction && owner;
      };
      // Files the springs of a round of lanes in candidate order. Slots are
      // counted on the measuring pass too (it writes none), so that the
      // partners beyond kPairSlots reach the frame's statistics.
      auto file = [&](bool keep, uint32_t j, Vec3d spring) {
        const uint32_t at = slots + g.count_before(keep);
        slots += g.count(keep);
        if (!keep) return;
        if (at >= uint32_t(kPairSlots)) {
          ++overflow;
        } else if (!measure) {
          new_slots[at] = FrictionSlot{j, float(spring.x), float(spring.y), float(spring.z)};
        }
      };
      bool shared = false;  // whether the lanes hold shares to add up
      if (g.size > 1) {  // lanes come with lists; the candidates in the order each() gives
        const auto js = cand.listed(i);
        const uint32_t total = js.count;
        shared = total > 1;  // else the first lane has it all (a particle in flight, mostly)
        for (uint32_t base = 0; base < total; base += g.size) {
          const uint32_t c = base + g.lane;
          const uint32_t j = c < total ? js[c] : 0;
          Vec3d spring{0, 0, 0};
          const bool keep = c < total && P.state[j] == kActive && touch(j, i < j, &spring);
          file(keep, j, spring);
        }
      } else {  // the lists in the order pair_gather sums them too, or the grid's cells
        cand.each(i, xf, rf, [&](uint32_t j) {
          Vec3d spring{0, 0, 0};
          if (P.state[j] == kActive) file(touch(j, i < j, &spring), j, spring);
        });
      }
      if (shared) {
        f = g.sum(f);
        if (rot) torque = g.sum(torque);
        elastic = g.sum(elastic);
        overlap_max = g.max(overlap_max);
        npair = g.sum(npair);
        overflow = g.sum(overflow);
      }
      if (g.lane != 0) return;
      P.flags[i] = npair ? uint8_t(kActive | kFlagParticleContact) : uint8_t(kActive);
      if (measure) {
        stats[kStatElasticPair * n + i] = elastic;
        stats[kStatOverlapPair * n + i] = overlap_max;
        stats[kStatPairContacts * n + i] = npair;
        stats[kStatOverflowPair * n + i] = overflow;
        return;
      }
      P.acc[i] = f * (1.0 / m);
      if (friction && slots < uint32_t(kPairSlots))
        new_slots[slots].key = kNoKey;  // terminates the list
      if (rot) P.alpha[i] = torque * (1.0 / (0.4 * m * r * r));
    };
    backend_.parallel_for_lanes(live_, lanes, particle);
  }

  // Wall contacts, one per touched feature: on top of pair_forces' accelerations when the
  // scene has particle contacts, else from gravity.
  // A moving wall (pose) is searched in its own frame: the particle's centre
  // is taken there, and the contact's normal brought back; the contact moves
  // with the wall's velocity at the contact point.
  // part_pose: the moving part's, when one moves (pose is then the identity).
  // The pass's inputs are gathered once (wall_pass) into a functor, so that
  // the one-thread pair pass can run it particle by particle too
  // (pair_forces_in_order).
  struct WallPass {
    ParticleArrays P;
    WallView wall, mwall;
    const PlanarTriangleD *tris_d, *mtris_d;
    Vec3d shift;
    uint32_t pb, pn;  // a moving part's triangles, [pb, pb + pn) of the wall as given
    const uint32_t *wl_start, *wl_count, *wl;
    ContactLaw law;
    Vec3d grav;
    const FrictionSlot* hin;
    FrictionSlot* hout;
    double *stats, *peak;
    size_t n;
    double dt;
    WallPose pose, part_pose;
    bool add, part, listed, rot, friction, measure;
    // Most particles list no wall candidate: they skip the contact set's
    // set-up (a call and its frame, most of this pass's time on the CPU), and
    // their spring lists, emptied in both generations at the build, stay so.
    // With particle contacts the pass leaves them as the pairs did. (A listed
    // wall stands still: it has no moving part either.)
    COLLIDO_HD bool idle(uint32_t i) const {
      return listed && !measure && wl_count[i] == 0 && P.state[i] == kActive;
    }
    // Particle i's pass, idle or not: an idle one gets only what a particle
    // touching nothing gets (without particle contacts, gravity alone), on one lane.
    COLLIDO_HD void step(uint32_t i, LaneGroup g) const {
      if (!idle(i)) return (*this)(i, g);
      if (g.lane == 0 && !add) {
        P.acc[i] = grav;
        if (rot) P.alpha[i] = Vec3d{0, 0, 0};
        P.flags[i] = uint8_t(kActive);
      }
    }
    COLLIDO_HD void operator()(uint32_t i, LaneGroup g) const {
      const uint8_t st = P.state[i];
      if (st != kActive) {
        if (g.lane != 0) return;
        if (measure)
          stats[kStatElasticWall * n + i] = stats[kStatOverlapWall * n + i] =
              stats[kStatWallContacts * n + i] = stats[kStatTouching * n + i] =
                  stats[kStatOverflowWall * n + i] = 0;
        else  // a waiting particle is released into free flight: its first kick is gravity's
          P.acc[i] = st == kWaiting ? grav : Vec3d{0, 0, 0};
        if (st != kWaiting) P.flags[i] = st;  // a waiting particle's holds its release decision
        return;
      }
      const Vec3d xi = pose.moving ? pose.to_body(P.x[i]) : P.x[i];
      const double r = P.r[i];
      // Candidates from the prepared wall; most particles have none and stop here.
      WallContactSet<kMaxWallContacts> set;
      const double r2 = r * r, tol = 1e-9 * r;
      // The contact of the centre x with triangle t, when they touch.
      auto touch = [&](const PlanarTriangleD& t, Vec3d x, uint32_t orig, WallContact* out) {
        Vec3d q;
        double h = 0, aside = 0;
        const double d2 = closest_point_planar(x, t, r2, &q, &h, &aside);
        if (!(d2 < r2)) return false;
        double d = sqrt(d2);
        Vec3d nrm;
        // Face contact, or the centre over the face's very edge (within 1e-9 r
        // of it, the centre on it included): the plane's own normal, towards
        // the centre. An edge's own normal there would carry the vertices'
        // rounding (a floor's edge 6e-19 m off its line) into a sideways push
        // that walks a resting ball off the edge, as off a ridge.
        if (!(aside > 1e-18 * r2)) {
          nrm = h >= 0 ? t.n : t.n * -1.0;
          d = hd_abs(h);
        } else {
          nrm = (x - q) * (1.0 / d);
        }
        *out = WallContact{q, nrm, d, orig};
        return true;
      };
      // Candidate k's contact offered to *into when it touches.
      auto probe = [&](uint32_t k, uint32_t orig, auto* into) {
        WallContact w;
        if (touch(tris_d[k], xi, part && orig >= pb ? orig + pn : orig, &w)) into->offer(w, tol);
      };
      auto consider = [&](uint32_t k, uint32_t orig) { probe(k, orig, &set); };
      if (g.size > 1) {  // lanes come with the lists
        const uint32_t q0 = wl_start[i], total = wl_count[i];
        for (uint32_t base = 0; base < total; base += g.size) {
          const uint32_t c = base + g.lane;
          WallContactSet<1> mine;  // this lane's candidate, if it touches
          if (c < total) {
            const uint32_t k = wl[q0 + c];
            probe(k, wall.original_of(k), &mine);
          }
          for (uint32_t hits = g.bits(mine.n > 0); hits; hits &= hits - 1) {
            const uint32_t src = LaneGroup::lowest(hits);
            const WallContact& w = mine.c[0];
            set.offer(WallContact{g.from(src, w.q), g.from(src, w.n), g.from(src, w.dist),
                                  g.from(src, w.triangle)},
                      tol);
          }
        }
        if (g.lane != 0) return;
      } else if (listed) {
        for (uint32_t q = wl_start[i], e = q + wl_count[i]; q < e; ++q)
          consider(wl[q], wall.original_of(wl[q]));
      } else {
        wall.for_each_candidate(cast3<float>(xi), consider);
      }
      if (part) {
        // The moving part's contacts, found in its frame and offered in the
        // wall's, so each shadows the other's as on one wall.
        const Vec3d xm = part_pose.to_body(P.x[i] + shift);
        mwall.for_each_candidate(cast3<float>(xm), [&](uint32_t k, uint32_t orig) {
          WallContact w;
          if (!touch(mtris_d[k], xm, pb + orig, &w)) return;
          w.q = part_pose.to_world(w.q) - shift;
          w.n = part_pose.rotate(w.n);
          set.offer(w, tol);
        });
      }
      // No springs are kept without friction (the buffers are empty): no pointer into them.
      const FrictionSlot* old_slots = friction ? hin + size_t(i) * kWallSlots : nullptr;
      FrictionSlot* new_slots = friction ? hout + size_t(i) * kWallSlots : nullptr;
      if (set.n == 0 && !measure) {
        // Away from the wall (most particles): nothing to add, no springs kept.
        if (!add) {
          P.acc[i] = grav;
          if (rot) P.alpha[i] = Vec3d{0, 0, 0};
          P.flags[i] = uint8_t(kActive);
        }
        if (friction) new_slots[0].key = kNoKey;
        return;
      }
      const double m = P.mass[i];
      Vec3d f{0, 0, 0}, torque{0, 0, 0};
      double elastic = 0, overlap_max = 0;
      const Vec3d vi = P.v[i];
      const Vec3d wi = rot ? P.w[i] : Vec3d{0, 0, 0};
      for (int k = 0; k < set.n; ++k) {
        const Vec3d nrm = pose.moving ? pose.rotate(set.c[k].n) : set.c[k].n;
        const double overlap = r - set.c[k].dist;
        Vec3d vrel = friction ? vi + cross(wi, nrm * (-r)) : vi;
        // The wall's own velocity where it touches (the point on it nearest the centre).
        const bool on_part = part && set.c[k].triangle - pb < pn;
        if (pose.moving) vrel = vrel - pose.velocity_at(P.x[i] - nrm * set.c[k].dist);
        if (on_part) vrel = vrel - part_pose.velocity_at(P.x[i] + shift - nrm * set.c[k].dist);
        const Vec3d wall_spin = on_part ? part_pose.w : pose.w;
        const uint32_t key = kWallKeyBit | set.c[k].triangle;
        Vec3d spring = friction ? find_spring(old_slots, kWallSlots, key) : Vec3d{0, 0, 0};
        const ContactForce cf = contact_force(law, nrm, overlap, vrel, m, r, r, &spring, dt);
        f = f + cf.f;
        torque = torque + cf.torque;
        if (rot && law.mu_roll > 0)
          torque = torque + rolling_torque(law, nrm, cf.fn, wi - wall_spin, r, 0.4 * m * r * r, dt);
        elastic += cf.elastic;
        overlap_max = hd_max(overlap_max, overlap / r);
        if (friction && !measure)
          new_slots[k] = FrictionSlot{key, float(spring.x), float(spring.y), float(spring.z)};
      }
      const uint8_t base = add ? P.flags[i] : uint8_t(kActive);
      P.flags[i] = set.n ? uint8_t(base | kFlagWallContact) : base;
      if (measure) {
        stats[kStatElasticWall * n + i] = elastic;
        stats[kStatOverlapWall * n + i] = overlap_max;
        stats[kStatWallContacts * n + i] = set.n;
        stats[kStatTouching * n + i] = set.n ? 1.0 : 0.0;
        stats[kStatOverflowWall * n + i] = set.dropped;
        return;
      }
      if (overlap_max > peak[i]) peak[i] = overlap_max;
      const Vec3d a = f * (1.0 / m);
      P.acc[i] = add ? P.acc[i] + a : a + grav;
      if (friction && set.n < kWallSlots) new_slots[set.n].key = kNoKey;  // terminates the list
      if (rot) {
        const Vec3d al = torque * (1.0 / (0.4 * m * r * r));
        P.alpha[i] = add ? P.alpha[i] + al : al;
      }
    }
  };
  WallPass wall_pass(double dt, bool measure, const WallPose pose, const WallPose part_pose) {
    WallPass w;
    w.add = cfg_.particle_contacts;
    w.P = arrays();
    w.wall = wall_.view();
    w.tris_d = wall_.tris_d.data();
    // A moving part's triangles are [pb, pe) of the wall as given; the still
    // ones are numbered around them, so every contact keeps the wall's own index.
    w.part = part_;
    w.mwall = part_ ? mover_.view() : WallView{};
    w.mtris_d = part_ ? mover_.tris_d.data() : nullptr;
    w.shift = shift_;
    w.pb = uint32_t(cfg_.wall_motion.part_begin);
    w.pn = part_ ? uint32_t(cfg_.wall_motion.part_end) - w.pb : 0;
    // The wall's candidates from the neighbour list when it has them.
    w.listed = wall_list_;
    w.wl_start = wl_start_.data();
    w.wl_count = wl_count_.data();
    w.wl = wl_list_.data();
    w.law = wall_law_;
    w.rot = rotation_;
    w.grav = cfg_.gravity;
    w.hin = wall_hist_[hist_in_].data();
    w.hout = wall_hist_[hist_in_ ^ 1].data();
    w.stats = scratch_.data();
    w.peak = peak_overlap_.data();
    w.n = n_;
    w.friction = wall_law_.mu > 0;
    w.dt = dt;
    w.measure = measure;
    w.pose = pose;
    w.part_pose = part_pose;
    return w;
  }

  void wall_forces(double dt, bool measure, const WallPose pose, const WallPose part_pose) {
    const WallPass pass = wall_pass(dt, measure, pose, part_pose);
    // With the wall's lists, lanes share a particle's candidates as in
    // pair_forces; the contacts they find are offered to the set in candidate
    // order on every lane, so the set, and the forces, are one lane's bit for bit.
    const uint32_t lanes = pass.listed && !measure
                               ? backend_.lanes_for(live_, wl_per_particle_, uint32_t(cfg_.lanes))
                               : 1u;
    backend_.parallel_for_lanes(live_, lanes,
                                [=] COLLIDO_HD(uint32_t i, LaneGroup g) { pass.step(i, g); });
  }

  // Kinetic and potential energy, speed and state counts for the measuring pass.
  void kinematics_stats() {
    const ParticleArrays P = arrays();
    double* stats = scratch_.data();
    const size_t n = n_;
    const bool rot = rotation_;
    const Vec3d g = cfg_.gravity;
    const double* rel = release_.data();
    const double t = released_to_;
    backend_.parallel_for(live_, [=] COLLIDO_HD(uint32_t i) {
      const uint8_t st = P.state[i];
      const bool active = st == kActive;
      const double m = P.mass[i];
      double ke = 0, pe = 0, sp = 0;
      if (active) {
        ke = 0.5 * m * dot(P.v[i], P.v[i]);
        if (rot) ke += 0.5 * 0.4 * m * P.r[i] * P.r[i] * dot(P.w[i], P.w[i]);
        pe = -m * dot(g, P.x[i]);
        sp = length(P.v[i]);
      }
      stats[kStatKinetic * n + i] = ke;
      stats[kStatPotential * n + i] = pe;
      stats[kStatSpeed * n + i] = sp;
      stats[kStatWaiting * n + i] = st == kWaiting;
      stats[kStatHeld * n + i] = due(P, rel, i, t);
      stats[kStatActive * n + i] = active;
      stats[kStatEscaped * n + i] = st == kEscaped;
      stats[kStatInvalid * n + i] = st == kInvalid;
    });
  }

  B backend_;
  DynamicsConfig cfg_;
  TimeStepInfo ts_;
  PrepareInfo info_;
  ContactLaw pair_law_, wall_law_;
  bool rotation_ = false;  // spins are followed (some contact has friction)
  WallIndex<B> wall_;  // the wall, or the part of it that stands still
  // The moving part (part_): its index, and its frame's offset from the wall's
  // (a position there is x + shift_).
  bool part_ = false;
  WallIndex<B> mover_;
  Vec3d shift_{0, 0, 0};
  GridSpec pgrid_;
  int pkey_bits_ = 32;  // radix sort bits of a particle bucket key, set with pgrid_
  size_t grid_keys_ = 0;  // keys sorted into p_key_sorted_ at the last grid build (their buckets set)
  Vec3d lo_{0, 0, 0}, hi_{0, 0, 0};  // the domain, in the local frame (origin: the wall's centre)
  size_t n_ = 0;
  // The live prefix: particles [0, live_) of the engine's numbering may have
  // been released, those past it all wait; a step's passes run over the prefix.
  size_t live_ = 0;
  std::vector<double> due_from_;  // host: the earliest release at or after each place
  double time_ = 0;
  double last_release_ = 0;  // s: no particle waits after this
  bool all_released_ = false;
  double released_to_ = 0;  // s: releases due by then have been decided (see takes_place)
  bool timing_ = false;
  StepTimes times_;
  std::chrono::steady_clock::time_point lap_;
  uint64_t steps_ = 0;
  std::vector<double> radius_host_, release_host_;

  Buf<Vec3d> pos_, vel_, acc_, omega_, alpha_;
  Buf<uint32_t> order_;  // order_[k]: the caller's index of the particle held at k
  uint64_t pair_builds_ = 0;  // pair-list builds so far (renumber_every counts them)
  Buf<double> radius_, mass_, release_, speed_, scratch_;
  Buf<double> peak_overlap_;  // deepest wall overlap per particle since the last measure
  Buf<uint8_t> state_, flags_;
  // Friction springs as terminated lists: last step's (hist_in_) and this step's.
  Buf<FrictionSlot> wall_hist_[2], pair_hist_[2];
  int hist_in_ = 0;
  Buf<uint32_t> p_key_, p_idx_, p_key_sorted_, p_idx_sorted_, cell_start_, cell_end_;
  Buf<PackedParticle> sorted_;  // float copies in cell order, for the pair loop's first test
  // The lists (lists_): the particle pairs' (nlist_, with particle contacts)
  // and the wall's (wall_list_), built together at the positions x_ref_;
  // per particle [nl_start_[i], nl_start_[i + 1]) of nl_list_.
  bool lists_ = false, nlist_ = false, nl_valid_ = false;
  double skin_ = 0;
  size_t nl_cover_ = 0;  // the lists hold the particles before this place (list_cover)
  double nl_per_particle_ = 0;  // candidates a particle in the lists (both sides), on average
  double wl_per_particle_ = 0;  // wall triangles a particle in its lists, on average (at most)
  double nl_built_at_ = 0, nl_life_ = 0;  // s: when they were last built, how long the one before lasted
  uint64_t nl_built_step_ = 0;            // the step count at the last build
  uint64_t nl_life_steps_ = 0;            // steps the last lists lasted (0 until a second build)
  // Velocity Verlet's close of the last step (its dt) waits for the next pass.
  bool close_pending_ = false;
  double pending_dt_ = 0;
  bool disp_fresh_ = false;  // disp_max_ is the largest move of the current positions
  // The steps launched since the host last read the lists' check (GPU).
  std::vector<WindowStep> window_;
  double disp_max_ = 0;      // squared, since the lists were built
  // Each list holds the partners whose pair the particle owns (upper, sorted);
  // lo_start_, lo_j_ and lo_rec_ give each particle the partners owning their
  // pair with it (sorted) and where each such pair sits in its owner's upper list.
  Buf<uint32_t> nl_start_, nl_list_, lo_start_, lo_j_, lo_rec_;
  // once_: pair forces evaluated once per pair, into records per upper-list entry.
  bool once_ = false;
  Buf<Vec3d> rec_f_, rec_torque_, rec_roll_;
  Buf<uint8_t> rec_touched_;
  PairBatch ordered_batch_;  // pair_forces_in_order's
  // The wall's candidates per particle (wall_list_, on a still wall):
  // wl_count_[i] triangles or pieces from wl_list_[wl_start_[i]].
  bool wall_list_ = false;
  Buf<uint32_t> wl_start_, wl_count_, wl_list_;
  Buf<Vec3d> x_ref_;
  float filter_slack_ = 0;
  std::unique_ptr<ThreadPool> one_thread_;  // a small scene's steps (see init)
};

}  // namespace collido::sim
