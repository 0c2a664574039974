// A run's changing state at a frame boundary, saved so a killed or preempted
// job resumes where it stopped. Little-endian binary:
//   char[8] "CLCKPT04", uint64 frame, uint64 particles, double time,
//   uint64 steps, uint8 all_released, uint32 array count,
//   then per array: uint64 bytes, the bytes; the same for the neighbour
//   lists (a count, then each array; "CLCKPT02" files end before them);
//   then the wall's method as uint32 length and its characters, and the grid
//   length as a double ("CLCKPT03" files end before them);
//   last, uint64 FNV-1a hash of everything before it.
// Written through a temporary name, so the file is always a whole checkpoint.
#pragma once

#include <cstdint>
#include <string>

#include "common/status.h"
#include "sim/dynamics.h"

namespace collido::job {

struct Checkpoint {
  uint64_t frame = 0;  // the last frame whose outputs are written
  sim::SimState state;
  // The wall's representation the state was made with ("" in older files):
  // a resumed run of method or grid length "auto" keeps it rather than timing
  // the candidates again, which may choose another one the state does not fit.
  std::string method;
  double grid_length = 0;
};

Status write_checkpoint(const std::string& path, const Checkpoint& c);
// Errors say whether the file is missing (kNotFound) or damaged (kParse).
Expected<Checkpoint> read_checkpoint(const std::string& path);

}  // namespace collido::job
