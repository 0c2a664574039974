// The generalised winding number of one mesh at many points, each far cheaper
// than winding_number's pass over every triangle, with the same value (to
// rounding). A fill of an open vessel asks it at every clear site of its
// lattice: 2,000 triangles times hundreds of thousands of sites took seconds.
//
// How: the mesh's boundary (its open rims, and edges its faces wind
// inconsistently) gets a cap, a cone of triangles from one point, so that the
// mesh and its cap make a closed surface, whose winding number is a whole
// number everywhere off it. That number needs only an estimate within 1/2: a
// tree of the mesh's triangles (Barill et al. 2018) gives one, each far node
// as the dipole of its summed vector area, with a rigorous bound on its error.
// The mesh's own number is that whole number less the cap's, summed exactly
// over the cap's few triangles. Where the bound cannot settle the whole number
// (a point on a face, or on the cap), the plain sum answers.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "sim/mesh.h"

namespace collido::sim {

class WindingField {
 public:
  // Keeps a reference to `mesh`, which must outlive the field.
  explicit WindingField(const TriangleMesh& mesh);

  // winding_number(mesh, p), to within 1e-12.
  double at(Vec3d p) const;

  // What at() did, for tests and benchmarks.
  struct Work {
    uint64_t points = 0, plain = 0;  // points asked; those the plain sum answered
    uint64_t exact_triangles = 0;    // triangles summed exactly (near leaves and caps)
    uint64_t far_nodes = 0;          // nodes taken as dipoles
  };
  // at(), counting its work into *work.
  double at(Vec3d p, Work* work) const;
  size_t cap_triangles() const { return cap_.size(); }
  size_t triangles() const { return mesh_.triangles.size(); }
  // Whether at() is the plain sum (a mesh whose boundary is as large as itself).
  bool plain() const { return plain_; }

 private:
  struct Node {
    Vec3d centre;          // of the box of its triangles' corners
    double radius = 0;     // the farthest corner from the centre
    Vec3d area{0, 0, 0};   // the sum of its triangles' vector areas (half the cross products)
    double area_abs = 0;   // the sum of their areas
    uint32_t begin = 0, end = 0;  // its triangles, order_[begin, end)
    uint32_t left = 0, right = 0;  // children; 0 for a leaf (the root is nobody's child)
  };
  uint32_t build(uint32_t begin, uint32_t end);

  const TriangleMesh& mesh_;
  std::vector<Node> nodes_;
  std::vector<uint32_t> order_;             // the triangles, each node's contiguous
  std::vector<std::array<Vec3d, 3>> cap_;   // the cone over the boundary, a triangle an edge use
  bool plain_ = false;
};

}  // namespace collido::sim
