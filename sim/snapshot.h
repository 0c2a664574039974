// One frame of a run as the engine writes it to disk, for the renderer and for
// later analysis. A run directory holds
//   DIR/wall.stl                     the wall (binary STL, world units)
//   DIR/frames/frame_NNNNNN.snap     one file per frame, NNNNNN = frame index
// A .snap file is little-endian binary:
//   char[8]  magic "CLSNAP01"
//   uint32   version (1)
//   uint32   particle count n
//   uint64   frame index
//   double   time (s)
//   double   origin[3] (world units; positions below are relative to it, so
//            float keeps its precision far from the world origin)
//   float    x[n], y[n], z[n], r[n], vx[n], vy[n], vz[n]
//   uint8    contact[n] (1 when the particle touches the wall in this frame)
// Structure of arrays: each array is read or written in one block, and a
// reader that only wants positions can skip the rest.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "sim/hd.h"
#include "sim/status.h"

namespace collido::sim {

inline constexpr char kSnapshotMagic[8] = {'C', 'L', 'S', 'N', 'A', 'P', '0', '1'};
inline constexpr uint32_t kSnapshotVersion = 1;
inline constexpr size_t kSnapshotHeaderBytes = 8 + 4 + 4 + 8 + 8 + 3 * 8;  // 56
inline constexpr size_t kSnapshotBytesPerParticle = 7 * 4 + 1;             // 29
// Far more particles than any run holds; a count above it means a corrupt file.
inline constexpr uint32_t kSnapshotMaxParticles = 1u << 30;

struct Snapshot {
  uint64_t frame = 0;
  double time = 0;                // s
  Vec3d origin{0, 0, 0};          // world units
  std::vector<float> x, y, z;     // position relative to origin, world units
  std::vector<float> r;           // radius, world units
  std::vector<float> vx, vy, vz;  // velocity, world units per second
  std::vector<uint8_t> contact;   // 0 or 1

  size_t size() const { return x.size(); }
  // Sizes every array for n particles (contents zeroed).
  void resize(size_t n);
};

// DIR/frames/frame_NNNNNN.snap for a frame index (six digits, more when needed).
std::string snapshot_path(const std::string& run_dir, uint64_t frame);

// Writes a snapshot to a temporary name in the same directory and renames it
// into place, so a reader never sees half a frame.
Status write_snapshot(const std::string& path, const Snapshot& snapshot);

// Reads and validates a snapshot: magic, version, a size that matches the
// count exactly, finite values and non-negative radii. Errors name the file.
Expected<Snapshot> read_snapshot(const std::string& path);

// Reads the header only (n, frame, time, origin; arrays left empty).
Expected<Snapshot> read_snapshot_header(const std::string& path);

}  // namespace collido::sim
