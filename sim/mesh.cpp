#include "sim/mesh.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <unordered_map>

namespace collido::sim {

void Bounds3d::grow(Vec3d p) {
  if (empty) {
    lo = hi = p;
    empty = false;
    return;
  }
  lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
  hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
}

double triangle_area(Vec3d a, Vec3d b, Vec3d c) { return 0.5 * length(cross(b - a, c - a)); }

double mesh_area(const TriangleMesh& mesh) {
  double total = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    total += triangle_area(mesh.corner(t, 0), mesh.corner(t, 1), mesh.corner(t, 2));
  return total;
}

Bounds3d mesh_bounds(const TriangleMesh& mesh) {
  Bounds3d b;
  for (const auto& v : mesh.vertices) b.grow(v);
  return b;
}

namespace {

struct CellKey {
  int64_t x, y, z;
  bool operator==(const CellKey& o) const { return x == o.x && y == o.y && z == o.z; }
};
struct CellKeyHash {
  size_t operator()(const CellKey& k) const {
    uint64_t h = static_cast<uint64_t>(k.x) * 0x9E3779B97F4A7C15ull;
    h ^= static_cast<uint64_t>(k.y) * 0xC2B2AE3D27D4EB4Full + (h << 6) + (h >> 2);
    h ^= static_cast<uint64_t>(k.z) * 0x165667B19E3779F9ull + (h << 6) + (h >> 2);
    return static_cast<size_t>(h);
  }
};

// Vertex welding by a hash of quantised coordinates. With tolerance 0 only
// bit-identical coordinates merge (what STL writers produce for shared corners).
class Welder {
 public:
  explicit Welder(double tolerance) : tol_(tolerance) {}

  uint32_t add(Vec3d p, std::vector<Vec3d>& vertices) {
    if (tol_ <= 0) {
      CellKey k{bits(p.x), bits(p.y), bits(p.z)};
      auto [it, inserted] = exact_.try_emplace(k, static_cast<uint32_t>(vertices.size()));
      if (inserted) vertices.push_back(p);
      return it->second;
    }
    CellKey c = cell(p);
    for (int64_t dz = -1; dz <= 1; ++dz)
      for (int64_t dy = -1; dy <= 1; ++dy)
        for (int64_t dx = -1; dx <= 1; ++dx) {
          auto it = cells_.find({c.x + dx, c.y + dy, c.z + dz});
          if (it == cells_.end()) continue;
          for (uint32_t id : it->second)
            if (norm2(vertices[id] - p) <= tol_ * tol_) return id;
        }
    uint32_t id = static_cast<uint32_t>(vertices.size());
    vertices.push_back(p);
    cells_[c].push_back(id);
    return id;
  }

 private:
  static int64_t bits(double v) {
    if (v == 0) v = 0;  // merge -0.0 and +0.0
    int64_t b;
    std::memcpy(&b, &v, sizeof b);
    return b;
  }
  CellKey cell(Vec3d p) const {
    return {static_cast<int64_t>(std::floor(p.x / tol_)), static_cast<int64_t>(std::floor(p.y / tol_)),
            static_cast<int64_t>(std::floor(p.z / tol_))};
  }
  double tol_;
  std::unordered_map<CellKey, uint32_t, CellKeyHash> exact_;
  std::unordered_map<CellKey, std::vector<uint32_t>, CellKeyHash> cells_;
};

}  // namespace

TriangleMesh weld_soup(const std::vector<std::array<Vec3d, 3>>& soup,
                       const std::vector<uint32_t>& source_ids, double weld_tolerance,
                       MeshReport* report) {
  TriangleMesh mesh;
  Welder welder(weld_tolerance);
  size_t dropped = 0;
  for (size_t t = 0; t < soup.size(); ++t) {
    const auto& s = soup[t];
    // Zero area relative to the triangle's own size: the cross product of two
    // edges of a triangle whose corners are collinear is rounding noise of
    // about 1e-16 times its longest edge squared (make_planar's test of a
    // segment). Not relative to the mesh: one stray facet far away would make
    // every small real triangle count as zero area.
    const double longest2 = std::max({norm2(s[1] - s[0]), norm2(s[2] - s[1]), norm2(s[0] - s[2])});
    if (!(length(cross(s[1] - s[0], s[2] - s[0])) > 1e-14 * longest2)) {
      ++dropped;
      continue;
    }
    std::array<uint32_t, 3> idx{welder.add(s[0], mesh.vertices), welder.add(s[1], mesh.vertices),
                                welder.add(s[2], mesh.vertices)};
    if (idx[0] == idx[1] || idx[1] == idx[2] || idx[0] == idx[2]) {
      ++dropped;  // welding collapsed an edge: the triangle has no area left
      continue;
    }
    mesh.triangles.push_back(idx);
    mesh.source_ids.push_back(source_ids.empty() ? static_cast<uint32_t>(t) : source_ids[t]);
  }
  if (report) {
    report->triangles_in = soup.size();
    report->dropped_zero_area = dropped;
    report->vertices_before_weld = 3 * soup.size();
    report->vertices_after_weld = mesh.vertices.size();
  }
  return mesh;
}

void append_mesh(TriangleMesh& a, const TriangleMesh& b) {
  const uint32_t offset = static_cast<uint32_t>(a.vertices.size());
  const uint32_t id_offset = static_cast<uint32_t>(a.source_ids.size());
  a.vertices.insert(a.vertices.end(), b.vertices.begin(), b.vertices.end());
  for (size_t t = 0; t < b.triangles.size(); ++t) {
    const auto& tri = b.triangles[t];
    a.triangles.push_back({tri[0] + offset, tri[1] + offset, tri[2] + offset});
    a.source_ids.push_back(id_offset + static_cast<uint32_t>(t));
  }
}

TriangleMesh mesh_range(const TriangleMesh& m, size_t begin, size_t end, bool inside) {
  TriangleMesh out;
  std::vector<uint32_t> renumbered(m.vertices.size(), UINT32_MAX);
  for (size_t t = 0; t < m.triangles.size(); ++t) {
    if ((t >= begin && t < end) != inside) continue;
    std::array<uint32_t, 3> tri{};
    for (int k = 0; k < 3; ++k) {
      uint32_t& v = renumbered[m.triangles[t][k]];
      if (v == UINT32_MAX) {
        v = static_cast<uint32_t>(out.vertices.size());
        out.vertices.push_back(m.vertices[m.triangles[t][k]]);
      }
      tri[k] = v;
    }
    out.triangles.push_back(tri);
    out.source_ids.push_back(t < m.source_ids.size() ? m.source_ids[t] : uint32_t(t));
  }
  return out;
}

bool is_closed_manifold(const TriangleMesh& mesh) {
  // Each directed edge must appear once, and its reverse exactly once.
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) ++directed[{t[k], t[(k + 1) % 3]}];
  for (const auto& [edge, count] : directed) {
    if (count != 1) return false;
    auto rev = directed.find({edge.second, edge.first});
    if (rev == directed.end() || rev->second != 1) return false;
  }
  return !mesh.triangles.empty();
}

double signed_volume(const TriangleMesh& mesh) {
  double v = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    v += dot(mesh.corner(t, 0), cross(mesh.corner(t, 1), mesh.corner(t, 2)));
  return v / 6.0;
}

bool SolidAngleSum::add(Vec3d a, Vec3d b, Vec3d c) {
  // Van Oosterom and Strackee: triangle t subtends 2 arg(w_t), w_t = den + i num.
  // The sum of the arguments is the argument of the product of the w_t plus the
  // full turns the product makes on the way, so add() multiplies and counts
  // turns, and one atan2 ends it instead of one a triangle (atan2 was three
  // quarters of placing a fill in an open wall of 2,000 triangles, by winding
  // numbers). A turn is counted when two factors of the same half-plane multiply
  // into the other one; those products' imaginary parts are sums of two terms of
  // one sign, so rounding cannot miss a turn (only a sum near pi is ambiguous,
  // and there both readings give the same angle).
  const double la = length(a), lb = length(b), lc = length(c);
  const double num = dot(a, cross(b, c));
  const double den = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb;
  if (num == 0) {  // atan2(+-0, den): 0 for den > 0 or +0, +-pi for den < 0 or -0
    if (den < 0 || (den == 0 && std::signbit(den))) halves_ += std::signbit(num) ? -1 : 1;
    return false;
  }
  const bool upper = im_ >= 0;  // the product's angle in [0, pi] (im == 0 and re < 0: pi)
  const double pre = re_ * den - im_ * num, pim = re_ * num + im_ * den;
  if (upper && num > 0 && (pim < 0 || (pim == 0 && pre > 0))) ++turns_;  // past pi
  if (!upper && num < 0 && pim >= 0) --turns_;                            // past -pi
  re_ = pre, im_ = pim;
  const double size = std::fabs(re_) + std::fabs(im_);
  if (size > 1e150 || size < 1e-150) {
    const int e = std::ilogb(size);
    re_ = std::ldexp(re_, -e), im_ = std::ldexp(im_, -e);
  }
  return std::fabs(num) > 1e-9 * (la * lb * lc);
}

double SolidAngleSum::winding() const {
  const double angle = im_ == 0 ? (re_ < 0 ? M_PI : 0.0) : std::atan2(im_, re_);
  return (angle + 2 * M_PI * double(turns_) + M_PI * halves_) / (2 * M_PI);
}

double winding_number(const TriangleMesh& mesh, Vec3d p) {
  SolidAngleSum sum;
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    sum.add(mesh.corner(t, 0) - p, mesh.corner(t, 1) - p, mesh.corner(t, 2) - p);
  return sum.winding();
}

}  // namespace collido::sim
