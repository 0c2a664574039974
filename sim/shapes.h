// Parametric vessels built in code: closed, with outward normals, standing on
// z = 0 around the z axis unless shifted. Also the paper's wall1 and wall2.
#pragma once

#include <string>
#include <vector>

#include "sim/mesh.h"

namespace collido::sim {

enum class Caps { kBoth, kNone, kBottom, kTop };

// Cylinder of radius r and height h (world units), `segments` around; caps are
// fan-triangulated polygons (n - 2 triangles), as in the paper's wall1 (156 triangles).
TriangleMesh make_cylinder(double r, double h, int segments, Caps caps = Caps::kBoth);
// Frustum from radius r_bottom at z = 0 to r_top at z = h; a zero radius makes an apex.
TriangleMesh make_cone(double r_bottom, double r_top, double h, int segments,
                       Caps caps = Caps::kBoth);
// Axis-aligned box sx x sy x sz centred on the z axis, bottom at z = 0.
TriangleMesh make_box(double sx, double sy, double sz);
// Icosphere of radius r centred at (0, 0, r); 20 * 4^subdivisions triangles.
TriangleMesh make_sphere(double r, int subdivisions);
// The paper's wall2 stand-in: a spallation-target-like vessel (body, funnel,
// outlet pipe, and a beam pipe hanging inside), about 1,500 triangles, closed.
TriangleMesh make_wall2();
// Moves every vertex by d (world units).
void translate(TriangleMesh& mesh, Vec3d d);

// Builds a wall from a spec such as "cylinder:r=50,h=100,segments=40", "wall1",
// "box:x=10,y=10,z=5", "sphere:r=5,subdivisions=3", "cone:r1=10,r2=0,h=20,segments=32",
// "funnel:r1=10,r2=40,h=30,segments=64" (an open cone), joined by '+' for unions;
// every shape accepts dx=,dy=,dz= offsets; cylinder, cone and funnel take axis=x|y|z
// (default z; "cylinder:r=5,h=2,axis=y" is a drum on its side, from y = 0 to h).
// Unknown keys and impossible values are errors.
// part_starts, when given, receives each part's first triangle in the union.
Expected<TriangleMesh> make_shape(const std::string& spec,
                                  std::vector<size_t>* part_starts = nullptr);

}  // namespace collido::sim
