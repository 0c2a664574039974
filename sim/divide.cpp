#include "sim/divide.h"

#include <algorithm>
#include <cmath>

namespace collido::sim {

const char* to_string(DivisionMethod m) {
  switch (m) {
    case DivisionMethod::kGravity: return "gravity";
    case DivisionMethod::kCircumcircle: return "circumcircle";
    case DivisionMethod::kMidpoint4: return "midpoint4";
  }
  return "?";
}

namespace {

using Tri = std::array<Vec3d, 3>;

double edge2(const Tri& t, int k) { return norm2(t[(k + 1) % 3] - t[k]); }

int longest_edge(const Tri& t) {
  double e0 = edge2(t, 0), e1 = edge2(t, 1), e2 = edge2(t, 2);
  return e0 >= e1 && e0 >= e2 ? 0 : (e1 >= e2 ? 1 : 2);
}

// Bisects the longest edge until every edge is <= max_edge (paper 3.3.2's binary
// tree, depth first), handing each final piece to leaf in a stable left-to-right order.
template <class Leaf>
void bisect_walk(const Tri& root, double max_edge, Leaf&& leaf) {
  const double limit2 = max_edge * max_edge;
  std::vector<Tri> stack{root};
  while (!stack.empty()) {
    Tri t = stack.back();
    stack.pop_back();
    int k = longest_edge(t);
    if (edge2(t, k) <= limit2) {
      leaf(t);
      continue;
    }
    const Vec3d a = t[k], b = t[(k + 1) % 3], c = t[(k + 2) % 3];
    const Vec3d m = (a + b) * 0.5;
    // Push the second half first so pieces come out in a stable left-to-right order.
    stack.push_back({m, b, c});
    stack.push_back({a, m, c});
  }
}

// Splits every edge at its midpoint until every edge is <= max_edge, handing
// each final piece to leaf (depth first, a stable order).
template <class Leaf>
void midpoint4_walk(const Tri& root, double max_edge, Leaf&& leaf) {
  const double limit2 = max_edge * max_edge;
  std::vector<Tri> stack{root};
  while (!stack.empty()) {
    Tri t = stack.back();
    stack.pop_back();
    if (edge2(t, longest_edge(t)) <= limit2) {
      leaf(t);
      continue;
    }
    const Vec3d ab = (t[0] + t[1]) * 0.5, bc = (t[1] + t[2]) * 0.5, ca = (t[2] + t[0]) * 0.5;
    stack.push_back({ab, bc, ca});
    stack.push_back({ca, bc, t[2]});
    stack.push_back({ab, t[1], bc});
    stack.push_back({t[0], ab, ca});
  }
}

// Index of the obtuse corner, or -1 for non-obtuse triangles.
int obtuse_corner(const Tri& t) {
  for (int k = 0; k < 3; ++k) {
    const Vec3d u = t[(k + 1) % 3] - t[k], v = t[(k + 2) % 3] - t[k];
    if (dot(u, v) < 0) return k;
  }
  return -1;
}

// Splits an obtuse triangle by the altitude from its obtuse corner into two right
// triangles, handed to leaf.
template <class Leaf>
void split_obtuse(const Tri& t, int k, Leaf&& leaf) {
  const Vec3d o = t[k], b = t[(k + 1) % 3], c = t[(k + 2) % 3];
  const Vec3d bc = c - b;
  const double s = dot(o - b, bc) / norm2(bc);
  const Vec3d foot = b + bc * s;
  leaf(Tri{o, b, foot});
  leaf(Tri{o, foot, c});
}

// One triangle's pieces under a method, each handed to leaf in divide()'s order:
// the one statement of each method's rule, for dividing and for counting.
template <class Leaf>
void divide_triangle(const Tri& root, DivisionMethod method, double r_max, Leaf&& leaf) {
  switch (method) {
    case DivisionMethod::kGravity: bisect_walk(root, r_max, leaf); break;
    case DivisionMethod::kMidpoint4: midpoint4_walk(root, r_max, leaf); break;
    case DivisionMethod::kCircumcircle:
      // Bisected to edges of sqrt(3) r_max, each obtuse piece then split in two.
      bisect_walk(root, std::sqrt(3.0) * r_max, [&](const Tri& p) {
        const int k = obtuse_corner(p);
        if (k >= 0)
          split_obtuse(p, k, leaf);
        else
          leaf(p);
      });
      break;
  }
}

// Smallest sphere through... the circumsphere for non-obtuse triangles; for a
// degenerate or obtuse one, the sphere on its longest edge, which contains it.
void circumsphere(const Tri& t, Vec3d& centre, double& radius) {
  const Vec3d a = t[0], b = t[1] - a, c = t[2] - a;
  const Vec3d n = cross(b, c);
  const double n2 = norm2(n);
  const int k = longest_edge(t);
  const double longest2 = edge2(t, k);
  if (obtuse_corner(t) >= 0 || n2 <= 1e-20 * longest2 * longest2) {
    centre = (t[k] + t[(k + 1) % 3]) * 0.5;
    radius = 0.5 * std::sqrt(longest2);
    return;
  }
  const Vec3d off = (cross(n, b) * norm2(c) + cross(c, n) * norm2(b)) * (1.0 / (2.0 * n2));
  centre = a + off;
  radius = std::max({length(t[0] - centre), length(t[1] - centre), length(t[2] - centre)});
}

void centroid_sphere(const Tri& t, Vec3d& centre, double& radius) {
  centre = (t[0] + t[1] + t[2]) * (1.0 / 3.0);
  radius = std::max({length(t[0] - centre), length(t[1] - centre), length(t[2] - centre)});
}

}  // namespace

double midpoint4_piece_count(const TriangleMesh& mesh, double r_max) {
  const double limit2 = r_max * r_max;  // midpoint4()'s stopping rule
  double count = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Tri tri{mesh.corner(t, 0), mesh.corner(t, 1), mesh.corner(t, 2)};
    double n = 1;
    for (double e2 = edge2(tri, longest_edge(tri)); e2 > limit2; e2 *= 0.25) n *= 4;
    count += n;
  }
  return count;
}

double division_piece_count(const TriangleMesh& mesh, DivisionMethod method, double r_max) {
  if (method == DivisionMethod::kMidpoint4) return midpoint4_piece_count(mesh, r_max);
  double count = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Tri root{mesh.corner(t, 0), mesh.corner(t, 1), mesh.corner(t, 2)};
    divide_triangle(root, method, r_max, [&](const Tri&) { count += 1; });
  }
  return count;
}

DividedMesh divide(const TriangleMesh& mesh, DivisionMethod method, double r_max) {
  DividedMesh out;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Tri root{mesh.corner(t, 0), mesh.corner(t, 1), mesh.corner(t, 2)};
    divide_triangle(root, method, r_max, [&](const Tri& p) {
      Vec3d c;
      double r;
      if (method == DivisionMethod::kCircumcircle)
        circumsphere(p, c, r);
      else
        centroid_sphere(p, c, r);
      out.pieces.push_back(p);
      out.original.push_back(static_cast<uint32_t>(t));
      out.sphere_centre.push_back(c);
      out.sphere_radius.push_back(r);
      out.max_sphere_radius = std::max(out.max_sphere_radius, r);
      out.max_edge = std::max(out.max_edge, std::sqrt(edge2(p, longest_edge(p))));
    });
  }
  return out;
}

double division_area_error(const TriangleMesh& mesh, const DividedMesh& divided) {
  double before = mesh_area(mesh), after = 0;
  for (const auto& p : divided.pieces) after += triangle_area(p[0], p[1], p[2]);
  return before > 0 ? std::fabs(after - before) / before : std::fabs(after);
}

}  // namespace collido::sim
