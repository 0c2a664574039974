// Video and PNG outputs decode back through libav/libpng to what was written.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "render/render.h"
#include "tests/render/scene_fixtures.h"

namespace collido::render {
namespace {

namespace fs = std::filesystem;

class VideoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("collido_video_test_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Renders `frames` frames of a particle crossing the vessel into a video;
  // keeps the first frame in first_.
  void write_video(VideoCodec codec, int frames, int fps, const std::string& path,
                   int fps_divisor = 1) {
    RenderOptions o;
    o.width = 320;
    o.height = 240;
    o.msaa_samples = 0;
    Status st;
    auto r = Renderer::create(o, &st);
    ASSERT_TRUE(r) << st.message();
    VideoOptions vo;
    vo.codec = codec;
    vo.width = 320;
    vo.height = 240;
    vo.fps = fps;
    vo.fps_divisor = fps_divisor;
    auto w = VideoWriter::open(path, vo, &st);
    ASSERT_TRUE(w) << st.message();
    Snapshot s = testing::one_particle_scene(1.5f, 0.5f);
    Image img;
    for (int f = 0; f < frames; ++f) {
      s.positions[0] = -8.f + 16.f * f / frames;
      s.frame = f;
      s.time = double(f) / fps;
      ASSERT_TRUE(r->render(s, &img));
      if (f == 0) first_ = img;
      ASSERT_TRUE(st = w->add_frame(img)) << st.message();
    }
    EXPECT_FALSE(fs::exists(path)) << "the file appears only when finished";
    ASSERT_TRUE(st = w->finish()) << st.message();
    EXPECT_EQ(w->frames_written(), frames);
  }

  // Mean absolute difference per channel between the decoded first frame and
  // the rendered one: catches wrong colour matrices, ranges and flipped rows.
  double first_frame_error(const std::string& path) {
    Image decoded;
    Status st = read_video_frame(path, 0, &decoded);
    EXPECT_TRUE(st) << st.message();
    if (decoded.rgb.size() != first_.rgb.size()) return 1e9;
    double sum = 0;
    for (size_t i = 0; i < decoded.rgb.size(); ++i)
      sum += std::abs(int(decoded.rgb[i]) - int(first_.rgb[i]));
    return sum / double(decoded.rgb.size());
  }

  fs::path dir_;
  Image first_;
};

TEST_F(VideoTest, Mp4H264DecodesToTheFramesWritten) {
  const std::string path = (dir_ / "clip.mp4").string();
  write_video(VideoCodec::kH264, 15, 30, path);
  VideoInfo info;
  Status st = probe_video(path, &info);
  ASSERT_TRUE(st) << st.message();
  EXPECT_EQ(info.codec, "h264");
  EXPECT_NE(info.container.find("mp4"), std::string::npos) << info.container;
  EXPECT_EQ(info.width, 320);
  EXPECT_EQ(info.height, 240);
  EXPECT_EQ(info.pixel_format, "yuv420p");
  EXPECT_EQ(info.frames, 15);
  EXPECT_NEAR(info.duration_s, 0.5, 1.0 / 30 + 1e-6);
  EXPECT_NEAR(info.fps, 30.0, 0.01);
  EXPECT_TRUE(info.index_at_front) << "+faststart puts moov before mdat";
  EXPECT_LT(first_frame_error(path), 3.0);
}

TEST_F(VideoTest, WebmVp9DecodesToTheFramesWritten) {
  const std::string path = (dir_ / "clip.webm").string();
  write_video(VideoCodec::kVP9, 12, 24, path);
  VideoInfo info;
  Status st = probe_video(path, &info);
  ASSERT_TRUE(st) << st.message();
  EXPECT_EQ(info.codec, "vp9");
  EXPECT_NE(info.container.find("webm"), std::string::npos) << info.container;
  EXPECT_EQ(info.width, 320);
  EXPECT_EQ(info.height, 240);
  EXPECT_EQ(info.pixel_format, "yuv420p");
  EXPECT_EQ(info.frames, 12);
  EXPECT_NEAR(info.duration_s, 0.5, 1.0 / 24 + 1e-6);
  EXPECT_LT(first_frame_error(path), 3.0);
}

// A GIF keeping every second frame of a 25 fps clip plays at 12.5 frames a
// second: its centisecond delays alternate so that the clip keeps its length
// (a rate rounded to 13 played 4 % fast).
TEST_F(VideoTest, GifKeepsAFractionalFrameRate) {
  const std::string path = (dir_ / "loop.gif").string();
  write_video(VideoCodec::kGif, 25, 25, path, /*fps_divisor=*/2);
  VideoInfo info;
  Status st = probe_video(path, &info);
  ASSERT_TRUE(st) << st.message();
  EXPECT_EQ(info.codec, "gif");
  EXPECT_EQ(info.frames, 25);
  EXPECT_NEAR(info.duration_s, 2.0, 0.011) << "25 frames at 12.5 a second";
  VideoOptions bad;
  bad.codec = VideoCodec::kGif;
  bad.fps = 10;
  bad.fps_divisor = 0;
  EXPECT_FALSE(VideoWriter::open((dir_ / "bad.gif").string(), bad, &st));
  EXPECT_NE(st.message().find("fps_divisor"), std::string::npos) << st.message();
}

TEST_F(VideoTest, OddSizeAndWrongFrameSizeAreErrors) {
  Status st;
  VideoOptions vo;
  vo.width = 321;
  vo.height = 240;
  EXPECT_FALSE(VideoWriter::open((dir_ / "odd.mp4").string(), vo, &st));
  EXPECT_NE(st.message().find("even"), std::string::npos) << st.message();

  vo.width = 320;
  auto w = VideoWriter::open((dir_ / "ok.mp4").string(), vo, &st);
  ASSERT_TRUE(w) << st.message();
  Image small;
  small.resize(160, 120);
  EXPECT_FALSE(w->add_frame(small));
  w.reset();  // abandoned: no file, no temporary left behind
  EXPECT_TRUE(fs::is_empty(dir_));
}

TEST_F(VideoTest, PosterPngDecodesToTheSamePixels) {
  RenderOptions o;
  o.width = 320;
  o.height = 240;
  Status st;
  auto r = Renderer::create(o, &st);
  ASSERT_TRUE(r) << st.message();
  Image img, back;
  ASSERT_TRUE(r->render(testing::cloud_scene(500, 5), &img));
  const std::string path = (dir_ / "poster.png").string();
  ASSERT_TRUE(st = write_png(path, img)) << st.message();
  ASSERT_TRUE(st = read_png(path, &back)) << st.message();
  EXPECT_EQ(back.width, 320);
  EXPECT_EQ(back.height, 240);
  EXPECT_EQ(back.rgb, img.rgb);
  // Only the PNG itself remains (written through a temporary name).
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 1);
}

TEST_F(VideoTest, ReadingANonPngFails) {
  const std::string path = (dir_ / "fake.png").string();
  std::ofstream(path) << "not a png";
  Image img;
  Status st = read_png(path, &img);
  EXPECT_FALSE(st);
  EXPECT_NE(st.message().find(path), std::string::npos) << st.message();
}

}  // namespace
}  // namespace collido::render
