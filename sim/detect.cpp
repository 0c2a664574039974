#include "sim/detect.h"

#include <algorithm>
#include <chrono>

#include "sim/backend_cpu.h"
#include "sim/detect_cuda.h"
#include "sim/detect_pipeline.h"
#include "sim/exact_distance.h"

namespace collido::sim {

const char* to_string(Method m) {
  switch (m) {
    case Method::kGravity: return "gravity";
    case Method::kCircumcircle: return "circumcircle";
    case Method::kMidpoint4: return "midpoint4";
    case Method::kBin: return "bin";
    case Method::kReference: return "reference";
    case Method::kBvh: return "bvh";
    case Method::kOctree:
      return "octree";
  }
  return "?";
}
const char* to_string(Traversal t) { return t == Traversal::kWall ? "wall" : "particle"; }
const char* to_string(Backend b) { return b == Backend::kCuda ? "cuda" : "cpu"; }
const char* to_string(Precision p) { return p == Precision::kFloat ? "float" : "exact"; }

bool parse_method(const std::string& s, Method* out) {
  for (Method m : {Method::kGravity, Method::kCircumcircle, Method::kMidpoint4, Method::kBin,
                   Method::kReference, Method::kBvh, Method::kOctree})
    if (s == to_string(m)) return *out = m, true;
  return false;
}
bool parse_traversal(const std::string& s, Traversal* out) {
  if (s == "wall") return *out = Traversal::kWall, true;
  if (s == "particle") return *out = Traversal::kParticle, true;
  return false;
}
bool parse_precision(const std::string& s, Precision* out) {
  if (s == "exact") return *out = Precision::kExact, true;
  if (s == "float") return *out = Precision::kFloat, true;
  return false;
}
bool parse_backend(const std::string& s, Backend* out) {
  if (s == "cpu") return *out = Backend::kCpu, true;
  if (s == "cuda" || s == "gpu") return *out = Backend::kCuda, true;
  return false;
}

bool cuda_available(std::string* why) {
#if defined(COLLIDO_HAVE_CUDA)
  return cuda_device_usable(why);
#else
  if (why) *why = "this build has no CUDA backend (configured with COLLIDO_CUDA=OFF or without nvcc)";
  return false;
#endif
}

namespace {

// The oracle: every particle against every original triangle in double
// precision, with only an exact bounding-box rejection in front.
class ReferenceDetector final : public Detector {
 public:
  ReferenceDetector(const TriangleMesh& mesh, const DetectConfig& cfg) : Detector(cfg), mesh_(mesh) {
    const auto t0 = std::chrono::steady_clock::now();
    info_.triangles_original = info_.triangles_used = mesh.triangles.size();
    for (size_t t = 0; t < mesh.triangles.size(); ++t) {
      const TriangleD tri{mesh.corner(t, 0), mesh.corner(t, 1), mesh.corner(t, 2)};
      Bounds3d b;
      for (const Vec3d& v : {tri.a, tri.b, tri.c}) b.grow(v);
      // Grown by far more than the rounding of the rejection test below, so
      // the box only ever rejects pairs the exact predicate also rejects.
      const double slack = 1e-9 * (length(b.extent()) + std::fabs(b.lo.x) + std::fabs(b.lo.y) +
                                   std::fabs(b.lo.z) + std::fabs(b.hi.x) + std::fabs(b.hi.y) +
                                   std::fabs(b.hi.z));
      b.lo = b.lo - Vec3d{slack, slack, slack};
      b.hi = b.hi + Vec3d{slack, slack, slack};
      boxes_.push_back(b);
      tris_.push_back(tri);
    }
    info_.prepare_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  }
  Status set_particles(const Particles& p) override {
    for (size_t i = 0; i < p.size(); ++i)
      if (!(p.r[i] > 0) || !std::isfinite(p.x[i]) || !std::isfinite(p.y[i]) || !std::isfinite(p.z[i]))
        return invalid_argument("particle " + std::to_string(i) + " has a non-finite position or radius <= 0");
    particles_ = p;
    return Status::ok();
  }
  Status detect(DetectResult* out) override {
    *out = DetectResult{};
    const auto t0 = std::chrono::steady_clock::now();
    const size_t n = particles_.size();
    std::vector<std::vector<Contact>> per(n);
    out->counts.assign(n, 0);
    cpu_parallel_for(cfg_.pool ? *cfg_.pool : default_pool(), n, [&](uint32_t i) {
      const ParticleD q{particles_.x[i], particles_.y[i], particles_.z[i], particles_.r[i]};
      const double r = q.r * (1 + 1e-9);
      for (size_t t = 0; t < tris_.size(); ++t) {
        const Bounds3d& b = boxes_[t];
        if (q.x < b.lo.x - r || q.x > b.hi.x + r || q.y < b.lo.y - r || q.y > b.hi.y + r ||
            q.z < b.lo.z - r || q.z > b.hi.z + r)
          continue;
        double d2 = 0;
        if (exact_touch(q, tris_[t], &d2)) per[i].push_back({i, mesh_.source_ids[t], std::sqrt(d2)});
      }
      std::sort(per[i].begin(), per[i].end(),
                [](const Contact& a, const Contact& b) { return a.triangle < b.triangle; });
      out->counts[i] = static_cast<uint32_t>(per[i].size());
    }, 64);
    out->times.traverse_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    out->times.frame_ms = out->times.traverse_ms;
    for (size_t i = 0; i < n; ++i) {
      out->contact_count += per[i].size();
      out->colliding_particles += !per[i].empty();
      if (cfg_.collect_contacts) out->contacts.insert(out->contacts.end(), per[i].begin(), per[i].end());
    }
    return Status::ok();
  }

 private:
  const TriangleMesh mesh_;
  std::vector<Bounds3d> boxes_;
  std::vector<TriangleD> tris_;
  Particles particles_;
};

}  // namespace

Backend usable_backend(Backend wanted, std::string* note) {
  if (wanted != Backend::kCuda) return wanted;
  std::string why;
  if (cuda_available(&why)) return Backend::kCuda;
  if (note) *note = "no usable GPU (" + why + "): running on the CPU";
  return Backend::kCpu;
}

#if !defined(COLLIDO_HAVE_CUDA)
// A build without CUDA has no device to name or measure (sim/detect_cuda.h).
std::string cuda_device_name() { return ""; }
double cuda_copy_bandwidth_gbs() { return 0; }
#endif

Expected<std::unique_ptr<Detector>> Detector::create(const TriangleMesh& mesh, const DetectConfig& config,
                                                     size_t max_particles) {
  if (config.method == Method::kReference) {
    if (config.backend != Backend::kCpu)
      return invalid_argument("the reference method runs on the CPU only (it is the double-precision oracle)");
    if (mesh.triangles.empty()) return invalid_argument("the wall has no triangles");
    return std::unique_ptr<Detector>(new ReferenceDetector(mesh, config));
  }
  if (config.method == Method::kBvh && config.traversal == Traversal::kWall)
    return invalid_argument(
        "the bvh method walks its tree from each particle: use the particle traversal");
  if (config.method == Method::kOctree && config.traversal == Traversal::kWall)
    return invalid_argument(
        "the octree method reads each particle's own leaf: use the particle traversal");
  if (config.backend == Backend::kCuda) {
#if defined(COLLIDO_HAVE_CUDA)
    return make_cuda_detector(mesh, config, max_particles);
#else
    return Status(ErrorCode::kBackend, "this build has no CUDA backend");
#endif
  }
  return GridDetector<CpuBackend>::make(mesh, config, max_particles);
}

}  // namespace collido::sim
