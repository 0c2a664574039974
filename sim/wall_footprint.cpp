#include "sim/wall_footprint.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "sim/wall_index.h"

namespace collido::sim {

WallFootprint wall_footprint(const TriangleMesh& mesh, Method method, double r_max, double cell,
                             uint64_t max_dense_cells, uint64_t particles, double pieces,
                             double visit_limit) {
  WallFootprint f;
  if (method == Method::kBvh || mesh.triangles.empty()) return f;
  const Bounds3d box = mesh_bounds(mesh);
  const Vec3d origin = box.center();
  if (method != Method::kBin) {
    // Pieces are hashed by bounding-sphere centre, padded by their reach (a
    // cell for pieces no larger than the particles) and one more.
    const Vec3d pad{2 * cell, 2 * cell, 2 * cell};
    uint64_t cells = 0;
    f.buckets = make_grid(box.lo - origin - pad, box.hi - origin + pad, cell, max_dense_cells,
                          uint64_t(std::max(pieces, 0.0)) + particles, &cells)
                    .buckets;
    return f;
  }
  const size_t m = mesh.triangles.size();
  const BinLayout layout = bin_layout(box, origin, r_max, cell, max_dense_cells, m, particles);
  f.buckets = layout.grid.buckets;
  const float grow = float(layout.grow);
  // The corners in the preparation's float frame, and each triangle's visits.
  std::vector<TriangleF> tris(m);
  std::vector<double> visits(m);
  double total = 0;
  for (size_t t = 0; t < m; ++t) {
    tris[t] = {cast3<float>(mesh.corner(t, 0) - origin), cast3<float>(mesh.corner(t, 1) - origin),
               cast3<float>(mesh.corner(t, 2) - origin)};
    int lo[3], hi[3];
    bin_cell_range(layout.grid, tris[t], grow, lo, hi);
    visits[t] = double(hi[0] - lo[0] + 1) * double(hi[1] - lo[1] + 1) * double(hi[2] - lo[2] + 1);
    total += visits[t];
  }
  const size_t stride =
      total <= visit_limit ? 1 : size_t(std::ceil(total / std::max(visit_limit, 1.0)));
  // A triangle that alone visits more than the limit is left to the others'
  // share (a wall of a few huge triangles against tiny particles: the
  // budget refuses it anyway); with none walked, the visits stand in.
  double walked = 0, entries = 0;
  for (size_t t = 0; t < m; t += stride) {
    if (stride > 1 && visits[t] > visit_limit) continue;
    walked += visits[t];
    for_each_bin_cell(layout.grid, tris[t], grow, [&](uint64_t) { entries += 1; });
  }
  f.sampled = stride > 1;
  f.bin_entries = !f.sampled ? entries : walked > 0 ? entries * total / walked : total;
  return f;
}

}  // namespace collido::sim
