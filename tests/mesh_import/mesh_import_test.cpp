#include "mesh_import/mesh_import.h"
#include "tests/scratch.h"

#include <gtest/gtest.h>

#include <fstream>

namespace collido::mesh_import {
namespace {

std::string write(const std::string& name, const std::string& text) {
  const std::string path = test::scratch_path(name);
  std::ofstream(path) << text;
  return path;
}

TEST(MeshImport, ObjQuadsAreTriangulatedAndWelded) {
  // A unit cube of six quads.
  const std::string obj =
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
      "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
  sim::MeshReport rep;
  auto m = import_mesh(write("cube.obj", obj), &rep);
  ASSERT_TRUE(m) << m.status().message();
  EXPECT_EQ(m->triangles.size(), 12u);
  EXPECT_EQ(m->vertices.size(), 8u);
  EXPECT_TRUE(sim::is_closed_manifold(*m));
  EXPECT_NEAR(sim::mesh_area(*m), 6.0, 1e-9);
}

TEST(MeshImport, PlyLoads) {
  const std::string ply =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  auto m = import_mesh(write("tri.ply", ply));
  ASSERT_TRUE(m) << m.status().message();
  EXPECT_EQ(m->triangles.size(), 1u);
}

TEST(MeshImport, BadFilesAreClearErrors) {
  auto missing = import_mesh("/nonexistent/wall.obj");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.status().message().find("/nonexistent/wall.obj"), std::string::npos);
  auto junk = import_mesh(write("junk.ply", "ply\nthis is not a ply file\n"));
  EXPECT_FALSE(junk);
  auto lines = import_mesh(write("lines.obj", "v 0 0 0\nv 1 0 0\nl 1 2\n"));
  EXPECT_FALSE(lines);
}

}  // namespace
}  // namespace collido::mesh_import
