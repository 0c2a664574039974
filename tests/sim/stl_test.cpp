#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>

#include "sim/mesh.h"
#include "sim/shapes.h"
#include "tests/scratch.h"

namespace collido::sim {
namespace {

const std::string kData = COLLIDO_TEST_DATA;

std::string binary_stl(const std::vector<std::array<float, 9>>& tris, const char* header = "binary") {
  std::string s(80, '\0');
  std::memcpy(&s[0], header, std::strlen(header));
  uint32_t n = static_cast<uint32_t>(tris.size());
  s.append(reinterpret_cast<const char*>(&n), 4);
  for (const auto& t : tris) {
    float rec[12] = {0, 0, 1, t[0], t[1], t[2], t[3], t[4], t[5], t[6], t[7], t[8]};
    s.append(reinterpret_cast<const char*>(rec), 48);
    s.append(2, '\0');
  }
  return s;
}

const std::vector<std::array<float, 9>> kQuad = {{0, 0, 0, 1, 0, 0, 1, 1, 0}, {0, 0, 0, 1, 1, 0, 0, 1, 0}};

TEST(Stl, AsciiLoadsAndWelds) {
  const std::string text =
      "solid quad\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n   vertex 1 1 0\n"
      "  endloop\n endfacet\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 1 0\n"
      "   vertex 0 1 0\n  endloop\n endfacet\nendsolid quad\n";
  MeshReport rep;
  auto m = parse_stl(text, "quad.stl", &rep);
  ASSERT_TRUE(m) << m.status().message();
  EXPECT_EQ(rep.format, "stl-ascii");
  EXPECT_EQ(m->triangles.size(), 2u);
  EXPECT_EQ(m->vertices.size(), 4u);  // six corners welded into four
  EXPECT_NEAR(mesh_area(*m), 1.0, 1e-12);
}

TEST(Stl, BinaryLoads) {
  MeshReport rep;
  auto m = parse_stl(binary_stl(kQuad), "quad.stl", &rep);
  ASSERT_TRUE(m) << m.status().message();
  EXPECT_EQ(rep.format, "stl-binary");
  EXPECT_EQ(m->triangles.size(), 2u);
  EXPECT_EQ(m->vertices.size(), 4u);
}

TEST(Stl, BinaryWhoseHeaderSaysSolidLoadsAsBinary) {
  MeshReport rep;
  auto m = parse_stl(binary_stl(kQuad, "solid but really binary"), "tricky.stl", &rep);
  ASSERT_TRUE(m) << m.status().message();
  EXPECT_EQ(rep.format, "stl-binary");
  // And the real file from trimesh.
  auto real = load_stl(kData + "/meshes/plate_holes_trimesh_binary_solid_header.stl", &rep);
  ASSERT_TRUE(real) << real.status().message();
  EXPECT_EQ(rep.format, "stl-binary");
  EXPECT_EQ(rep.triangles_in, 1252u);
}

TEST(Stl, TruncatedBinaryNamesFileAndTriangle) {
  std::string s = binary_stl(kQuad);
  s.resize(s.size() - 30);
  auto m = parse_stl(s, "cut.stl");
  ASSERT_FALSE(m);
  EXPECT_NE(m.status().message().find("cut.stl"), std::string::npos);
  EXPECT_NE(m.status().message().find("truncated"), std::string::npos);
  EXPECT_NE(m.status().message().find("triangle 1"), std::string::npos) << m.status().message();
  auto tiny = parse_stl(std::string(40, 'x'), "tiny.stl");
  ASSERT_FALSE(tiny);
  EXPECT_NE(tiny.status().message().find("truncated"), std::string::npos);
  // One whose header says "solid" is still read as the binary file it is,
  // not as text whose error would quote its bytes.
  s = binary_stl(kQuad, "solid by SolidWorks");
  s.pop_back();
  m = parse_stl(s, "cut_solid.stl");
  ASSERT_FALSE(m);
  EXPECT_NE(m.status().message().find("the header announces 2 triangles"), std::string::npos)
      << m.status().message();
}

TEST(Stl, TruncatedAsciiNamesLineAndTriangle) {
  const std::string text = "solid t\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n";
  auto m = parse_stl(text, "cut_ascii.stl");
  ASSERT_FALSE(m);
  EXPECT_NE(m.status().message().find("cut_ascii.stl"), std::string::npos);
  EXPECT_NE(m.status().message().find("triangle 0"), std::string::npos) << m.status().message();
  // Cut between two facets: refused, not loaded with the rest of its wall missing.
  const std::string facet =
      " facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n   vertex 0 1 0\n"
      "  endloop\n endfacet\n";
  auto between = parse_stl("solid t\n" + facet + facet, "cut_between.stl");
  ASSERT_FALSE(between);
  EXPECT_NE(between.status().message().find("no 'endsolid'"), std::string::npos)
      << between.status().message();
  EXPECT_TRUE(parse_stl("solid t\n" + facet + "endsolid t\n", "whole.stl"));
  // Bytes an error quotes are printable: a token of control bytes is escaped.
  auto junk = parse_stl("solid t\n\x01\x02\xff\n", "junk.stl");
  ASSERT_FALSE(junk);
  EXPECT_NE(junk.status().message().find("\\x01\\x02\\xff"), std::string::npos)
      << junk.status().message();
}

TEST(Stl, NanIsRejectedWithTriangleIndex) {
  auto tris = kQuad;
  tris[1][4] = std::numeric_limits<float>::quiet_NaN();
  auto m = parse_stl(binary_stl(tris), "nan.stl");
  ASSERT_FALSE(m);
  EXPECT_NE(m.status().message().find("nan.stl: triangle 1"), std::string::npos) << m.status().message();
  const std::string text =
      "solid q\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex nan 0 0\nvertex 1 1 0\nendloop\nendfacet\nendsolid\n";
  auto a = parse_stl(text, "nan_ascii.stl");
  ASSERT_FALSE(a);
  EXPECT_NE(a.status().message().find("non-finite"), std::string::npos) << a.status().message();
  auto inf = parse_stl(std::string(text).replace(text.find("nan"), 3, "inf"), "inf.stl");
  EXPECT_FALSE(inf);
}

TEST(Stl, EmptyFilesAreErrors) {
  auto m = parse_stl("", "empty.stl");
  ASSERT_FALSE(m);
  EXPECT_NE(m.status().message().find("empty"), std::string::npos);
  auto none = parse_stl(binary_stl({}), "zero.stl");
  ASSERT_FALSE(none);
  EXPECT_NE(none.status().message().find("no triangles"), std::string::npos);
  auto missing = load_stl("/nonexistent/none.stl");
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.status().code(), ErrorCode::kNotFound);  // bad input, not an I/O failure
}

TEST(Stl, ZeroAreaTrianglesAreDroppedAndCounted) {
  auto tris = kQuad;
  tris.push_back({0, 0, 0, 1, 1, 0, 2, 2, 0});  // collinear
  tris.push_back({3, 3, 3, 3, 3, 3, 4, 4, 4});  // repeated corner
  MeshReport rep;
  auto m = parse_stl(binary_stl(tris), "degenerate.stl", &rep);
  ASSERT_TRUE(m);
  EXPECT_EQ(rep.dropped_zero_area, 2u);
  EXPECT_EQ(m->triangles.size(), 2u);
  EXPECT_EQ(m->source_ids, (std::vector<uint32_t>{0, 1}));
}

// Zero area is judged against each triangle's own size: a millimetre facet
// beside a stray facet ten kilometres away is kept (against the mesh's box it
// counted as zero area and was dropped), and a collinear one far out is still dropped.
TEST(Stl, ZeroAreaIsRelativeToTheTriangleNotTheMesh) {
  auto tris = kQuad;
  for (auto& t : tris)
    for (float& c : t) c *= 1e-3f;                                        // a 1 mm square
  tris.push_back({1e4f, 1e4f, 0, 1e4f + 1, 1e4f, 0, 1e4f, 1e4f + 1, 0});  // a stray facet
  tris.push_back({1e4f, 0, 0, 1e4f + 1, 0, 0, 1e4f + 2, 0, 0});           // collinear, far out
  MeshReport rep;
  auto m = parse_stl(binary_stl(tris), "stray.stl", &rep);
  ASSERT_TRUE(m) << m.status().message();
  EXPECT_EQ(rep.dropped_zero_area, 1u);
  EXPECT_EQ(m->source_ids, (std::vector<uint32_t>{0, 1, 2}));
  EXPECT_NEAR(mesh_area(*m), 1e-6 + 0.5, 1e-9);
}

TEST(Stl, MultiSolidAsciiAndRealFiles) {
  struct Case {
    const char* file;
    size_t triangles;
    const char* format;
  } cases[] = {{"triangle_with_two_solids_assimp.stl", 2, "stl-ascii"},
               {"sphere_with_hole_assimp.stl", 285, "stl-ascii"},
               {"teapot_trimesh.stl", 894, "stl-binary"},
               {"3dsmax_export_assimp.stl", 2000, "stl-binary"},
               {"wuson_assimp.stl", 3732, "stl-binary"}};
  for (const auto& c : cases) {
    MeshReport rep;
    auto m = load_stl(kData + "/meshes/" + c.file, &rep);
    ASSERT_TRUE(m) << c.file << ": " << m.status().message();
    EXPECT_EQ(rep.triangles_in, c.triangles) << c.file;
    EXPECT_EQ(rep.format, c.format) << c.file;
    EXPECT_EQ(m->triangles.size() + rep.dropped_zero_area, c.triangles) << c.file;
    // Closed or connected meshes share corners; the two-solid file's triangles are apart.
    if (c.triangles > 2) {
      EXPECT_LT(rep.vertices_after_weld, rep.vertices_before_weld) << c.file;
    }
  }
}

TEST(Stl, SaveRoundTrip) {
  TriangleMesh wall = make_cylinder(50, 100, 40);
  const std::string path = test::scratch_path("wall1_roundtrip.stl");
  ASSERT_TRUE(save_stl(wall, path));
  auto back = load_stl(path);
  ASSERT_TRUE(back);
  EXPECT_EQ(back->triangles.size(), 156u);
  EXPECT_EQ(back->vertices.size(), wall.vertices.size());
  EXPECT_NEAR(mesh_area(*back), mesh_area(wall), 1e-7 * mesh_area(wall));  // float coordinates
  EXPECT_TRUE(is_closed_manifold(*back));
}

// Fuzzing light: random mutations of valid files never crash and always
// either load or explain themselves.
TEST(Stl, MutatedInputsNeverCrash) {
  std::ifstream in(kData + "/meshes/sphere_with_hole_assimp.stl", std::ios::binary);
  const std::string ascii((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_FALSE(ascii.empty());  // else the ASCII half would fuzz nothing
  const std::string binary = binary_stl(kQuad);
  uint64_t state = 12345;
  auto next = [&] { return state = state * 6364136223846793005ull + 1442695040888963407ull; };
  for (int trial = 0; trial < 2000; ++trial) {
    std::string s = (trial % 2) ? ascii : binary;
    const int edits = 1 + next() % 8;
    for (int e = 0; e < edits && !s.empty(); ++e) {
      const size_t at = next() % s.size();
      switch (next() % 3) {
        case 0: s[at] = static_cast<char>(next()); break;
        case 1: s.erase(at, 1 + next() % 16); break;
        default: s.resize(at); break;
      }
    }
    auto m = parse_stl(s, "fuzz.stl");
    if (!m) {
      EXPECT_FALSE(m.status().message().empty());
    } else {
      for (const auto& v : m->vertices) EXPECT_TRUE(std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z));
    }
  }
}

}  // namespace
}  // namespace collido::sim
