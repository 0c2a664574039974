#include "sim/narrow_phase.h"

#include <gtest/gtest.h>

#include <cmath>

#include "sim/particles.h"

namespace collido::sim {
namespace {

// Brute force: the minimum over a fine barycentric sampling of the triangle plus
// an exact search along each edge; an upper bound that converges to the truth.
double brute_dist2(Vec3d p, Vec3d a, Vec3d b, Vec3d c) {
  double best = 1e300;
  const int n = 400;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; i + j <= n; ++j) {
      double u = double(i) / n, v = double(j) / n;
      Vec3d q = a + (b - a) * u + (c - a) * v;
      best = std::min(best, norm2(q - p));
    }
  for (auto [s, e] : {std::pair{a, b}, std::pair{b, c}, std::pair{c, a}})
    best = std::min(best, norm2(closest_on_segment(p, s, e) - p));
  return best;
}

TEST(NarrowPhase, SevenRegionsMatchBruteForce) {
  const Vec3d a{0, 0, 0}, b{4, 0, 0}, c{1, 3, 0};
  // One probe per Voronoi region: three vertices, three edges, the face; above and below the plane.
  const Vec3d probes[] = {{-1, -1, 0.5}, {5, -1, -0.5}, {1, 4, 0.3}, {2, -2, 0.2},
                          {3.5, 2.5, -1}, {-1, 1.5, 0.1}, {1.5, 1, 2}, {1.5, 1, -2}};
  for (const Vec3d& p : probes) {
    const double exact = point_triangle_dist2(p, a, b, c);
    EXPECT_NEAR(std::sqrt(exact), std::sqrt(brute_dist2(p, a, b, c)), 2e-3) << p.x << "," << p.y << "," << p.z;
    const Vec3d q = closest_point_on_triangle(p, a, b, c);
    EXPECT_NEAR(norm2(q - p), exact, 1e-9);
  }
}

TEST(NarrowPhase, RandomTrianglesMatchBruteForce) {
  SplitMix64 rng(7);
  for (int trial = 0; trial < 300; ++trial) {
    auto rv = [&] { return Vec3d{rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-2, 2)}; };
    Vec3d a = rv(), b = rv(), c = rv(), p = rv() * 1.5;
    double exact = std::sqrt(point_triangle_dist2(p, a, b, c));
    double brute = std::sqrt(brute_dist2(p, a, b, c));
    // The brute force samples the surface: it can only be above the truth, by the sampling step.
    EXPECT_LE(exact, brute + 1e-12);
    EXPECT_NEAR(exact, brute, 2e-2);
    // The float version agrees with double to float rounding.
    float ef = std::sqrt(point_triangle_dist2(cast3<float>(p), cast3<float>(a), cast3<float>(b), cast3<float>(c)));
    EXPECT_NEAR(ef, exact, 1e-5);
  }
}

TEST(NarrowPhase, DegenerateTrianglesAreFinite) {
  const Vec3d p{0.3, 1, 0.2};
  // Zero-length edge: a segment in disguise.
  const Vec3d a{0, 0, 0}, b{0, 0, 0}, c{1, 0, 0};
  double d = point_triangle_dist2(p, a, b, c);
  EXPECT_TRUE(std::isfinite(d));
  EXPECT_NEAR(d, norm2(closest_on_segment(p, a, c) - p), 1e-12);
  // All three corners equal: a point.
  EXPECT_NEAR(point_triangle_dist2(p, a, a, a), norm2(p), 1e-12);
  // Collinear corners with the middle one outside the first two.
  const Vec3d e{2, 0, 0}, f{-1, 0, 0};
  d = point_triangle_dist2(Vec3d{3, 1, 0}, a, e, f);
  EXPECT_NEAR(d, 2.0, 1e-12);  // nearest point (2, 0, 0)
  // Same in float, where rounding decides most.
  float df = point_triangle_dist2(Vec3f{0.3f, 1, 0.2f}, Vec3f{0, 0, 0}, Vec3f{0, 0, 0}, Vec3f{1, 0, 0});
  EXPECT_TRUE(std::isfinite(df));
  EXPECT_NEAR(df, 1.04f, 1e-5f);
}

TEST(NarrowPhase, SliversAgreeWithDouble) {
  SplitMix64 rng(11);
  for (int trial = 0; trial < 2000; ++trial) {
    // A needle 10 long and 1e-4 wide, and a point anywhere near it.
    Vec3d a{0, 0, 0}, b{10, 0, 0}, c{rng.uniform(0, 10), 1e-4 * rng.uniform(-1, 1), 0};
    Vec3d p{rng.uniform(-1, 11), rng.uniform(-1, 1), rng.uniform(-1, 1)};
    double exact = std::sqrt(point_triangle_dist2(p, a, b, c));
    float f = std::sqrt(point_triangle_dist2(cast3<float>(p), cast3<float>(a), cast3<float>(b), cast3<float>(c)));
    EXPECT_NEAR(f, exact, 1e-5) << trial;
  }
}

TEST(TriangleBox, SeparatingAxesAgreeWithSampling) {
  SplitMix64 rng(3);
  int overlaps = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    auto rv = [&] { return Vec3d{rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-2, 2)}; };
    Vec3d a = rv(), b = rv(), c = rv();
    const Vec3d centre{0, 0, 0}, half{0.5, 0.7, 0.3};
    bool sat = triangle_box_overlap(a, b, c, centre, half);
    // Any sampled triangle point inside the box proves overlap.
    bool sampled = false;
    const int n = 60;
    for (int i = 0; i <= n && !sampled; ++i)
      for (int j = 0; i + j <= n && !sampled; ++j) {
        Vec3d q = a + (b - a) * (double(i) / n) + (c - a) * (double(j) / n);
        sampled = std::fabs(q.x) <= half.x && std::fabs(q.y) <= half.y && std::fabs(q.z) <= half.z;
      }
    if (sampled) {
      EXPECT_TRUE(sat) << trial;
    }
    overlaps += sat;
  }
  EXPECT_GT(overlaps, 100);
  EXPECT_LT(overlaps, 2900);
  // A triangle far from the box, and one that only touches a face.
  EXPECT_FALSE(triangle_box_overlap(Vec3d{5, 5, 5}, Vec3d{6, 5, 5}, Vec3d{5, 6, 5}, Vec3d{0, 0, 0}, Vec3d{1, 1, 1}));
  EXPECT_TRUE(triangle_box_overlap(Vec3d{1, -5, -5}, Vec3d{1, 5, -5}, Vec3d{1, 0, 5}, Vec3d{0, 0, 0}, Vec3d{1, 1, 1}));
  // A large triangle cutting diagonally through the box without a corner inside it.
  EXPECT_TRUE(triangle_box_overlap(Vec3d{-10, -10, 0}, Vec3d{10, -10, 0}, Vec3d{0, 10, 0}, Vec3d{0, 0, 0}, Vec3d{1, 1, 1}));
}

}  // namespace
}  // namespace collido::sim
