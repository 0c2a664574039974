// Scene documents through placement and a few simulation steps on the CPU:
// whatever the document says, the engine refuses it or steps it without a
// crash, a sanitizer report or a non-finite statistic.
#include <cmath>
#include <cstdint>
#include <string>

#include "job/budget.h"
#include "job/wall_source.h"
#include "scene/scene.h"
#include "sim/parallel.h"
#include "sim/placement.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace collido;
  const std::string text(reinterpret_cast<const char*>(data), size);
  auto scene = scene::parse_scene(text);
  if (!scene || scene->wall_is_file) return 0;  // files are the STL target's
  // Small runs only: the fuzzer explores settings, not sizes.
  if (scene->particles.count > 2000) scene->particles.count = 2000;
  static sim::ThreadPool pool(1);
  scene->dynamics.pool = &pool;
  scene->dynamics.backend = sim::Backend::kCpu;
  auto wall = job::load_wall(scene->wall, nullptr);
  if (!wall) return 0;
  job::Budget budget;
  budget.wall_cells = 2e6;
  budget.pieces = 2e5;
  budget.host_bytes = uint64_t(1) << 30;
  const auto work = job::estimate_work(*wall, scene->dynamics, scene->particles.count,
                                       scene->particles.r_max);
  if (!job::check_budget(work, budget)) return 0;
  auto particles = sim::place_particles(*wall, scene->particles, scene->placement,
                                        scene->dynamics.gravity, scene->seed);
  if (!particles) return 0;
  auto sim = sim::Simulation::create(*wall, scene->dynamics, *particles);
  if (!sim) return 0;
  const double dt = (*sim)->time_step_info().explicit_step > 0
                        ? (*sim)->time_step_info().explicit_step
                        : (*sim)->time_step_info().spring_step;
  if (!(*sim)->step(3, dt)) return 0;
  sim::FrameStats st;
  if ((*sim)->measure(&st) && !std::isfinite(st.time)) __builtin_trap();
  return 0;
}
