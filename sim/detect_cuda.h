// Entry points of the CUDA backend (sim/detect_cuda.cu), used by sim/detect.cpp.
#pragma once

#include <memory>
#include <string>

#include "sim/detect.h"

namespace collido::sim {

#if defined(COLLIDO_HAVE_CUDA)
Expected<std::unique_ptr<Detector>> make_cuda_detector(const TriangleMesh& mesh, const DetectConfig& cfg,
                                                       size_t max_particles);
bool cuda_device_usable(std::string* why);
#endif

}  // namespace collido::sim
