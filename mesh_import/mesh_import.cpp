#include "mesh_import/mesh_import.h"

#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <assimp/Importer.hpp>
#include <cmath>

namespace collido::mesh_import {

sim::Expected<sim::TriangleMesh> import_mesh(const std::string& path, sim::MeshReport* report) {
  Assimp::Importer importer;
  // Triangulate polygons; keep vertices unjoined so welding and zero-area
  // dropping follow the same rules as for STL.
  const aiScene* scene = importer.ReadFile(path, aiProcess_Triangulate | aiProcess_PreTransformVertices);
  if (!scene || !scene->mRootNode) return sim::parse_error(path + ": " + importer.GetErrorString());
  std::vector<std::array<sim::Vec3d, 3>> soup;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* mesh = scene->mMeshes[m];
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      if (face.mNumIndices != 3) continue;  // points and lines are not walls
      std::array<sim::Vec3d, 3> tri;
      for (int k = 0; k < 3; ++k) {
        // Assimp checks its indices only when asked to validate; a damaged file may hold any.
        if (face.mIndices[k] >= mesh->mNumVertices)
          return sim::parse_error(path + ": triangle " + std::to_string(soup.size()) +
                                  " names vertex " + std::to_string(face.mIndices[k]) + " of " +
                                  std::to_string(mesh->mNumVertices));
        const aiVector3D& v = mesh->mVertices[face.mIndices[k]];
        tri[k] = {v.x, v.y, v.z};
        if (!std::isfinite(tri[k].x) || !std::isfinite(tri[k].y) || !std::isfinite(tri[k].z))
          return sim::parse_error(path + ": triangle " + std::to_string(soup.size()) + " has a non-finite coordinate");
      }
      soup.push_back(tri);
    }
  }
  if (soup.empty()) return sim::parse_error(path + ": the file holds no triangles");
  sim::MeshReport local;
  sim::TriangleMesh out = sim::weld_soup(soup, {}, 0.0, &local);
  local.format = "assimp";
  if (report) *report = local;
  if (out.triangles.empty()) return sim::parse_error(path + ": all triangles have zero area");
  return out;
}

}  // namespace collido::mesh_import
