// `collidoscope bench detect`: the paper's Table 4 (time per detection frame
// for 10^2..10^6 particles on wall1) for every method and traversal, with the
// stage breakdown and an exactness check against the double reference.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "app/cli.h"
#include "app/commands.h"
#include "app/detect_setup.h"
#include "sim/accuracy.h"
#include "sim/detect_cuda.h"
#include "sim/parallel.h"
#include "sim/shapes.h"
#include "sim/particles.h"

namespace collido::app {

namespace {

const std::vector<FlagSpec> kFlags = {
    {"wall", true, "wall spec or STL file (default wall1)"},
    {"backend", true, "cpu | cuda (default cpu)"},
    {"methods", true, "comma list (default gravity,circumcircle,midpoint4,bin)"},
    {"traversals", true, "comma list (default particle,wall)"},
    {"precisions", true, "comma list: exact (float with the double filter), float (default exact,float)"},
    {"min", true, "smallest particle count (default 100)"},
    {"max", true, "largest particle count (default 1e6)"},
    {"radius-range", true, "A:B particle radii (default 0.5:1)"},
    {"grid-length", true, "cell edge (default: method default)"},
    {"repeats", true, "timed frames per point; the median is reported (default 5)"},
    {"check-max", true, "compare with the reference up to this many particles (default 1e5, 0 = never)"},
    {"threads", true, "CPU threads (default all cores)"},
    {"seed", true, "random seed (default 1)"},
    {"near-surface", true, "fraction of particles within 1.5 r_max of the wall (default 0: uniform in the box)"},
    {"sweep", true, "grid: time against grid length (paper Fig. 14); triangles: against triangle count (Fig. 13)"},
    {"grid-lengths", true, "grid lengths for --sweep grid, in units of r_max (default 2,3,4,5,6,7)"},
    {"octree-flat-cost", true,
     "octree, for tuning: a flattened round of runs against a leaf's (default 1.3; 0 always flattens)"},
    {"help", false, "show this help"},
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

double median_frame_ms(sim::Detector& det, const sim::Particles& scene, int64_t repeats) {
  sim::DetectResult res;
  det.set_particles(scene);
  det.detect(&res);  // warm-up
  std::vector<double> times;
  for (int64_t k = 0; k < repeats; ++k) {
    det.detect(&res);
    times.push_back(res.times.frame_ms);
  }
  return median(times);
}

// Paper Fig. 13 and 14: time per frame against triangle count or grid length.
int run_sweep(const std::string& kind, const DetectSetup& base, const std::vector<sim::Method>& methods,
              const std::vector<sim::Traversal>& traversals, size_t n, double r_lo, double r_hi, int64_t repeats,
              uint64_t seed, const std::vector<double>& grid_factors) {
  std::vector<std::pair<std::string, sim::TriangleMesh>> walls;
  if (kind == "triangles") {
    for (int s = 2; s <= 6; ++s) walls.emplace_back("sphere r=50 subdiv " + std::to_string(s), sim::make_sphere(50, s));
  } else {
    walls.emplace_back(base.wall_spec, base.wall);
  }
  std::printf("# sweep %s: %zu particles, radii %g..%g, backend %s, median of %lld frames (ms per frame)\n",
              kind.c_str(), n, r_lo, r_hi, sim::to_string(base.config.backend), static_cast<long long>(repeats));
  std::printf("| method | traversal |");
  if (kind == "triangles")
    for (auto& w : walls) std::printf(" %s |", w.first.c_str());
  else
    for (double f : grid_factors) std::printf(" L=%g |", f * r_hi);
  std::printf("\n|---|---|");
  const size_t cols = kind == "triangles" ? walls.size() : grid_factors.size();
  for (size_t i = 0; i < cols; ++i) std::printf("---|");
  std::printf("\n");
  for (sim::Method m : methods)
    for (sim::Traversal tr : traversals) {
      std::printf("| %s | %s |", sim::to_string(m), sim::to_string(tr));
      for (size_t col = 0; col < cols; ++col) {
        const auto& wall = walls[kind == "triangles" ? col : 0].second;
        sim::DetectConfig cfg = base.config;
        cfg.method = m, cfg.traversal = tr, cfg.r_max = r_hi, cfg.collect_contacts = false, cfg.time_stages = false;
        if (kind == "grid") cfg.grid_length = grid_factors[col] * r_hi;
        auto det = sim::Detector::create(wall, cfg, n);
        if (!det) {
          std::printf(" - |");
          continue;
        }
        const sim::Particles scene = sim::random_particles(n, sim::mesh_bounds(wall), r_lo, r_hi, seed);
        const double t = median_frame_ms(**det, scene, repeats);
        if (kind == "triangles")
          std::printf(" %.3f (%zu tri) |", t, (*det)->info().triangles_used);
        else
          std::printf(" %.3f |", t);
        std::fflush(stdout);
      }
      std::printf("\n");
    }
  return kExitOk;
}

}  // namespace

int bench_detect(const Args& args) {
  std::string err;
  auto parsed = parse_args(args, kFlags, &err);
  if (!parsed) return usage_error("bench detect", err);
  if (parsed->has("help")) {
    print_help("usage: collidoscope bench detect [options]", kFlags);
    return kExitOk;
  }
  DetectSetup base;
  if (int rc = build_detect_setup(*parsed, "bench detect", &base); rc != kExitOk) return rc;
  const int64_t nmin = parsed->get_int("min", 100, &err), nmax = parsed->get_int("max", 1000000, &err),
                repeats = parsed->get_int("repeats", 5, &err), check_max = parsed->get_int("check-max", 100000, &err),
                seed = parsed->get_int("seed", 1, &err);
  base.config.octree_flat_cost =
      float(parsed->get_double("octree-flat-cost", base.config.octree_flat_cost, &err));
  if (!err.empty()) return usage_error("bench detect", err);
  if (!(base.config.octree_flat_cost >= 0))
    return usage_error("bench detect", "--octree-flat-cost must be >= 0 (0: always flattened)");
  if (nmin < 1 || nmax < nmin || repeats < 1) return usage_error("bench detect", "need 1 <= min <= max, repeats >= 1");
  double r_lo = 0.5, r_hi = 1.0;
  if (parsed->has("radius-range") &&
      std::sscanf(parsed->get("radius-range").c_str(), "%lf:%lf", &r_lo, &r_hi) != 2)
    return usage_error("bench detect", "--radius-range expects A:B");
  if (!(r_lo > 0 && r_hi >= r_lo)) return usage_error("bench detect", "radii must satisfy 0 < A <= B");

  std::vector<sim::Method> methods;
  for (const auto& m : split_list(parsed->get("methods", "gravity,circumcircle,midpoint4,bin"))) {
    sim::Method mm;
    if (!sim::parse_method(m, &mm)) return usage_error("bench detect", "unknown method '" + m + "'");
    methods.push_back(mm);
  }
  std::vector<sim::Traversal> traversals;
  for (const auto& t : split_list(parsed->get("traversals", "particle,wall"))) {
    sim::Traversal tt;
    if (!sim::parse_traversal(t, &tt)) return usage_error("bench detect", "unknown traversal '" + t + "'");
    traversals.push_back(tt);
  }
  std::vector<sim::Precision> precisions;
  for (const auto& p : split_list(parsed->get("precisions", "exact,float"))) {
    sim::Precision pp;
    if (!sim::parse_precision(p, &pp)) return usage_error("bench detect", "unknown precision '" + p + "'");
    precisions.push_back(pp);
  }
  const double near = parsed->get_double("near-surface", 0, &err);
  if (!err.empty() || near < 0 || near > 1) return usage_error("bench detect", "--near-surface expects a fraction in [0, 1]");
  if (parsed->has("sweep")) {
    const std::string kind = parsed->get("sweep");
    if (kind != "grid" && kind != "triangles") return usage_error("bench detect", "--sweep is grid or triangles");
    std::vector<double> factors;
    for (const auto& f : split_list(parsed->get("grid-lengths", "2,3,4,5,6,7"))) factors.push_back(std::atof(f.c_str()));
    for (double f : factors)
      if (!(f > 0)) return usage_error("bench detect", "--grid-lengths must be positive numbers");
    return run_sweep(kind, base, methods, traversals, static_cast<size_t>(nmax), r_lo, r_hi, repeats,
                     static_cast<uint64_t>(seed), factors);
  }
  std::vector<size_t> sizes;
  for (double n = static_cast<double>(nmin); n <= static_cast<double>(nmax) * 1.0001; n *= 10)
    sizes.push_back(static_cast<size_t>(std::llround(n)));

  const bool cuda = base.config.backend == sim::Backend::kCuda;
  std::string device = "CPU";
  double copy_gbs = 0;
#if defined(COLLIDO_HAVE_CUDA)
  if (cuda) {
    device = sim::cuda_device_name();
    copy_gbs = sim::cuda_copy_bandwidth_gbs();
  }
#endif
  std::printf("# bench detect: wall %s (%zu triangles), radii %g..%g, %.0f%% of particles within 1.5 r_max of the "
              "wall and the rest uniform in its bounding box, backend %s (%s), %d CPU threads, median of %lld frames\n",
              base.wall_spec.c_str(), base.wall.triangles.size(), r_lo, r_hi, 100 * near,
              sim::to_string(base.config.backend), device.c_str(), base.pool->size(), static_cast<long long>(repeats));
  if (cuda) std::printf("# measured device-to-device copy: %.0f GB/s (read + write)\n", copy_gbs);
  std::printf("| method | traversal | precision | triangles | prepare ms |");
  for (size_t n : sizes) std::printf(" %.0e |", static_cast<double>(n));
  std::printf(" contact set | pairs in the band at max | extra memory B/elem |%s\n|---|---|---|---|---|",
              cuda ? " bandwidth at max |" : "");
  for (size_t i = 0; i < sizes.size(); ++i) std::printf("---|");
  std::printf("---|---|---|%s\n", cuda ? "---|" : "");

  // Reference counts per size, computed once.
  std::vector<sim::Particles> scenes;
  for (size_t n : sizes)
    scenes.push_back(sim::particles_near_surface(base.wall, n, r_lo, r_hi, near, 1.5 * r_hi, static_cast<uint64_t>(seed)));
  std::vector<std::vector<sim::Contact>> ref_pairs(sizes.size());

  struct Breakdown {
    std::string label;
    sim::StageTimes t;
    uint64_t contacts;
  };
  std::vector<Breakdown> breakdowns;
  bool all_exact = true;
  for (sim::Method m : methods) {
    for (sim::Traversal tr : traversals) {
     for (sim::Precision prec : precisions) {
      sim::DetectConfig cfg = base.config;
      cfg.method = m;
      cfg.traversal = tr;
      cfg.precision = prec;
      cfg.r_max = r_hi;
      cfg.collect_contacts = false;
      cfg.time_stages = false;
      auto det = sim::Detector::create(base.wall, cfg, sizes.back());
      if (!det) {
        std::printf("| %s | %s | %s | - | - | %s |\n", sim::to_string(m), sim::to_string(tr),
                    sim::to_string(prec), det.status().message().c_str());
        continue;
      }
      std::printf("| %s | %s | %s | %zu | %.1f |", sim::to_string(m), sim::to_string(tr), sim::to_string(prec),
                  (*det)->info().triangles_used, (*det)->info().prepare_ms);
      std::fflush(stdout);
      std::string exact = "yes";
      uint64_t missed = 0, invented = 0, band_at_max = 0;
      double frame_at_max = 0;
      for (size_t si = 0; si < sizes.size(); ++si) {
        const double t = median_frame_ms(**det, scenes[si], repeats);
        frame_at_max = t;
        std::printf(" %.3f |", t);
        std::fflush(stdout);
        if (static_cast<int64_t>(sizes[si]) <= check_max) {
          // The accuracy contract, pair by pair: contacts of a collecting run against the reference.
          if (ref_pairs[si].empty()) {
            sim::DetectConfig rc = cfg;
            rc.method = sim::Method::kReference;
            rc.backend = sim::Backend::kCpu;
            rc.collect_contacts = true;
            auto ref = sim::Detector::create(base.wall, rc, sizes[si]);
            sim::DetectResult rr;
            (*ref)->set_particles(scenes[si]);
            (*ref)->detect(&rr);
            ref_pairs[si] = std::move(rr.contacts);
          }
          sim::DetectResult got;
          (*det)->set_frame_options(/*collect_contacts=*/true, /*time_stages=*/false);
          (*det)->detect(&got);
          (*det)->set_frame_options(false, false);
          // No tolerance: the contract is the reference's set, bit for bit.
          const sim::ContactDiff d = sim::compare_contacts(base.wall, scenes[si], ref_pairs[si], got.contacts, 0.0);
          missed += d.missed + d.borderline, invented += d.invented;
        }
        if (si + 1 == sizes.size()) {
          sim::DetectResult sr;
          (*det)->set_frame_options(false, /*time_stages=*/true);
          (*det)->detect(&sr);
          (*det)->detect(&sr);
          (*det)->set_frame_options(false, false);
          band_at_max = sr.band_pairs;
          breakdowns.push_back({std::string(sim::to_string(m)) + " / " + sim::to_string(tr) + " / " +
                                    sim::to_string(prec),
                                sr.times, sr.contact_count});
        }
      }
      if (missed || invented)
        exact = (prec == sim::Precision::kExact ? "NOT the reference's (" : "differs (") +
                std::to_string(missed) + " missed, " + std::to_string(invented) + " invented)";
      else
        exact = check_max > 0 ? "the reference's" : "not checked";
      // Extra memory beyond the inputs (particles 16 B, triangles 36 B), per particle and triangle.
      const double inputs = 16.0 * sizes.back() + 36.0 * (*det)->info().triangles_original;
      const double extra = (static_cast<double>((*det)->info().device_bytes) - inputs) /
                           static_cast<double>(sizes.back() + (*det)->info().triangles_used);
      std::printf(" %s | %llu | %.1f |", exact.c_str(), static_cast<unsigned long long>(band_at_max), extra);
      if (cuda) {
        // Fewest bytes a frame must move: each particle read once (16 B) and its count written (4 B).
        const double gbs = 20.0 * sizes.back() / (frame_at_max * 1e-3) / 1e9;
        std::printf(" %.0f GB/s = %.0f%% |", gbs, copy_gbs > 0 ? 100 * gbs / copy_gbs : 0.0);
      }
      std::printf("\n");
      // Float precision may differ (that is what the filter is for); exact may not.
      if ((missed || invented) && prec == sim::Precision::kExact) all_exact = false;
     }
    }
  }
  std::printf("\n# stage breakdown at %zu particles (ms, one frame with a sync between stages)\n", sizes.back());
  std::printf("| method / traversal | hash | sort | cells | traverse | finalize | frame | contacts |\n");
  std::printf("|---|---|---|---|---|---|---|---|\n");
  for (const auto& b : breakdowns)
    std::printf("| %s | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f | %llu |\n", b.label.c_str(), b.t.hash_ms, b.t.sort_ms,
                b.t.cells_ms, b.t.traverse_ms, b.t.finalize_ms, b.t.frame_ms,
                static_cast<unsigned long long>(b.contacts));
  std::printf("\npaper Table 4 (s per frame, 1e2..1e6): CPU 0.025 0.038 0.195 1.674 16.56 | GTX480 gravity 0.056 "
              "0.068 0.159 0.836 6.518 | GTX480 circumcircle 0.037 0.044 0.103 0.453 3.315\n");
  return all_exact ? kExitOk : kExitFailure;
}

}  // namespace collido::app
