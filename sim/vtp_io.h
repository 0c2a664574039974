// VTK PolyData (.vtp) frames and a ParaView collection (.pvd) that lists them
// with their times, so a run opens in ParaView as an animation.
#pragma once

#include <string>
#include <vector>

#include "sim/snapshot.h"
#include "sim/status.h"

namespace collido::sim {

// Writes the snapshot's particles as vertices with point data radius,
// velocity and contact (world units: origin added back). ASCII XML.
Status write_vtp(const std::string& path, const Snapshot& snapshot);

// One entry of a .pvd collection: the time (s) and the file (relative to the .pvd).
struct PvdEntry {
  double time;
  std::string file;
};
Status write_pvd(const std::string& path, const std::vector<PvdEntry>& entries);

}  // namespace collido::sim
