// The renderer's entry header: snapshots in, images out, then PNG and video.
// Free of GL, FFmpeg and FreeType types; every call reports errors through
// Status, never by exceptions. One Renderer uses one offscreen GL context bound
// to the calling thread on each render(): never use one Renderer from two
// threads at once.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>

#include "render/image.h"
#include "render/snapshot.h"
#include "render/status.h"
#include "render/video.h"

namespace collido::render {

// Where the camera looks from. The world's up axis is +z.
enum class CameraPreset {
  kFront,  // from -y, 8 degrees above the horizon
  kIso,    // from the front-left (35 degrees round), 28 degrees above
  kTop,    // straight down
  kOrbit,  // like kIso, turning around the vertical axis (see RenderOptions::orbit_deg)
};
enum class ColorMode { kSpeed, kContact };
enum class WallStyle {
  kGlass,    // far side opaque, near side see-through with bright rims
  kCutaway,  // near side removed: only the faces turned away from the camera
  kHidden,   // no wall
};

// Parses "front", "iso", "top", "orbit" / "speed", "contact" / "glass",
// "cutaway", "hidden"; false for anything else.
bool parse_camera(const std::string& s, CameraPreset* out);
bool parse_color_mode(const std::string& s, ColorMode* out);
bool parse_wall_style(const std::string& s, WallStyle* out);

// The next round number at or above v (1, 1.5, 2, 2.5, 3, 4, 5, 6 or 8 times a
// power of ten), for colour-map ranges whose top legend tick reads at a glance.
float round_up_nicely(float v);

inline constexpr const char* kDefaultFont = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

struct RenderOptions {
  int width = 1280;  // pixels
  int height = 720;  // pixels
  CameraPreset camera = CameraPreset::kIso;
  double orbit_deg = 0;       // extra azimuth in degrees (kOrbit turns by this)
  double elevation_deg = -1;  // camera height angle; negative = the preset's own
  double fov_deg = 30;        // vertical field of view, degrees
  ColorMode color = ColorMode::kSpeed;
  // Speed mapped to the ends of the colour map (world units/s). When
  // color_max <= color_min the range is taken from each frame: its min..max,
  // or 0..max rounded up (round_up_nicely) when no value is negative. A run
  // should pass a fixed range so colours mean the same in every frame.
  float color_min = 0;
  float color_max = 0;
  std::string color_label = "speed";  // legend title
  WallStyle wall = WallStyle::kGlass;
  float wall_opacity = 0.18f;  // near side of the glass wall, 0..1
  bool shading = true;         // false: flat colours (tests compare exact pixels)
  bool overlay = true;         // time/frame/count text and the colour legend
  std::string font_path = kDefaultFont;
  // Multisampling smooths the wall's edges only (the spheres are cut out by
  // the shader, which multisampling does not smooth) and costs about 3x in
  // llvmpipe, so it is off unless asked for; 0 or 1 means off.
  int msaa_samples = 0;
  // Skip particles that are certainly hidden behind nearer ones (CPU test,
  // conservative: the image does not change, dense scenes draw far faster).
  bool cull_hidden = true;
  // Vertical background gradient, top and bottom (sRGB).
  std::array<uint8_t, 3> background_top = {38, 44, 56};
  std::array<uint8_t, 3> background_bottom = {12, 14, 20};
};

// Time spent on the last frame, milliseconds.
struct FrameTiming {
  double cull_ms = 0;          // sorting and occlusion culling on the CPU
  double upload_ms = 0;        // particle arrays to GL buffers
  double draw_ms = 0;          // GL draw calls until the frame is finished
  double readback_ms = 0;      // pixels back to memory, flipped to top-down
  double overlay_ms = 0;       // text and legend
  size_t particles_drawn = 0;  // after culling
  double total_ms() const { return cull_ms + upload_ms + draw_ms + readback_ms + overlay_ms; }
};

// llvmpipe reads LP_NUM_THREADS once, when the first context creates its
// screen; without it Mesa may use fewer rasterizer threads than the process
// may use. A library must not change the environment of a running,
// threaded process, so the program sets it at start-up (app/main.cpp).

class Renderer {
 public:
  // Creates the offscreen context, shaders and framebuffers. nullptr and
  // *status when the GL driver, the font or the options are unusable.
  static std::unique_ptr<Renderer> create(const RenderOptions& options, Status* status);
  ~Renderer();

  // Draws one snapshot into *image (resized to width x height).
  Status render(const Snapshot& snapshot, Image* image);

  // Changes the orbit angle (degrees) for the next frames of a kOrbit camera.
  void set_orbit_deg(double deg);
  const RenderOptions& options() const;
  const FrameTiming& last_timing() const;
  // GL_RENDERER and GL_VERSION strings, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)".
  std::string gl_description() const;

 private:
  struct Impl;
  explicit Renderer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace collido::render
