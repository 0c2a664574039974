// What a job will be, known before it runs: the scene resolved as run_job()
// would resolve it, the wall loaded and the budget checked, but no particle
// placed and no engine built. The service answers a submission with it at
// once (a bad scene is refused before it is queued), and it holds the inputs
// the cost model prices a job by.
#pragma once

#include <array>

#include <cstdint>
#include <string>
#include <vector>

#include "common/status.h"
#include "job/budget.h"
#include "job/job.h"
#include "scene/scene.h"
#include "sim/dynamics.h"
#include "sim/mesh.h"
#include "sim/placement.h"

namespace collido::job {

// The scene of a spec with the spec's overrides applied (wall path, backend,
// duration, ParaView frames) and the render settings resolved (fps 0 = the
// scene's). Errors name the key.
struct ResolvedScene {
  scene::Scene scene;
  RenderSettings render;  // meaningful when spec.render
};
Expected<ResolvedScene> resolve_scene(const JobSpec& spec);

// The scene's wall in metres (a shape or a mesh file, scaled by the scene's
// unit). What the wall decides is then set in *scene: a moving part's
// triangles and box, and a rotation without a centre turns about the box
// centre of what moves.
Expected<sim::TriangleMesh> load_scene_wall(scene::Scene* scene);

struct JobAssessment {
  ResolvedScene resolved;
  uint64_t particles = 0;
  double r_min = 0, r_max = 0;  // m
  uint64_t triangles = 0;       // of the wall as loaded
  double wall_area = 0;         // m^2
  bool wall_closed = false;     // sim::is_closed_manifold: how a fill tells its sites in and out
  double box[3] = {0, 0, 0};    // m: the wall's bounding box
  uint64_t frames = 0;          // written after the initial one
  WorkEstimate work;            // engine work and peak host memory, estimated
  uint64_t render_pixels = 0;   // width x height of a rendered frame; 0 = no render
  std::vector<std::string> formats;  // videos asked for: mp4, webm, gif
  // When the particles take part and the steps the run will take, planned from
  // the scene (sim::plan_release, sim::plan_steps) as the engine will size them.
  sim::ReleasePlan release;
  sim::StepPlan steps;
  sim::TriangleMesh wall;  // as the run loads it (m), kept for what else is asked before it runs
};

// What an assessed job's files may take on disk, estimated from its counts:
// the frames' snapshots (29 bytes a particle), the checkpoint (1 KiB a
// particle; 660 measured for a pour of 1,500), the wall's copy, a fixed 256
// KiB for the documents and logs, and where it renders 1 byte a pixel of
// every frame for the PNG frames and videos together (the CPU job log's 613
// rendered jobs wrote at most 0.45). Admission uses it where no job cost
// model prices the output, and beside the model's where the job lies
// outside what the model was trained on.
double output_bytes_estimate(const JobAssessment& a);

// "" where the job's pour lands within its duration (or is no pour); else why
// nothing would touch the wall (ReleasePlan::first_contact against the
// duration), for the service's prediction and `collidoscope predict`.
std::string landing_warning(const JobAssessment& a);

// Resolves, loads and checks the job without running it. The same errors as
// run_job() gives for the same spec before its first frame, except those of
// placement (a placement that cannot fit is only found by placing).
Expected<JobAssessment> assess_job(const JobSpec& spec);

// Where an assessed job's particles start, placed as run_job() places them (the
// same wall, placement and seed): the whole count, and at most `most` of them,
// every k-th, in the scene document's length unit (x, y, z, radius), with
// their release times (0 for a fill). A placement that cannot fit is refused
// with run_job()'s error, which says how many fit.
struct StartPreview {
  uint64_t particles = 0;
  std::vector<std::array<double, 4>> shown;
  std::vector<double> release_s;
};
Expected<StartPreview> preview_start(const JobAssessment& a, size_t most);

}  // namespace collido::job
