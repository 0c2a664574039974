// Triangle meshes: the walls particles collide with. Loaded from STL, built from
// parametric shapes (sim/shapes.h), welded, cleaned, exported.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "sim/hd.h"
#include "sim/status.h"

namespace collido::sim {

// An indexed triangle mesh in double precision (world units, e.g. mm).
struct TriangleMesh {
  std::vector<Vec3d> vertices;
  std::vector<std::array<uint32_t, 3>> triangles;
  // For every triangle, its 0-based index in the file it came from (or its
  // creation index for generated meshes). Contacts are reported with these ids.
  std::vector<uint32_t> source_ids;

  size_t triangle_count() const { return triangles.size(); }
  Vec3d corner(size_t tri, int k) const { return vertices[triangles[tri][k]]; }
};

struct Bounds3d {
  Vec3d lo{0, 0, 0}, hi{0, 0, 0};
  bool empty = true;
  void grow(Vec3d p);
  void merge(const Bounds3d& b) {  // the union (an empty b changes nothing)
    if (!b.empty) grow(b.lo), grow(b.hi);
  }
  Vec3d center() const { return (lo + hi) * 0.5; }
  Vec3d extent() const { return hi - lo; }
};

// What loading and cleaning did to a mesh; printed by the CLI, stored by the service.
struct MeshReport {
  std::string format;               // "stl-ascii", "stl-binary", "generated", ...
  size_t triangles_in = 0;          // triangles read from the source
  size_t dropped_zero_area = 0;     // degenerate triangles removed
  size_t vertices_before_weld = 0;  // 3 x triangles_in for STL
  size_t vertices_after_weld = 0;
};

// Area of one triangle, in squared world units, computed in double.
double triangle_area(Vec3d a, Vec3d b, Vec3d c);
// Total area of a mesh, squared world units.
double mesh_area(const TriangleMesh& mesh);
Bounds3d mesh_bounds(const TriangleMesh& mesh);

// Builds an indexed mesh from a triangle soup (3 corners per triangle), merging
// vertices closer than weld_tolerance (world units) and dropping triangles whose
// area is <= area_epsilon (relative to the squared bounding-box diagonal).
TriangleMesh weld_soup(const std::vector<std::array<Vec3d, 3>>& soup,
                       const std::vector<uint32_t>& source_ids, double weld_tolerance,
                       MeshReport* report);

// Loads an STL file (ASCII or binary, told apart by the 84 + 50 N size rule).
// Errors name the file and, for bad data, the triangle.
Expected<TriangleMesh> load_stl(const std::string& path, MeshReport* report = nullptr);
// Parses STL bytes already in memory; `name` is used in error messages.
Expected<TriangleMesh> parse_stl(const std::string& bytes, const std::string& name,
                                 MeshReport* report = nullptr);
// A binary STL with per-face normals, in memory (the bytes save_stl writes).
std::string stl_bytes(const TriangleMesh& mesh);
// Writes a binary STL with per-face normals (through a temporary name).
Status save_stl(const TriangleMesh& mesh, const std::string& path);

// Appends b's triangles to a (a union of shapes as one wall; no boolean CSG).
void append_mesh(TriangleMesh& a, const TriangleMesh& b);
// The triangles [begin, end) of a mesh (inside), or all the others (!inside),
// with only the vertices they use, in their order.
TriangleMesh mesh_range(const TriangleMesh& m, size_t begin, size_t end, bool inside);

// True when every edge is shared by exactly two triangles with opposite orientation.
bool is_closed_manifold(const TriangleMesh& mesh);
// Signed volume (positive when normals point outward), cubic world units.
double signed_volume(const TriangleMesh& mesh);
// Generalised winding number of p (sum of the triangles' signed solid angles
// over 4 pi): 1 inside a closed outward mesh, 0 outside, fractional near holes.
// A pass over every triangle; WindingField (sim/winding_field.h) answers many
// points of one mesh faster.
double winding_number(const TriangleMesh& mesh, Vec3d p);

// The signed solid angles of triangles seen from one point, summed exactly as
// far as rounding lets (no atan2 a triangle: see mesh.cpp), as a winding number.
class SolidAngleSum {
 public:
  // Adds the triangle whose corners lie at a, b and c from the point; false
  // when the point lies in the triangle's plane to 1e-9 of its distances to
  // the corners (on the triangle or beside it), where a surface's winding
  // number jumps.
  bool add(Vec3d a, Vec3d b, Vec3d c);
  // The sum over 4 pi.
  double winding() const;

 private:
  double re_ = 1, im_ = 0;  // the product of the triangles' factors, rescaled by powers of two
  long turns_ = 0;          // full turns made by the product
  double halves_ = 0;       // factors on the negative real axis (the point inside a face): +-pi
};

}  // namespace collido::sim
