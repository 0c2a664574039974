#include "sim/particles.h"
#include "tests/scratch.h"

#include <gtest/gtest.h>

#include <fstream>

namespace collido::sim {
namespace {

std::string write(const std::string& name, const std::string& text) {
  const std::string path = test::scratch_path(name);
  std::ofstream(path) << text;
  return path;
}

TEST(Particles, RandomIsReproducibleAndInsideTheBox) {
  Bounds3d box;
  box.grow({-1, -2, -3});
  box.grow({1, 2, 3});
  Particles a = random_particles(1000, box, 0.5, 1, 42), b = random_particles(1000, box, 0.5, 1, 42);
  EXPECT_EQ(a.x, b.x);
  EXPECT_EQ(a.r, b.r);
  EXPECT_NE(a.x, random_particles(1000, box, 0.5, 1, 43).x);
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_GE(a.x[i], -1);
    EXPECT_LT(a.z[i], 3);
    EXPECT_GE(a.r[i], 0.5);
    EXPECT_LE(a.r[i], 1);
  }
  EXPECT_LE(max_radius(a), 1.0);
}

TEST(Particles, CsvWithHeaderLoads) {
  auto p = load_particles_csv(write("ok.csv", "x,y,z,r\n1,2,3,0.5\n4, 5, 6, 1\n\n"));
  ASSERT_TRUE(p) << p.status().message();
  EXPECT_EQ(p->size(), 2u);
  EXPECT_EQ(p->r[1], 1.0);
}

TEST(Particles, CsvErrorsNameTheLine) {
  auto bad = load_particles_csv(write("bad.csv", "1,2,3,0.5\n1,2,oops,1\n"));
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.status().message().find("line 2"), std::string::npos) << bad.status().message();
  auto neg = load_particles_csv(write("neg.csv", "1,2,3,-1\n"));
  ASSERT_FALSE(neg);
  EXPECT_NE(neg.status().message().find("radius"), std::string::npos);
  auto nan = load_particles_csv(write("nan.csv", "1,nan,3,1\n"));
  ASSERT_FALSE(nan);
  EXPECT_FALSE(load_particles_csv(write("empty.csv", "")));
  EXPECT_FALSE(load_particles_csv("/nonexistent.csv"));
}

}  // namespace
}  // namespace collido::sim
