#include "common/stopwatch.h"
#include "job/render_run.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <memory>
#include <mutex>
#include <thread>

#include "common/atomic_file.h"
#include "job/assess.h"
#include "render/render.h"
#include "scene/scene.h"
#include "sim/mesh.h"
#include "sim/snapshot.h"

namespace collido::job {
namespace {

namespace fs = std::filesystem;
using Clock = SteadyClock;


struct FrameFile {
  uint64_t index;
  std::string path;
};

// The frames of a run, ordered by frame index (not by name, so frame 1000000
// comes after 999999).
Expected<std::vector<FrameFile>> list_frames(const std::string& run_dir) {
  std::vector<FrameFile> out;
  const fs::path dir = fs::path(run_dir) / "frames";
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    return not_found(dir.string() + " is not a directory (expected DIR/frames/frame_NNNNNN.snap)");
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.size() < 12 || name.compare(0, 6, "frame_") != 0 ||
        name.compare(name.size() - 5, 5, ".snap") != 0)
      continue;
    const std::string digits = name.substr(6, name.size() - 11);
    if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos) continue;
    out.push_back({std::strtoull(digits.c_str(), nullptr, 10), entry.path().string()});
  }
  if (ec) return io_error("cannot list " + dir.string() + ": " + ec.message());
  if (out.empty()) return not_found("no frame_NNNNNN.snap files in " + dir.string());
  std::sort(out.begin(), out.end(),
            [](const FrameFile& a, const FrameFile& b) { return a.index < b.index; });
  return out;
}

// The bridge from the engine to the renderer. The wall in render coordinates:
// world minus the render origin, in float.
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


// How the run's wall moves, from the scene it wrote beside its frames (none
// when the run has no scene file, as with frames from elsewhere). When one
// part moves, *parts gets the wall rebuilt from the scene, its parts apart
// (wall.stl welds them where they meet), and the motion its part's triangles.
sim::WallMotion run_wall_motion(const std::string& run_dir, sim::TriangleMesh* parts) {
  auto scene = scene::load_scene((fs::path(run_dir) / "scene.json").string());
  if (!scene) return sim::WallMotion{};
  if (scene->dynamics.wall_motion.part > 0) {
    auto wall = load_scene_wall(&*scene);
    if (!wall) return sim::WallMotion{};  // drawn standing still
    *parts = std::move(*wall);
  }
  return scene->dynamics.wall_motion;
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

// Encodes and writes finished frames on a second thread, so rendering the
// next frame overlaps encoding this one. At most kDepth frames wait in the
// queue, so memory stays flat however long the run; images are recycled.
class OutputWorker {
 public:
  struct Job {
    render::Image image;
    bool to_gif = false;                 // this frame also goes into the GIF
    std::vector<std::string> png_paths;  // PNG files to write this frame to
  };

  OutputWorker(std::vector<render::VideoWriter*> videos, render::VideoWriter* gif)
      : videos_(std::move(videos)), gif_(gif), thread_([this] { run(); }) {}
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
  Status push(Job job) {
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait(lock, [&] { return queue_.size() < kDepth || !error_.is_ok(); });
    if (!error_.is_ok()) return error_;
    queue_.push_back(std::move(job));
    cv_.notify_all();
    return Status::ok();
  }

  // Waits until every queued frame is written; returns the first error.
  Status drain() {
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
        // After an error the rest is dropped: nothing more is encoded or
        // written for a render that has failed.
        if (!error_.is_ok()) {
          spare_.push_back(std::move(job.image));
          cv_.notify_all();
          continue;
        }
        busy_ = true;
      }
      Status st;
      auto t0 = Clock::now();
      for (auto* w : videos_)
        if (st) st = w->add_frame(job.image);
      if (st && gif_ && job.to_gif) st = gif_->add_frame(job.image);
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

  std::vector<render::VideoWriter*> videos_;
  render::VideoWriter* gif_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Job> queue_;
  std::vector<render::Image> spare_;
  Status error_;
  bool busy_ = false, closing_ = false;
  double encode_s_ = 0, png_s_ = 0;
  std::thread thread_;  // last: starts after everything it uses exists
};

Status int_in(const char* name, int v, int lo, int hi) {
  if (v < lo || v > hi)
    return invalid_argument(std::string("render.") + name + ": " + std::to_string(v) +
                            " is outside [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
  return Status::ok();
}

}  // namespace

Status validate(const RenderSettings& s) {
  for (Status st : {int_in("width", s.width, kMinFrameSide, kMaxFrameSide),
                    int_in("height", s.height, kMinFrameSide, kMaxFrameSide),
                    int_in("fps", s.fps, 1, 240), int_in("png_every", s.png_every, 0, 1000000000),
                    int_in("msaa", s.msaa, 0, 16), int_in("gif_width", s.gif_width, 16, 4096),
                    int_in("gif_fps", s.gif_fps, 1, 50)})
    if (!st) return st;
  render::CameraPreset camera;
  render::ColorMode color;
  render::WallStyle wall;
  if (!render::parse_camera(s.camera, &camera))
    return invalid_argument("render.camera: must be front, iso, top or orbit");
  if (!render::parse_color_mode(s.color, &color))
    return invalid_argument("render.color: must be speed or contact");
  if (!render::parse_wall_style(s.wall, &wall))
    return invalid_argument("render.wall: must be glass, cutaway or hidden");
  if ((s.mp4 || s.webm) && (s.width % 2 || s.height % 2))
    return invalid_argument("render.width, render.height: video needs an even size (yuv420p)");
  if (!(s.speed_max >= 0) || !std::isfinite(s.speed_max))
    return invalid_argument("render.speed_max: must be a positive speed (or 0 for automatic)");
  return Status::ok();
}

void set_render_wall(const sim::TriangleMesh& wall, const sim::WallMotion& motion,
                     sim::Vec3d origin, render::Snapshot* out) {
  if (!motion.moves_part()) {
    out->wall = to_render_wall(wall, origin);
    out->part = {};
    return;
  }
  out->wall = to_render_wall(sim::mesh_range(wall, motion.part_begin, motion.part_end, false), origin);
  out->part = to_render_wall(sim::mesh_range(wall, motion.part_begin, motion.part_end, true), origin);
}

void pose_render_wall(const sim::WallMotion& motion, double t, sim::Vec3d origin,
                      render::Snapshot* out) {
  if (motion.moving())
    wall_model_matrix(motion.pose(t), origin, motion.moves_part() ? out->part_model : out->wall_model);
}

void wall_model_matrix(const sim::WallPose& pose, sim::Vec3d origin, float out[16]) {
  const sim::Vec3d t = pose.rotate(origin - pose.c) + pose.c + pose.d - origin;
  const sim::Vec3d rows[3] = {pose.r0, pose.r1, pose.r2};
  const double shift[3] = {t.x, t.y, t.z};
  for (int r = 0; r < 3; ++r) {
    out[0 * 4 + r] = float(rows[r].x);
    out[1 * 4 + r] = float(rows[r].y);
    out[2 * 4 + r] = float(rows[r].z);
    out[3 * 4 + r] = float(shift[r]);
  }
  out[3] = out[7] = out[11] = 0;
  out[15] = 1;
}

// A render replaces the one before it in out_dir: its videos, poster and frame
// images go, whatever the new settings ask for (an old WebM beside a new MP4
// would be listed as this render's), and so do the temporary files of a writer
// that was killed. Only these names: out_dir may hold other files.
static Status clear_previous_outputs(const fs::path& out_dir) {
  auto ours = [](const std::string& name, bool frames) {
    std::string base = name;
    if (is_temp_name(name)) base = name.substr(0, name.rfind(".tmp"));
    if (frames)
      return base.size() > 10 && base.compare(0, 6, "frame_") == 0 &&
             base.compare(base.size() - 4, 4, ".png") == 0;
    return base == "video.mp4" || base == "video.webm" || base == "loop.gif" || base == "poster.png";
  };
  for (const auto& [dir, frames] : {std::pair{out_dir, false}, std::pair{out_dir / "frames", true}}) {
    std::error_code ec;
    for (auto it = fs::directory_iterator(dir, ec); !ec && it != fs::directory_iterator();
         it.increment(ec)) {
      if (!ours(it->path().filename().string(), frames)) continue;
      std::error_code rm;
      fs::remove(it->path(), rm);
      if (rm) return io_error(it->path().string() + ": cannot remove it: " + rm.message());
    }
  }
  return Status::ok();
}

// render_run's work, into a folder of its own (render_run's staging folder).
static Status render_outputs(const std::string& run_dir, const std::string& out_dir,
                             const RenderSettings& settings, const FrameProgress& progress,
                             const std::atomic<bool>* cancel, RenderOutcome* outcome) {
  if (Status st = validate(settings); !st) return st;
  render::RenderOptions ro;
  ro.width = settings.width;
  ro.height = settings.height;
  ro.msaa_samples = settings.msaa;
  ro.overlay = settings.overlay;
  ro.cull_hidden = settings.cull;
  render::parse_camera(settings.camera, &ro.camera);
  render::parse_color_mode(settings.color, &ro.color);
  render::parse_wall_style(settings.wall, &ro.wall);

  auto frames_or = list_frames(run_dir);
  if (!frames_or) return frames_or.status();
  const std::vector<FrameFile>& frames = *frames_or;
  std::error_code ec;
  fs::create_directories(fs::path(out_dir) / "frames", ec);
  if (ec) return io_error("cannot create " + out_dir + ": " + ec.message());

  // Render coordinates are centred on the first frame's origin, so float keeps
  // its precision however far from the world origin the scene lies.
  auto first = sim::read_snapshot(frames.front().path);
  if (!first) return first.status();
  const sim::Vec3d origin = first->origin;
  render::Snapshot scene;
  const std::string wall_path = (fs::path(run_dir) / "wall.stl").string();
  // A moving wall is drawn where it is at each frame's time.
  sim::TriangleMesh wall_mesh;
  const sim::WallMotion motion = run_wall_motion(run_dir, &wall_mesh);
  // (With a moving part the wall is the scene's, rebuilt with its parts apart.)
  if (!motion.moves_part() && fs::exists(wall_path)) {
    auto mesh = sim::load_stl(wall_path);
    if (!mesh) return mesh.status();
    wall_mesh = std::move(*mesh);
  }
  if (!wall_mesh.triangles.empty()) set_render_wall(wall_mesh, motion, origin, &scene);
  // A fixed frame for the whole run: the wall's box (all it sweeps when it
  // turns), or the first frame's particles.
  fill_particles(*first, origin, &scene);
  scene.bounds = render::compute_bounds(scene);
  if (motion.moving() && !wall_mesh.vertices.empty()) {
    const sim::Bounds3d swept = motion.swept_box(sim::mesh_bounds(wall_mesh));
    const sim::Vec3d lo = swept.lo - origin, hi = swept.hi - origin;
    const double los[3] = {lo.x, lo.y, lo.z}, his[3] = {hi.x, hi.y, hi.z};
    for (int k = 0; k < 3; ++k) {
      scene.bounds.lo[k] = std::min(scene.bounds.lo[k], float(los[k]));
      scene.bounds.hi[k] = std::max(scene.bounds.hi[k], float(his[k]));
    }
  }

  if (ro.color == render::ColorMode::kSpeed) {
    ro.color_min = 0;
    ro.color_max = settings.speed_max > 0 ? settings.speed_max : estimate_speed_max(frames);
    ro.color_label = "speed";
  }
  Status st;
  auto renderer = render::Renderer::create(ro, &st);
  if (!renderer) return st;
  outcome->gl = renderer->gl_description();

  // Writers keep their files under temporary names until finish().
  std::unique_ptr<render::VideoWriter> mp4, webm, gif;
  render::VideoOptions vo;
  vo.width = ro.width;
  vo.height = ro.height;
  vo.fps = settings.fps;
  const std::string mp4_path = (fs::path(out_dir) / "video.mp4").string();
  const std::string webm_path = (fs::path(out_dir) / "video.webm").string();
  const std::string gif_path = (fs::path(out_dir) / "loop.gif").string();
  if (settings.mp4) {
    vo.codec = render::VideoCodec::kH264;
    if (!(mp4 = render::VideoWriter::open(mp4_path, vo, &st))) return st;
  }
  if (settings.webm) {
    vo.codec = render::VideoCodec::kVP9;
    if (!(webm = render::VideoWriter::open(webm_path, vo, &st))) return st;
  }
  // The GIF keeps every gif_stride-th frame, at the rate that keeps its speed,
  // at most gif_fps (rounding the stride down gave up to twice that: at 90 fps
  // and 50 kept, every frame, whose 1/90 s delays a browser shows as 1/10 s).
  const int gif_fps = std::max(1, settings.gif_fps);
  const int gif_stride = std::max(1, (settings.fps + gif_fps - 1) / gif_fps);
  if (settings.gif) {
    render::VideoOptions go;
    go.codec = render::VideoCodec::kGif;
    go.width = std::min(settings.gif_width, ro.width);
    go.height = std::max(2, int(std::lround(double(ro.height) * go.width / ro.width)));
    go.source_width = ro.width;
    go.source_height = ro.height;
    go.fps = settings.fps;
    go.fps_divisor = gif_stride;
    if (!(gif = render::VideoWriter::open(gif_path, go, &st))) return st;
  }
  std::vector<render::VideoWriter*> videos;
  for (auto* w : {mp4.get(), webm.get()})
    if (w) videos.push_back(w);

  const size_t poster_at = frames.size() / 2;
  const std::string poster_path = (fs::path(out_dir) / "poster.png").string();
  const auto t_start = Clock::now();
  {
    // Declared after the writers: it is destroyed (joined) before them.
    OutputWorker output(videos, gif.get());
    for (size_t i = 0; i < frames.size(); ++i) {
      if (cancel && cancel->load()) {
        output.drain();
        return cancelled("render cancelled at frame " + std::to_string(i));
      }
      auto snap = i == 0 ? std::move(first) : sim::read_snapshot(frames[i].path);
      if (!snap) return snap.status();
      fill_particles(*snap, origin, &scene);
      pose_render_wall(motion, snap->time, origin, &scene);
      // One full turn over the run.
      if (ro.camera == render::CameraPreset::kOrbit)
        renderer->set_orbit_deg(360.0 * double(i) / double(frames.size()));
      OutputWorker::Job job;
      job.image = output.take_image();
      const auto t0 = Clock::now();
      if (!(st = renderer->render(scene, &job.image)))
        return backend_error(frames[i].path + ": " + st.message());
      outcome->render_s += seconds_since(t0);
      if (settings.png_every > 0 && i % size_t(settings.png_every) == 0) {
        job.png_paths.push_back(
            (fs::path(out_dir) / "frames" / frame_png_name(frames[i].index)).string());
        ++outcome->pngs;
      }
      if (i == poster_at) job.png_paths.push_back(poster_path);
      job.to_gif = i % size_t(gif_stride) == 0;
      if (!(st = output.push(std::move(job)))) return st;
      if (progress) progress(i + 1, frames.size());
    }
    if (!(st = output.drain())) return st;
    outcome->encode_s = output.encode_s();
    outcome->png_s = output.png_s();
  }
  const auto t_finish = Clock::now();
  for (auto* w : {mp4.get(), webm.get(), gif.get()})
    if (w && !(st = w->finish())) return st;
  outcome->encode_s += seconds_since(t_finish);
  outcome->total_s = seconds_since(t_start);
  outcome->frames = frames.size();
  outcome->poster = poster_path;
  if (mp4) outcome->mp4 = mp4_path, outcome->mp4_encoder = mp4->encoder_name();
  if (webm) outcome->webm = webm_path, outcome->webm_encoder = webm->encoder_name();
  if (gif) outcome->gif = gif_path;
  return Status::ok();
}

// Moves a finished render from `staging` into out_dir, in place of the one
// before it, and points the outcome's paths there.
static Status publish_outputs(const fs::path& staging, const fs::path& out_dir,
                              RenderOutcome* outcome) {
  std::error_code ec;
  fs::create_directories(out_dir / "frames", ec);
  if (ec) return io_error("cannot create " + (out_dir / "frames").string() + ": " + ec.message());
  if (Status st = clear_previous_outputs(out_dir); !st) return st;
  for (const char* sub : {"", "frames"}) {
    for (auto it = fs::directory_iterator(staging / sub, ec); !ec && it != fs::directory_iterator();
         it.increment(ec)) {
      if (!it->is_regular_file()) continue;
      const fs::path to = out_dir / sub / it->path().filename();
      std::error_code mv;
      fs::rename(it->path(), to, mv);
      if (mv)
        return io_error("cannot move " + it->path().string() + " to " + to.string() + ": " +
                        mv.message());
    }
    if (ec) return io_error((staging / sub).string() + ": " + ec.message());
  }
  for (std::string* path : {&outcome->poster, &outcome->mp4, &outcome->webm, &outcome->gif})
    if (!path->empty()) *path = (out_dir / fs::path(*path).filename()).string();
  return Status::ok();
}

Status render_run(const std::string& run_dir, const std::string& out_dir,
                  const RenderSettings& settings, const FrameProgress& progress,
                  const std::atomic<bool>* cancel, RenderOutcome* outcome) {
  *outcome = RenderOutcome{};
  // Rendered apart and moved in whole: a render that fails or is cancelled
  // leaves the one before it as it was, not a few frame images or an MP4
  // finished before the WebM failed (which would be listed as this render's).
  const fs::path staging = fs::path(out_dir) / ".render-staging";
  std::error_code ec;
  fs::remove_all(staging, ec);  // a killed render's
  if (ec) return io_error(staging.string() + ": cannot remove it: " + ec.message());
  Status st = render_outputs(run_dir, staging.string(), settings, progress, cancel, outcome);
  if (st) st = publish_outputs(staging, out_dir, outcome);
  fs::remove_all(staging, ec);
  if (!st) *outcome = RenderOutcome{};
  return st;
}

}  // namespace collido::job
