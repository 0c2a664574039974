// `collidoscope bench run`: steps per second of the dynamics for a range of
// particle counts, with and without particle-particle contacts. The scene is a
// settled-like block: particles on a lattice just touching their six
// neighbours, standing on the floor of a box, under gravity.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "app/cli.h"
#include "app/commands.h"
#include "sim/detect_cuda.h"
#include "sim/dynamics.h"
#include "sim/parallel.h"
#include "sim/particles.h"
#include "sim/shapes.h"

namespace collido::app {

namespace {

const std::vector<FlagSpec> kFlags = {
    {"backend", true, "cpu | cuda (default cpu; cuda falls back to cpu with a note)"},
    {"counts", true, "particle counts, comma-separated (default 1e4,1e5,1e6)"},
    {"pairs", true, "on | off | both: particle-particle contacts (default both)"},
    {"friction", true, "Coulomb coefficient (default 0.3)"},
    {"model", true, "linear | hertz_mindlin contact law (default linear)"},
    {"rolling", true, "rolling resistance coefficient (default 0: none)"},
    {"wall-motion", true, "none | rotate: the wall turns about its vertical axis (default none)"},
    {"skin", true, "neighbour-list skin in m (default automatic; 0: search the grid every step)"},
    {"pairs-once", true,
     "auto | on | off: a listed pair's force evaluated once, or by both particles (default auto: "
     "the backend's choice)"},
    {"simd", true,
     "auto | off: the CPU's AVX2 passes, pairs evaluated once four at a time and Verlet's "
     "opening pass four particles at a time (default auto: where the CPU has AVX2)"},
    {"method", true,
     "bin | gravity | circumcircle | midpoint4 | bvh: how the box is prepared (default bin)"},
    {"wall-lists", true,
     "auto | on | off: without pair contacts, the still wall's candidates kept in lists with the "
     "skin, or searched every step (default auto: the CPU lists; the GPU searches a binned wall "
     "and lists a divided one)"},
    {"lanes", true,
     "auto | 1 | 2 | 4 | 8: GPU threads sharing a particle's pairs (default auto: the backend's "
     "choice)"},
    {"steps", true, "timed steps per configuration (default 50)"},
    {"warmup", true, "untimed steps first (default 5)"},
    {"threads", true, "CPU threads (default: all cores)"},
    {"stages", false, "also time each stage (a sync after each) and print the breakdown"},
    {"shuffle", false,
     "number the particles in a random order (as a pour's end up), not along the lattice"},
    {"run-ahead", true,
     "N: GPU steps launched before the host reads the lists' check; 0 = automatic (default), 1 = "
     "every step"},
    {"renumber", true,
     "auto | never | N: renumber the particles by cell when scattered, never, or every N-th list "
     "build (default auto)"},
    {"help", false, "this help"},
};

// n particles of radius 1 on a cubic lattice of spacing 1.999 (each touches its
// neighbours) in a box whose floor they stand on.
void block_scene(uint64_t n, sim::TriangleMesh* wall, sim::ParticleSet* p) {
  const int side = int(std::ceil(std::cbrt(double(n))));
  const double r = 1, s = 1.999 * r, extent = side * s;
  *wall = sim::make_box(extent + 4 * r, extent + 4 * r, extent * 1.5 + 4 * r);
  p->resize(n);
  uint64_t k = 0;
  for (int z = 0; z < side && k < n; ++z)
    for (int y = 0; y < side && k < n; ++y)
      for (int x = 0; x < side && k < n; ++x, ++k) {
        p->x[k] = -0.5 * extent + (x + 0.5) * s;
        p->y[k] = -0.5 * extent + (y + 0.5) * s;
        p->z[k] = r * 0.999 + z * s;
        p->r[k] = r;
      }
}

// The same particles numbered in a random order (Fisher-Yates, a fixed seed).
void shuffle_particles(sim::ParticleSet* p, uint64_t seed) {
  sim::SplitMix64 rng(seed);
  for (size_t i = p->size(); i > 1; --i) {
    const size_t j = size_t(rng.next() % i);
    for (std::vector<double>* a : {&p->x, &p->y, &p->z, &p->vx, &p->vy, &p->vz, &p->r, &p->release})
      std::swap((*a)[i - 1], (*a)[j]);
  }
}

}  // namespace

int bench_run(const Args& args) {
  std::string err;
  auto p = parse_args(args, kFlags, &err);
  if (!p) return usage_error("bench run", err);
  if (p->has("help")) {
    print_help(
        "usage: collidoscope bench run [--backend cpu|cuda] [--counts 1e4,1e5,1e6] [--pairs both]",
        kFlags);
    return kExitOk;
  }
  sim::Backend backend = sim::Backend::kCpu;
  if (!sim::parse_backend(p->get("backend", "cpu"), &backend))
    return usage_error("bench run", "--backend must be cpu or cuda");
  std::string note;
  backend = sim::usable_backend(backend, &note);
  if (!note.empty()) std::fprintf(stderr, "collidoscope bench run: note: %s\n", note.c_str());
  const int64_t steps = p->get_int("steps", 50, &err), warmup = p->get_int("warmup", 5, &err);
  const double friction = p->get_double("friction", 0.3, &err);
  const int64_t threads = p->get_int("threads", 0, &err);
  if (!err.empty()) return usage_error("bench run", err);
  if (steps < 1 || warmup < 0 || !(friction >= 0 && friction <= 10))
    return usage_error("bench run", "--steps >= 1, --warmup >= 0, --friction in [0, 10]");
  if (threads < 0 || threads > 4096) return usage_error("bench run", "--threads must be in [0, 4096]");
  sim::ContactModel model = sim::ContactModel::kLinear;
  if (!sim::parse_contact_model(p->get("model", "linear"), &model))
    return usage_error("bench run", "--model must be linear or hertz_mindlin");
  const double rolling = p->get_double("rolling", 0, &err);
  if (!err.empty() || !(rolling >= 0 && rolling <= 1))
    return usage_error("bench run", "--rolling must be in [0, 1]");
  const double skin = p->get_double("skin", -1, &err);
  if (!err.empty() || !(skin >= -1 && skin <= 4)) return usage_error("bench run", "--skin must be in [0, 4] m");
  const std::string motion = p->get("wall-motion", "none");
  if (motion != "none" && motion != "rotate")
    return usage_error("bench run", "--wall-motion must be none or rotate");
  const std::string once = p->get("pairs-once", "auto");
  if (once != "auto" && once != "on" && once != "off")
    return usage_error("bench run", "--pairs-once must be auto, on or off");
  const int pairs_once = once == "auto" ? -1 : once == "on" ? 1 : 0;
  const std::string simd = p->get("simd", "auto");
  if (simd != "auto" && simd != "off")
    return usage_error("bench run", "--simd must be auto or off");
  sim::Method method = sim::Method::kBin;
  if (!sim::parse_method(p->get("method", "bin"), &method) || method == sim::Method::kReference)
    return usage_error("bench run",
                       "--method must be bin, gravity, circumcircle, midpoint4 or bvh");
  const std::string wall_lists = p->get("wall-lists", "auto");
  if (wall_lists != "auto" && wall_lists != "on" && wall_lists != "off")
    return usage_error("bench run", "--wall-lists must be auto, on or off");
  const std::string lanes_arg = p->get("lanes", "auto");
  if (lanes_arg != "auto" && lanes_arg != "1" && lanes_arg != "2" && lanes_arg != "4" &&
      lanes_arg != "8")
    return usage_error("bench run", "--lanes must be auto, 1, 2, 4 or 8");
  const int lanes = lanes_arg == "auto" ? 0 : std::stoi(lanes_arg);
  const std::string renumber = p->get("renumber", "auto");
  int renumber_every = -1;
  if (renumber == "never") {
    renumber_every = 0;
  } else if (renumber != "auto") {
    const int64_t every = p->get_int("renumber", -1, &err);
    if (!err.empty() || every < 1 || every > 1000000)
      return usage_error("bench run", "--renumber must be auto, never or a count of builds");
    renumber_every = int(every);
  }
  const int64_t run_ahead = p->get_int("run-ahead", 0, &err);
  if (!err.empty() || run_ahead < 0 || run_ahead > 1024)
    return usage_error("bench run", "--run-ahead must be a count of steps in [0, 1024]");
  sim::ThreadPool pool{int(threads)};
  const std::string pairs = p->get("pairs", "both");
  std::vector<bool> pair_modes;
  if (pairs == "both")
    pair_modes = {false, true};
  else if (pairs == "on")
    pair_modes = {true};
  else if (pairs == "off")
    pair_modes = {false};
  else
    return usage_error("bench run", "--pairs must be on, off or both");
  std::vector<uint64_t> counts;
  {
    for (const std::string& item : split_list(p->get("counts", "1e4,1e5,1e6"))) {
      char* end = nullptr;
      const double v = std::strtod(item.c_str(), &end);
      if (end == item.c_str() || *end || !(v >= 1 && v <= 2e8))
        return usage_error("bench run", "--counts expects numbers in 1..2e8, got '" + item + "'");
      counts.push_back(uint64_t(v));
    }
  }

  std::printf(
      "# bench run: %s%s, %s contacts, friction %.2g, rolling %.2g, wall motion %s, "
      "wall %s, %lld timed steps\n",
      sim::to_string(backend),
      backend == sim::Backend::kCuda ? (" (" + sim::cuda_device_name() + ")").c_str() : "",
      sim::to_string(model), friction, rolling, motion.c_str(), sim::to_string(method),
      (long long)steps);
  std::printf(
      "| particles | pair contacts | ms/step | steps/s | particle-steps/s | wall contacts | pair "
      "contacts | device MB | skin (radii) | list builds |\n"
      "|---:|:---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  struct Breakdown {
    uint64_t n;
    bool pairs;
    sim::StepTimes t;  // summed over t.steps
  };
  std::vector<Breakdown> breakdown;
  std::string retaken;  // GPU steps launched ahead that a build voided, per row
  std::string pieces;   // a divided box's pieces, per count
  for (uint64_t n : counts) {
    sim::TriangleMesh wall;
    sim::ParticleSet ps;
    block_scene(n, &wall, &ps);
    if (p->has("shuffle")) shuffle_particles(&ps, 7);
    for (bool with_pairs : pair_modes) {
      sim::DynamicsConfig cfg;
      cfg.backend = backend;
      cfg.method = method;
      cfg.pool = &pool;
      cfg.particle_contacts = with_pairs;
      cfg.material.friction = friction;
      cfg.material.rolling_friction = rolling;
      cfg.neighbour_skin = skin;
      cfg.pairs_once = pairs_once;
      cfg.simd = simd == "off" ? 0 : -1;
      cfg.lanes = lanes;
      cfg.wall_lists = wall_lists == "auto" ? -1 : wall_lists == "on" ? 1 : 0;
      cfg.renumber_every = renumber_every;
      cfg.run_ahead = int(run_ahead);
      cfg.contact_model = model;
      // The linear spring of the earlier benchmarks; Hertz sizes its modulus itself.
      if (model == sim::ContactModel::kLinear) cfg.material.stiffness = 1e9;
      if (motion == "rotate") {
        // Slowly, so the work stays that of the still wall: this measures the transform.
        const sim::Bounds3d box = sim::mesh_bounds(wall);
        cfg.wall_motion.kind = sim::WallMotionKind::kRotate;
        cfg.wall_motion.center = box.center();
        cfg.wall_motion.angular_speed = 0.1;
      }
      auto s = sim::Simulation::create(wall, cfg, ps);
      if (!s) {
        std::fprintf(stderr, "collidoscope bench run: %s\n", s.status().message().c_str());
        return kExitFailure;
      }
      const double dt = (*s)->time_step_info().spring_step;
      if (sim::divides(method) && with_pairs == pair_modes.front())
        pieces +=
            " " + std::to_string(n) + ": " + std::to_string((*s)->wall_info().triangles_used) + ";";
      if (warmup && !(*s)->step(uint64_t(warmup), dt)) return kExitFailure;
      (*s)->set_stage_timing(false);  // counts (list builds) from here
      const auto t0 = std::chrono::steady_clock::now();
      if (Status e = (*s)->step(uint64_t(steps), dt); !e) {
        std::fprintf(stderr, "collidoscope bench run: %s\n", e.message().c_str());
        return kExitFailure;
      }
      const double sec =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const uint64_t builds = (*s)->stage_times().neighbour_builds;
      if (const uint64_t again = (*s)->stage_times().steps_retaken)
        retaken += " " + std::to_string(n) + (with_pairs ? " with pairs: " : ": ") +
                   std::to_string(again) + ";";
      sim::FrameStats st;
      (*s)->measure(&st);
      const double ms = 1e3 * sec / double(steps);
      if (p->has("stages")) {
        (*s)->set_stage_timing(true);
        (*s)->step(uint64_t(steps), dt);
        breakdown.push_back({n, with_pairs, (*s)->stage_times()});
      }
      const sim::TimeStepInfo& ts = (*s)->time_step_info();
      std::printf("| %llu | %s | %.4g | %.4g | %.3g | %llu | %llu | %.1f | %.2g | %llu |\n",
                  (unsigned long long)n, with_pairs ? "yes" : "no", ms, 1e3 / ms,
                  double(n) * 1e3 / ms, (unsigned long long)st.wall_contacts,
                  (unsigned long long)st.particle_contacts, double((*s)->device_bytes()) / 1e6,
                  ts.neighbour_skin / ts.r_min, (unsigned long long)builds);
      std::fflush(stdout);
    }
  }
  if (!pieces.empty()) std::printf("\n# the box's pieces, per particle count:%s\n", pieces.c_str());
  if (!retaken.empty())
    std::printf("\n# steps launched ahead, voided by a list build and launched again:%s\n",
                retaken.c_str());
  if (!breakdown.empty()) {
    std::printf(
        "\n# stage breakdown (ms per step, a sync after each stage)\n"
        "| particles | pair contacts | release + drift | grid (hash, sort, cells) | pair forces | "
        "wall forces | "
        "kick + checks |\n|---:|:---:|---:|---:|---:|---:|---:|\n");
    for (const Breakdown& b : breakdown) {
      const double k = 1.0 / double(b.t.steps);
      // One CPU thread runs a still wall's forces inside the pair pass, batch
      // by batch: no lap of their own, their time in the pairs'.
      char wall[32];
      if (b.pairs && b.t.wall_ms == 0)
        std::snprintf(wall, sizeof wall, "in pair forces");
      else
        std::snprintf(wall, sizeof wall, "%.4f", b.t.wall_ms * k);
      std::printf("| %llu | %s | %.4f | %.4f | %.4f | %s | %.4f |\n", (unsigned long long)b.n,
                  b.pairs ? "yes" : "no", b.t.drift_ms * k, b.t.grid_ms * k, b.t.pair_ms * k, wall,
                  b.t.kick_ms * k);
    }
  }
  return kExitOk;
}

}  // namespace collido::app
