// Pixels of known scenes: the particle, the background and the wall where they
// must be; the same scene twice gives the same image; framing and overlay.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>

#include "render/camera.h"
#include "render/colormap.h"
#include "render/render.h"
#include "tests/render/scene_fixtures.h"

namespace collido::render {
namespace {

using testing::cloud_scene;
using testing::flat_options;
using testing::one_particle_scene;

int max_channel_diff(const uint8_t* a, const uint8_t* b) {
  return std::max({std::abs(a[0] - b[0]), std::abs(a[1] - b[1]), std::abs(a[2] - b[2])});
}

std::unique_ptr<Renderer> make(const RenderOptions& o) {
  Status st;
  auto r = Renderer::create(o, &st);
  EXPECT_TRUE(r) << st.message();
  return r;
}

TEST(RenderTest, CentreIsParticleCornerIsBackgroundWallDiffersFromBoth) {
  RenderOptions o = flat_options(320, 240);
  o.camera = CameraPreset::kFront;
  o.wall = WallStyle::kCutaway;  // the near side removed: nothing in front of the particle
  auto r = make(o);
  ASSERT_TRUE(r);
  Image img;
  ASSERT_TRUE(r->render(one_particle_scene(2.f, 1.f), &img)) << "render failed";
  ASSERT_EQ(img.width, 320);
  ASSERT_EQ(img.height, 240);

  const Rgb8 top = viridis(1.f);  // speed 1 on a 0..1 scale
  const uint8_t particle[3] = {top.r, top.g, top.b};
  const uint8_t background[3] = {10, 20, 30};
  EXPECT_LE(max_channel_diff(img.pixel(160, 120), particle), 2)
      << "centre " << int(img.pixel(160, 120)[0]) << "," << int(img.pixel(160, 120)[1]) << ","
      << int(img.pixel(160, 120)[2]);
  for (auto [x, y] : {std::pair{0, 0}, {319, 0}, {0, 239}, {319, 239}})
    EXPECT_EQ(max_channel_diff(img.pixel(x, y), background), 0) << "corner " << x << "," << y;

  // Along the centre row, right of the particle (radius 2 in a vessel of
  // radius 10 spans about a fifth of the vessel's width), lies the inside of
  // the far wall: neither particle nor background.
  int wall_pixels = 0;
  for (int x = 200; x < 240; ++x) {
    const uint8_t* p = img.pixel(x, 120);
    if (max_channel_diff(p, particle) > 30 && max_channel_diff(p, background) > 30) ++wall_pixels;
  }
  EXPECT_EQ(wall_pixels, 40);
}

TEST(RenderTest, GlassWallTintsButKeepsTheParticleVisible) {
  RenderOptions o = flat_options(320, 240);
  o.camera = CameraPreset::kFront;
  o.wall = WallStyle::kGlass;
  o.shading = true;
  o.color = ColorMode::kContact;
  auto r = make(o);
  ASSERT_TRUE(r);
  Snapshot s = one_particle_scene(2.f, 0.f);
  s.contact = {1};
  Image img;
  ASSERT_TRUE(r->render(s, &img));
  const uint8_t* c = img.pixel(160, 120);
  // Contact orange stays orange behind the glass: red well above blue.
  EXPECT_GT(int(c[0]), int(c[2]) + 60) << int(c[0]) << "," << int(c[1]) << "," << int(c[2]);
}

TEST(RenderTest, SameSceneTwiceGivesTheSameImage) {
  RenderOptions o;
  o.width = 320;
  o.height = 240;
  o.msaa_samples = 0;
  const Snapshot s = cloud_scene(2000, 3);
  Image a, b, c;
  {
    auto r = make(o);
    ASSERT_TRUE(r);
    ASSERT_TRUE(r->render(s, &a));
    ASSERT_TRUE(r->render(s, &b));
  }
  auto r2 = make(o);
  ASSERT_TRUE(r2);
  ASSERT_TRUE(r2->render(s, &c));
  // llvmpipe rasterizes each tile on one thread in submission order, so the
  // result is bit-exact; tolerance 0.
  EXPECT_EQ(a.rgb, b.rgb);
  EXPECT_EQ(a.rgb, c.rgb);
}

TEST(RenderTest, OcclusionCullingDropsHiddenParticlesButNotPixels) {
  RenderOptions o;
  o.width = 320;
  o.height = 240;
  o.msaa_samples = 0;
  o.overlay = false;
  const Snapshot s = cloud_scene(30000, 4);  // dense: most particles are hidden
  Image culled, full;
  auto r = make(o);
  ASSERT_TRUE(r);
  ASSERT_TRUE(r->render(s, &culled));
  const size_t drawn = r->last_timing().particles_drawn;
  o.cull_hidden = false;
  auto r2 = make(o);
  ASSERT_TRUE(r2);
  ASSERT_TRUE(r2->render(s, &full));
  EXPECT_EQ(r2->last_timing().particles_drawn, s.particle_count());
  EXPECT_LT(drawn, s.particle_count() / 2) << "the culler should drop most of a dense cloud";
  // Conservative culling leaves every pixel as it was; drawing order changes,
  // so allow pixels where two spheres meet at exactly the same depth.
  int differing = 0;
  for (size_t i = 0; i < full.rgb.size(); i += 3)
    differing += max_channel_diff(&full.rgb[i], &culled.rgb[i]) > 2;
  EXPECT_LE(differing, int(full.rgb.size() / 3 / 2000)) << "pixels differing: " << differing;
}

TEST(RenderTest, EveryCameraPresetFramesTheWholeVessel) {
  for (CameraPreset cam :
       {CameraPreset::kFront, CameraPreset::kIso, CameraPreset::kTop, CameraPreset::kOrbit}) {
    RenderOptions o = flat_options(320, 240);
    o.camera = cam;
    o.orbit_deg = 100;
    auto r = make(o);
    ASSERT_TRUE(r);
    Image img;
    ASSERT_TRUE(r->render(cloud_scene(300, 1), &img));
    const uint8_t bg[3] = {10, 20, 30};
    int x0 = img.width, x1 = -1, y0 = img.height, y1 = -1;
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x)
        if (max_channel_diff(img.pixel(x, y), bg) > 0) {
          x0 = std::min(x0, x), x1 = std::max(x1, x);
          y0 = std::min(y0, y), y1 = std::max(y1, y);
        }
    SCOPED_TRACE(int(cam));
    // Inside the image with a margin, and filling most of its height.
    EXPECT_GT(x0, 2);
    EXPECT_GT(y0, 2);
    EXPECT_LT(x1, img.width - 3);
    EXPECT_LT(y1, img.height - 3);
    EXPECT_GT(y1 - y0, img.height * 6 / 10);
  }
}

TEST(RenderTest, OverlayDrawsTextAndLegend) {
  RenderOptions o = flat_options(640, 360);
  const Snapshot s = cloud_scene(200, 2);
  Image plain, with_text;
  {
    auto r = make(o);
    ASSERT_TRUE(r);
    ASSERT_TRUE(r->render(s, &plain));
  }
  o.overlay = true;
  auto r = make(o);
  ASSERT_TRUE(r);
  ASSERT_TRUE(r->render(s, &with_text));
  auto changed = [&](int x0, int y0, int x1, int y1) {
    int n = 0;
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x)
        n += max_channel_diff(plain.pixel(x, y), with_text.pixel(x, y)) > 40;
    return n;
  };
  EXPECT_GT(changed(0, 0, 200, 60), 200) << "time/frame text, top left";
  EXPECT_GT(changed(560, 90, 640, 270), 300) << "colour legend, right edge";
}

TEST(RenderTest, MissingFontIsAClearError) {
  RenderOptions o;
  o.width = 64;
  o.height = 64;
  o.font_path = "/nonexistent/font.ttf";
  Status st;
  EXPECT_FALSE(Renderer::create(o, &st));
  EXPECT_NE(st.message().find("/nonexistent/font.ttf"), std::string::npos) << st.message();
}

TEST(RenderTest, InconsistentSnapshotIsRejected) {
  auto r = make(flat_options(64, 64));
  ASSERT_TRUE(r);
  Snapshot s = one_particle_scene(1.f, 1.f);
  s.radius.push_back(1.f);  // two radii, one position
  Image img;
  Status st = r->render(s, &img);
  EXPECT_FALSE(st);
  EXPECT_NE(st.message().find("position"), std::string::npos) << st.message();
  s = one_particle_scene(1.f, 1.f);
  s.wall.indices.push_back(100000);
  s.wall.indices.push_back(0);
  s.wall.indices.push_back(1);
  EXPECT_FALSE(r->render(s, &img));
}

TEST(RenderTest, EmptySceneRendersBackgroundOnly) {
  auto r = make(flat_options(64, 48));
  ASSERT_TRUE(r);
  Image img;
  ASSERT_TRUE(r->render(Snapshot{}, &img));
  for (int y = 0; y < 48; ++y)
    for (int x = 0; x < 64; ++x) ASSERT_EQ(img.pixel(x, y)[2], 30);
}

TEST(CameraTest, FramedBoxProjectsInsideTheView) {
  Bounds b;
  b.lo[0] = -50, b.lo[1] = -50, b.lo[2] = 0;
  b.hi[0] = 50, b.hi[1] = 50, b.hi[2] = 100;
  for (float az : {0.f, 35.f, 90.f}) {
    for (float el : {0.f, 30.f, 90.f}) {
      const CameraSetup cam = frame_bounds(b, az, el, 30.f, 16.f / 9.f, 0.9f, false);
      const Mat4 vp = cam.proj * cam.view;
      float max_abs = 0;
      for (int c = 0; c < 8; ++c) {
        const float p[4] = {(c & 1) ? 50.f : -50.f, (c & 2) ? 50.f : -50.f, (c & 4) ? 100.f : 0.f,
                            1.f};
        float q[4] = {0, 0, 0, 0};
        for (int r = 0; r < 4; ++r)
          for (int k = 0; k < 4; ++k) q[r] += vp.m[k * 4 + r] * p[k];
        ASSERT_GT(q[3], 0.f);
        for (int k = 0; k < 3; ++k) {
          EXPECT_LE(std::fabs(q[k] / q[3]), 1.f) << "az " << az << " el " << el;
          if (k < 2) max_abs = std::max(max_abs, std::fabs(q[k] / q[3]));
        }
      }
      // Tight: some corner reaches the 90 % fill line.
      EXPECT_NEAR(max_abs, 0.9f, 0.01f) << "az " << az << " el " << el;
    }
  }
}

TEST(ColormapTest, ViridisEndsAndMonotoneLightness) {
  const Rgb8 lo = viridis(0.f), hi = viridis(1.f);
  EXPECT_EQ(lo.r, 68);
  EXPECT_EQ(lo.g, 1);
  EXPECT_EQ(lo.b, 84);
  EXPECT_EQ(hi.r, 253);
  EXPECT_EQ(hi.g, 231);
  EXPECT_EQ(hi.b, 37);
  // Perceptual maps grow in lightness; the luma of viridis rises throughout.
  float prev = -1;
  for (int i = 0; i < 256; i += 8) {
    const Rgb8 c = viridis_table()[i];
    const float y = 0.2126f * c.r + 0.7152f * c.g + 0.0722f * c.b;
    EXPECT_GT(y, prev) << i;
    prev = y;
  }
  EXPECT_EQ(viridis(-1.f).r, lo.r);  // clamped
  EXPECT_EQ(viridis(2.f).g, hi.g);
}

}  // namespace
}  // namespace collido::render
