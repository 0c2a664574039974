#include "sim/bvh.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "sim/parallel.h"

namespace collido::sim {

namespace {

double axis(Vec3d v, int a) { return a == 0 ? v.x : (a == 1 ? v.y : v.z); }

struct Item {
  Bounds3d box;
  Vec3d centre;
  uint32_t triangle;
};

constexpr int kBins = 32;
// Relative costs of visiting a node (two box tests) and testing one triangle.
// (A sweep of the triangle's cost from 0.6 to 5 moved the H200's frame on the
// counter, its twelvefold tiling and a 1.3M-triangle sphere by under 10 %.)
constexpr double kNodeCost = 1.0, kTriangleCost = 1.2;

// A subtree left for the parallel phase: its range, depth and the slot that will point to it.
struct Deferred {
  size_t b, e;
  int depth;
  uint32_t node;
  int slot;
};

class Builder {
 public:
  // Ranges of at most `defer_below` triangles (0: none) are not built but
  // listed in *deferred, each with a placeholder in its parent's slot.
  Builder(std::vector<Item>& items, double reach, double margin, BvhBuild* out,
          size_t defer_below = 0, std::vector<Deferred>* deferred = nullptr)
      : items_(items), reach_(reach), margin_(margin), out_(out), defer_below_(defer_below),
        deferred_(deferred) {}

  // Builds [b, e); returns the child code (node index or leaf) and its box in *box.
  uint32_t build(size_t b, size_t e, int depth, Bounds3d* box) {
    Bounds3d bounds, centres;
    for (size_t i = b; i < e; ++i) {
      bounds.merge(items_[i].box);
      centres.grow(items_[i].centre);
    }
    *box = bounds;
    const size_t n = e - b;
    if (n == 1) return leaf(b, e, depth);
    if (depth > 0 && n <= defer_below_) {
      deferred_->push_back({b, e, depth, 0, 0});
      return kDeferredCode;
    }
    size_t mid = 0;
    const double leaf_cost = kTriangleCost * double(n);
    double split_cost = 0;
    if (depth >= kBvhSahDepth || !sah_split(b, e, bounds, centres, &mid, &split_cost)) {
      if (n <= kBvhMaxLeaf) return leaf(b, e, depth);
      mid = median_split(b, e, centres);
    } else if (n <= kBvhMaxLeaf && leaf_cost <= split_cost) {
      return leaf(b, e, depth);
    }
    const uint32_t index = static_cast<uint32_t>(out_->nodes.size());
    out_->nodes.emplace_back();
    Bounds3d lb, rb;
    // A deferred child lists exactly one range, at the list's size before it was built.
    const size_t left_entry = deferred_ ? deferred_->size() : 0;
    const uint32_t left = build(b, mid, depth + 1, &lb);
    const size_t right_entry = deferred_ ? deferred_->size() : 0;
    const uint32_t right = build(mid, e, depth + 1, &rb);
    set_child(out_->nodes[index], 0, left, lb);
    set_child(out_->nodes[index], 1, right, rb);
    if (left == kDeferredCode) (*deferred_)[left_entry].node = index, (*deferred_)[left_entry].slot = 0;
    if (right == kDeferredCode) (*deferred_)[right_entry].node = index, (*deferred_)[right_entry].slot = 1;
    return index;
  }
  static constexpr uint32_t kDeferredCode = 0xFFFFFFFFu;

  // Writes child slot `c` of `node`: its code and its box, rounded outward to float and grown.
  void set_child(BvhNode& node, int c, uint32_t code, const Bounds3d& b) const {
    float v[6];
    if (b.empty) {  // never visited
      v[0] = v[1] = v[2] = std::numeric_limits<float>::infinity();
      v[3] = v[4] = v[5] = -std::numeric_limits<float>::infinity();
    } else {
      v[0] = down(b.lo.x - margin_), v[1] = down(b.lo.y - margin_), v[2] = down(b.lo.z - margin_);
      v[3] = up(b.hi.x + margin_), v[4] = up(b.hi.y + margin_), v[5] = up(b.hi.z + margin_);
    }
    if (c == 0) {
      node.lo0x = v[0], node.lo0y = v[1], node.lo0z = v[2];
      node.hi0x = v[3], node.hi0y = v[4], node.hi0z = v[5];
      node.child0 = code;
    } else {
      node.lo1x = v[0], node.lo1y = v[1], node.lo1z = v[2];
      node.hi1x = v[3], node.hi1y = v[4], node.hi1z = v[5];
      node.child1 = code;
    }
  }

 private:
  static float down(double x) {
    float f = static_cast<float>(x);
    if (static_cast<double>(f) > x) f = std::nextafter(f, -std::numeric_limits<float>::infinity());
    return f;
  }
  static float up(double x) {
    float f = static_cast<float>(x);
    if (static_cast<double>(f) < x) f = std::nextafter(f, std::numeric_limits<float>::infinity());
    return f;
  }

  // The volume of points within reach_ of the box: how likely a query visits it.
  double measure(const Bounds3d& b) const {
    if (b.empty) return 0;
    const double x = b.hi.x - b.lo.x, y = b.hi.y - b.lo.y, z = b.hi.z - b.lo.z, r = reach_;
    constexpr double kPi = 3.14159265358979323846;
    return x * y * z + 2 * r * (x * y + y * z + z * x) + kPi * r * r * (x + y + z) +
           4.0 / 3.0 * kPi * r * r * r;
  }

  uint32_t leaf(size_t b, size_t e, int depth) {
    out_->depth = std::max(out_->depth, depth);
    ++out_->leaves;
    return bvh_leaf(static_cast<uint32_t>(b), static_cast<uint32_t>(e - b));
  }

  // Object median along the centres' longest axis.
  size_t median_split(size_t b, size_t e, const Bounds3d& centres) {
    const Vec3d ext = centres.hi - centres.lo;
    const int a = ext.x >= ext.y && ext.x >= ext.z ? 0 : (ext.y >= ext.z ? 1 : 2);
    const size_t mid = b + (e - b) / 2;
    std::nth_element(items_.begin() + b, items_.begin() + mid, items_.begin() + e,
                     [a](const Item& p, const Item& q) {
                       const double u = axis(p.centre, a), v = axis(q.centre, a);
                       return u != v ? u < v : p.triangle < q.triangle;
                     });
    return mid;
  }

  // The cheapest of the binned planes on all three axes; false when the
  // centres coincide (no plane separates them).
  bool sah_split(size_t b, size_t e, const Bounds3d& bounds, const Bounds3d& centres, size_t* mid,
                 double* cost) {
    double best = std::numeric_limits<double>::infinity();
    int best_axis = -1, best_plane = 0;
    const double parent = measure(bounds);
    for (int a = 0; a < 3; ++a) {
      const double lo = axis(centres.lo, a), ext = axis(centres.hi, a) - lo;
      if (!(ext > 0)) continue;
      const double scale = kBins * (1 - 1e-9) / ext;
      Bounds3d bin_box[kBins];
      size_t bin_count[kBins] = {};
      for (size_t i = b; i < e; ++i) {
        const int k = std::min(kBins - 1, static_cast<int>((axis(items_[i].centre, a) - lo) * scale));
        bin_box[k].merge(items_[i].box);
        ++bin_count[k];
      }
      double right_measure[kBins];
      size_t right_count[kBins];
      Bounds3d acc;
      size_t cnt = 0;
      for (int k = kBins - 1; k > 0; --k) {
        acc.merge(bin_box[k]);
        cnt += bin_count[k];
        right_measure[k] = measure(acc);
        right_count[k] = cnt;
      }
      acc = Bounds3d{};
      cnt = 0;
      for (int k = 0; k < kBins - 1; ++k) {
        acc.merge(bin_box[k]);
        cnt += bin_count[k];
        if (cnt == 0 || right_count[k + 1] == 0) continue;
        const double c = kNodeCost + kTriangleCost *
                                         (measure(acc) * double(cnt) +
                                          right_measure[k + 1] * double(right_count[k + 1])) /
                                         parent;
        if (c < best) best = c, best_axis = a, best_plane = k;
      }
    }
    if (best_axis < 0) return false;
    const double lo = axis(centres.lo, best_axis);
    const double scale = kBins * (1 - 1e-9) / (axis(centres.hi, best_axis) - lo);
    auto it = std::partition(items_.begin() + b, items_.begin() + e, [&](const Item& it) {
      return std::min(kBins - 1, static_cast<int>((axis(it.centre, best_axis) - lo) * scale)) <=
             best_plane;
    });
    *mid = static_cast<size_t>(it - items_.begin());
    *cost = best;
    return *mid > b && *mid < e;
  }

  std::vector<Item>& items_;
  double reach_, margin_;
  BvhBuild* out_;
  size_t defer_below_;
  std::vector<Deferred>* deferred_;
};

// A child slot of a binary node: its code and its (float, already rounded) box.
struct Slot {
  uint32_t code;
  float lo[3], hi[3];
};

Slot slot_of(const BvhNode& n, int c) {
  return c == 0 ? Slot{n.child0, {n.lo0x, n.lo0y, n.lo0z}, {n.hi0x, n.hi0y, n.hi0z}}
                : Slot{n.child1, {n.lo1x, n.lo1y, n.lo1z}, {n.hi1x, n.hi1y, n.hi1z}};
}

double surface(const Slot& s) {
  if (!(s.lo[0] <= s.hi[0])) return -1;  // the empty slot
  const double x = double(s.hi[0]) - s.lo[0], y = double(s.hi[1]) - s.lo[1],
               z = double(s.hi[2]) - s.lo[2];
  return x * y + y * z + z * x;
}

// Collapses the binary subtree at `node` into wide nodes: the node's two
// children are opened, largest box first, until four slots are filled or
// only leaves are left; the slots keep their left-to-right order.
uint32_t collapse(const std::vector<BvhNode>& binary, uint32_t node, int depth, BvhBuild* out) {
  Slot slots[4] = {slot_of(binary[node], 0), slot_of(binary[node], 1)};
  int n = 2;
  while (n < 4) {
    int open = -1;
    double largest = -1;
    for (int k = 0; k < n; ++k)
      if (!(slots[k].code & kBvhLeafBit) && surface(slots[k]) > largest) open = k, largest = surface(slots[k]);
    if (open < 0) break;
    const BvhNode& b = binary[slots[open].code];
    for (int k = n; k > open + 1; --k) slots[k] = slots[k - 1];
    slots[open] = slot_of(b, 0);
    slots[open + 1] = slot_of(b, 1);
    ++n;
  }
  const uint32_t index = static_cast<uint32_t>(out->wide.size());
  out->wide.emplace_back();
  uint32_t codes[4];
  for (int k = 0; k < n; ++k) {
    if (slots[k].code & kBvhLeafBit) {
      codes[k] = slots[k].code;
      out->wide_depth = std::max(out->wide_depth, depth + 1);
    } else {
      codes[k] = collapse(binary, slots[k].code, depth + 1, out);
    }
  }
  BvhWideNode& w = out->wide[index];  // after the recursion, which grows the vector
  for (int k = 0; k < 4; ++k) {
    const bool used = k < n;
    const float inf = std::numeric_limits<float>::infinity();
    w.lo_x[k] = used ? slots[k].lo[0] : inf, w.lo_y[k] = used ? slots[k].lo[1] : inf;
    w.lo_z[k] = used ? slots[k].lo[2] : inf;
    w.hi_x[k] = used ? slots[k].hi[0] : -inf, w.hi_y[k] = used ? slots[k].hi[1] : -inf;
    w.hi_z[k] = used ? slots[k].hi[2] : -inf;
    w.child[k] = used ? codes[k] : bvh_leaf(0, 1);
  }
  return index;
}

}  // namespace

BvhBuild build_bvh(const TriangleMesh& mesh, Vec3d origin, double reach, double margin,
                   ThreadPool* pool) {
  BvhBuild out;
  const size_t m = mesh.triangles.size();
  std::vector<Item> items(m);
  for (size_t t = 0; t < m; ++t) {
    Item& it = items[t];
    for (int k = 0; k < 3; ++k) it.box.grow(mesh.corner(t, k) - origin);
    it.centre = (it.box.lo + it.box.hi) * 0.5;
    it.triangle = static_cast<uint32_t>(t);
  }
  // The top levels are built here; below them, ranges of at most `defer`
  // triangles are independent and built on the pool, then appended in order.
  // The threshold does not depend on the threads, so the tree is the same on
  // every machine.
  const size_t defer = std::max<size_t>(4096, m / 256);
  std::vector<Deferred> deferred;
  Builder builder(items, reach, margin, &out, defer, &deferred);
  Bounds3d box, empty;
  // The first node build() makes is the root (index 0); a wall small enough
  // for one leaf gets a root above it whose other slot is never visited.
  const uint32_t top = m ? builder.build(0, m, 0, &box) : bvh_leaf(0, 1);
  if (top & kBvhLeafBit) {
    out.nodes.emplace_back();
    builder.set_child(out.nodes[0], 0, top, box);
    builder.set_child(out.nodes[0], 1, bvh_leaf(0, 1), empty);
  }
  std::vector<BvhBuild> parts(deferred.size());
  std::vector<uint32_t> part_top(deferred.size());
  cpu_parallel_for(pool ? *pool : default_pool(), deferred.size(), [&](uint32_t k) {
    Builder sub(items, reach, margin, &parts[k]);
    Bounds3d unused;
    part_top[k] = sub.build(deferred[k].b, deferred[k].e, deferred[k].depth, &unused);
  }, 1);
  for (size_t k = 0; k < deferred.size(); ++k) {
    const uint32_t offset = static_cast<uint32_t>(out.nodes.size());
    for (BvhNode n : parts[k].nodes) {
      if (!(n.child0 & kBvhLeafBit)) n.child0 += offset;
      if (!(n.child1 & kBvhLeafBit)) n.child1 += offset;
      out.nodes.push_back(n);
    }
    const uint32_t code = part_top[k] & kBvhLeafBit ? part_top[k] : part_top[k] + offset;
    BvhNode& parent = out.nodes[deferred[k].node];
    (deferred[k].slot == 0 ? parent.child0 : parent.child1) = code;
    out.depth = std::max(out.depth, parts[k].depth);
    out.leaves += parts[k].leaves;
  }
  out.wide.reserve(out.nodes.size() / 2 + 1);
  collapse(out.nodes, 0, 0, &out);
  out.order.resize(m);
  for (size_t k = 0; k < m; ++k) out.order[k] = items[k].triangle;
  return out;
}

}  // namespace collido::sim
