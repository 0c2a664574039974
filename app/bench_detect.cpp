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
#include "sim/parallel.h"
#include "sim/particles.h"

namespace collido::app {

namespace {

const std::vector<FlagSpec> kFlags = {
    {"wall", true, "wall spec or STL file (default wall1)"},
    {"backend", true, "cpu | cuda (default cpu)"},
    {"methods", true, "comma list (default gravity,circumcircle,midpoint4,bin)"},
    {"traversals", true, "comma list (default particle,wall)"},
    {"min", true, "smallest particle count (default 100)"},
    {"max", true, "largest particle count (default 1e6)"},
    {"radius-range", true, "A:B particle radii (default 0.5:1)"},
    {"grid-length", true, "cell edge (default: method default)"},
    {"repeats", true, "timed frames per point; the median is reported (default 5)"},
    {"check-max", true, "compare with the reference up to this many particles (default 1e5, 0 = never)"},
    {"threads", true, "CPU threads (default all cores)"},
    {"seed", true, "random seed (default 1)"},
    {"help", false, "show this help"},
};

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  size_t pos = 0;
  while (pos <= s.size()) {
    size_t c = s.find(',', pos);
    out.push_back(s.substr(pos, c == std::string::npos ? std::string::npos : c - pos));
    if (c == std::string::npos) break;
    pos = c + 1;
  }
  return out;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
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
  if (!err.empty()) return usage_error("bench detect", err);
  if (nmin < 1 || nmax < nmin || repeats < 1) return usage_error("bench detect", "need 1 <= min <= max, repeats >= 1");
  double r_lo = 0.5, r_hi = 1.0;
  if (parsed->has("radius-range") &&
      std::sscanf(parsed->get("radius-range").c_str(), "%lf:%lf", &r_lo, &r_hi) != 2)
    return usage_error("bench detect", "--radius-range expects A:B");
  if (!(r_lo > 0 && r_hi >= r_lo)) return usage_error("bench detect", "radii must satisfy 0 < A <= B");

  std::vector<sim::Method> methods;
  for (const auto& m : split(parsed->get("methods", "gravity,circumcircle,midpoint4,bin"))) {
    sim::Method mm;
    if (!sim::parse_method(m, &mm)) return usage_error("bench detect", "unknown method '" + m + "'");
    methods.push_back(mm);
  }
  std::vector<sim::Traversal> traversals;
  for (const auto& t : split(parsed->get("traversals", "particle,wall"))) {
    sim::Traversal tt;
    if (!sim::parse_traversal(t, &tt)) return usage_error("bench detect", "unknown traversal '" + t + "'");
    traversals.push_back(tt);
  }
  std::vector<size_t> sizes;
  for (double n = static_cast<double>(nmin); n <= static_cast<double>(nmax) * 1.0001; n *= 10)
    sizes.push_back(static_cast<size_t>(std::llround(n)));

  const sim::Bounds3d box = sim::mesh_bounds(base.wall);
  std::printf("# bench detect: wall %s (%zu triangles), radii %g..%g uniform in the wall's bounding box, "
              "backend %s, %d CPU threads, median of %lld frames\n",
              base.wall_spec.c_str(), base.wall.triangles.size(), r_lo, r_hi, sim::to_string(base.config.backend),
              sim::cpu_threads(), static_cast<long long>(repeats));
  std::printf("| method | traversal | triangles | prepare ms |");
  for (size_t n : sizes) std::printf(" %.0e |", static_cast<double>(n));
  std::printf(" exact |\n|---|---|---|---|");
  for (size_t i = 0; i < sizes.size(); ++i) std::printf("---|");
  std::printf("---|\n");

  // Reference counts per size, computed once.
  std::vector<uint64_t> ref_contacts(sizes.size(), UINT64_MAX);
  std::vector<sim::Particles> scenes;
  for (size_t n : sizes) scenes.push_back(sim::random_particles(n, box, r_lo, r_hi, static_cast<uint64_t>(seed)));

  struct Breakdown {
    std::string label;
    sim::StageTimes t;
    uint64_t contacts;
  };
  std::vector<Breakdown> breakdowns;
  bool all_exact = true;
  for (sim::Method m : methods) {
    for (sim::Traversal tr : traversals) {
      sim::DetectConfig cfg = base.config;
      cfg.method = m;
      cfg.traversal = tr;
      cfg.r_max = r_hi;
      cfg.collect_contacts = false;
      cfg.time_stages = false;
      auto det = sim::Detector::create(base.wall, cfg, sizes.back());
      if (!det) {
        std::printf("| %s | %s | - | - | %s |\n", sim::to_string(m), sim::to_string(tr), det.status().message().c_str());
        continue;
      }
      std::printf("| %s | %s | %zu | %.1f |", sim::to_string(m), sim::to_string(tr), (*det)->info().triangles_used,
                  (*det)->info().prepare_ms);
      std::fflush(stdout);
      std::string exact = "yes";
      for (size_t si = 0; si < sizes.size(); ++si) {
        sim::DetectResult res;
        if (auto s = (*det)->set_particles(scenes[si]); !s) return usage_error("bench detect", s.message());
        (*det)->detect(&res);  // warm-up
        std::vector<double> times;
        for (int64_t k = 0; k < repeats; ++k) {
          (*det)->detect(&res);
          times.push_back(res.times.frame_ms);
        }
        std::printf(" %.3f |", median(times));
        std::fflush(stdout);
        if (static_cast<int64_t>(sizes[si]) <= check_max) {
          if (ref_contacts[si] == UINT64_MAX) {
            sim::DetectConfig rc = cfg;
            rc.method = sim::Method::kReference;
            rc.backend = sim::Backend::kCpu;
            auto ref = sim::Detector::create(base.wall, rc, sizes[si]);
            sim::DetectResult rr;
            (*ref)->set_particles(scenes[si]);
            (*ref)->detect(&rr);
            ref_contacts[si] = rr.contact_count;
          }
          if (res.contact_count != ref_contacts[si]) exact = "NO (" + std::to_string(res.contact_count) + " vs " +
                                                           std::to_string(ref_contacts[si]) + ")";
        }
        if (si + 1 == sizes.size()) {
          sim::DetectConfig staged = cfg;
          staged.time_stages = true;
          auto d2 = sim::Detector::create(base.wall, staged, sizes.back());
          sim::DetectResult sr;
          (*d2)->set_particles(scenes[si]);
          (*d2)->detect(&sr);
          (*d2)->detect(&sr);
          breakdowns.push_back({std::string(sim::to_string(m)) + " / " + sim::to_string(tr), sr.times, sr.contact_count});
        }
      }
      if (exact != "yes") all_exact = false;
      std::printf(" %s |\n", exact.c_str());
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
