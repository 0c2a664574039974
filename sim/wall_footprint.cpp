#include "sim/wall_footprint.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <mutex>
#include <optional>
#include <utility>
#include <vector>

#include "sim/wall_index.h"

namespace collido::sim {

namespace {

// A hash of the wall's vertices and triangles, eight bytes a step: a byte a
// step, a remembered wall of 10^6 triangles still cost 30 ms a prediction
// (the counter tiled twelvefold; 7.7 ms so, and 187 ms its first pricing).
uint64_t mesh_fingerprint(const TriangleMesh& mesh) {
  uint64_t h = 1469598103934665603ull;
  auto mix = [&h](const void* data, size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < bytes; i += 8) {
      uint64_t w = 0;
      std::memcpy(&w, p + i, std::min<size_t>(8, bytes - i));
      h = (h ^ w) * 0x9E3779B97F4A7C15ull;
      h ^= h >> 32;
    }
  };
  const uint64_t counts[2] = {mesh.vertices.size(), mesh.triangles.size()};
  mix(counts, sizeof counts);
  mix(mesh.vertices.data(), mesh.vertices.size() * sizeof(Vec3d));
  mix(mesh.triangles.data(), mesh.triangles.size() * sizeof(mesh.triangles[0]));
  return h;
}

struct EntriesKey {
  uint64_t mesh;
  double r_max, cell;
  uint64_t max_dense_cells;
  double visit_limit;
  bool operator==(const EntriesKey& o) const {
    return mesh == o.mesh && r_max == o.r_max && cell == o.cell &&
           max_dense_cells == o.max_dense_cells && visit_limit == o.visit_limit;
  }
};

// The last few walls' entries, newest last.
std::mutex g_entries_mu;
std::vector<std::pair<EntriesKey, std::pair<double, bool>>> g_entries;
constexpr size_t kRememberedEntries = 32;

std::optional<std::pair<double, bool>> remembered_entries(const EntriesKey& key) {
  std::lock_guard lock(g_entries_mu);
  for (const auto& [k, v] : g_entries)
    if (k == key) return v;
  return std::nullopt;
}

void remember_entries(const EntriesKey& key, std::pair<double, bool> value) {
  std::lock_guard lock(g_entries_mu);
  if (g_entries.size() >= kRememberedEntries) g_entries.erase(g_entries.begin());
  g_entries.emplace_back(key, value);
}

}  // namespace

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
  // The entries depend on the wall and the grid's cells, not on the
  // particles (they size only a hashed grid's table): a service prices the
  // same wall again and again as a form's fields change, and the walk was
  // most of a prediction (wall1 at r = 0.5: 17 of 20 ms).
  const EntriesKey key{mesh_fingerprint(mesh), r_max, cell, max_dense_cells, visit_limit};
  if (auto known = remembered_entries(key)) {
    f.bin_entries = known->first;
    f.sampled = known->second;
    return f;
  }
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
  remember_entries(key, {f.bin_entries, f.sampled});
  return f;
}

}  // namespace collido::sim
