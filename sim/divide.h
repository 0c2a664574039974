// Triangle division (paper 3.3): cut wall triangles until each piece fits a
// bounding sphere of the particles' scale. Every piece keeps the index of its
// original triangle, so contacts are reported against originals.
#pragma once

#include <string>
#include <vector>

#include "sim/mesh.h"

namespace collido::sim {

enum class DivisionMethod {
  kGravity,       // longest-edge bisection to edges <= r_max; sphere at the centroid
  kCircumcircle,  // bisection to edges <= sqrt(3) r_max, obtuse pieces split by the altitude; circumsphere
  kMidpoint4,     // four-way split at edge midpoints to edges <= r_max; sphere at the centroid
};

const char* to_string(DivisionMethod m);

struct DividedMesh {
  std::vector<std::array<Vec3d, 3>> pieces;  // corners, world units
  std::vector<uint32_t> original;            // index of the original triangle in the mesh
  std::vector<Vec3d> sphere_centre;          // bounding sphere of each piece
  std::vector<double> sphere_radius;
  double max_sphere_radius = 0;
  double max_edge = 0;
};

// Divides every triangle of `mesh` for particles of largest radius r_max (world units).
// Pieces are produced per original triangle, in order, so each original's pieces are contiguous.
DividedMesh divide(const TriangleMesh& mesh, DivisionMethod method, double r_max);

// The number of pieces divide(mesh, kMidpoint4, r_max) makes, without making them: a
// four-way split halves every edge, so a triangle becomes 4^levels pieces, levels being
// how often its longest edge halves before it fits. A double, because it can be
// astronomical (a large wall for small particles) where dividing would never finish.
double midpoint4_piece_count(const TriangleMesh& mesh, double r_max);

// The number of pieces divide(mesh, method, r_max) makes, exactly, without making
// them: the bisections are walked and their leaves counted (time in proportion to
// the pieces, no memory for them); midpoint4's is midpoint4_piece_count.
double division_piece_count(const TriangleMesh& mesh, DivisionMethod method, double r_max);

// Relative difference between the total area of the pieces and of the mesh,
// both summed in double (paper Eq. 6).
double division_area_error(const TriangleMesh& mesh, const DividedMesh& divided);

}  // namespace collido::sim
