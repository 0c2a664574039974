// `collidoscope render DIR`: a run directory's snapshots into PNG frames, a poster
// and browser-playable video; `collidoscope bench render`: renderer and encoder
// speed on a synthetic vessel.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <mutex>
#include <random>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include <unistd.h>

#include "app/cli.h"
#include "app/commands.h"
#include "render/render.h"
#include "sim/mesh.h"
#include "sim/snapshot.h"

namespace collido::app {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

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
    {"video", true, "mp4,webm | mp4 | webm | none (default mp4,webm)"},
    {"msaa", true, "multisample anti-aliasing of the wall edges: 0 (default) or 2..16"},
    {"no-overlay", false, "no time/frame text and no legend"},
    {"no-cull", false, "draw every particle (the occlusion test never changes the image)"},
    {"help", false, "show this help"},
};

struct FrameFile {
  uint64_t index;
  std::string path;
};

// The frames of a run, ordered by frame index (not by name, so frame 1000000
// comes after 999999).
std::vector<FrameFile> list_frames(const std::string& run_dir, std::string* error) {
  std::vector<FrameFile> out;
  const fs::path dir = fs::path(run_dir) / "frames";
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    *error = dir.string() + " is not a directory (expected DIR/frames/frame_NNNNNN.snap)";
    return out;
  }
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.size() < 12 || name.compare(0, 6, "frame_") != 0 ||
        name.compare(name.size() - 5, 5, ".snap") != 0)
      continue;
    const std::string digits = name.substr(6, name.size() - 11);
    if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos) continue;
    out.push_back({std::strtoull(digits.c_str(), nullptr, 10), entry.path().string()});
  }
  if (ec) *error = "cannot list " + dir.string() + ": " + ec.message();
  std::sort(out.begin(), out.end(),
            [](const FrameFile& a, const FrameFile& b) { return a.index < b.index; });
  return out;
}

// The wall in render coordinates: world minus the render origin, in float.
render::WallMesh to_render_wall(const sim::TriangleMesh& mesh, sim::Vec3d origin) {
  render::WallMesh w;
  w.vertices.reserve(mesh.vertices.size() * 3);
  for (const auto& v : mesh.vertices) {
    w.vertices.push_back(float(v.x - origin.x));
    w.vertices.push_back(float(v.y - origin.y));
    w.vertices.push_back(float(v.z - origin.z));
  }
  w.indices.reserve(mesh.triangles.size() * 3);
  for (const auto& t : mesh.triangles) w.indices.insert(w.indices.end(), t.begin(), t.end());
  return w;
}

// Particles of one engine snapshot into the render snapshot (the wall and the
// bounds of *out are left as they are). Speed is |v| in world units/s.
void fill_particles(const sim::Snapshot& s, sim::Vec3d origin, render::Snapshot* out) {
  const size_t n = s.size();
  // The offset between the two origins is applied in double, then the small
  // relative positions are rounded to float once.
  const double ox = s.origin.x - origin.x, oy = s.origin.y - origin.y, oz = s.origin.z - origin.z;
  out->positions.resize(3 * n);
  out->radius.resize(n);
  out->scalar.resize(n);
  out->contact.assign(s.contact.begin(), s.contact.end());
  for (size_t i = 0; i < n; ++i) {
    out->positions[3 * i] = float(ox + s.x[i]);
    out->positions[3 * i + 1] = float(oy + s.y[i]);
    out->positions[3 * i + 2] = float(oz + s.z[i]);
    out->radius[i] = s.r[i];
    out->scalar[i] = std::sqrt(s.vx[i] * s.vx[i] + s.vy[i] * s.vy[i] + s.vz[i] * s.vz[i]);
  }
  out->time = s.time;
  out->frame = s.frame;
}

// Top of the colour map: the largest 99.5th-percentile speed over up to 16
// frames spread through the run, so a few outliers do not wash out the rest
// and the scale stays the same in every frame of the video.
float estimate_speed_max(const std::vector<FrameFile>& frames) {
  const size_t samples = std::min<size_t>(16, frames.size());
  float best = 0;
  std::vector<float> speed;
  for (size_t k = 0; k < samples; ++k) {
    const size_t i = samples == 1 ? 0 : k * (frames.size() - 1) / (samples - 1);
    auto s = sim::read_snapshot(frames[i].path);
    if (!s) continue;  // the render loop reports unreadable frames
    speed.resize(s->size());
    for (size_t p = 0; p < s->size(); ++p)
      speed[p] = std::sqrt(s->vx[p] * s->vx[p] + s->vy[p] * s->vy[p] + s->vz[p] * s->vz[p]);
    if (speed.empty()) continue;
    const size_t q = std::min(speed.size() - 1, size_t(0.995 * double(speed.size())));
    std::nth_element(speed.begin(), speed.begin() + q, speed.end());
    best = std::max(best, speed[q]);
  }
  return render::round_up_nicely(best);
}

std::string frame_png_name(uint64_t index) {
  char name[40];
  std::snprintf(name, sizeof name, "frame_%06llu.png", static_cast<unsigned long long>(index));
  return name;
}

// Integer flag in [lo, hi]; false with *error set otherwise.
bool int_flag(const ParsedArgs& p, const std::string& name, int64_t fallback, int64_t lo,
              int64_t hi, int* out, std::string* error) {
  std::string e;
  const int64_t v = p.get_int(name, fallback, &e);
  if (!e.empty()) {
    *error = e;
    return false;
  }
  if (v < lo || v > hi) {
    *error = "--" + name + " must be in " + std::to_string(lo) + ".." + std::to_string(hi) +
             ", got " + std::to_string(v);
    return false;
  }
  *out = int(v);
  return true;
}

// Encodes and writes finished frames on a second thread, so rendering the
// next frame overlaps encoding this one. At most kDepth frames wait in the
// queue, so memory stays flat however long the run; images are recycled.
class OutputWorker {
 public:
  struct Job {
    render::Image image;
    std::vector<std::string> png_paths;  // PNG files to write this frame to
  };

  OutputWorker(render::VideoWriter* mp4, render::VideoWriter* webm)
      : mp4_(mp4), webm_(webm), thread_([this] { run(); }) {}
  ~OutputWorker() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      closing_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }

  // An image buffer to render into (a recycled one when available).
  render::Image take_image() {
    std::lock_guard<std::mutex> lock(mu_);
    if (spare_.empty()) return {};
    render::Image img = std::move(spare_.back());
    spare_.pop_back();
    return img;
  }

  // Queues a frame, waiting while the queue is full. Returns the first error
  // the worker has met so far (the frame is dropped then).
  render::Status push(Job job) {
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait(lock, [&] { return queue_.size() < kDepth || !error_.is_ok(); });
    if (!error_.is_ok()) return error_;
    queue_.push_back(std::move(job));
    cv_.notify_all();
    return render::Status::ok();
  }

  // Waits until every queued frame is written; returns the first error.
  render::Status drain() {
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait(lock, [&] { return (queue_.empty() && !busy_) || !error_.is_ok(); });
    return error_;
  }

  double encode_s() const { return encode_s_; }  // read after drain()
  double png_s() const { return png_s_; }

 private:
  static constexpr size_t kDepth = 2;

  void run() {
    for (;;) {
      Job job;
      {
        std::unique_lock<std::mutex> lock(mu_);
        cv_.wait(lock, [&] { return !queue_.empty() || closing_; });
        if (queue_.empty()) return;
        job = std::move(queue_.front());
        queue_.pop_front();
        busy_ = true;
      }
      render::Status st;
      auto t0 = Clock::now();
      for (auto* w : {mp4_, webm_})
        if (st && w) st = w->add_frame(job.image);
      encode_s_ += seconds_since(t0);
      t0 = Clock::now();
      for (const auto& path : job.png_paths)
        if (st) st = render::write_png(path, job.image);
      png_s_ += seconds_since(t0);
      {
        std::lock_guard<std::mutex> lock(mu_);
        busy_ = false;
        if (!st && error_.is_ok()) error_ = st;
        spare_.push_back(std::move(job.image));
      }
      cv_.notify_all();
    }
  }

  render::VideoWriter* mp4_;
  render::VideoWriter* webm_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Job> queue_;
  std::vector<render::Image> spare_;
  render::Status error_;
  bool busy_ = false, closing_ = false;
  double encode_s_ = 0, png_s_ = 0;
  std::thread thread_;  // last: starts after everything it uses exists
};

}  // namespace

int cmd_render(const Args& args) {
  std::string err;
  auto p = parse_args(args, kRenderFlags, &err);
  if (!p) return usage_error("render", err);
  if (p->has("help")) {
    print_help(
        "usage: collidoscope render DIR [--out OUTDIR] [--width 1280 --height 720 --fps 30 "
        "--png-every K --camera front|iso|top|orbit --color speed|contact]\n\n"
        "Reads DIR/wall.stl and DIR/frames/frame_NNNNNN.snap and writes OUTDIR/frames/*.png,\n"
        "OUTDIR/poster.png, OUTDIR/video.mp4 (H.264) and OUTDIR/video.webm (VP9).",
        kRenderFlags);
    return kExitOk;
  }
  if (p->positional().size() != 1)
    return usage_error("render", p->positional().empty() ? "the run directory DIR is required"
                                                         : "one run directory expected, got '" +
                                                               p->positional()[1] + "' as well");
  const std::string run_dir = p->positional()[0];

  render::RenderOptions ro;
  int fps = 30, png_every = 10;
  if (!int_flag(*p, "width", 1280, 16, 8192, &ro.width, &err) ||
      !int_flag(*p, "height", 720, 16, 8192, &ro.height, &err) ||
      !int_flag(*p, "fps", 30, 1, 240, &fps, &err) ||
      !int_flag(*p, "png-every", 10, 0, 1000000000, &png_every, &err) ||
      !int_flag(*p, "msaa", 0, 0, 16, &ro.msaa_samples, &err))
    return usage_error("render", err);
  if (!render::parse_camera(p->get("camera", "iso"), &ro.camera))
    return usage_error("render", "--camera must be front, iso, top or orbit");
  if (!render::parse_color_mode(p->get("color", "speed"), &ro.color))
    return usage_error("render", "--color must be speed or contact");
  if (!render::parse_wall_style(p->get("wall", "glass"), &ro.wall))
    return usage_error("render", "--wall must be glass, cutaway or hidden");
  ro.overlay = !p->has("no-overlay");
  ro.cull_hidden = !p->has("no-cull");
  bool want_mp4 = false, want_webm = false;
  {
    const std::string v = p->get("video", "mp4,webm");
    if (v == "mp4,webm" || v == "webm,mp4")
      want_mp4 = want_webm = true;
    else if (v == "mp4")
      want_mp4 = true;
    else if (v == "webm")
      want_webm = true;
    else if (v != "none")
      return usage_error("render", "--video must be mp4,webm, mp4, webm or none");
  }
  if ((want_mp4 || want_webm) && (ro.width % 2 || ro.height % 2))
    return usage_error("render", "video needs an even --width and --height (yuv420p)");
  float speed_max = 0;
  if (p->has("speed-max")) {
    speed_max = float(p->get_double("speed-max", 0, &err));
    if (!err.empty()) return usage_error("render", err);
    if (!(speed_max > 0)) return usage_error("render", "--speed-max must be positive");
  }

  const auto frames = list_frames(run_dir, &err);
  if (!err.empty()) {
    std::fprintf(stderr, "collidoscope render: %s\n", err.c_str());
    return kExitFailure;
  }
  if (frames.empty()) {
    std::fprintf(stderr, "collidoscope render: no frame_NNNNNN.snap files in %s/frames\n",
                 run_dir.c_str());
    return kExitFailure;
  }
  const std::string out_dir = p->get("out", (fs::path(run_dir) / "render").string());
  std::error_code ec;
  fs::create_directories(fs::path(out_dir) / "frames", ec);
  if (ec) {
    std::fprintf(stderr, "collidoscope render: cannot create %s: %s\n", out_dir.c_str(),
                 ec.message().c_str());
    return kExitFailure;
  }

  // Render coordinates are centred on the first frame's origin, so float keeps
  // its precision however far from the world origin the scene lies.
  auto first = sim::read_snapshot(frames.front().path);
  if (!first) {
    std::fprintf(stderr, "collidoscope render: %s\n", first.status().message().c_str());
    return kExitFailure;
  }
  const sim::Vec3d origin = first->origin;
  render::Snapshot scene;
  const std::string wall_path = (fs::path(run_dir) / "wall.stl").string();
  if (fs::exists(wall_path)) {
    auto mesh = sim::load_stl(wall_path);
    if (!mesh) {
      std::fprintf(stderr, "collidoscope render: %s\n", mesh.status().message().c_str());
      return kExitFailure;
    }
    scene.wall = to_render_wall(*mesh, origin);
  } else {
    std::fprintf(stderr, "collidoscope render: note: %s not found, rendering particles only\n",
                 wall_path.c_str());
  }
  // A fixed frame for the whole run: the wall's box, or the first frame's particles.
  fill_particles(*first, origin, &scene);
  scene.bounds = render::compute_bounds(scene);

  if (ro.color == render::ColorMode::kSpeed) {
    ro.color_min = 0;
    ro.color_max = speed_max > 0 ? speed_max : estimate_speed_max(frames);
    ro.color_label = "speed";
  }
  render::Status st;
  auto renderer = render::Renderer::create(ro, &st);
  if (!renderer) {
    std::fprintf(stderr, "collidoscope render: %s\n", st.message().c_str());
    return kExitFailure;
  }

  std::unique_ptr<render::VideoWriter> mp4, webm;
  const std::string mp4_path = (fs::path(out_dir) / "video.mp4").string();
  const std::string webm_path = (fs::path(out_dir) / "video.webm").string();
  render::VideoOptions vo;
  vo.width = ro.width;
  vo.height = ro.height;
  vo.fps = fps;
  if (want_mp4) {
    vo.codec = render::VideoCodec::kH264;
    if (!(mp4 = render::VideoWriter::open(mp4_path, vo, &st))) {
      std::fprintf(stderr, "collidoscope render: %s\n", st.message().c_str());
      return kExitFailure;
    }
  }
  if (want_webm) {
    vo.codec = render::VideoCodec::kVP9;
    if (!(webm = render::VideoWriter::open(webm_path, vo, &st))) {
      std::fprintf(stderr, "collidoscope render: %s\n", st.message().c_str());
      return kExitFailure;
    }
  }

  const bool progress = stderr_is_terminal();
  const size_t poster_at = frames.size() / 2;
  const std::string poster_path = (fs::path(out_dir) / "poster.png").string();
  double render_s = 0;
  size_t pngs = 0;
  const auto t_start = Clock::now();
  // Declared after the writers: it is destroyed (joined) before them.
  OutputWorker output(mp4.get(), webm.get());
  for (size_t i = 0; i < frames.size(); ++i) {
    auto snap = i == 0 ? std::move(first) : sim::read_snapshot(frames[i].path);
    if (!snap) {
      std::fprintf(stderr, "\ncollidoscope render: %s\n", snap.status().message().c_str());
      return kExitFailure;
    }
    fill_particles(*snap, origin, &scene);
    // One full turn over the run.
    if (ro.camera == render::CameraPreset::kOrbit)
      renderer->set_orbit_deg(360.0 * double(i) / double(frames.size()));
    OutputWorker::Job job;
    job.image = output.take_image();
    const auto t0 = Clock::now();
    if (!(st = renderer->render(scene, &job.image))) {
      std::fprintf(stderr, "\ncollidoscope render: %s: %s\n", frames[i].path.c_str(),
                   st.message().c_str());
      return kExitFailure;
    }
    render_s += seconds_since(t0);
    if (png_every > 0 && i % size_t(png_every) == 0) {
      job.png_paths.push_back(
          (fs::path(out_dir) / "frames" / frame_png_name(frames[i].index)).string());
      ++pngs;
    }
    if (i == poster_at) job.png_paths.push_back(poster_path);
    if (!(st = output.push(std::move(job)))) {
      std::fprintf(stderr, "\ncollidoscope render: %s\n", st.message().c_str());
      return kExitFailure;
    }
    if (progress)
      std::fprintf(stderr, "\rrender: frame %zu/%zu (%.0f ms/frame)", i + 1, frames.size(),
                   1e3 * seconds_since(t_start) / double(i + 1));
  }
  if (progress) std::fprintf(stderr, "\n");
  if (!(st = output.drain())) {
    std::fprintf(stderr, "collidoscope render: %s\n", st.message().c_str());
    return kExitFailure;
  }
  double encode_s = output.encode_s();
  const double png_s = output.png_s();
  const auto t_finish = Clock::now();
  for (auto* w : {mp4.get(), webm.get()})
    if (w && !(st = w->finish())) {
      std::fprintf(stderr, "collidoscope render: %s\n", st.message().c_str());
      return kExitFailure;
    }
  encode_s += seconds_since(t_finish);

  const double n = double(frames.size());
  std::printf("rendered %zu frames at %dx%d with %s\n", frames.size(), ro.width, ro.height,
              renderer->gl_description().c_str());
  // Encoding runs beside rendering, so the parts add up to more than the total.
  std::printf(
      "  render %.1f ms/frame, encode %.1f ms/frame, png %.1f ms/frame (in parallel), "
      "total %.1f s = %.1f ms/frame\n",
      1e3 * render_s / n, 1e3 * encode_s / n, 1e3 * png_s / n, seconds_since(t_start),
      1e3 * seconds_since(t_start) / n);
  std::printf("  poster   %s\n", poster_path.c_str());
  if (pngs) std::printf("  frames   %s/frames/ (%zu PNG)\n", out_dir.c_str(), pngs);
  if (mp4) std::printf("  mp4      %s (%s)\n", mp4_path.c_str(), mp4->encoder_name().c_str());
  if (webm) std::printf("  webm     %s (%s)\n", webm_path.c_str(), webm->encoder_name().c_str());
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
  if (!int_flag(*p, "width", 1280, 16, 8192, &ro.width, &err) ||
      !int_flag(*p, "height", 720, 16, 8192, &ro.height, &err) ||
      !int_flag(*p, "frames", 10, 1, 100000, &frames, &err) ||
      !int_flag(*p, "encode-frames", 90, 1, 100000, &encode_frames, &err) ||
      !int_flag(*p, "msaa", 0, 0, 16, &ro.msaa_samples, &err) ||
      !int_flag(*p, "seed", 1, 0, 1 << 30, &seed, &err))
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
