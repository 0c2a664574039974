// `collidoscope detect`: one detection frame on a wall and a particle set.
#include <cerrno>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "common/atomic_file.h"
#include "app/cli.h"
#include "app/commands.h"
#include "app/detect_setup.h"
#include "sim/snapshot.h"

#include <sys/stat.h>

namespace collido::app {

namespace {

const std::vector<FlagSpec> kFlags = {
    {"wall", true,
     "FILE.stl | cylinder:r=50,h=100,segments=40 | wall1 | wall2 | box:... (default wall1)"},
    {"particles", true, "N random particles in the wall's bounding box, or FILE.csv (x,y,z,r)"},
    {"seed", true, "random seed for --particles N (default 1)"},
    {"radius", true, "radius of random particles (default 1)"},
    {"radius-range", true, "A:B radii uniform in [A, B] (overrides --radius)"},
    {"method", true,
     "gravity | circumcircle | midpoint4 | bin | bvh | octree | reference (default bin)"},
    {"traversal", true, "particle | wall (default particle)"},
    {"precision", true,
     "exact (float, pairs near touching re-decided in double) | float (default exact)"},
    {"backend", true, "cpu | cuda (default cpu; cuda falls back to cpu with a note)"},
    {"grid-length", true, "cell edge in world units (default 2 r_max)"},
    {"threads", true, "CPU threads (default: all cores)"},
    {"out", true, "write contacts to this CSV: particle,triangle,distance"},
    {"json", false, "print a machine-readable summary"},
    {"snapshot", true,
     "write DIR/wall.stl and DIR/frames/frame_000000.snap (contact flags) for `render`"},
    {"help", false, "show this help"},
};

// One frame as a run directory: the wall and the particles with their contact flags.
sim::Status write_detect_snapshot(const std::string& dir, const DetectSetup& setup, const sim::DetectResult& result) {
  for (const std::string& d : {dir, dir + "/frames"})
    if (::mkdir(d.c_str(), 0755) != 0 && errno != EEXIST) return sim::io_error(d + ": cannot create directory");
  if (sim::Status s = sim::save_stl(setup.wall, dir + "/wall.stl"); !s) return s;
  sim::Snapshot snap;
  const sim::Vec3d origin = sim::mesh_bounds(setup.wall).center();
  snap.origin = origin;
  snap.resize(setup.particles.size());
  for (size_t i = 0; i < setup.particles.size(); ++i) {
    snap.x[i] = static_cast<float>(setup.particles.x[i] - origin.x);
    snap.y[i] = static_cast<float>(setup.particles.y[i] - origin.y);
    snap.z[i] = static_cast<float>(setup.particles.z[i] - origin.z);
    snap.r[i] = static_cast<float>(setup.particles.r[i]);
    snap.contact[i] = result.counts[i] != 0;
  }
  return sim::write_snapshot(sim::snapshot_path(dir, 0), snap);
}

}  // namespace

int cmd_detect(const Args& args) {
  std::string err;
  auto parsed = parse_args(args, kFlags, &err);
  if (!parsed) return usage_error("detect", err);
  if (parsed->has("help")) {
    print_help("usage: collidoscope detect --particles N|FILE.csv [--wall SPEC] [--method M] ...", kFlags);
    return kExitOk;
  }
  if (!parsed->positional().empty())
    return usage_error("detect", "unexpected argument '" + parsed->positional()[0] + "'");
  if (!parsed->has("particles")) return usage_error("detect", "--particles N|FILE.csv is required");

  DetectSetup setup;
  if (int rc = build_detect_setup(*parsed, "detect", &setup); rc != kExitOk) return rc;

  auto detector = sim::Detector::create(setup.wall, setup.config, setup.particles.size());
  if (!detector) {
    std::fprintf(stderr, "collidoscope detect: %s\n", detector.status().message().c_str());
    return kExitFailure;
  }
  sim::Status s = (*detector)->set_particles(setup.particles);
  sim::DetectResult result;
  if (s) s = (*detector)->detect(&result);
  if (!s) {
    std::fprintf(stderr, "collidoscope detect: %s\n", s.message().c_str());
    return kExitFailure;
  }

  if (parsed->has("out")) {
    const std::string path = parsed->get("out");
    std::string text = "particle,triangle,distance\n";
    char buf[96];
    for (const auto& c : result.contacts) {
      std::snprintf(buf, sizeof buf, "%u,%u,%.9g\n", c.particle, c.triangle, c.distance);
      text += buf;
    }
    if (Status w = write_file_atomic(path, text); !w) {
      std::fprintf(stderr, "collidoscope detect: %s\n", w.message().c_str());
      return kExitFailure;
    }
  }

  if (parsed->has("snapshot")) {
    if (sim::Status w = write_detect_snapshot(parsed->get("snapshot"), setup, result); !w) {
      std::fprintf(stderr, "collidoscope detect: %s\n", w.message().c_str());
      return kExitFailure;
    }
  }

  const sim::PrepareInfo& info = (*detector)->info();
  if (parsed->has("json")) {
    std::printf("%s\n", detect_summary_json(setup, info, result).c_str());
  } else {
    std::printf("%s", detect_summary_text(setup, info, result).c_str());
  }
  return kExitOk;
}

}  // namespace collido::app
