// The scene file: one JSON document that says everything a run needs (wall,
// particles, placement, physics, duration, method, backend). The command line
// reads it from a file; the service will accept the same document.
#pragma once

#include <cstdint>
#include <string>

#include "common/status.h"
#include "sim/dynamics.h"
#include "sim/placement.h"

namespace collido::scene {

struct Scene {
  std::string wall;  // a shape spec ("wall1", "cylinder:r=..") or a file path
  bool wall_is_file = false;
  sim::ParticleSpec particles;
  sim::PlacementSpec placement;
  sim::DynamicsConfig dynamics;
  bool backend_auto = true;  // "auto": the GPU when one is usable, else the CPU
  // "method": "auto" / "grid_length": "auto": chosen by timing the candidates
  // on the placed particles (sim/auto_choice.h) when the job starts.
  bool method_auto = false;
  bool grid_auto = false;
  // A rotation given without a "center" turns about the wall's own box centre,
  // which is known once the wall is loaded (job::load_scene_wall sets it).
  bool motion_center_auto = false;
  double duration = 2;       // simulated seconds
  double fps = 30;           // output frames per simulated second
  uint64_t seed = 1;
  bool vtp = false;  // also write VTK PolyData frames for ParaView
  // The unit of the wall (file or shape) and of every length and speed in the
  // document: "m", "cm" or "mm" (STL has no unit; CAD writes millimetres).
  // The parsed scene holds SI values; only the wall is scaled when it is loaded.
  // Gravity stays in m/s^2, stiffness in N/m, times in s.
  std::string length_unit = "m";
  double length_scale() const;  // metres per unit

  // Frames written after the initial one.
  uint64_t frames() const;
};

// Limits on a scene's timing, one place for the parser and `run --duration`.
inline constexpr double kMaxDuration = 1e5;      // simulated seconds
inline constexpr uint64_t kMaxFrames = 1000000;  // duration x fps
// duration / a fixed time_step: past it a run would take days at any speed
// (a job answers a cancel only between frames, and one frame would be most of it).
inline constexpr double kMaxFixedSteps = 1e9;
// Checks duration in (0, kMaxDuration], at most kMaxFrames frames and, with a
// fixed time step, at most kMaxFixedSteps steps; the message names the key
// ("duration: ...", "fps: ..." or "time_step: ...").
Status check_timing(const Scene& s);

// Parses and validates a scene document. Unknown keys, wrong types and
// impossible values are errors that name the key ("material.restitution: ...").
Expected<Scene> parse_scene(const std::string& json_text);
// Makes the scene's wall file, written either way ("wall": "vessel.stl" or
// {"file": "vessel.stl"}), a path relative to `base_dir` (unless absolute). A
// string wall that names no parametric shape and has no ':' is a file.
void resolve_wall_path(Scene* scene, const std::string& base_dir);
// Reads a scene file; a wall file named in it is taken relative to the scene's folder.
Expected<Scene> load_scene(const std::string& path);
// The scene as a JSON document (every key, defaults filled in); parse_scene reads it back.
std::string to_json(const Scene& scene);

}  // namespace collido::scene
