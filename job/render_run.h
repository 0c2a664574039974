// The render step of a job: a run directory's snapshots (DIR/frames/*.snap and
// DIR/wall.stl) into PNG frames, a poster, MP4 (H.264), WebM (VP9) and an
// animated GIF loop. `collidoscope render` and every job call this one step.
// Built only where the renderer is (COLLIDO_HAVE_RENDER).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "common/status.h"
#include "sim/dynamics.h"

namespace collido::render {
struct Snapshot;
}

namespace collido::job {

// A frame's width and height, pixels.
inline constexpr int kMinFrameSide = 16, kMaxFrameSide = 8192;

struct RenderSettings {
  int width = 1280, height = 720;  // pixels, kMinFrameSide..kMaxFrameSide; even when a video is written
  int fps = 30;                    // video frame rate
  int png_every = 10;              // every K-th frame as PNG; 0 = none
  std::string camera = "iso";      // front | iso | top | orbit
  std::string color = "speed";     // speed | contact
  std::string wall = "glass";      // glass | cutaway | hidden
  float speed_max = 0;             // top of the colour map, m/s; 0 = from the frames
  bool mp4 = true, webm = true;
  bool gif = false;
  int gif_width = 480;  // the GIF is scaled to this width (height in proportion)
  int gif_fps = 10;     // and keeps about this many frames a second (at most fps)
  int msaa = 0;         // 0 or 2..16
  bool overlay = true;  // time, frame and legend text
  bool cull = true;     // skip particles hidden behind nearer ones (same image)
};

// Checks every field; the message names it ("render.width: ...").
Status validate(const RenderSettings& s);

struct RenderOutcome {
  size_t frames = 0, pngs = 0;
  // Paths of what was written (empty when not asked for).
  std::string poster, mp4, webm, gif;
  std::string mp4_encoder, webm_encoder, gl;
  double render_s = 0, encode_s = 0, png_s = 0, total_s = 0;
};

// A moving wall's pose as the renderer's column-major model matrix, in render
// coordinates (world minus `origin`): the matrix takes v - origin to
// pose.to_world(v) - origin, so the mesh is uploaded once and only this changes.
void wall_model_matrix(const sim::WallPose& pose, sim::Vec3d origin, float out[16]);
// The run's wall into a render snapshot, in render coordinates: the whole
// wall, or, when one part moves, the rest as `wall` and the part as `part`;
// each is uploaded once. pose_render_wall then sets, each frame, the model
// matrix of what moves at time t.
void set_render_wall(const sim::TriangleMesh& wall, const sim::WallMotion& motion,
                     sim::Vec3d origin, render::Snapshot* out);
void pose_render_wall(const sim::WallMotion& motion, double t, sim::Vec3d origin,
                      render::Snapshot* out);

// Called after each frame is rendered with (frames done, frames in all).
using FrameProgress = std::function<void(size_t, size_t)>;

// Renders run_dir's frames into out_dir (out_dir/frames/*.png, poster.png,
// video.mp4, video.webm, loop.gif). Every file appears under its final name
// only when complete, and replaces the previous render's only when the whole
// render is: one that fails or is cancelled leaves the previous one as it was
// (a killed one leaves a hidden staging folder, which the next render
// removes). `cancel`, when set, is polled every frame: the step then stops
// with kCancelled.
Status render_run(const std::string& run_dir, const std::string& out_dir,
                  const RenderSettings& settings, const FrameProgress& progress,
                  const std::atomic<bool>* cancel, RenderOutcome* outcome);

}  // namespace collido::job
