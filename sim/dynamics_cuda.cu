// CUDA instantiation of the dynamics: the same DynamicsPipeline as the CPU on
// the shared CUDA backend. No physics lives here.
#include "sim/backend_cuda.cuh"
#include "sim/detect_cuda.h"
#include "sim/dynamics_pipeline.h"

namespace collido::sim {

Expected<std::unique_ptr<Simulation>> make_cuda_simulation(const TriangleMesh& mesh,
                                                           const DynamicsConfig& cfg,
                                                           const ParticleSet& particles,
                                                           const TimeStepInfo& ts, Vec3d domain_lo,
                                                           Vec3d domain_hi) {
  std::string why;
  if (!cuda_device_usable(&why))
    return Status(ErrorCode::kBackend, "no usable CUDA device: " + why);
  return DynamicsPipeline<CudaBackend>::make(mesh, cfg, particles, ts, domain_lo, domain_hi);
}

}  // namespace collido::sim
