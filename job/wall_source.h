// Walls as people bring them: a parametric spec ("wall1", "cylinder:r=50,h=100",
// unions joined by "+") or a mesh file (STL; OBJ, PLY and other formats through
// assimp where the build has it). Shared by `detect`, jobs and the service.
#pragma once

#include <string>

#include "sim/mesh.h"

namespace collido::job {

// A wall from a file or a parametric spec. A spec that names no shape and
// looks like a path is reported as a missing file (not_found).
sim::Expected<sim::TriangleMesh> load_wall(const std::string& spec, sim::MeshReport* report);

// True when `spec` names a parametric wall rather than a file.
bool is_shape_spec(const std::string& spec);

}  // namespace collido::job
