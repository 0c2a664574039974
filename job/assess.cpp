#include "job/assess.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "job/wall_source.h"
#include "sim/shapes.h"
#include "sim/snapshot.h"

namespace collido::job {

Expected<ResolvedScene> resolve_scene(const JobSpec& spec) {
  auto parsed = scene::parse_scene(spec.scene_json);
  if (!parsed) return parsed.status();
  ResolvedScene out;
  scene::Scene& s = out.scene;
  s = std::move(*parsed);
  scene::resolve_wall_path(&s, spec.scene_dir);
  if (spec.vtp) s.vtp = true;
  if (!spec.backend.empty()) {
    s.backend_auto = spec.backend == "auto";
    if (!s.backend_auto && !sim::parse_backend(spec.backend, &s.dynamics.backend))
      return invalid_argument("backend: must be auto, cpu or cuda");
  }
  if (spec.duration > 0) {
    s.duration = spec.duration;
    if (Status st = scene::check_timing(s); !st) return st;
  }
  if (spec.render) {
#ifdef COLLIDO_HAVE_RENDER
    // The video plays at the scene's frame rate unless the spec says otherwise,
    // so a second on screen is a simulated second.
    out.render = spec.render_settings;
    RenderSettings& rs = out.render;
    if (rs.fps == 0) rs.fps = std::max(1, std::min(240, int(std::lround(s.fps))));
    if (Status st = validate(rs); !st) return st;
#else
    return invalid_argument("render: this build has no renderer");
#endif
  }
  if (spec.threads < 0 || spec.threads > kMaxThreads)
    return invalid_argument("threads: must be in [0, " + std::to_string(kMaxThreads) + "]");
  return out;
}

Expected<sim::TriangleMesh> load_scene_wall(scene::Scene* scene) {
  sim::MeshReport report;
  sim::WallMotion& motion = scene->dynamics.wall_motion;
  // A moving part: the union's triangles are its parts' in order, so the part is a range.
  std::vector<size_t> starts;
  auto wall = motion.part > 0 ? sim::make_shape(scene->wall, &starts) : load_wall(scene->wall, &report);
  if (!wall) return Status(wall.status().code(), "wall: " + wall.status().message());
  const double unit = scene->length_scale();
  if (unit != 1)
    for (auto& v : wall->vertices) v = v * unit;
  sim::Bounds3d moving = sim::mesh_bounds(*wall);
  if (motion.part > 0) {
    if (size_t(motion.part) > starts.size() || starts.size() < 2)
      return invalid_argument("wall_motion.part: the wall has " + std::to_string(starts.size()) +
                              " part(s), not " + std::to_string(motion.part));
    motion.part_begin = starts[size_t(motion.part) - 1];
    motion.part_end = size_t(motion.part) < starts.size() ? starts[size_t(motion.part)]
                                                          : wall->triangles.size();
    motion.part_box = moving =
        sim::mesh_bounds(sim::mesh_range(*wall, motion.part_begin, motion.part_end, true));
  }
  if (scene->motion_center_auto) {  // what moves turns about its own centre
    motion.center = moving.center();
    scene->motion_center_auto = false;
  }
  return std::move(*wall);
}

double output_bytes_estimate(const JobAssessment& a) {
  const double frames = double(a.frames) + 1;  // the initial one too
  const double particles = double(a.particles);
  return 256.0 * 1024 + 84 + 50 * double(a.triangles) + 1024 * particles +
         frames * (double(sim::kSnapshotHeaderBytes) +
                   double(sim::kSnapshotBytesPerParticle) * particles) +
         frames * double(a.render_pixels);
}

std::string landing_warning(const JobAssessment& a) {
  const double lands = a.release.first_contact, ends = a.resolved.scene.duration;
  if (!(lands >= 0) || lands < ends) return "";
  char text[240];
  std::snprintf(text, sizeof text,
                "the first particles reach the wall after about %.2g s of falling, and the job "
                "ends at %.2g s: nothing would touch the wall; make the duration longer or the "
                "inlet lower",
                lands, ends);
  return text;
}

Expected<JobAssessment> assess_job(const JobSpec& spec) {
  auto resolved = resolve_scene(spec);
  if (!resolved) return resolved.status();
  JobAssessment a;
  a.resolved = std::move(*resolved);
  auto wall = load_scene_wall(&a.resolved.scene);
  const scene::Scene& s = a.resolved.scene;
  if (!wall) return wall.status();
  a.particles = s.particles.count;
  a.r_min = s.particles.r_min;
  a.r_max = s.particles.r_max;
  a.triangles = wall->triangles.size();
  a.wall_area = sim::mesh_area(*wall);
  a.wall_closed = sim::is_closed_manifold(*wall);
  const sim::Vec3d extent = sim::mesh_bounds(*wall).extent();
  a.box[0] = extent.x, a.box[1] = extent.y, a.box[2] = extent.z;
  a.frames = s.frames();
  auto release = sim::plan_release(*wall, s.particles, s.placement,
                                   s.dynamics.gravity);
  if (!release) return release.status();
  a.release = *release;
  a.steps = sim::plan_steps(s.dynamics, s.particles.r_min, s.particles.r_max,
                            0.5 * (s.particles.r_min + s.particles.r_max), a.release.speed,
                            sim::mesh_bounds(*wall), s.duration / double(std::max<uint64_t>(a.frames, 1)),
                            a.frames);
  a.work = estimate_work(*wall, s.dynamics, s.particles.count, s.particles.r_max);
  if (Status st = check_budget(a.work, spec.budget); !st) return st;
  if (spec.render) {
    const RenderSettings& rs = a.resolved.render;
    a.render_pixels = uint64_t(rs.width) * uint64_t(rs.height);
    if (rs.mp4) a.formats.push_back("mp4");
    if (rs.webm) a.formats.push_back("webm");
    if (rs.gif) a.formats.push_back("gif");
  }
  a.wall = std::move(*wall);
  return a;
}

Expected<StartPreview> preview_start(const JobAssessment& a, size_t most) {
  const scene::Scene& s = a.resolved.scene;
  auto placed =
      sim::place_particles(a.wall, s.particles, s.placement, s.dynamics.gravity, s.seed);
  if (!placed) return placed.status();
  StartPreview out;
  out.particles = placed->size();
  const size_t every = most == 0 ? 0 : (placed->size() + most - 1) / most;
  const double to_unit = 1.0 / s.length_scale();
  for (size_t i = 0; every && i < placed->size(); i += every) {
    out.shown.push_back({placed->x[i] * to_unit, placed->y[i] * to_unit, placed->z[i] * to_unit,
                         placed->r[i] * to_unit});
    out.release_s.push_back(placed->release[i]);
  }
  return out;
}

}  // namespace collido::job
