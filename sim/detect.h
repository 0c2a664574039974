// Particle-wall collision detection: the engine's public entry point.
// A Detector prepares a wall once (division, grid, bins) and then answers
// frames: which particles touch which original triangles, and how far away.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "sim/divide.h"
#include "sim/mesh.h"
#include "sim/status.h"

namespace collido::sim {

class ThreadPool;  // sim/parallel.h

enum class Method {
  kGravity,       // paper: division by longest-edge bisection, centroid spheres
  kCircumcircle,  // paper: division with obtuse split, circumspheres
  kMidpoint4,     // paper: four-way midpoint division
  kBin,           // no division: original triangles binned into every cell they reach
  kReference,     // exact brute force in double precision (the test oracle)
  kBvh,           // no division: a bounding volume hierarchy over the original triangles
  kOctree,  // no division: grid cells split where triangles crowd, each leaf listing the originals
};
// Whether a method lays a uniform grid over the wall (cells of grid_length)
// and offers both traversals: all but the tree and the octree, which a frame
// walks from each particle, and the reference, which tests every triangle.
inline bool uses_grid(Method m) {
  return m != Method::kBvh && m != Method::kOctree && m != Method::kReference;
}
// Whether the dynamics (and so a job) may step with a method: all but the
// reference, the test oracle, and the octree, whose lists the dynamics' wall
// stage does not read yet (a detection method: `collidoscope detect`, `bench detect`).
inline bool dynamics_can_use(Method m) {
  return m != Method::kReference && m != Method::kOctree;
}
// Whether a method divides the wall into pieces (gravity, circumcircle, midpoint4).
inline bool divides(Method m) {
  return m == Method::kGravity || m == Method::kCircumcircle || m == Method::kMidpoint4;
}
// How a dividing method divides (gravity, circumcircle, midpoint4; any other: midpoint4).
inline DivisionMethod division_of(Method m) {
  return m == Method::kGravity        ? DivisionMethod::kGravity
         : m == Method::kCircumcircle ? DivisionMethod::kCircumcircle
                                      : DivisionMethod::kMidpoint4;
}
enum class Traversal { kParticle, kWall };
enum class Backend { kCpu, kCuda };
// How a float method decides a pair: `exact` re-decides in double every pair
// whose float distance lies inside float's error band of the radius (the
// reference's contact set, bit for bit); `float` takes the float answer.
enum class Precision { kExact, kFloat };

const char* to_string(Method m);
const char* to_string(Traversal t);
const char* to_string(Backend b);
const char* to_string(Precision p);
bool parse_method(const std::string& s, Method* out);
bool parse_traversal(const std::string& s, Traversal* out);
bool parse_backend(const std::string& s, Backend* out);
bool parse_precision(const std::string& s, Precision* out);

// Particles in world coordinates (as given by the user), structure of arrays.
struct Particles {
  std::vector<double> x, y, z, r;
  size_t size() const { return x.size(); }
  void resize(size_t n) { x.resize(n), y.resize(n), z.resize(n), r.resize(n); }
};

struct DetectConfig {
  Method method = Method::kBin;
  Traversal traversal = Traversal::kParticle;  // the paper's two traversals; bin reads its own cell
  Backend backend = Backend::kCpu;
  Precision precision = Precision::kExact;
  double r_max = 0;              // largest particle radius of the run, world units (> 0)
  double grid_length = 0;        // cell edge, world units; 0 = method default (2 r_max)
  bool collect_contacts = true;  // false: only counts per particle (benchmarks)
  bool time_stages = true;       // synchronise between stages to time each one
  // Dense cell arrays above this many cells switch to a hashed table whose
  // size follows the element counts, so sparse or huge domains stay bounded.
  uint64_t max_dense_cells = 1ull << 24;
  // Threads of the CPU backend, owned by the caller; nullptr = default_pool().
  ThreadPool* pool = nullptr;
  // Candidate (particle, triangle) pairs one frame may hold, 24 bytes each of
  // scratch (at most 2^31): a frame that finds more is refused with an error
  // instead of a wrong contact count.
  uint64_t max_frame_pairs = 1ull << 30;
  // octree: how the test stage deals out its particles. Below this many a
  // chunk on average (a chunk: up to 32 of one leaf's), runs of 32 that take
  // their leaves in turn instead. H200, 10^6 particles half near, frame ms
  // chunks / runs: the counter mesh, 5.4 a chunk, 0.32 / 0.48; the
  // 81,920-triangle icosphere, 1.7, 0.49 / 0.35; the counter's tiling, 1.4,
  // 0.70 / 0.62; wall1, 16, 0.14 / 0.18 (docs/benchmarks.md). 0 keeps chunks,
  // UINT32_MAX runs (the tests take both ways).
  uint32_t octree_runs_below = 3;
  // octree, runs: a batch of 32 particles whose leaves hold one or two each
  // tests leaf by leaf (a lane a triangle, or a pair of a short list) or its
  // pairs flattened (a lane a pair, whichever leaf), whichever takes fewer of
  // the warp's rounds, a flattened round counted as this many of the others
  // (its lanes each load their own triangle and shuffle in their particle).
  // H200, 10^6 half near, always flattened against never: the large icosphere
  // 0.29 against 0.40 ms, the small one 0.33 against 0.31; chosen at 1.8 / 1.3:
  // the large icosphere 0.332 / 0.292, the small 0.313 / 0.317, the tiling
  // 0.559 / 0.567 (docs/benchmarks.md; bench detect --octree-flat-cost).
  // 0 always flattens, infinity never (the tests take both ways).
  float octree_flat_cost = 1.3f;
};

// One contact: particle index, the triangle's id in the input file, centre distance.
struct Contact {
  uint32_t particle;
  uint32_t triangle;
  double distance;
};

// Milliseconds spent in each stage of one frame.
struct StageTimes {
  double upload_ms = 0, hash_ms = 0, sort_ms = 0, cells_ms = 0, traverse_ms = 0, finalize_ms = 0,
         download_ms = 0, frame_ms = 0;
};

struct DetectResult {
  std::vector<Contact> contacts;  // sorted by particle, then triangle (collect_contacts)
  std::vector<uint32_t> counts;   // contacts per particle
  uint64_t contact_count = 0;
  uint64_t colliding_particles = 0;
  // Pairs whose float distance fell inside float's error band of the radius:
  // re-decided in double (precision exact), or decided in float and possibly
  // wrong (precision float: a warning counter).
  uint64_t band_pairs = 0;
  StageTimes times;
};

// What preparing the wall produced; printed by the CLI and the benchmark.
struct PrepareInfo {
  size_t triangles_original = 0;
  size_t triangles_used = 0;  // after division (= original for bin and reference)
  double max_sphere_radius = 0;
  double area_error = 0;  // division's relative area error (Eq. 6), double
  double grid_length = 0;
  int reach = 0;         // neighbour cells searched in each direction
  uint64_t cells = 0;    // cells of the domain box
  uint32_t buckets = 0;  // table entries actually stored
  bool hashed = false;
  uint64_t bin_entries = 0;  // bin: (cell, triangle) pairs stored
  uint64_t bvh_nodes = 0;    // bvh: nodes of the (four-wide) tree
  int bvh_depth = 0;         // bvh: its levels to the deepest leaf
  uint64_t octree_leaves = 0;   // octree: leaves (cells or parts of cells that list triangles)
  uint64_t octree_entries = 0;  // octree: (leaf, triangle) pairs stored
  uint64_t octree_splits = 0;   // octree: cells split in eight
  uint64_t octree_wide_entries = 0;  // octree: entries of leaves listing whole slots (sim/octree.h)
  uint64_t octree_long_leaves = 0;   // octree: leaves listing over kOctreeLongList triangles
  double prepare_ms = 0;
  uint64_t device_bytes = 0;  // scratch and prepared data held by the backend
};

class Detector {
 public:
  virtual ~Detector() = default;
  // Prepares `mesh` for particles of radius <= config.r_max, up to max_particles per frame.
  static Expected<std::unique_ptr<Detector>> create(const TriangleMesh& mesh,
                                                    const DetectConfig& config,
                                                    size_t max_particles);
  // Loads a frame's particles (converted to the engine's float local frame; on
  // the GPU, copied to the device). Not part of a detection frame's time.
  virtual Status set_particles(const Particles& particles) = 0;
  // Runs one detection frame over the particles last set.
  virtual Status detect(DetectResult* out) = 0;
  // Per-frame choices that need no new preparation: collect the contact list
  // (else counts only) and time each stage (a sync between stages).
  void set_frame_options(bool collect_contacts, bool time_stages) {
    cfg_.collect_contacts = collect_contacts;
    cfg_.time_stages = time_stages;
  }
  // Switches between exact and float decisions without preparing again. A
  // detector created exact holds the double data and may go either way; one
  // created float cannot become exact (an error says so).
  Status set_precision(Precision p) {
    if (p == Precision::kExact && created_precision_ != Precision::kExact)
      return invalid_argument("this detector was prepared for float precision; create it exact");
    cfg_.precision = p;
    return Status::ok();
  }
  const PrepareInfo& info() const { return info_; }
  const DetectConfig& config() const { return cfg_; }

 protected:
  explicit Detector(const DetectConfig& config)
      : cfg_(config), created_precision_(config.precision) {}
  DetectConfig cfg_;  // as created, with the frame options last set
  Precision created_precision_;
  PrepareInfo info_;  // filled by the implementation's preparation
};

// True when a CUDA device is usable; otherwise *why says what failed.
bool cuda_available(std::string* why = nullptr);

// The backend to run on: `wanted`, except CUDA when no device is usable, which
// falls back to the CPU with *note saying why (note untouched otherwise).
Backend usable_backend(Backend wanted, std::string* note);

}  // namespace collido::sim
