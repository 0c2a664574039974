// Turning command-line scene arguments (--wall, --particles) into engine inputs.
#pragma once

#include <string>

#include "sim/detect.h"
#include "sim/mesh.h"

namespace collido::app {

// A wall from a file (STL; other formats through assimp when built) or a
// parametric spec such as "cylinder:r=50,h=100,segments=40" or "wall1".
sim::Expected<sim::TriangleMesh> load_wall(const std::string& spec, sim::MeshReport* report);

}  // namespace collido::app
