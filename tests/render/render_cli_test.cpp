// `collidoscope render DIR` end to end: a run directory in the engine's format
// in, PNG frames, poster, MP4 and WebM out; bad arguments exit 2.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "app/cli.h"
#include "app/commands.h"
#include "render/render.h"
#include "sim/mesh.h"
#include "sim/shapes.h"
#include "sim/snapshot.h"

namespace collido::app {
namespace {

namespace fs = std::filesystem;

class RenderCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("collido_render_cli_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_ / "run" / "frames");
  }
  void TearDown() override { fs::remove_all(dir_); }

  // A cylinder of radius 10, height 20 at `shift`, and `frames` frames of 150
  // particles falling inside it, positions stored relative to `shift`.
  void write_run(int frames, sim::Vec3d shift = {0, 0, 0}) {
    sim::TriangleMesh wall = sim::make_cylinder(10, 20, 24);
    sim::translate(wall, shift);
    ASSERT_TRUE(sim::save_stl(wall, run() + "/wall.stl"));
    for (int f = 0; f < frames; ++f) {
      sim::Snapshot s;
      s.frame = uint64_t(f);
      s.time = 0.05 * f;
      s.origin = shift;
      s.resize(150);
      for (int i = 0; i < 150; ++i) {
        const double phi = 0.7 * i, rho = 8.0 * std::sqrt((i + 0.5) / 150.0);
        s.x[i] = float(rho * std::cos(phi));
        s.y[i] = float(rho * std::sin(phi));
        s.vz[i] = float(-9.81 * s.time);
        s.z[i] = float(std::max(0.6, 5.0 + 0.1 * i - 4.9 * s.time * s.time));
        s.r[i] = 0.6f;
        s.contact[i] = s.z[i] <= 0.6f;
      }
      ASSERT_TRUE(sim::write_snapshot(sim::snapshot_path(run(), uint64_t(f)), s));
    }
  }
  std::string run() const { return (dir_ / "run").string(); }
  std::string out() const { return (dir_ / "out").string(); }

  fs::path dir_;
};

TEST_F(RenderCliTest, RendersFramesPosterAndBothVideos) {
  write_run(8);
  ASSERT_EQ(cmd_render({run(), "--out", out(), "--width", "160", "--height", "120", "--fps", "8",
                        "--png-every", "4", "--camera", "orbit"}),
            kExitOk);
  render::Image img;
  ASSERT_TRUE(render::read_png(out() + "/poster.png", &img));
  EXPECT_EQ(img.width, 160);
  EXPECT_EQ(img.height, 120);
  EXPECT_TRUE(fs::exists(out() + "/frames/frame_000000.png"));
  EXPECT_TRUE(fs::exists(out() + "/frames/frame_000004.png"));
  EXPECT_FALSE(fs::exists(out() + "/frames/frame_000001.png"));
  for (const char* name : {"/video.mp4", "/video.webm"}) {
    render::VideoInfo info;
    render::Status st = render::probe_video(out() + name, &info);
    ASSERT_TRUE(st) << st.message();
    EXPECT_EQ(info.frames, 8) << name;
    EXPECT_EQ(info.width, 160) << name;
    EXPECT_NEAR(info.duration_s, 1.0, 0.13) << name;
  }
}

// A render replaces the one before it: what the new settings do not make
// (the WebM, frame images) goes, as do a killed writer's temporary files;
// files that are not a render's stay.
TEST_F(RenderCliTest, ARenderReplacesThePreviousOne) {
  write_run(4);
  const std::vector<std::string> small = {"--out", out(), "--width", "96", "--height", "64"};
  std::vector<std::string> first = {run(), "--png-every", "1"};
  first.insert(first.end(), small.begin(), small.end());
  ASSERT_EQ(cmd_render(first), kExitOk);
  ASSERT_TRUE(fs::exists(out() + "/video.webm"));
  ASSERT_TRUE(fs::exists(out() + "/frames/frame_000003.png"));
  std::ofstream(out() + "/video.mp4.tmp-12345-0") << "half";
  std::ofstream(out() + "/notes.txt") << "mine";
  std::vector<std::string> second = {run(), "--png-every", "0", "--video", "mp4"};
  second.insert(second.end(), small.begin(), small.end());
  ASSERT_EQ(cmd_render(second), kExitOk);
  EXPECT_TRUE(fs::exists(out() + "/video.mp4"));
  EXPECT_FALSE(fs::exists(out() + "/video.webm"));
  EXPECT_FALSE(fs::exists(out() + "/frames/frame_000000.png"));
  EXPECT_FALSE(fs::exists(out() + "/video.mp4.tmp-12345-0"));
  EXPECT_TRUE(fs::exists(out() + "/notes.txt"));
}

// A render that fails part way (a damaged frame) leaves the one before it as
// it was: not the frame images it drew before failing, nor a half set of videos.
TEST_F(RenderCliTest, AFailedRenderLeavesThePreviousOne) {
  write_run(4);
  ASSERT_EQ(
      cmd_render({run(), "--out", out(), "--width", "96", "--height", "64", "--png-every", "1"}),
      kExitOk);
  render::Image before;
  ASSERT_TRUE(render::read_png(out() + "/poster.png", &before));
  std::ofstream(sim::snapshot_path(run(), 3), std::ios::trunc) << "not a snapshot";
  EXPECT_NE(
      cmd_render({run(), "--out", out(), "--width", "160", "--height", "120", "--png-every", "1"}),
      kExitOk);
  render::Image after;
  ASSERT_TRUE(render::read_png(out() + "/poster.png", &after));
  EXPECT_EQ(after.width, 96) << "the previous poster";
  EXPECT_EQ(after.rgb, before.rgb);
  for (const char* name : {"/video.mp4", "/video.webm", "/frames/frame_000003.png"})
    EXPECT_TRUE(fs::exists(out() + name)) << name;
  render::Image frame0;
  ASSERT_TRUE(render::read_png(out() + "/frames/frame_000000.png", &frame0));
  EXPECT_EQ(frame0.width, 96) << "frame 0 drawn by the failed render replaced the previous one's";
  EXPECT_FALSE(fs::exists(out() + "/.render-staging"));
}

TEST_F(RenderCliTest, FarFromOriginRendersLikeNearOrigin) {
  // The same scene a million units away: the render origin keeps float
  // precision, so the poster matches the one rendered at the origin.
  write_run(1);
  ASSERT_EQ(cmd_render({run(), "--out", out(), "--width", "160", "--height", "120", "--video",
                        "none", "--png-every", "0", "--no-overlay", "--msaa", "0"}),
            kExitOk);
  render::Image near_img, far_img;
  ASSERT_TRUE(render::read_png(out() + "/poster.png", &near_img));
  fs::remove_all(dir_ / "run");
  fs::create_directories(dir_ / "run" / "frames");
  write_run(1, {1e6, -1e6, 5e5});
  ASSERT_EQ(cmd_render({run(), "--out", out(), "--width", "160", "--height", "120", "--video",
                        "none", "--png-every", "0", "--no-overlay", "--msaa", "0"}),
            kExitOk);
  ASSERT_TRUE(render::read_png(out() + "/poster.png", &far_img));
  int differing = 0;
  for (size_t i = 0; i < near_img.rgb.size(); ++i)
    differing += std::abs(int(near_img.rgb[i]) - int(far_img.rgb[i])) > 8;
  EXPECT_LT(differing, int(near_img.rgb.size() / 100));
}

TEST_F(RenderCliTest, BadArgumentsExitTwo) {
  write_run(1);
  EXPECT_EQ(cmd_render({}), kExitUsage);
  EXPECT_EQ(cmd_render({run(), "--camera", "side"}), kExitUsage);
  EXPECT_EQ(cmd_render({run(), "--color", "rainbow"}), kExitUsage);
  EXPECT_EQ(cmd_render({run(), "--width", "abc"}), kExitUsage);
  EXPECT_EQ(cmd_render({run(), "--width", "161"}), kExitUsage);  // odd, and video is on
  EXPECT_EQ(cmd_render({run(), "--fps", "0"}), kExitUsage);
  EXPECT_EQ(cmd_render({run(), "--bogus"}), kExitUsage);
  EXPECT_EQ(cmd_render({run(), run()}), kExitUsage);
  EXPECT_EQ(cmd_render({"--help"}), kExitOk);
  EXPECT_EQ(bench_render({"--counts", "ten"}), kExitUsage);
  EXPECT_EQ(bench_render({"--help"}), kExitOk);
}

TEST_F(RenderCliTest, MissingOrCorruptFramesFailWithoutLeavingVideo) {
  // Missing and corrupt frames are bad input: exit 2, the one rule of app/cli.h.
  EXPECT_EQ(cmd_render({(dir_ / "nowhere").string()}), kExitUsage);
  write_run(3);
  {
    std::ofstream f(sim::snapshot_path(run(), 2), std::ios::binary | std::ios::trunc);
    f << "CLSNAP01 but then nothing";
  }
  EXPECT_EQ(cmd_render({run(), "--out", out(), "--width", "64", "--height", "48"}), kExitUsage);
  EXPECT_FALSE(fs::exists(out() + "/video.mp4"));
  EXPECT_FALSE(fs::exists(out() + "/video.webm"));
  for (const auto& e : fs::directory_iterator(out()))
    EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << e.path();
}

}  // namespace
}  // namespace collido::app
