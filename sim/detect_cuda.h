// Entry points of the CUDA backend (sim/detect_cuda.cu), used by sim/detect.cpp.
#pragma once

#include <memory>
#include <string>

#include "sim/detect.h"
#include "sim/dynamics.h"

namespace collido::sim {

#if defined(COLLIDO_HAVE_CUDA)
Expected<std::unique_ptr<Detector>> make_cuda_detector(const TriangleMesh& mesh, const DetectConfig& cfg,
                                                       size_t max_particles);
bool cuda_device_usable(std::string* why);
// The dynamics on the GPU (sim/dynamics_cuda.cu); arguments as DynamicsPipeline::make.
Expected<std::unique_ptr<Simulation>> make_cuda_simulation(const TriangleMesh& mesh, const DynamicsConfig& cfg,
                                                           const ParticleSet& particles, const TimeStepInfo& ts,
                                                           Vec3d domain_lo, Vec3d domain_hi);
#endif

}  // namespace collido::sim

namespace collido::sim {
// Device name and the measured device-to-device copy bandwidth (GB/s, bytes
// read plus written), the ceiling for memory-bound frames. 0 without CUDA.
std::string cuda_device_name();
double cuda_copy_bandwidth_gbs();
}  // namespace collido::sim
