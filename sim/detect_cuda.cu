// CUDA backend of the detection pipeline: the same GridDetector as the CPU,
// with device buffers, a generic kernel for parallel_for, and CUB for scan,
// radix sort, segmented sort and reduce-by-key. No geometry lives here.
#include "sim/backend_cuda.cuh"
#include "sim/detect_cuda.h"
#include "sim/detect_pipeline.h"

namespace collido::sim {

bool cuda_device_usable(std::string* why) {
  int count = 0;
  const cudaError_t e = cudaGetDeviceCount(&count);
  if (e != cudaSuccess) {
    if (why) *why = cudaGetErrorString(e);
    cudaGetLastError();  // clear the sticky error so later calls start clean
    return false;
  }
  if (count == 0) {
    if (why) *why = "no CUDA device";
    return false;
  }
  return true;
}

Expected<std::unique_ptr<Detector>> make_cuda_detector(const TriangleMesh& mesh, const DetectConfig& cfg,
                                                       size_t max_particles) {
  std::string why;
  if (!cuda_device_usable(&why)) return Status(ErrorCode::kBackend, "no usable CUDA device: " + why);
  return GridDetector<CudaBackend>::make(mesh, cfg, max_particles);
}

}  // namespace collido::sim

namespace collido::sim {

std::string cuda_device_name() {
  cudaDeviceProp prop{};
  if (cudaGetDeviceProperties(&prop, 0) != cudaSuccess) return "unknown";
  return prop.name;
}

double cuda_copy_bandwidth_gbs() {
  const size_t bytes = size_t(1) << 30;
  void *a = nullptr, *b = nullptr;
  if (cudaMalloc(&a, bytes) != cudaSuccess) return 0;
  if (cudaMalloc(&b, bytes) != cudaSuccess) {
    cudaFree(a);
    return 0;
  }
  cudaMemset(a, 1, bytes);
  cudaEvent_t start, stop;
  cudaEventCreate(&start);
  cudaEventCreate(&stop);
  cudaMemcpy(b, a, bytes, cudaMemcpyDeviceToDevice);  // warm-up
  float best = 1e30f;
  for (int k = 0; k < 10; ++k) {
    cudaEventRecord(start);
    cudaMemcpy(b, a, bytes, cudaMemcpyDeviceToDevice);
    cudaEventRecord(stop);
    cudaEventSynchronize(stop);
    float ms = 0;
    cudaEventElapsedTime(&ms, start, stop);
    best = ms < best ? ms : best;
  }
  cudaEventDestroy(start);
  cudaEventDestroy(stop);
  cudaFree(a);
  cudaFree(b);
  return 2.0 * double(bytes) / (best * 1e-3) / 1e9;
}

}  // namespace collido::sim
