// `method: auto` and `grid_length: auto`: the detection setting a scene needs,
// chosen on the scene itself. The study (docs/study.md) found no rule of thumb
// that orders the candidates on every wall: which grid length wins depends on
// the triangle sizes against the radius, how the particles crowd the surface
// and the backend. So the choice measures, as FFTW's planner and cuDNN's
// benchmark mode do: each candidate is prepared and timed on (a sample of) the
// scene's own particles on the run's backend, and the fastest is kept. Every
// candidate is exact (sim/exact_distance.h), so the fastest is also the
// setting on the speed/accuracy front.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "sim/detect.h"
#include "sim/mesh.h"
#include "sim/status.h"

namespace collido::sim {

struct AutoRequest {
  bool method = true;       // choose the method (else keep base.method)
  bool grid_length = true;  // choose the grid length (else keep base.grid_length)
  // Particles timed per candidate (a seeded subset beyond; 0 = the backend's
  // default: every particle up to 4e6 on the GPU, where a frame costs well
  // under a millisecond and a subset's fixed costs would weigh differently, and
  // 2e5 on the CPU).
  size_t max_sample = 0;
  // Timed frames per candidate: at least this many (0 = kAutoMinFrames) and at
  // least kAutoTimingBudgetMs of frames, at most kAutoMaxFrames (fastest_frames_ms).
  // The fastest frame counts: the work is deterministic, so anything slower is
  // interference (other processes, clocks), which the minimum filters best,
  // given enough frames that one ran undisturbed.
  int repeats = 0;
  // Choosing for the dynamics, which walk the wall per particle through bin's,
  // the tree's or the pieces' lists: time only the particle traversal, and
  // not the octree (a detection method only).
  bool for_dynamics = false;
  // When set, a candidate it refuses (a run's memory budget, say: a finer grid
  // or a divided wall holds more) is not prepared; its error is the reason.
  std::function<Status(Method, double grid_length)> admit;
};

struct AutoCandidate {
  Method method;
  Traversal traversal;
  double grid_length;  // world units
  double frame_ms = 0;
  double prepare_ms = 0;
  std::string error;  // why it could not be prepared (then not chosen)
};

struct AutoChoice {
  Method method = Method::kBin;
  Traversal traversal = Traversal::kParticle;
  double grid_length = 0;  // world units
  std::vector<AutoCandidate> candidates;  // as measured, the chosen one among them
  std::string reason;                     // one line: what was chosen, among what, and why
};

inline constexpr double kAutoTimingBudgetMs = 20;
inline constexpr int kAutoMaxFrames = 200;
inline constexpr int kAutoFramesPerTurn = 3;
// Frames timed at least: three turns, so the fastest frame is picked from
// three moments between the other detectors' turns.
inline constexpr int kAutoMinFrames = 3 * kAutoFramesPerTurn;

// How the automatic choice and the study time a setting: the fastest of at
// least `min_frames` frames (after one warm-up), timing for at least
// kAutoTimingBudgetMs and at most kAutoMaxFrames frames. Several detectors are timed in rounds, a turn of kAutoFramesPerTurn
// frames in a row for each that still needs frames, so a slow spell of the
// machine (another process, a clock change) falls on all of them alike, while
// each is timed with its own data in the caches. (*ms)[i] is dets[i]'s
// fastest frame; (*status)[i] its error, after which it is dropped (a null
// detector is skipped).
void fastest_frames_ms(const std::vector<Detector*>& dets, int min_frames, std::vector<double>* ms,
                       std::vector<Status>* status);

// The grid lengths tried, in units of r_max (the study's grid).
inline constexpr double kAutoGridFactors[] = {1.0, 1.5, 2.0, 3.0};

// The methods worth timing for `mesh`, r_max and the backend: `bin` and
// `bvh` always (no division: the wall as it is; the tree wins on large meshes
// whose triangle sizes span decades); on the GPU also the octree, for
// detection (not `for_dynamics`: the dynamics cannot read it), ahead of the
// tree on every wall of its benchmark there; not on the CPU, where it only
// drew level with the tree on the counter mesh, at four times its preparation
// (docs/benchmarks.md, "The octree's test stage"); and `circumcircle` where
// binning copies the average triangle into more than 16 cells (triangles large
// against the radius), the one case where the paper's pieces have been seen to
// win. On the CPU bin was 30x ahead of every division method in every study scene.
std::vector<Method> auto_method_candidates(const TriangleMesh& mesh, double r_max, Backend backend,
                                           bool for_dynamics = false);

// Times the candidates on `particles` with base's backend, precision and pool
// and returns the fastest. base.r_max must be set.
Expected<AutoChoice> choose_detection(const TriangleMesh& mesh, const Particles& particles,
                                      const DetectConfig& base, const AutoRequest& request);

}  // namespace collido::sim
