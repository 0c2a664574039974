// `collidoscope render DIR`: a run directory's snapshots into PNG frames, a poster
// and browser-playable video; `collidoscope bench render`: renderer and encoder
// speed on a synthetic vessel.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include <unistd.h>

#include "common/stopwatch.h"
#include "app/cli.h"
#include "app/commands.h"
#include "job/render_run.h"
#include "render/render.h"

namespace collido::app {
namespace {

namespace fs = std::filesystem;
using Clock = SteadyClock;


const std::vector<FlagSpec> kRenderFlags = {
    {"out", true, "output directory (default DIR/render)"},
    {"width", true, "frame width in pixels, even (default 1280)"},
    {"height", true, "frame height in pixels, even (default 720)"},
    {"fps", true, "video frame rate (default 30)"},
    {"png-every", true, "write every K-th frame as PNG, 0 for none (default 10)"},
    {"camera", true, "front | iso | top | orbit (default iso)"},
    {"color", true, "speed | contact (default speed)"},
    {"wall", true, "glass | cutaway | hidden (default glass)"},
    {"speed-max", true, "speed at the top of the colour map (default: from the frames)"},
    {"video", true, "comma list of mp4, webm, gif, or none (default mp4,webm)"},
    {"msaa", true, "multisample anti-aliasing of the wall edges: 0 (default) or 2..16"},
    {"no-overlay", false, "no time/frame text and no legend"},
    {"no-cull", false, "draw every particle (the occlusion test never changes the image)"},
    {"help", false, "show this help"},
};

}  // namespace

bool parse_video_list(const std::string& list, job::RenderSettings* rs, std::string* error) {
  rs->mp4 = rs->webm = rs->gif = false;
  if (list == "none") return true;
  size_t start = 0;
  while (start <= list.size()) {
    const size_t comma = std::min(list.find(',', start), list.size());
    const std::string item = list.substr(start, comma - start);
    if (item == "mp4")
      rs->mp4 = true;
    else if (item == "webm")
      rs->webm = true;
    else if (item == "gif")
      rs->gif = true;
    else {
      *error = "--video takes a comma list of mp4, webm and gif, or none; got '" + list + "'";
      return false;
    }
    start = comma + 1;
  }
  return true;
}

int cmd_render(const Args& args) {
  std::string err;
  auto p = parse_args(args, kRenderFlags, &err);
  if (!p) return usage_error("render", err);
  if (p->has("help")) {
    print_help(
        "usage: collidoscope render DIR [--out OUTDIR] [--width 1280 --height 720 --fps 30 "
        "--png-every K --camera front|iso|top|orbit --color speed|contact]\n\n"
        "Reads DIR/wall.stl and DIR/frames/frame_NNNNNN.snap and writes OUTDIR/frames/*.png,\n"
        "OUTDIR/poster.png, OUTDIR/video.mp4 (H.264), OUTDIR/video.webm (VP9) and, with\n"
        "--video including gif, OUTDIR/loop.gif.",
        kRenderFlags);
    return kExitOk;
  }
  if (p->positional().size() != 1)
    return usage_error("render", p->positional().empty() ? "the run directory DIR is required"
                                                         : "one run directory expected, got '" +
                                                               p->positional()[1] + "' as well");
  const std::string run_dir = p->positional()[0];

  job::RenderSettings rs;
  if (!p->get_int_in("width", 1280, job::kMinFrameSide, job::kMaxFrameSide, &rs.width, &err) ||
      !p->get_int_in("height", 720, job::kMinFrameSide, job::kMaxFrameSide, &rs.height, &err) ||
      !p->get_int_in("fps", 30, 1, 240, &rs.fps, &err) ||
      !p->get_int_in("png-every", 10, 0, 1000000000, &rs.png_every, &err) ||
      !p->get_int_in("msaa", 0, 0, 16, &rs.msaa, &err))
    return usage_error("render", err);
  rs.camera = p->get("camera", "iso");
  rs.color = p->get("color", "speed");
  rs.wall = p->get("wall", "glass");
  rs.overlay = !p->has("no-overlay");
  rs.cull = !p->has("no-cull");
  if (!parse_video_list(p->get("video", "mp4,webm"), &rs, &err)) return usage_error("render", err);
  if (p->has("speed-max")) {
    rs.speed_max = float(p->get_double("speed-max", 0, &err));
    if (!err.empty()) return usage_error("render", err);
    if (!(rs.speed_max > 0)) return usage_error("render", "--speed-max must be positive");
  }
  if (Status st = job::validate(rs); !st) return usage_error("render", st.message());
  const std::string out_dir = p->get("out", (fs::path(run_dir) / "render").string());

  const bool tty = stderr_is_terminal();
  const auto t_start = Clock::now();
  job::RenderOutcome out;
  auto progress = [&](size_t done, size_t total) {
    if (tty)
      std::fprintf(stderr, "\rrender: frame %zu/%zu (%.0f ms/frame)", done, total,
                   1e3 * seconds_since(t_start) / double(done));
  };
  const Status st = job::render_run(run_dir, out_dir, rs, progress, nullptr, &out);
  if (tty) std::fprintf(stderr, "\n");
  if (!st) {
    std::fprintf(stderr, "collidoscope render: %s\n", st.message().c_str());
    return exit_code(st);
  }
  const double n = double(out.frames);
  std::printf("rendered %zu frames at %dx%d with %s\n", out.frames, rs.width, rs.height,
              out.gl.c_str());
  // Encoding runs beside rendering, so the parts add up to more than the total.
  std::printf(
      "  render %.1f ms/frame, encode %.1f ms/frame, png %.1f ms/frame (in parallel), "
      "total %.1f s = %.1f ms/frame\n",
      1e3 * out.render_s / n, 1e3 * out.encode_s / n, 1e3 * out.png_s / n, out.total_s,
      1e3 * out.total_s / n);
  std::printf("  poster   %s\n", out.poster.c_str());
  if (out.pngs) std::printf("  frames   %s/frames/ (%zu PNG)\n", out_dir.c_str(), out.pngs);
  if (!out.mp4.empty()) std::printf("  mp4      %s (%s)\n", out.mp4.c_str(), out.mp4_encoder.c_str());
  if (!out.webm.empty())
    std::printf("  webm     %s (%s)\n", out.webm.c_str(), out.webm_encoder.c_str());
  if (!out.gif.empty()) std::printf("  gif      %s\n", out.gif.c_str());
  return kExitOk;
}

// ---------------------------------------------------------------------------
// bench render

namespace {

const std::vector<FlagSpec> kBenchFlags = {
    {"width", true, "frame width in pixels (default 1280)"},
    {"height", true, "frame height in pixels (default 720)"},
    {"counts", true, "particle counts, comma separated (default 1e4,1e5,1e6)"},
    {"frames", true, "timed frames per count, after one warm-up frame (default 10)"},
    {"encode-frames", true, "frames encoded per codec (default 90)"},
    {"msaa", true, "multisample anti-aliasing samples (default 0, as `render`)"},
    {"seed", true, "random seed (default 1)"},
    {"save", true, "also write the last frame of each count to DIR/bench_N.png"},
    {"no-cull", false, "draw every particle, to measure what occlusion culling saves"},
    {"help", false, "show this help"},
};

constexpr double kPi = 3.14159265358979323846;

// The paper's wall1: a closed cylinder, radius 50, height 100, 40 segments,
// 156 triangles (80 on the side, 38 in each cap fan), outward normals.
render::WallMesh bench_vessel(float radius, float height, int segments) {
  render::WallMesh w;
  for (int i = 0; i < segments; ++i) {
    const float a = float(2 * kPi * i / segments);
    const float x = radius * std::cos(a), y = radius * std::sin(a);
    w.vertices.insert(w.vertices.end(), {x, y, 0.f, x, y, height});
  }
  auto bottom = [](int i) { return uint32_t(2 * i); };
  auto top = [](int i) { return uint32_t(2 * i + 1); };
  for (int i = 0; i < segments; ++i) {
    const int j = (i + 1) % segments;
    w.indices.insert(w.indices.end(), {bottom(i), bottom(j), top(j), bottom(i), top(j), top(i)});
  }
  for (int i = 1; i + 1 < segments; ++i) {
    w.indices.insert(w.indices.end(), {bottom(0), bottom(i + 1), bottom(i)});
    w.indices.insert(w.indices.end(), {top(0), top(i), top(i + 1)});
  }
  return w;
}

// n random particles filling the vessel, denser towards the bottom as if
// settling, radii up to about half the mean spacing (at most 1, the paper's
// r_max), speeds growing with height.
void bench_particles(size_t n, float radius, float height, uint32_t seed, render::Snapshot* s) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  const double volume = kPi * radius * radius * height;
  const float r_max = float(std::min(1.0, 0.5 * std::cbrt(volume / double(n))));
  s->positions.resize(3 * n);
  s->radius.resize(n);
  s->scalar.resize(n);
  s->contact.resize(n);
  for (size_t i = 0; i < n; ++i) {
    const float r = r_max * (0.6f + 0.4f * u(rng));
    const float rho = (radius - r) * std::sqrt(u(rng));
    const float phi = float(2 * kPi) * u(rng);
    const float z = r + (height - 2 * r) * std::pow(u(rng), 1.6f);
    s->positions[3 * i] = rho * std::cos(phi);
    s->positions[3 * i + 1] = rho * std::sin(phi);
    s->positions[3 * i + 2] = z;
    s->radius[i] = r;
    s->scalar[i] = 4.f * z / height + 0.8f * u(rng);
    s->contact[i] = (rho > radius - 1.05f * r || z < 1.05f * r) ? 1 : 0;
  }
  s->total_particles = 0;
}

}  // namespace

int bench_render(const Args& args) {
  std::string err;
  auto p = parse_args(args, kBenchFlags, &err);
  if (!p) return usage_error("bench render", err);
  if (p->has("help")) {
    print_help(
        "usage: collidoscope bench render [--counts 1e4,1e5,1e6] [--frames 10]\n\n"
        "Times rendering (upload, draw, readback, overlay) per frame for each particle\n"
        "count in the paper's wall1 cylinder, then H.264 and VP9 encoding per frame.",
        kBenchFlags);
    return kExitOk;
  }
  if (!p->positional().empty())
    return usage_error("bench render", "unexpected argument '" + p->positional()[0] + "'");
  render::RenderOptions ro;
  int frames = 10, encode_frames = 90, seed = 1;
  if (!p->get_int_in("width", 1280, job::kMinFrameSide, job::kMaxFrameSide, &ro.width, &err) ||
      !p->get_int_in("height", 720, job::kMinFrameSide, job::kMaxFrameSide, &ro.height, &err) ||
      !p->get_int_in("frames", 10, 1, 100000, &frames, &err) ||
      !p->get_int_in("encode-frames", 90, 1, 100000, &encode_frames, &err) ||
      !p->get_int_in("msaa", 0, 0, 16, &ro.msaa_samples, &err) ||
      !p->get_int_in("seed", 1, 0, 1 << 30, &seed, &err))
    return usage_error("bench render", err);
  if (ro.width % 2 || ro.height % 2)
    return usage_error("bench render", "--width and --height must be even (video)");
  std::vector<size_t> counts;
  {
    const std::string list = p->get("counts", "1e4,1e5,1e6");
    size_t start = 0;
    while (start <= list.size()) {
      const size_t comma = std::min(list.find(',', start), list.size());
      const std::string item = list.substr(start, comma - start);
      char* end = nullptr;
      const double v = std::strtod(item.c_str(), &end);
      if (item.empty() || *end != '\0' || !(v >= 1) || v > 5e7)
        return usage_error("bench render",
                           "--counts expects numbers in 1..5e7, got '" + item + "'");
      counts.push_back(size_t(v));
      start = comma + 1;
    }
  }

  ro.camera = render::CameraPreset::kOrbit;
  ro.cull_hidden = !p->has("no-cull");
  ro.color_min = 0;
  ro.color_max = 5.f;
  render::Status st;
  auto renderer = render::Renderer::create(ro, &st);
  if (!renderer) {
    std::fprintf(stderr, "collidoscope bench render: %s\n", st.message().c_str());
    return kExitFailure;
  }
  const char* lp = std::getenv("LP_NUM_THREADS");
  std::printf("renderer: %s, LP_NUM_THREADS=%s, %u hardware threads, %dx%d, msaa %d\n",
              renderer->gl_description().c_str(), lp ? lp : "unset",
              std::thread::hardware_concurrency(), ro.width, ro.height, ro.msaa_samples);

  const float kRadius = 50, kHeight = 100;
  render::Snapshot scene;
  scene.wall = bench_vessel(kRadius, kHeight, 40);
  render::Image image;
  std::vector<render::Image> clip;  // frames of the 1e5 scene (or the middle count) to encode

  std::printf(
      "\n| particles | drawn after culling | render ms/frame | cull | upload | draw | readback "
      "| overlay | frames/s |\n");
  std::printf("|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  const size_t clip_count = counts[counts.size() / 2];
  for (size_t n : counts) {
    bench_particles(n, kRadius, kHeight, uint32_t(seed), &scene);
    scene.bounds = render::compute_bounds(scene);
    render::FrameTiming sum;
    size_t drawn = 0;
    for (int f = -1; f < frames; ++f) {  // frame -1 warms up (shader JIT, buffer sizes)
      scene.frame = uint64_t(f + 1);
      scene.time = 0.01 * (f + 1);
      renderer->set_orbit_deg(3.0 * (f + 1));
      if (!(st = renderer->render(scene, &image))) {
        std::fprintf(stderr, "collidoscope bench render: %s\n", st.message().c_str());
        return kExitFailure;
      }
      if (f < 0) continue;
      const auto& t = renderer->last_timing();
      sum.cull_ms += t.cull_ms, sum.upload_ms += t.upload_ms, sum.draw_ms += t.draw_ms;
      drawn += t.particles_drawn;
      sum.readback_ms += t.readback_ms, sum.overlay_ms += t.overlay_ms;
    }
    const double k = 1.0 / frames;
    std::printf("| %zu | %zu | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f |\n", n,
                drawn / size_t(frames), sum.total_ms() * k, sum.cull_ms * k, sum.upload_ms * k,
                sum.draw_ms * k, sum.readback_ms * k, sum.overlay_ms * k,
                1e3 / (sum.total_ms() * k));
    std::fflush(stdout);
    if (p->has("save")) {
      const std::string path = p->get("save") + "/bench_" + std::to_string(n) + ".png";
      if (!(st = render::write_png(path, image)))
        std::fprintf(stderr, "collidoscope bench render: %s\n", st.message().c_str());
    }
    if (n == clip_count) {
      // 30 different frames (a slow orbit) so the encoders see real motion.
      for (int f = 0; f < 30; ++f) {
        renderer->set_orbit_deg(2.0 * f);
        scene.frame = uint64_t(f);
        if (!(st = renderer->render(scene, &image))) {
          std::fprintf(stderr, "collidoscope bench render: %s\n", st.message().c_str());
          return kExitFailure;
        }
        clip.push_back(image);
      }
    }
  }

  const fs::path tmp =
      fs::temp_directory_path() / ("collido_bench_render_" + std::to_string(::getpid()));
  std::error_code ec;
  fs::create_directories(tmp, ec);
  std::printf("\n| output (%zu-particle frames) | encoder | ms/frame | frames/s | file size |\n",
              clip_count);
  std::printf("|---|---|---:|---:|---:|\n");
  for (render::VideoCodec codec : {render::VideoCodec::kH264, render::VideoCodec::kVP9}) {
    render::VideoOptions vo;
    vo.codec = codec;
    vo.width = ro.width;
    vo.height = ro.height;
    const std::string path =
        (tmp / (std::string("bench.") + render::video_extension(codec))).string();
    const auto t0 = Clock::now();
    auto writer = render::VideoWriter::open(path, vo, &st);
    for (int f = 0; writer && st && f < encode_frames; ++f) {
      // Ping-pong through the clip so consecutive frames always differ a little.
      const int period = 2 * int(clip.size()) - 2;
      int idx = period > 0 ? f % period : 0;
      if (idx >= int(clip.size())) idx = period - idx;
      st = writer->add_frame(clip[size_t(idx)]);
    }
    if (writer && st) st = writer->finish();
    if (!writer || !st) {
      std::fprintf(stderr, "collidoscope bench render: %s\n", st.message().c_str());
      fs::remove_all(tmp, ec);
      return kExitFailure;
    }
    const double ms = 1e3 * seconds_since(t0) / encode_frames;
    const auto bytes = fs::file_size(path, ec);
    std::printf("| %s | %s | %.1f | %.1f | %.2f MB |\n",
                codec == render::VideoCodec::kH264 ? "MP4 (H.264)" : "WebM (VP9)",
                writer->encoder_name().c_str(), ms, 1e3 / ms, double(bytes) / 1e6);
    std::fflush(stdout);
  }
  {
    const int n = std::min<int>(10, int(clip.size()));
    const auto t0 = Clock::now();
    for (int f = 0; f < n; ++f)
      if (!(st = render::write_png((tmp / "bench.png").string(), clip[size_t(f)]))) {
        std::fprintf(stderr, "collidoscope bench render: %s\n", st.message().c_str());
        fs::remove_all(tmp, ec);
        return kExitFailure;
      }
    const double ms = 1e3 * seconds_since(t0) / n;
    std::printf("| PNG | libpng | %.1f | %.1f | %.2f MB |\n", ms, 1e3 / ms,
                double(fs::file_size(tmp / "bench.png", ec)) / 1e6);
  }
  fs::remove_all(tmp, ec);
  return kExitOk;
}

}  // namespace collido::app
