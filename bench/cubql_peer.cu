// The GPU peer of `bench detect` on large meshes: cuBQL (github.com/ingowald/cuBQL, Ingo
// Wald's header-only CUDA BVH library, Apache-2.0) answering the same question as
// bench/cgal_peer for the same particles: how many triangles lie within each sphere's
// radius. The library's defaults throughout: its GPU builder (a binary BVH over the
// triangles' float boxes, adaptive spatial median, one triangle per leaf), its fixed-radius
// traversal and its float point-triangle distance.
//
// cuBQL is not part of this repository and the engine never links it: the build points -I
// at a copy holding cuBQL/bvh.h (gpu-carry/cubql here, git-ignored). One command, from the
// repo root (wrapped here):
//   nvcc -O3 -DNDEBUG -std=c++17 -arch=sm_90 --extended-lambda --expt-relaxed-constexpr
//     -Xcompiler -ffp-contract=off -I. -Igpu-carry/cubql bench/cubql_peer.cu
//     sim/accuracy.cpp sim/stl_io.cpp sim/mesh.cpp -o build-dev/bench/cubql_peer
// The three sources are all of collido_sim that loading and particle generation need,
// built with its Release flags (-O3 -DNDEBUG -ffp-contract=off), so the particles are
// cgal_peer's. NDEBUG also quiets cuBQL's per-allocation warning on multi-GPU hosts.
//
// Usage: cubql_peer WALL.stl PARTICLES NEAR_FRACTION R_LO R_HI SEED [REPEATS]
// Arguments as cgal_peer's; REPEATS (default 10) timed runs of the build and of the query
// follow one untimed warm-up of each. Prints one line: triangles, particles, build ms, query
// ms (medians, cudaEvent times on the GPU; the query is timed on the spheres as generated and
// in Morton order, and the faster counts), contacts.
#define CUBQL_GPU_BUILDER_IMPLEMENTATION 1
#include "cuBQL/bvh.h"
#include "cuBQL/queries/triangleData/math/pointToTriangleDistance.h"
#include "cuBQL/traversal/fixedRadiusQuery.h"

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <utility>
#include <vector>

#include "sim/accuracy.h"
#include "sim/mesh.h"

namespace {

using Bvh = cuBQL::BinaryBVH<float, 3>;
using cuBQL::box3f;
using cuBQL::Triangle;
using cuBQL::vec3f;

constexpr int kBlock = 128;      // threads per block, a multiple of the warp
constexpr int kStackDepth = 64;  // entries of fixedRadiusQuery's traversal stack

// Every CUDA call is checked: a failure names the call and ends the run.
void check(cudaError_t e, const char* call) {
  if (e == cudaSuccess) return;
  std::fprintf(stderr, "cubql_peer: %s: %s\n", call, cudaGetErrorString(e));
  std::exit(1);
}
#define CUDA_CHECK(call) check((call), #call)

unsigned blocks(size_t n) {
  return static_cast<unsigned>((n + kBlock - 1) / kBlock);
}

// The builder's input: one float box per triangle.
__global__ void triangle_boxes(const Triangle* tris, uint32_t n, box3f* boxes) {
  const uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
  if (t < n) boxes[t] = tris[t].bounds();
}

// One thread per sphere. cuBQL's fixed-radius traversal hands over every triangle of every
// leaf whose box it finds within the radius; a triangle counts when cuBQL's float
// point-triangle squared distance is strictly below r^2 (the engine's contact predicate).
// Each warp adds its sum to the one 64-bit total.
__global__ void count_contacts(Bvh bvh, const Triangle* tris, const float4* spheres, uint32_t n,
                               unsigned long long* total) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  unsigned count = 0;
  if (i < n) {  // no early return: the whole warp meets at the reduction below
    const float4 s = spheres[i];
    const vec3f centre(s.x, s.y, s.z);
    const float r2 = s.w * s.w;
    auto per_triangle = [&](uint32_t t) -> int {
      if (cuBQL::triangles::computeClosestPoint(centre, tris[t]).sqrDist < r2) ++count;
      return CUBQL_CONTINUE_TRAVERSAL;
    };
    cuBQL::fixedRadiusQuery::forEachPrim(per_triangle, bvh, centre, r2);
  }
  count = __reduce_add_sync(0xffffffffu, count);
  if ((threadIdx.x & 31) == 0 && count != 0) atomicAdd(total, count);
}

// Depth of the deepest leaf (root 0). The traversal defers at most one child per inner node
// on its path, so a tree deeper than its stack would overflow it.
int tree_depth(const Bvh& bvh) {
  std::vector<Bvh::Node> nodes(bvh.numNodes);
  CUDA_CHECK(cudaMemcpy(nodes.data(), bvh.nodes, nodes.size() * sizeof(Bvh::Node),
                        cudaMemcpyDeviceToHost));
  int depth = 0;
  std::vector<std::pair<uint64_t, int>> todo{{0, 0}};
  while (!todo.empty()) {
    const auto [id, d] = todo.back();
    todo.pop_back();
    depth = std::max(depth, d);
    const auto& admin = nodes[id].admin;
    if (admin.count == 0 && admin.offset + 1 < nodes.size()) {
      todo.push_back({admin.offset, d + 1});
      todo.push_back({admin.offset + 1, d + 1});
    }
  }
  return depth;
}

float elapsed_ms(cudaEvent_t start, cudaEvent_t stop) {
  float ms = 0;
  CUDA_CHECK(cudaEventElapsedTime(&ms, start, stop));
  return ms;
}

// Spread the low 10 bits of v to every third bit (a 30-bit Morton code's one axis).
uint32_t spread_bits(uint32_t v) {
  v = (v | (v << 16)) & 0x030000FFu;
  v = (v | (v << 8)) & 0x0300F00Fu;
  v = (v | (v << 4)) & 0x030C30C3u;
  return (v | (v << 2)) & 0x09249249u;
}

// The spheres in Morton order of their centres (10 bits an axis over their box): the
// library takes its queries in the order given, and neighbouring threads that walk the
// same nodes run faster, so the peer is timed both ways and the faster counts.
std::vector<float4> morton_sorted(const std::vector<float4>& s) {
  if (s.empty()) return s;
  float lo[3] = {s[0].x, s[0].y, s[0].z}, hi[3] = {s[0].x, s[0].y, s[0].z};
  for (const float4& q : s) {
    const float c[3] = {q.x, q.y, q.z};
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c[a]), hi[a] = std::max(hi[a], c[a]);
  }
  std::vector<std::pair<uint32_t, uint32_t>> key(s.size());
  for (size_t i = 0; i < s.size(); ++i) {
    const float c[3] = {s[i].x, s[i].y, s[i].z};
    uint32_t code = 0;
    for (int a = 0; a < 3; ++a) {
      const float t = hi[a] > lo[a] ? (c[a] - lo[a]) / (hi[a] - lo[a]) : 0.f;
      code |= spread_bits(static_cast<uint32_t>(std::min(1023.f, t * 1024.f))) << a;
    }
    key[i] = {code, static_cast<uint32_t>(i)};
  }
  std::sort(key.begin(), key.end());
  std::vector<float4> out(s.size());
  for (size_t i = 0; i < s.size(); ++i) out[i] = s[key[i].second];
  return out;
}

float median(std::vector<float> v) {
  std::sort(v.begin(), v.end());
  const size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5f * (v[m - 1] + v[m]);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 7 && argc != 8) {
    std::fprintf(stderr,
                 "usage: cubql_peer WALL.stl PARTICLES NEAR_FRACTION R_LO R_HI SEED [REPEATS]\n");
    return 2;
  }
  auto mesh = collido::sim::load_stl(argv[1]);
  if (!mesh) {
    std::fprintf(stderr, "cubql_peer: %s\n", mesh.status().message().c_str());
    return 1;
  }
  const size_t n = std::strtoull(argv[2], nullptr, 10);
  const double near = std::atof(argv[3]), r_lo = std::atof(argv[4]), r_hi = std::atof(argv[5]);
  const int repeats = argc == 8 ? std::atoi(argv[7]) : 10;
  const size_t num_tris = mesh->triangles.size();
  if (num_tris == 0 || n > UINT32_MAX || repeats < 1) {
    std::fprintf(stderr, "cubql_peer: needs triangles, at most 2^32-1 particles, REPEATS >= 1\n");
    return 2;
  }
  // The same particles as `collidoscope bench detect` (and cgal_peer) with these settings.
  const collido::sim::Particles p = collido::sim::particles_near_surface(
      *mesh, n, r_lo, r_hi, near, 1.5 * r_hi, std::strtoull(argv[6], nullptr, 10));

  // Float copies of the triangles and spheres, the precision cuBQL works in.
  std::vector<Triangle> tris(num_tris);
  for (size_t t = 0; t < num_tris; ++t) {
    Triangle& tri = tris[t];
    vec3f* corner[3] = {&tri.a, &tri.b, &tri.c};
    for (int k = 0; k < 3; ++k) {
      const auto v = mesh->corner(t, k);
      *corner[k] = vec3f(static_cast<float>(v.x), static_cast<float>(v.y), static_cast<float>(v.z));
    }
  }
  std::vector<float4> spheres(n);
  for (size_t i = 0; i < n; ++i)
    spheres[i] = make_float4(static_cast<float>(p.x[i]), static_cast<float>(p.y[i]),
                             static_cast<float>(p.z[i]), static_cast<float>(p.r[i]));

  CUDA_CHECK(cudaFree(nullptr));  // create the context before anything is timed
  Triangle* d_tris = nullptr;
  box3f* d_boxes = nullptr;
  float4* d_spheres = nullptr;
  unsigned long long* d_total = nullptr;
  CUDA_CHECK(cudaMalloc(&d_tris, num_tris * sizeof(Triangle)));
  CUDA_CHECK(cudaMalloc(&d_boxes, num_tris * sizeof(box3f)));
  CUDA_CHECK(cudaMalloc(&d_spheres, std::max<size_t>(n, 1) * sizeof(float4)));
  CUDA_CHECK(cudaMalloc(&d_total, sizeof(unsigned long long)));
  CUDA_CHECK(cudaMemcpy(d_tris, tris.data(), num_tris * sizeof(Triangle), cudaMemcpyHostToDevice));
  CUDA_CHECK(cudaMemcpy(d_spheres, spheres.data(), n * sizeof(float4), cudaMemcpyHostToDevice));
  cudaEvent_t start, stop;
  CUDA_CHECK(cudaEventCreate(&start));
  CUDA_CHECK(cudaEventCreate(&stop));

  // Build: the boxes kernel and cuBQL's default gpuBuilder on the default stream, timed
  // together between two events. The builder reads node counts back between its passes, so
  // this is the build's wall time on the GPU timeline. Run 0 is the warm-up (module loading,
  // the memory pool cuBQL allocates from); each run frees the previous tree.
  Bvh bvh;
  std::vector<float> build_ms;
  for (int k = 0; k <= repeats; ++k) {
    if (bvh.nodes) cuBQL::cuda::free(bvh);
    CUDA_CHECK(cudaEventRecord(start));
    triangle_boxes<<<blocks(num_tris), kBlock>>>(d_tris, static_cast<uint32_t>(num_tris), d_boxes);
    CUDA_CHECK(cudaGetLastError());
    cuBQL::gpuBuilder(bvh, d_boxes, static_cast<uint32_t>(num_tris));
    CUDA_CHECK(cudaGetLastError());
    CUDA_CHECK(cudaEventRecord(stop));
    CUDA_CHECK(cudaEventSynchronize(stop));
    if (k > 0) build_ms.push_back(elapsed_ms(start, stop));
  }
  const int depth = tree_depth(bvh);
  if (depth > kStackDepth) {
    std::fprintf(stderr, "cubql_peer: tree depth %d exceeds the traversal's %d-entry stack\n",
                 depth, kStackDepth);
    return 1;
  }

  // Query: the kernel alone between two events, the counter cleared before each run; run 0
  // is the warm-up. Every run must find the same contacts.
  unsigned long long contacts = 0;
  bool counted = false;
  auto time_query = [&]() {
    std::vector<float> ms;
    for (int k = 0; k <= repeats; ++k) {
      CUDA_CHECK(cudaMemset(d_total, 0, sizeof(unsigned long long)));
      CUDA_CHECK(cudaEventRecord(start));
      if (n > 0) {
        count_contacts<<<blocks(n), kBlock>>>(bvh, d_tris, d_spheres, static_cast<uint32_t>(n),
                                              d_total);
        CUDA_CHECK(cudaGetLastError());
      }
      CUDA_CHECK(cudaEventRecord(stop));
      CUDA_CHECK(cudaEventSynchronize(stop));
      unsigned long long got = 0;
      CUDA_CHECK(cudaMemcpy(&got, d_total, sizeof(got), cudaMemcpyDeviceToHost));
      if (!counted) contacts = got, counted = true;
      if (got != contacts) {
        std::fprintf(stderr, "cubql_peer: contacts changed between runs (%llu, then %llu)\n",
                     contacts, got);
        std::exit(1);
      }
      if (k > 0) ms.push_back(elapsed_ms(start, stop));
    }
    return median(ms);
  };
  const float generated_ms = time_query();  // the spheres as generated
  spheres = morton_sorted(spheres);
  CUDA_CHECK(cudaMemcpy(d_spheres, spheres.data(), n * sizeof(float4), cudaMemcpyHostToDevice));
  const float morton_ms = time_query();

  std::printf(
      "cubql_peer: %zu triangles, %zu particles, build %.3f ms, query %.3f ms, %llu contacts "
      "(medians of %d runs; query as generated %.3f ms, Morton order %.3f ms; %u nodes, depth %d)\n",
      num_tris, n, median(build_ms), std::min(generated_ms, morton_ms), contacts, repeats,
      generated_ms, morton_ms, bvh.numNodes, depth);

  cuBQL::cuda::free(bvh);
  CUDA_CHECK(cudaEventDestroy(start));
  CUDA_CHECK(cudaEventDestroy(stop));
  CUDA_CHECK(cudaFree(d_total));
  CUDA_CHECK(cudaFree(d_spheres));
  CUDA_CHECK(cudaFree(d_boxes));
  CUDA_CHECK(cudaFree(d_tris));
  return 0;
}
