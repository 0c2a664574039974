// Walls from OBJ, PLY, OFF and the other formats assimp reads.
#pragma once

#include <string>

#include "sim/mesh.h"

namespace collido::mesh_import {

// Loads every mesh of the file as one triangle soup, welded and cleaned like STL
// (zero-area triangles dropped and counted). Errors name the file.
sim::Expected<sim::TriangleMesh> import_mesh(const std::string& path, sim::MeshReport* report = nullptr);

}  // namespace collido::mesh_import
