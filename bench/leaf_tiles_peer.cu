// The prototype the octree method came from (#18; docs/benchmarks.md, "The octree
// method"): a grid over the wall whose crowded cells are split in eight (up to DEPTH
// levels, while a cell lists more than K triangles), each leaf listing the triangles
// within r_max of its box; a frame groups the particles by leaf (a counting sort: each
// particle's leaf and rank, a scan, a scatter) and tests each leaf's particles against
// its list. Two ways to test: `tiles` (default), a warp a leaf, a triangle a lane while
// the leaf's particles pass (or, for a short list, 32 / T particles at a time); and
// WALK=1, a thread a particle in leaf order. It counts contacts with a float
// point-triangle distance only (no error band, no double re-decision) and checks the
// counts of the first SAMPLE particles against every triangle in double on the GPU.
// Standalone: the engine never links it. It reads the engine's STL loader and particle
// generator, so its particles are `bench detect`'s.
//
// Build (repo root, on the GPU machine; bench/leaf_tiles_peer.sh does it):
//   nvcc -O3 -std=c++17 -arch=sm_90 -I. -Xcompiler -ffp-contract=off bench/leaf_tiles_peer.cu
//     sim/accuracy.cpp sim/stl_io.cpp sim/mesh.cpp -o leaf_tiles_peer
// Usage: leaf_tiles_peer WALL.stl N NEAR R_LO R_HI SEED L0 DEPTH K [REPEATS] [SAMPLE]
//   L0: the top cells' edge in r_max. Prints the structure (leaves, entries, memory),
//   the frame's median time and its stages (cudaEvents), contacts and tests, and the check.
#include <cub/cub.cuh>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "sim/accuracy.h"
#include "sim/mesh.h"
#include "sim/narrow_phase.h"

namespace {

void check(cudaError_t e, const char* call) {
  if (e == cudaSuccess) return;
  std::fprintf(stderr, "leaf_tiles_peer: %s: %s\n", call, cudaGetErrorString(e));
  std::exit(1);
}
#define CK(call) check((call), #call)

using D3 = collido::sim::Vec3d;  // with the engine's vector operations (sim/hd.h)

// The engine's closest point on a triangle in double (sim/narrow_phase.h), squared
// distance, for a triangle given as nine coordinates.
__host__ __device__ inline double dist2_d(double px, double py, double pz, const double* t) {
  using V = collido::sim::Vec3d;
  return collido::sim::point_triangle_dist2<double>(V{px, py, pz}, V{t[0], t[1], t[2]},
                                                    V{t[3], t[4], t[5]}, V{t[6], t[7], t[8]});
}

// Ericson's closest point in float, on a triangle given as a and the edges ab, ac: the
// prototype's own, a bare float distance (what its figures time), unlike the
// engine's planar form.
__device__ inline float dist2_f(float px, float py, float pz, float4 A, float4 AB, float4 AC) {
  const float ax = A.x, ay = A.y, az = A.z, abx = AB.x, aby = AB.y, abz = AB.z, acx = AC.x,
              acy = AC.y, acz = AC.z;
  const float apx = px - ax, apy = py - ay, apz = pz - az;
  const float d1 = abx * apx + aby * apy + abz * apz, d2 = acx * apx + acy * apy + acz * apz;
  float qx, qy, qz;
  if (d1 <= 0 && d2 <= 0) {
    qx = ax, qy = ay, qz = az;
  } else {
    const float bx = ax + abx, by = ay + aby, bz = az + abz;
    const float bpx = px - bx, bpy = py - by, bpz = pz - bz;
    const float d3 = abx * bpx + aby * bpy + abz * bpz, d4 = acx * bpx + acy * bpy + acz * bpz;
    if (d3 >= 0 && d4 <= d3) {
      qx = bx, qy = by, qz = bz;
    } else {
      const float vc = d1 * d4 - d3 * d2;
      if (vc <= 0 && d1 >= 0 && d3 <= 0) {
        const float v = d1 / (d1 - d3);
        qx = ax + v * abx, qy = ay + v * aby, qz = az + v * abz;
      } else {
        const float cx = ax + acx, cy = ay + acy, cz = az + acz;
        const float cpx = px - cx, cpy = py - cy, cpz = pz - cz;
        const float d5 = abx * cpx + aby * cpy + abz * cpz, d6 = acx * cpx + acy * cpy + acz * cpz;
        if (d6 >= 0 && d5 <= d6) {
          qx = cx, qy = cy, qz = cz;
        } else {
          const float vb = d5 * d2 - d1 * d6;
          if (vb <= 0 && d2 >= 0 && d6 <= 0) {
            const float w = d2 / (d2 - d6);
            qx = ax + w * acx, qy = ay + w * acy, qz = az + w * acz;
          } else {
            const float va = d3 * d6 - d5 * d4;
            if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
              const float w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
              qx = bx + w * (cx - bx), qy = by + w * (cy - by), qz = bz + w * (cz - bz);
            } else {
              const float denom = 1 / (va + vb + vc);
              const float v = vb * denom, w = vc * denom;
              qx = ax + abx * v + acx * w, qy = ay + aby * v + acy * w, qz = az + abz * v + acz * w;
            }
          }
        }
      }
    }
  }
  const float dx = px - qx, dy = py - qy, dz = pz - qz;
  return dx * dx + dy * dy + dz * dz;
}

struct GridF {
  float lo[3];
  float inv_s0;
  int dim[3];
};

// The particle's leaf: its coarse cell's node, then down the octants.
__device__ inline int find_leaf(float4 q, const GridF& g, const int* nodes) {
  const float fx = (q.x - g.lo[0]) * g.inv_s0, fy = (q.y - g.lo[1]) * g.inv_s0,
              fz = (q.z - g.lo[2]) * g.inv_s0;
  const int ix = int(floorf(fx)), iy = int(floorf(fy)), iz = int(floorf(fz));
  if (ix < 0 || iy < 0 || iz < 0 || ix >= g.dim[0] || iy >= g.dim[1] || iz >= g.dim[2]) return -1;
  int node = nodes[(size_t(iz) * g.dim[1] + iy) * g.dim[0] + ix];
  float ux = fx - ix, uy = fy - iy, uz = fz - iz;
  while (node < -1) {
    const int base = -node - 2;
    ux *= 2, uy *= 2, uz *= 2;
    const int ox = ux >= 1, oy = uy >= 1, oz = uz >= 1;
    ux -= ox, uy -= oy, uz -= oz;
    node = nodes[base + ox + 2 * oy + 4 * oz];
  }
  return node;
}

__global__ void locate(const float4* p, int n, GridF g, const int* nodes, int* leaf_of,
                       int* rank_of, int* pcount, int* active, int* nactive, int* count,
                       int* nlocated) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  count[i] = 0;
  const int leaf = find_leaf(p[i], g, nodes);
  leaf_of[i] = leaf;
  if (leaf < 0) return;
  const int r = atomicAdd(&pcount[leaf], 1);
  rank_of[i] = r;
  if (r == 0) active[atomicAdd(nactive, 1)] = leaf;
  atomicAdd(nlocated, 1);
}

__global__ void scatter(const float4* p, int n, const int* leaf_of, const int* rank_of,
                        const int* pstart, float4* sp, int* sid, int* sleaf) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const int leaf = leaf_of[i];
  if (leaf < 0) return;
  const int at = pstart[leaf] + rank_of[i];
  sp[at] = p[i];
  sid[at] = i;
  sleaf[at] = leaf;
}

// A thread a particle in leaf order: its leaf's list, the same for its neighbours.
__global__ void walk(const int* nlocated, const uint32_t* leaf_start, const uint32_t* leaf_len,
                     const uint32_t* list, const float4* tri, const float4* sp, const int* sid,
                     const int* sleaf, int* count, unsigned long long* total,
                     unsigned long long* tests) {
  const int j = blockIdx.x * blockDim.x + threadIdx.x;
  unsigned found = 0, tried = 0;
  if (j < *nlocated) {
    const float4 q = sp[j];
    const int leaf = sleaf[j];
    const uint32_t ts = leaf_start[leaf], T = leaf_len[leaf];
    for (uint32_t k = 0; k < T; ++k) {
      const uint32_t t = list[ts + k];
      found += dist2_f(q.x, q.y, q.z, tri[3 * t], tri[3 * t + 1], tri[3 * t + 2]) < q.w * q.w;
    }
    tried = T;
    count[sid[j]] = found;
  }
  found = __reduce_add_sync(0xffffffffu, found);
  tried = __reduce_add_sync(0xffffffffu, tried);
  if ((threadIdx.x & 31) == 0) {
    if (found) atomicAdd(total, found);
    if (tried) atomicAdd(tests, tried);
  }
}

// One warp a leaf at a time: its P particles x T triangles, lanes over the pairs.
__global__ void tiles(const int* active, const int* nactive, const int* pcount, const int* pstart,
                      const uint32_t* leaf_start, const uint32_t* leaf_len, const uint32_t* list,
                      const float4* tri, const float4* sp, const int* sid, int* count,
                      unsigned long long* total, unsigned long long* tests) {
  const int lane = threadIdx.x & 31;
  const int warp = (blockIdx.x * blockDim.x + threadIdx.x) >> 5;
  const int warps = (gridDim.x * blockDim.x) >> 5;
  const int na = *nactive;
  unsigned found = 0, tried = 0;
  for (int a = warp; a < na; a += warps) {
    const int leaf = active[a];
    const int P = pcount[leaf], ps = pstart[leaf];
    const int T = int(leaf_len[leaf]);
    const uint32_t ts = leaf_start[leaf];
    if (T >= 16) {  // a triangle a lane, held while the leaf's particles pass
      for (int tb = 0; tb < T; tb += 32) {
        const int ti = tb + lane;
        float4 A = make_float4(0, 0, 0, 0), AB = A, AC = A;
        if (ti < T) {
          const uint32_t t = list[ts + ti];
          A = tri[3 * t], AB = tri[3 * t + 1], AC = tri[3 * t + 2];
        }
        for (int pi = 0; pi < P; ++pi) {
          const float4 q = sp[ps + pi];
          const bool hit = ti < T && dist2_f(q.x, q.y, q.z, A, AB, AC) < q.w * q.w;
          tried += ti < T;
          const unsigned hits = __popc(__ballot_sync(0xffffffffu, hit));
          if (hits && lane == 0) atomicAdd(&count[sid[ps + pi]], int(hits));
          found += hit;
        }
      }
    } else {  // 32 / T particles at a time, a lane a pair
      const int G = 32 / T, g = lane / T, ti = lane - g * T;
      if (g < G) {
        const uint32_t t = list[ts + ti];
        const float4 A = tri[3 * t], AB = tri[3 * t + 1], AC = tri[3 * t + 2];
        for (int pi = g; pi < P; pi += G) {
          const float4 q = sp[ps + pi];
          const float d2 = dist2_f(q.x, q.y, q.z, A, AB, AC);
          ++tried;
          if (d2 < q.w * q.w) atomicAdd(&count[sid[ps + pi]], 1), ++found;
        }
      }
    }
  }
  found = __reduce_add_sync(0xffffffffu, found);
  tried = __reduce_add_sync(0xffffffffu, tried);
  if (lane == 0) {
    if (found) atomicAdd(total, found);
    if (tried) atomicAdd(tests, tried);
  }
}

// Reference: every triangle for each of the first m particles, in double.
__global__ void brute(const float4* p, int m, const double* tri, int nt, int* ref) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= m) return;
  const float4 q = p[i];
  int c = 0;
  const double r2 = double(q.w) * double(q.w);
  for (int t = 0; t < nt; ++t)
    if (dist2_d(q.x, q.y, q.z, tri + 9 * t) < r2) ++c;
  ref[i] = c;
}

float ms_between(cudaEvent_t a, cudaEvent_t b) {
  float ms = 0;
  CK(cudaEventElapsedTime(&ms, a, b));
  return ms;
}

float median(std::vector<float> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

struct Builder {
  const std::vector<std::array<double, 9>>& tri;
  const std::vector<std::array<double, 6>>& box;  // lo, hi
  const std::vector<D3>& normal;                  // unit
  double R;
  int max_depth, K;
  bool edge_axes;
  std::vector<int> nodes;
  std::vector<uint32_t> leaf_start, leaf_len, list;
  size_t splits = 0;

  bool near(uint32_t t, const D3& lo, double s) const {
    const double h = s / 2;
    const D3 c{lo.x + h, lo.y + h, lo.z + h};
    const auto& b = box[t];
    if (b[0] > lo.x + s + R || b[3] < lo.x - R || b[1] > lo.y + s + R || b[4] < lo.y - R ||
        b[2] > lo.z + s + R || b[5] < lo.z - R)
      return false;
    const D3 n = normal[t];
    const D3 a{tri[t][0], tri[t][1], tri[t][2]};
    if (std::fabs(dot(n, c - a)) > R + h * (std::fabs(n.x) + std::fabs(n.y) + std::fabs(n.z)))
      return false;
    const double reach = R + h * std::sqrt(3.0);
    if (dist2_d(c.x, c.y, c.z, tri[t].data()) > reach * reach) return false;
    if (!edge_axes) return true;
    // The separating axes of the triangle's edges and the box's axes, against the box
    // grown by R on every side (it holds the box grown by a ball of R).
    const D3 v[3] = {D3{tri[t][0], tri[t][1], tri[t][2]} - c,
                     D3{tri[t][3], tri[t][4], tri[t][5]} - c,
                     D3{tri[t][6], tri[t][7], tri[t][8]} - c};
    const double e = h + R;
    for (int i = 0; i < 3; ++i) {
      const D3 edge = v[(i + 1) % 3] - v[i];
      const D3 axes[3] = {D3{0, -edge.z, edge.y}, D3{edge.z, 0, -edge.x}, D3{-edge.y, edge.x, 0}};
      for (const D3& ax : axes) {
        const double p0 = dot(v[0], ax), p1 = dot(v[1], ax), p2 = dot(v[2], ax);
        const double rad = e * (std::fabs(ax.x) + std::fabs(ax.y) + std::fabs(ax.z));
        if (std::min({p0, p1, p2}) > rad * (1 + 1e-12) ||
            std::max({p0, p1, p2}) < -rad * (1 + 1e-12))
          return false;
      }
    }
    return true;
  }

  // Writes the node for the cell at lo of side s holding `cand` (its parent's list).
  int make(const std::vector<uint32_t>& cand, const D3& lo, double s, int depth) {
    std::vector<uint32_t> mine;
    for (uint32_t t : cand)
      if (near(t, lo, s)) mine.push_back(t);
    if (mine.empty()) return -1;
    if (int(mine.size()) > K && depth < max_depth) {
      const int base = int(nodes.size());
      nodes.resize(nodes.size() + 8);
      ++splits;
      for (int o = 0; o < 8; ++o) {
        const D3 clo{lo.x + (o & 1) * s / 2, lo.y + ((o >> 1) & 1) * s / 2,
                     lo.z + ((o >> 2) & 1) * s / 2};
        const int v = make(mine, clo, s / 2, depth + 1);
        nodes[base + o] = v;
      }
      return -base - 2;
    }
    const int leaf = int(leaf_start.size());
    leaf_start.push_back(uint32_t(list.size()));
    leaf_len.push_back(uint32_t(mine.size()));
    list.insert(list.end(), mine.begin(), mine.end());
    return leaf;
  }
};

}  // namespace

int main(int argc, char** argv) {
  if (argc < 10) {
    std::fprintf(
        stderr,
        "usage: leaf_tiles_peer WALL.stl N NEAR R_LO R_HI SEED L0 DEPTH K [REPEATS] [SAMPLE]\n");
    return 2;
  }
  auto mesh = collido::sim::load_stl(argv[1]);
  if (!mesh) {
    std::fprintf(stderr, "leaf_tiles_peer: %s\n", mesh.status().message().c_str());
    return 1;
  }
  const int n = std::atoi(argv[2]);
  const double near_share = std::atof(argv[3]), r_lo = std::atof(argv[4]),
               r_hi = std::atof(argv[5]);
  const uint64_t seed = std::strtoull(argv[6], nullptr, 10);
  const double L0 = std::atof(argv[7]);
  const int depth = std::atoi(argv[8]), K = std::atoi(argv[9]);
  const int repeats = argc > 10 ? std::atoi(argv[10]) : 10;
  const int sample = argc > 11 ? std::atoi(argv[11]) : 20000;
  const collido::sim::Particles p =
      collido::sim::particles_near_surface(*mesh, n, r_lo, r_hi, near_share, 1.5 * r_hi, seed);
  const size_t nt = mesh->triangles.size();

  // Host preparation: the adaptive grid.
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<std::array<double, 9>> tri(nt);
  std::vector<std::array<double, 6>> box(nt);
  std::vector<D3> normal(nt);
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (size_t t = 0; t < nt; ++t) {
    std::array<double, 6> b = {1e300, 1e300, 1e300, -1e300, -1e300, -1e300};
    for (int k = 0; k < 3; ++k) {
      const auto v = mesh->corner(t, k);
      const double c[3] = {v.x, v.y, v.z};
      for (int a = 0; a < 3; ++a) {
        tri[t][3 * k + a] = c[a];
        b[a] = std::min(b[a], c[a]), b[3 + a] = std::max(b[3 + a], c[a]);
        lo[a] = std::min(lo[a], c[a]), hi[a] = std::max(hi[a], c[a]);
      }
    }
    box[t] = b;
    const D3 A{tri[t][0], tri[t][1], tri[t][2]}, B{tri[t][3], tri[t][4], tri[t][5]},
        C{tri[t][6], tri[t][7], tri[t][8]};
    D3 nn = cross(B - A, C - A);
    const double len = std::sqrt(dot(nn, nn));
    normal[t] = len > 0 ? nn * (1 / len) : D3{0, 0, 0};
  }
  const double size = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  const double R = r_hi * (1 + 1e-5) + 1e-6 * size;  // float rounding of the particle's cell
  const double s0 = L0 * r_hi;
  GridF g;
  int dim[3];
  for (int a = 0; a < 3; ++a) {
    g.lo[a] = float(lo[a] - r_hi);
    dim[a] = g.dim[a] = int(std::ceil((hi[a] - lo[a] + 2 * r_hi) / s0)) + 1;
  }
  g.inv_s0 = float(1 / s0);
  const size_t ncoarse = size_t(dim[0]) * dim[1] * dim[2];
  Builder bld{tri, box, normal, R, depth, K, true};
  bld.nodes.assign(ncoarse, -1);
  // Coarse lists: each triangle into the cells its box reaches, then each cell built.
  std::vector<std::vector<uint32_t>> cells(ncoarse);
  for (size_t t = 0; t < nt; ++t) {
    int c0[3], c1[3];
    for (int a = 0; a < 3; ++a) {
      c0[a] = std::max(0, int(std::floor((box[t][a] - R - g.lo[a]) / s0)));
      c1[a] = std::min(dim[a] - 1, int(std::floor((box[t][3 + a] + R - g.lo[a]) / s0)));
    }
    for (int z = c0[2]; z <= c1[2]; ++z)
      for (int y = c0[1]; y <= c1[1]; ++y)
        for (int x = c0[0]; x <= c1[0]; ++x)
          cells[(size_t(z) * dim[1] + y) * dim[0] + x].push_back(uint32_t(t));
  }
  for (int z = 0; z < dim[2]; ++z)
    for (int y = 0; y < dim[1]; ++y)
      for (int x = 0; x < dim[0]; ++x) {
        const size_t c = (size_t(z) * dim[1] + y) * dim[0] + x;
        if (cells[c].empty()) continue;
        const D3 clo{g.lo[0] + x * s0, g.lo[1] + y * s0, g.lo[2] + z * s0};
        const int v = bld.make(cells[c], clo, s0, 0);
        bld.nodes[c] = v;
        std::vector<uint32_t>().swap(cells[c]);
      }
  const double prep_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  const int nleaves = int(bld.leaf_start.size());
  uint32_t max_len = 0;
  for (uint32_t l : bld.leaf_len) max_len = std::max(max_len, l);
  const double mem_mb =
      (bld.nodes.size() * 4.0 + nleaves * 8.0 + bld.list.size() * 4.0 + nt * 48.0 +
       nleaves * 12.0 /*pcount,pstart,active*/ + n * (16.0 + 4 + 4 + 4 + 4 + 4)) /
      1e6;
  const double extra = bld.nodes.size() * 4.0 + nleaves * 20.0 + bld.list.size() * 4.0 + n * 28.0;
  std::printf("extra device bytes %.1f MB: %.1f B per particle+triangle\n", extra / 1e6,
              extra / double(n + nt));
  std::printf(
      "wall %s: %zu triangles; grid %dx%dx%d of %.3g (L0 %.2g r_max), depth %d, K %d: %d leaves, "
      "%zu splits, %zu entries (max list %u), %zu nodes; host prep %.0f ms; memory %.1f MB "
      "(%.1f B per particle+triangle)\n",
      argv[1], nt, dim[0], dim[1], dim[2], s0, L0, depth, K, nleaves, bld.splits, bld.list.size(),
      max_len, bld.nodes.size(), prep_ms, mem_mb, mem_mb * 1e6 / double(n + nt));

  // Device data.
  std::vector<float4> hp(n), ht(3 * nt);
  for (int i = 0; i < n; ++i)
    hp[i] = make_float4(float(p.x[i]), float(p.y[i]), float(p.z[i]), float(p.r[i]));
  std::vector<double> htd(9 * nt);
  for (size_t t = 0; t < nt; ++t) {
    const float ax = float(tri[t][0]), ay = float(tri[t][1]), az = float(tri[t][2]);
    ht[3 * t] = make_float4(ax, ay, az, 0);
    ht[3 * t + 1] =
        make_float4(float(tri[t][3]) - ax, float(tri[t][4]) - ay, float(tri[t][5]) - az, 0);
    ht[3 * t + 2] =
        make_float4(float(tri[t][6]) - ax, float(tri[t][7]) - ay, float(tri[t][8]) - az, 0);
    for (int k = 0; k < 9; ++k) htd[9 * t + k] = tri[t][k];
  }
  CK(cudaFree(nullptr));
  float4 *dp, *dt, *dsp;
  double* dtd;
  int *dnodes, *dleaf, *dsleaf, *dnloc, *drank, *dpcount, *dpstart, *dactive, *dnactive, *dsid,
      *dcount, *dref;
  uint32_t *dls, *dll, *dlist;
  unsigned long long *dtotal, *dtests;
  CK(cudaMalloc(&dp, n * sizeof(float4)));
  CK(cudaMalloc(&dsp, n * sizeof(float4)));
  CK(cudaMalloc(&dt, 3 * nt * sizeof(float4)));
  CK(cudaMalloc(&dtd, 9 * nt * sizeof(double)));
  CK(cudaMalloc(&dnodes, bld.nodes.size() * 4));
  CK(cudaMalloc(&dleaf, n * 4));
  CK(cudaMalloc(&drank, n * 4));
  CK(cudaMalloc(&dsid, n * 4));
  CK(cudaMalloc(&dsleaf, n * 4));
  CK(cudaMalloc(&dnloc, 4));
  CK(cudaMalloc(&dcount, n * 4));
  CK(cudaMalloc(&dref, std::max(sample, 1) * 4));
  CK(cudaMalloc(&dpcount, (nleaves + 1) * 4));
  CK(cudaMalloc(&dpstart, (nleaves + 1) * 4));
  CK(cudaMalloc(&dactive, (nleaves + 1) * 4));
  CK(cudaMalloc(&dnactive, 4));
  CK(cudaMalloc(&dls, (nleaves + 1) * 4));
  CK(cudaMalloc(&dll, (nleaves + 1) * 4));
  CK(cudaMalloc(&dlist, (bld.list.size() + 1) * 4));
  CK(cudaMalloc(&dtotal, 8));
  CK(cudaMalloc(&dtests, 8));
  CK(cudaMemcpy(dp, hp.data(), n * sizeof(float4), cudaMemcpyHostToDevice));
  CK(cudaMemcpy(dt, ht.data(), 3 * nt * sizeof(float4), cudaMemcpyHostToDevice));
  CK(cudaMemcpy(dtd, htd.data(), 9 * nt * sizeof(double), cudaMemcpyHostToDevice));
  CK(cudaMemcpy(dnodes, bld.nodes.data(), bld.nodes.size() * 4, cudaMemcpyHostToDevice));
  CK(cudaMemcpy(dls, bld.leaf_start.data(), nleaves * 4, cudaMemcpyHostToDevice));
  CK(cudaMemcpy(dll, bld.leaf_len.data(), nleaves * 4, cudaMemcpyHostToDevice));
  CK(cudaMemcpy(dlist, bld.list.data(), bld.list.size() * 4, cudaMemcpyHostToDevice));
  void* scan_tmp = nullptr;
  size_t scan_bytes = 0;
  CK(cub::DeviceScan::ExclusiveSum(scan_tmp, scan_bytes, dpcount, dpstart, nleaves));
  CK(cudaMalloc(&scan_tmp, scan_bytes));
  int sms = 0;
  CK(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, 0));

  cudaEvent_t ev[6];
  for (auto& e : ev) CK(cudaEventCreate(&e));
  std::vector<float> t_all, t_loc, t_scan, t_scat, t_tile;
  unsigned long long total = 0, tests = 0;
  int nactive = 0;
  const int B = 256;
  for (int k = 0; k <= repeats; ++k) {
    CK(cudaMemset(dtotal, 0, 8));
    CK(cudaMemset(dtests, 0, 8));
    CK(cudaEventRecord(ev[0]));
    CK(cudaMemsetAsync(dpcount, 0, nleaves * 4));
    CK(cudaMemsetAsync(dnactive, 0, 4));
    CK(cudaMemsetAsync(dnloc, 0, 4));
    locate<<<(n + B - 1) / B, B>>>(dp, n, g, dnodes, dleaf, drank, dpcount, dactive, dnactive,
                                   dcount, dnloc);
    CK(cudaEventRecord(ev[1]));
    CK(cub::DeviceScan::ExclusiveSum(scan_tmp, scan_bytes, dpcount, dpstart, nleaves));
    CK(cudaEventRecord(ev[2]));
    scatter<<<(n + B - 1) / B, B>>>(dp, n, dleaf, drank, dpstart, dsp, dsid, dsleaf);
    CK(cudaEventRecord(ev[3]));
    if (getenv("WALK"))
      walk<<<(n + B - 1) / B, B>>>(dnloc, dls, dll, dlist, dt, dsp, dsid, dsleaf, dcount, dtotal,
                                   dtests);
    else
      tiles<<<sms * 8, B>>>(dactive, dnactive, dpcount, dpstart, dls, dll, dlist, dt, dsp, dsid,
                            dcount, dtotal, dtests);
    CK(cudaEventRecord(ev[4]));
    CK(cudaEventSynchronize(ev[4]));
    CK(cudaGetLastError());
    if (k == 0) continue;
    t_all.push_back(ms_between(ev[0], ev[4]));
    t_loc.push_back(ms_between(ev[0], ev[1]));
    t_scan.push_back(ms_between(ev[1], ev[2]));
    t_scat.push_back(ms_between(ev[2], ev[3]));
    t_tile.push_back(ms_between(ev[3], ev[4]));
  }
  CK(cudaMemcpy(&total, dtotal, 8, cudaMemcpyDeviceToHost));
  CK(cudaMemcpy(&tests, dtests, 8, cudaMemcpyDeviceToHost));
  CK(cudaMemcpy(&nactive, dnactive, 4, cudaMemcpyDeviceToHost));
  std::printf(
      "%s frame %.3f ms (locate %.3f, scan %.3f, scatter %.3f, tiles %.3f); contacts %llu, tests "
      "%llu "
      "(%.2f a contact), %d active leaves\n",
      getenv("WALK") ? "walk" : "tiles", median(t_all), median(t_loc), median(t_scan),
      median(t_scat), median(t_tile), total, tests, double(tests) / double(std::max(total, 1ull)),
      nactive);

  // Check the first `sample` particles against every triangle in double.
  const int m = std::min(sample, n);
  if (m > 0) {
    brute<<<(m + 127) / 128, 128>>>(dp, m, dtd, int(nt), dref);
    CK(cudaDeviceSynchronize());
    std::vector<int> ref(m), got(m);
    CK(cudaMemcpy(ref.data(), dref, m * 4, cudaMemcpyDeviceToHost));
    CK(cudaMemcpy(got.data(), dcount, m * 4, cudaMemcpyDeviceToHost));
    long diff = 0, refsum = 0, bad = 0;
    for (int i = 0; i < m; ++i) {
      refsum += ref[i];
      diff += std::labs(long(ref[i]) - got[i]);
      bad += ref[i] != got[i];
    }
    std::printf(
        "check: first %d particles, %ld reference contacts, %ld particles differ (%ld contacts)\n",
        m, refsum, bad, diff);
  }
  return 0;
}
