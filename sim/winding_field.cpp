#include "sim/winding_field.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

namespace collido::sim {
namespace {

constexpr uint32_t kLeafTriangles = 8;
constexpr double kFourPi = 4 * M_PI;
// The dipoles' summed error bound, a solid angle, under which a point's closed
// number settles: under half a turn (2 pi), with room for rounding.
constexpr double kErrorBudget = 0.4 * kFourPi;

}  // namespace

WindingField::WindingField(const TriangleMesh& mesh) : mesh_(mesh) {
  const size_t n = mesh.triangles.size();
  // The boundary as a chain: each undirected edge's uses a -> b less its uses
  // b -> a. A closed, consistently wound mesh has none; an open rim's edges
  // are used once, an edge two faces wind alike twice over.
  std::unordered_map<uint64_t, int> net;
  net.reserve(n * 3);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = t[k], b = t[(k + 1) % 3];
      if (a == b) continue;
      const uint64_t key = (uint64_t(std::min(a, b)) << 32) | std::max(a, b);
      net[key] += a < b ? 1 : -1;
    }
  Vec3d apex{0, 0, 0};
  size_t ends = 0;
  for (const auto& [key, m] : net)
    if (m != 0) {
      apex = apex + mesh.vertices[key >> 32] + mesh.vertices[uint32_t(key)];
      ends += 2;
    }
  if (ends) apex = apex * (1.0 / double(ends));
  // The cap: for each boundary use lo -> hi, the triangle (apex, hi, lo), whose
  // edge hi -> lo cancels it; the edges to the apex cancel among themselves
  // (a boundary is a cycle).
  for (const auto& [key, m] : net) {
    const Vec3d lo = mesh.vertices[key >> 32], hi = mesh.vertices[uint32_t(key)];
    for (int k = 0; k < std::abs(m); ++k)
      cap_.push_back(m > 0 ? std::array<Vec3d, 3>{apex, hi, lo} : std::array<Vec3d, 3>{apex, lo, hi});
  }
  plain_ = n == 0 || cap_.size() * 2 > n;  // the cap's exact sum would cost as much as the plain one
  if (plain_) return;
  order_.resize(n);
  for (uint32_t t = 0; t < n; ++t) order_[t] = t;
  nodes_.reserve(2 * n / kLeafTriangles + 1);
  build(0, uint32_t(n));
}

uint32_t WindingField::build(uint32_t begin, uint32_t end) {
  const uint32_t index = uint32_t(nodes_.size());
  nodes_.emplace_back();
  Bounds3d box, centres;
  Vec3d area{0, 0, 0};
  double area_abs = 0;
  for (uint32_t i = begin; i < end; ++i) {
    const size_t t = order_[i];
    const Vec3d a = mesh_.corner(t, 0), b = mesh_.corner(t, 1), c = mesh_.corner(t, 2);
    box.grow(a), box.grow(b), box.grow(c);
    centres.grow((a + b + c) * (1.0 / 3));
    const Vec3d v = cross(b - a, c - a) * 0.5;
    area = area + v;
    area_abs += length(v);
  }
  const Vec3d centre = box.center();
  double radius2 = 0;
  for (uint32_t i = begin; i < end; ++i)
    for (int k = 0; k < 3; ++k) radius2 = std::max(radius2, norm2(mesh_.corner(order_[i], k) - centre));
  {
    Node& node = nodes_[index];
    node.centre = centre;
    node.radius = std::sqrt(radius2);
    node.area = area;
    node.area_abs = area_abs;
    node.begin = begin, node.end = end;
  }
  if (end - begin <= kLeafTriangles) return index;
  // Halves at the median along the longest side of the triangles' centres.
  const Vec3d e = centres.extent();
  const int axis = e.x >= e.y && e.x >= e.z ? 0 : e.y >= e.z ? 1 : 2;
  auto key = [&](uint32_t t) {
    const Vec3d c = mesh_.corner(t, 0) + mesh_.corner(t, 1) + mesh_.corner(t, 2);
    return axis == 0 ? c.x : axis == 1 ? c.y : c.z;
  };
  const uint32_t mid = begin + (end - begin) / 2;
  std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                   [&](uint32_t a, uint32_t b) { return key(a) < key(b); });
  const uint32_t left = build(begin, mid), right = build(mid, end);
  nodes_[index].left = left, nodes_[index].right = right;
  return index;
}

double WindingField::at(Vec3d p) const { return at(p, nullptr); }

double WindingField::at(Vec3d p, Work* work) const {
  Work w;
  w.points = 1;
  double result = 0;
  if (plain_) {
    w.plain = 1;
    result = winding_number(mesh_, p);
  } else {
    // The closed surface's number: nodes as dipoles, each with a bound on its
    // error, the node of the largest bound opened (or a leaf summed exactly)
    // until the bounds add up to under kErrorBudget.
    SolidAngleSum near, cap;
    bool off = true;  // p lies off the near triangles' and the cap's planes
    struct Open {
      double error;  // bound on the node's dipole's error, a solid angle (infinite: p in its ball)
      uint32_t node;
      bool operator<(const Open& o) const { return error < o.error; }
    };
    auto bound_of = [&](const Node& node) {
      // Each area element's solid angle is K(y).dA with K(y) = (y - p) / |y - p|^3;
      // the dipole takes K at the centre for all. |K(y) - K(c)| <= |y - c| times
      // the largest norm of K's Jacobian on the node's ball, 2 / (d - R)^3.
      const double gap = length(node.centre - p) - node.radius;
      return gap > 0 ? 2 * node.radius * node.area_abs / (gap * gap * gap) : INFINITY;
    };
    std::vector<Open> heap;  // a max-heap by error
    heap.reserve(256);
    // The open nodes' bounds: the count of those over the budget, which must
    // be opened anyway, and the others' sum (all under the budget, so its
    // rounding, 1e-16 of the budget a step, is nothing beside the margin).
    double bound = 0;
    size_t over = 0;
    auto open = [&](uint32_t k) {
      const double e = bound_of(nodes_[k]);
      heap.push_back({e, k});
      std::push_heap(heap.begin(), heap.end());
      if (e < kErrorBudget) bound += e;
      else ++over;
    };
    open(0);
    while (!heap.empty() && (over > 0 || !(bound < kErrorBudget))) {
      std::pop_heap(heap.begin(), heap.end());
      const Open o = heap.back();
      heap.pop_back();
      if (o.error < kErrorBudget) bound = std::max(0.0, bound - o.error);
      else --over;
      const Node& node = nodes_[o.node];
      if (node.left == 0) {
        for (uint32_t i = node.begin; i < node.end; ++i) {
          const size_t t = order_[i];
          off &= near.add(mesh_.corner(t, 0) - p, mesh_.corner(t, 1) - p, mesh_.corner(t, 2) - p);
        }
        w.exact_triangles += node.end - node.begin;
      } else {
        open(node.left);
        open(node.right);
      }
    }
    double dipoles = 0;
    for (const Open& h : heap) {
      const Node& node = nodes_[h.node];
      const Vec3d to = node.centre - p;
      const double d2 = norm2(to);
      dipoles += dot(node.area, to) / (d2 * std::sqrt(d2));
    }
    w.far_nodes += heap.size();
    for (const auto& c : cap_) off &= cap.add(c[0] - p, c[1] - p, c[2] - p);
    w.exact_triangles += cap_.size();
    // Off the closed surface its number is whole, and the estimate lies within
    // the bound of it (1e-9 more for the exact sums' rounding, far above it).
    // On it (p in the plane of a near triangle or of the cap) the number is any
    // fraction, and the plain sum gives it.
    const double closed = dipoles / kFourPi + near.winding() + cap.winding();
    if (off && bound / kFourPi + 1e-9 < 0.5) {
      result = std::nearbyint(closed) - cap.winding();
    } else {
      w.plain = 1;
      result = winding_number(mesh_, p);
    }
  }
  if (work) {
    work->points += w.points, work->plain += w.plain;
    work->exact_triangles += w.exact_triangles, work->far_nodes += w.far_nodes;
  }
  return result;
}

}  // namespace collido::sim
