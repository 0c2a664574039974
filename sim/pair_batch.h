// The CPU's pair contacts, four at a time (AVX2): the touching pairs a chunk
// of particles owns are filed (owner, partner, spring), their forces computed
// across the vector's lanes, reading the particles' values from their arrays,
// and the results handed back. And Verlet's opening pass, four particles at a
// time (open_plain_groups), and the one-thread pair pass's last step, sums to
// accelerations (accelerate_active_groups), at the end.
//
// The arithmetic is that of pair_contact (sim/dynamics_pipeline.h),
// contact_force and rolling_torque (sim/contact_force.h), for both laws,
// operation for operation, in the same order, with no fused multiply-adds:
// IEEE rounds each lane as it rounds the scalar code, so the records are the
// scalar path's bit for bit (test PairsOnceOrFromBothSidesAgreeBitForBit
// compares them with the pairs evaluated from both sides one at a time). One
// contact at a time, a contact's three square roots and three divisions ran
// one after another, and the pair pass was most of a step (docs/benchmarks.md).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "sim/contact_force.h"

namespace collido::sim {

// The touching pairs of a chunk in the order they were found: the pair's
// particles i (the owner) and j, and a column per input and output. The
// particles' positions, velocities, spins, radii and masses are read from
// their arrays (src) through owner and partner: filed into columns as well
// (34 doubles a pair) they made the filing the step's costliest pass, its
// stores more than the arithmetic (docs/benchmarks.md, stop 57).
struct PairBatch {
  // In: the spring as last step left it. (i < j always: a pair is its
  // owner's, the particle of lower index, so should the centres coincide the
  // normal is +z; the squared distance is computed from x_i - x_j with
  // pair_contact's operations.)
  // clang-format off
  enum Column {
    kSx, kSy, kSz,
    // Out: the force on i, the torque per metre of lever on i, the spring,
    // the rolling torque on i.
    kFx, kFy, kFz, kTx, kTy, kTz, kSxOut, kSyOut, kSzOut, kRollX, kRollY, kRollZ,
    kColumns
  };
  // clang-format on
  size_t size = 0;
  size_t stride = 0;          // column c holds data[c * stride, c * stride + size)
  std::vector<double> data;
  std::vector<uint32_t> record;     // the listed pair's record index
  std::vector<uint32_t> owner, partner;  // the pair's i and j
  std::vector<FrictionSlot*> slot;  // where its spring goes (nullptr: past the slots)
  // The particles' arrays, which pair_batch_forces reads through owner and partner.
  struct Sources {
    const Vec3d *x = nullptr, *v = nullptr, *w = nullptr;  // w null: no spins
    const double *r = nullptr, *m = nullptr;
  } src;

  // Empties the batch, with room for `pairs` (and the padding of a group of four).
  void reset(size_t pairs) {
    size = 0;
    if (pairs + 3 > stride) {
      // Whole cache lines, an odd number of them: columns a power of two
      // apart share the cache's sets and the store buffer's 4 KiB aliasing.
      stride = ((pairs + 3 + 7) & ~size_t(7)) | 8;
      data.resize(stride * kColumns);
      record.resize(stride);
      owner.resize(stride);
      partner.resize(stride);
      slot.resize(stride);
    }
  }
  double* col(Column c) { return data.data() + c * stride; }
  const double* col(Column c) const { return data.data() + c * stride; }
};

// Whether this CPU runs pair_batch_forces (AVX2; false on other machines and
// architectures, where the scalar path runs).
bool pair_batch_supported();

// Fills the batch's output columns for pairs [0, size) under either law
// (friction when law.mu > 0, rolling resistance when rot and law.mu_roll > 0;
// spins read only when rot), the particles' values read through b.src. Pads
// the last group of four with copies of the last pair, whose results are the
// same bits.
void pair_batch_forces(const ContactLaw& law, bool rot, double dt, PairBatch& b);

// Velocity Verlet's opening pass (OpenStep in sim/dynamics_pipeline.h), four
// particles at a time, for groups of four whose particles are all active and
// plain: finite, well short of overflowing a squared speed, and inside the
// domain before and after the drift. Each value goes through the scalar
// pass's operations in its order (a Vec3's components are independent, so
// the vectors work on the arrays as they lie, three components and a
// quarter a register), so the results are its bits.
struct OpenGroups {
  Vec3d *x = nullptr, *v = nullptr, *w = nullptr;  // w: only with rot
  const Vec3d *acc = nullptr, *alpha = nullptr;
  const uint8_t* state = nullptr;
  const Vec3d* ref = nullptr;  // where each particle was at the lists' build (only with disp)
  bool close = false;          // the pending step's closing kick first
  bool rot = false, disp = false;
  double close_half = 0;  // 0.5 x the pending step's length (the closing kick's)
  double half_dt = 0, dt = 0;
  Vec3d lo, hi;            // the domain where the pending step ended
  Vec3d next_lo, next_hi;  // where this step ends
};
// Opens the plain groups [i, i + 4), [i + 4, i + 8), .. before `end`, up to
// the first group that is not plain; returns where it stopped (that group's
// first particle, or the last whole group's end), having raised *most to the
// largest squared move since the lists' build (with disp).
uint32_t open_plain_groups(const OpenGroups& g, uint32_t i, uint32_t end, double* most);

// A particle's summed force and torque become its accelerations
// (sums_to_accelerations in sim/dynamics_pipeline.h), four particles at a
// time, for groups of four whose particles are all active: acc = f * (1 / m)
// and, with rot, alpha = torque * (1 / (0.4 m r r)), the same operations. Four
// divisions in one instruction: one at a time they were 2 % of the block's step.
struct GroupSums {
  Vec3d *acc = nullptr, *alpha = nullptr;  // the sums in, the accelerations out
  const double *m = nullptr, *r = nullptr;
  const uint8_t* state = nullptr;
  bool rot = false;
};
// Groups [i, i + 4), [i + 4, i + 8), .. before `end`, up to the first with a
// particle that is not active; returns where it stopped.
uint32_t accelerate_active_groups(const GroupSums& g, uint32_t i, uint32_t end);
}  // namespace collido::sim
