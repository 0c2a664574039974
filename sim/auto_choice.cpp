#include "sim/auto_choice.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>

#include "sim/particles.h"

namespace collido::sim {

std::vector<Method> auto_method_candidates(const TriangleMesh& mesh, double r_max, Backend backend,
                                           bool for_dynamics) {
  std::vector<Method> out{Method::kBin, Method::kBvh};
  if (backend != Backend::kCuda) return out;
  if (!for_dynamics) out.push_back(Method::kOctree);
  if (mesh.triangles.empty() || !(r_max > 0)) return out;
  const double cell = 2 * r_max;
  const double mean_area = mesh_area(mesh) / static_cast<double>(mesh.triangles.size());
  if (mean_area > 16 * cell * cell) out.push_back(Method::kCircumcircle);
  return out;
}

void fastest_frames_ms(const std::vector<Detector*>& dets, int min_frames, std::vector<double>* ms,
                       std::vector<Status>* status) {
  const size_t n = dets.size();
  ms->assign(n, 1e300);
  status->assign(n, Status::ok());
  std::vector<double> spent(n, 0.0);
  std::vector<int> frames(n, 0);
  std::vector<bool> live(n);
  DetectResult r;
  for (size_t i = 0; i < n; ++i) {
    live[i] = dets[i] != nullptr;
    if (live[i] && !((*status)[i] = dets[i]->detect(&r))) live[i] = false;  // the warm-up frame
  }
  // A detector leaves the rounds once it has its frames and its time: a slow
  // one is not run again only because a fast one needs more frames.
  auto wants = [&](size_t i) {
    return live[i] && frames[i] < kAutoMaxFrames && (frames[i] < min_frames || spent[i] < kAutoTimingBudgetMs);
  };
  for (bool more = true; more;) {
    more = false;
    for (size_t i = 0; i < n; ++i) {
      // A turn of a few frames in a row: the first refills the caches the
      // other detectors' turns took over, and the fastest frame counts, so
      // every setting is timed warm, as it runs frame after frame in a job.
      for (int k = 0; k < kAutoFramesPerTurn && wants(i); ++k) {
        if (!((*status)[i] = dets[i]->detect(&r))) {
          live[i] = false;
          break;
        }
        (*ms)[i] = std::min((*ms)[i], r.times.frame_ms);
        spent[i] += r.times.frame_ms;
        ++frames[i];
      }
      more = more || wants(i);
    }
  }
}

namespace {

// A seeded subset of at most n particles (all of them when there are fewer).
Particles sample_of(const Particles& p, size_t n) {
  if (p.size() <= n) return p;
  Particles s;
  s.resize(n);
  SplitMix64 rng(0x5eed);
  for (size_t i = 0; i < n; ++i) {
    const size_t k = rng.next() % p.size();
    s.x[i] = p.x[k], s.y[i] = p.y[k], s.z[i] = p.z[k], s.r[i] = p.r[k];
  }
  return s;
}

// A candidate's detector on the sample, ready to time (c->error says why not:
// the caller refused it, or it could not be prepared).
std::unique_ptr<Detector> prepare_candidate(const TriangleMesh& mesh, const Particles& sample,
                                            const DetectConfig& base, const AutoRequest& req,
                                            AutoCandidate* c) {
  if (req.admit)
    if (Status ok = req.admit(c->method, c->grid_length); !ok) {
      c->error = ok.message();
      return nullptr;
    }
  DetectConfig cfg = base;
  cfg.method = c->method, cfg.traversal = c->traversal, cfg.grid_length = c->grid_length;
  cfg.collect_contacts = false, cfg.time_stages = false;
  auto det = Detector::create(mesh, cfg, std::max<size_t>(sample.size(), 1));
  if (!det) {
    c->error = det.status().message();
    return nullptr;
  }
  c->prepare_ms = (*det)->info().prepare_ms;
  if (Status s = (*det)->set_particles(sample); !s) {
    c->error = s.message();
    return nullptr;
  }
  return std::move(*det);
}

// Times candidates [begin, end) together (fastest_frames_ms), each on its
// own detector.
void time_together(const TriangleMesh& mesh, const Particles& sample, const DetectConfig& base,
                   const AutoRequest& req, int min_frames, AutoCandidate* begin,
                   AutoCandidate* end) {
  std::vector<std::unique_ptr<Detector>> owned;
  std::vector<Detector*> dets;
  for (AutoCandidate* c = begin; c != end; ++c) {
    owned.push_back(prepare_candidate(mesh, sample, base, req, c));
    dets.push_back(owned.back().get());
  }
  std::vector<double> ms;
  std::vector<Status> status;
  fastest_frames_ms(dets, min_frames, &ms, &status);
  for (size_t i = 0; i < dets.size(); ++i) {
    if (!status[i]) begin[i].error = status[i].message();
    begin[i].frame_ms = begin[i].error.empty() ? ms[i] : 0;
  }
}

}  // namespace

Expected<AutoChoice> choose_detection(const TriangleMesh& mesh, const Particles& particles,
                                      const DetectConfig& base, const AutoRequest& req) {
  if (!(base.r_max > 0)) return invalid_argument("automatic choice: r_max must be positive");
  const bool gpu = base.backend == Backend::kCuda;
  const size_t max_sample = req.max_sample ? req.max_sample : (gpu ? 4000000 : 200000);
  const int repeats = req.repeats > 0 ? req.repeats : kAutoMinFrames;
  const Particles sample = sample_of(particles, max_sample);
  std::vector<Method> methods =
      req.method ? auto_method_candidates(mesh, base.r_max, base.backend, req.for_dynamics)
                 : std::vector<Method>{base.method};
  std::vector<double> grids;
  if (req.grid_length)
    for (double f : kAutoGridFactors) grids.push_back(f * base.r_max);
  else
    grids.push_back(base.grid_length);
  AutoChoice choice;
  for (Method m : methods) {
    if (!uses_grid(m)) {  // the tree and the octree: no grid length to choose, one candidate
      choice.candidates.push_back(AutoCandidate{m, Traversal::kParticle, 0, 0, 0, {}});
      continue;
    }
    // bin reads its own cell (particle traversal); the paper's pieces are timed both ways.
    std::vector<Traversal> traversals{Traversal::kParticle};
    if (m != Method::kBin && req.method && !req.for_dynamics)
      traversals.push_back(Traversal::kWall);
    if (!req.method) traversals = {base.traversal};
    for (Traversal t : traversals)
      for (double g : grids) choice.candidates.push_back(AutoCandidate{m, t, g, 0, 0, {}});
  }
  // All candidates at once on the CPU, whose timings drift with the machine's
  // other work; one at a time on the GPU, whose timings are steady and where
  // a dozen detectors on four million particles would hold gigabytes.
  AutoCandidate* all = choice.candidates.data();
  const size_t n = choice.candidates.size();
  if (gpu) {
    for (size_t i = 0; i < n; ++i)
      time_together(mesh, sample, base, req, repeats, all + i, all + i + 1);
  } else {
    time_together(mesh, sample, base, req, repeats, all, all + n);
  }
  const AutoCandidate* best = nullptr;
  for (const auto& c : choice.candidates)
    if (c.error.empty() && (!best || c.frame_ms < best->frame_ms)) best = &c;
  if (!best)
    return invalid_argument("automatic choice: no candidate could be prepared (" +
                            choice.candidates.front().error + ")");
  choice.method = best->method, choice.traversal = best->traversal, choice.grid_length = best->grid_length;
  // "bin/particle with grid 2 r_max" (0 is the detector's default, 2 r_max),
  // or "bvh/particle" (no grid).
  auto setting = [&](const AutoCandidate& c, const char* grid_word) {
    std::string s = std::string(to_string(c.method)) + "/" + to_string(c.traversal);
    if (uses_grid(c.method)) {
      char g[48];
      const double grid = c.grid_length > 0 ? c.grid_length : 2 * base.r_max;
      std::snprintf(g, sizeof g, "%s%.3g r_max", grid_word, grid / base.r_max);
      s += g;
    }
    return s;
  };
  char line[160];
  std::snprintf(line, sizeof line, " (%.3g ms a frame on %zu particles); tried:", best->frame_ms,
                sample.size());
  choice.reason = setting(*best, " with grid ") + line;
  for (const auto& c : choice.candidates) {
    if (!c.error.empty()) {
      choice.reason += std::string(" ") + to_string(c.method) + " refused;";
      continue;
    }
    std::snprintf(line, sizeof line, " %.3g ms;", c.frame_ms);
    choice.reason += " " + setting(c, " ") + line;
  }
  choice.reason.pop_back();
  return choice;
}

}  // namespace collido::sim
