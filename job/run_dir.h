// The layout of a run directory, and who owns it. Every job writes
//   job.json            the spec it ran (what --resume reads back)
//   scene.json          the scene with every default filled in
//   wall.stl            the wall as the engine used it (binary STL, metres)
//   frames/frame_NNNNNN.snap   one snapshot per frame (sim/snapshot.h)
//   stats.csv           one row per frame; stats.csv.partial while running
//   checkpoint.bin      the state at the last saved frame (job/checkpoint.h)
//   vtp/*.vtp, frames.pvd      ParaView frames (optional)
//   render/             poster.png, video.mp4, video.webm, loop.gif, frames/*.png
//   result.json         the manifest: status, artifacts, measured cost
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/status.h"
#include "job/job.h"

namespace collido::job {

struct RunPaths {
  std::string dir;
  std::string join(const std::string& name) const { return dir + "/" + name; }
  std::string job() const { return join("job.json"); }
  std::string scene() const { return join("scene.json"); }
  std::string wall() const { return join("wall.stl"); }
  std::string frames() const { return join("frames"); }
  std::string stats() const { return join("stats.csv"); }
  std::string stats_partial() const { return join("stats.csv.partial"); }
  std::string checkpoint() const { return join("checkpoint.bin"); }
  std::string vtp() const { return join("vtp"); }
  std::string pvd() const { return join("frames.pvd"); }
  std::string render() const { return join("render"); }
  std::string result() const { return join("result.json"); }
};

// Makes `dir` this run's own, by the policy: an empty or missing directory is
// taken as it is; one holding files is refused (kRefuse), emptied when it holds
// a run (kReplace: a directory with files but no run in it is refused, so a
// mistyped --out never deletes someone's folder), or kept for kResume. Leftover
// temporary files (common/atomic_file.h) are removed in every case.
Status claim_run_dir(const std::string& dir, DirPolicy policy);

// Whether `dir` holds a run (started or finished) that kResume can continue.
bool holds_a_run(const std::string& dir);

// Every file of the run, relative to the directory, with size, MIME type and
// role; a folder of many frames is one entry with its total size and count.
std::vector<Artifact> list_artifacts(const RunPaths& paths, uint64_t* frame_files);

// MIME type by file name extension ("video/mp4", "image/gif", ...).
std::string mime_type(const std::string& path);

}  // namespace collido::job
