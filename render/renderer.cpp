// The OpenGL side of the renderer: context, shaders, buffers, the frame's draw
// passes, readback, then the CPU overlay.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <unordered_map>

#include "render/camera.h"
#include "render/colormap.h"
#include "render/cull.h"
#include "render/gl_context.h"
#include "render/gl_functions.h"
#include "render/overlay.h"
#include "render/render.h"
#include "render/shaders.h"

namespace collido::render {

bool parse_camera(const std::string& s, CameraPreset* out) {
  if (s == "front")
    *out = CameraPreset::kFront;
  else if (s == "iso")
    *out = CameraPreset::kIso;
  else if (s == "top")
    *out = CameraPreset::kTop;
  else if (s == "orbit")
    *out = CameraPreset::kOrbit;
  else
    return false;
  return true;
}

bool parse_color_mode(const std::string& s, ColorMode* out) {
  if (s == "speed")
    *out = ColorMode::kSpeed;
  else if (s == "contact")
    *out = ColorMode::kContact;
  else
    return false;
  return true;
}

bool parse_wall_style(const std::string& s, WallStyle* out) {
  if (s == "glass")
    *out = WallStyle::kGlass;
  else if (s == "cutaway")
    *out = WallStyle::kCutaway;
  else if (s == "hidden")
    *out = WallStyle::kHidden;
  else
    return false;
  return true;
}

float round_up_nicely(float v) {
  if (!(v > 0) || !std::isfinite(v)) return 1.f;
  const double p10 = std::pow(10.0, std::floor(std::log10(double(v))));
  for (double f : {1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0})
    if (f * p10 >= double(v) * (1 - 1e-6)) return float(f * p10);
  return float(10 * p10);
}

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

constexpr float kPi = 3.14159265358979f;
constexpr float kWallColor[3] = {0.70f, 0.76f, 0.86f};
constexpr float kWallInnerColor[3] = {0.60f, 0.65f, 0.74f};

// Wall geometry as the GPU wants it: a triangle soup with smoothed normals
// (smooth within a crease angle, so a cylinder's side is round but its rim
// stays sharp) and the crease/boundary edges as line segments.
struct WallGeometry {
  std::vector<float> soup;   // per corner: x, y, z, nx, ny, nz
  std::vector<float> edges;  // per line end: x, y, z
};

WallGeometry build_wall_geometry(const WallMesh& mesh) {
  WallGeometry g;
  const size_t nt = mesh.triangle_count();
  const size_t nv = mesh.vertices.size() / 3;
  auto vtx = [&](uint32_t i) { return &mesh.vertices[3 * size_t(i)]; };

  // Weld by exact position: callers may pass an unwelded soup, and adjacency
  // (for smoothing and edges) must not depend on that.
  std::vector<uint32_t> canon(nv);
  {
    struct Key {
      float x, y, z;
      bool operator==(const Key& o) const { return x == o.x && y == o.y && z == o.z; }
    };
    struct Hash {
      size_t operator()(const Key& k) const {
        uint32_t a, b, c;
        std::memcpy(&a, &k.x, 4), std::memcpy(&b, &k.y, 4), std::memcpy(&c, &k.z, 4);
        return (size_t(a) * 73856093u) ^ (size_t(b) * 19349663u) ^ (size_t(c) * 83492791u);
      }
    };
    std::unordered_map<Key, uint32_t, Hash> first;
    first.reserve(nv);
    for (size_t i = 0; i < nv; ++i) {
      const float* p = vtx(uint32_t(i));
      canon[i] = first.emplace(Key{p[0], p[1], p[2]}, uint32_t(i)).first->second;
    }
  }

  std::vector<float> fn(3 * nt);  // area-weighted face normals
  std::vector<float> fn_unit(3 * nt);
  for (size_t t = 0; t < nt; ++t) {
    const float* a = vtx(mesh.indices[3 * t]);
    const float* b = vtx(mesh.indices[3 * t + 1]);
    const float* c = vtx(mesh.indices[3 * t + 2]);
    const float e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const float e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    float n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                  e1[0] * e2[1] - e1[1] * e2[0]};
    const float l = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int k = 0; k < 3; ++k) {
      fn[3 * t + k] = n[k];
      fn_unit[3 * t + k] = l > 0 ? n[k] / l : 0;
    }
  }

  // Triangles around each (welded) vertex, as CSR arrays.
  std::vector<uint32_t> start(nv + 1, 0), around(3 * nt);
  for (size_t i = 0; i < 3 * nt; ++i) ++start[canon[mesh.indices[i]] + 1];
  for (size_t v = 0; v < nv; ++v) start[v + 1] += start[v];
  {
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (size_t i = 0; i < 3 * nt; ++i) around[fill[canon[mesh.indices[i]]]++] = uint32_t(i / 3);
  }

  const float crease = std::cos(40.f * kPi / 180.f);
  g.soup.resize(nt * 18);
  for (size_t t = 0; t < nt; ++t) {
    const float* ft = &fn_unit[3 * t];
    for (int k = 0; k < 3; ++k) {
      const uint32_t vi = mesh.indices[3 * t + k];
      const uint32_t cv = canon[vi];
      float n[3] = {0, 0, 0};
      for (uint32_t j = start[cv]; j < start[cv + 1]; ++j) {
        const uint32_t o = around[j];
        const float* fo = &fn_unit[3 * o];
        if (ft[0] * fo[0] + ft[1] * fo[1] + ft[2] * fo[2] >= crease)
          for (int q = 0; q < 3; ++q) n[q] += fn[3 * o + q];
      }
      const float l = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      float* out = &g.soup[t * 18 + k * 6];
      const float* p = vtx(vi);
      for (int q = 0; q < 3; ++q) {
        out[q] = p[q];
        out[3 + q] = l > 0 ? n[q] / l : ft[q];
      }
    }
  }

  // Edges shared by two triangles bent more than the crease angle, edges of one
  // triangle only (open rims), and non-manifold edges.
  struct EdgeUse {
    uint32_t first = 0, count = 0;
    bool feature = false;
  };
  std::unordered_map<uint64_t, EdgeUse> edges;
  edges.reserve(3 * nt);
  const float feature_cos = std::cos(35.f * kPi / 180.f);
  for (size_t t = 0; t < nt; ++t) {
    if (fn_unit[3 * t] == 0 && fn_unit[3 * t + 1] == 0 && fn_unit[3 * t + 2] == 0) continue;
    for (int k = 0; k < 3; ++k) {
      uint32_t a = canon[mesh.indices[3 * t + k]], b = canon[mesh.indices[3 * t + (k + 1) % 3]];
      if (a == b) continue;
      if (a > b) std::swap(a, b);
      EdgeUse& e = edges[(uint64_t(a) << 32) | b];
      if (e.count == 0) {
        e.first = uint32_t(t);
      } else {
        const float* f0 = &fn_unit[3 * size_t(e.first)];
        const float* f1 = &fn_unit[3 * t];
        if (f0[0] * f1[0] + f0[1] * f1[1] + f0[2] * f1[2] < feature_cos) e.feature = true;
      }
      ++e.count;
    }
  }
  for (const auto& [key, e] : edges) {
    if (!(e.count == 1 || e.count > 2 || e.feature)) continue;
    for (uint32_t v : {uint32_t(key >> 32), uint32_t(key & 0xffffffffu)}) {
      const float* p = vtx(v);
      g.edges.insert(g.edges.end(), p, p + 3);
    }
  }
  return g;
}

std::string format_count(uint64_t n) {
  std::string s = std::to_string(n), out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (i && (s.size() - i) % 3 == 0) out += ',';
    out += s[i];
  }
  return out;
}

// Legend ticks at a round step (1, 2, 2.5 or 5 times a power of ten) giving
// three to six labels, all printed with the same number of decimals.
std::vector<std::pair<double, std::string>> legend_ticks(double lo, double hi) {
  std::vector<std::pair<double, std::string>> ticks;
  const double range = hi - lo;
  if (!(range > 0) || !std::isfinite(range)) return ticks;
  // Prefer a step that lands on both ends (0..5 by 1, 0..150 by 50), else
  // the round step nearest a quarter of the range.
  const double raw = range / 4, p10 = std::pow(10.0, std::floor(std::log10(raw)));
  double step = 0;
  for (double scale : {p10 * 10, p10, p10 / 10})
    for (double f : {5.0, 2.5, 2.0, 1.0}) {
      const double q = range / (f * scale);
      if (!step && q >= 2 - 1e-9 && q <= 6 + 1e-9 && std::fabs(q - std::round(q)) < 1e-6 &&
          std::fabs(lo / (f * scale) - std::round(lo / (f * scale))) < 1e-6)
        step = f * scale;
    }
  if (!step) {
    step = 5 * p10;
    for (double f : {1.0, 2.0, 2.5, 5.0})
      if (f * p10 >= raw) {
        step = f * p10;
        break;
      }
  }
  const double mag = std::max(std::fabs(lo), std::fabs(hi));
  const bool sci = mag >= 1e5 || (mag > 0 && step < 1e-3);
  int decimals = 0;  // as many as the step needs: 0.25 -> 2, 50 -> 0
  for (double scaled = step; decimals < 4 && std::fabs(scaled - std::round(scaled)) > 1e-6 * scaled;
       scaled *= 10)
    ++decimals;
  for (double v = std::ceil(lo / step - 1e-9) * step; v <= hi + 1e-9 * range; v += step) {
    char buf[32];
    if (sci)
      std::snprintf(buf, sizeof buf, "%.2g", v);
    else
      std::snprintf(buf, sizeof buf, "%.*f", decimals, std::fabs(v) < 1e-12 * range ? 0.0 : v);
    ticks.emplace_back(v, buf);
  }
  return ticks;
}

}  // namespace

struct Renderer::Impl {
  RenderOptions options;
  std::unique_ptr<GlContext> context;
  GlFunctions gl;
  std::string description;
  FrameTiming timing;
  float max_point_size = 64;

  GLuint background_prog = 0, particle_prog = 0, wall_prog = 0, edge_prog = 0;
  GLuint empty_vao = 0, particle_vao = 0;
  GLuint particle_vbo[2] = {0, 0};
  std::vector<float> cmap;  // 256 x rgb in 0..1, the particle shader's colour map
  GLuint fbo = 0, color_rb = 0, depth_rb = 0;  // what we draw into
  GLuint resolve_fbo = 0, resolve_rb = 0;      // single-sample copy when multisampling
  int samples = 0;

  // A wall mesh on the GPU: its faces and its edges, and what was last
  // uploaded, to skip re-uploading an unchanged mesh. Two: the wall, and a
  // part of it that moves with a model matrix of its own.
  struct WallGl {
    GLuint vao = 0, edge_vao = 0, vbo = 0, edge_vbo = 0;
    std::vector<float> vertices;
    std::vector<uint32_t> indices;
    GLsizei corners = 0, edge_points = 0;
  };
  WallGl walls[2];

  std::vector<uint8_t> rgba;              // readback staging
  std::vector<float> pos_radius, values;  // particle upload staging
  CullScratch cull_scratch;
  std::vector<uint32_t> drawn;  // particles that passed culling, nearest first
  std::unique_ptr<Font> font, small_font;

  ~Impl() {
    if (!context) return;
    context->make_current();
    for (GLuint p : {background_prog, particle_prog, wall_prog, edge_prog})
      if (p) gl.DeleteProgram(p);
    GLuint vaos[] = {empty_vao, particle_vao};
    if (gl.DeleteVertexArrays) gl.DeleteVertexArrays(2, vaos);
    if (gl.DeleteBuffers) gl.DeleteBuffers(2, particle_vbo);
    for (WallGl& w : walls) {
      GLuint v[] = {w.vao, w.edge_vao}, b[] = {w.vbo, w.edge_vbo};
      if (gl.DeleteVertexArrays) gl.DeleteVertexArrays(2, v);
      if (gl.DeleteBuffers) gl.DeleteBuffers(2, b);
    }
    if (gl.DeleteFramebuffers) {
      GLuint f[] = {fbo, resolve_fbo};
      gl.DeleteFramebuffers(2, f);
    }
    if (gl.DeleteRenderbuffers) {
      GLuint r[] = {color_rb, depth_rb, resolve_rb};
      gl.DeleteRenderbuffers(3, r);
    }
  }

  std::string compile(const char* vs_src, const char* fs_src, GLuint* program) {
    GLuint shaders[2];
    const char* srcs[2] = {vs_src, fs_src};
    const GLenum types[2] = {GL_VERTEX_SHADER, GL_FRAGMENT_SHADER};
    for (int i = 0; i < 2; ++i) {
      shaders[i] = gl.CreateShader(types[i]);
      gl.ShaderSource(shaders[i], 1, &srcs[i], nullptr);
      gl.CompileShader(shaders[i]);
      GLint ok = 0;
      gl.GetShaderiv(shaders[i], GL_COMPILE_STATUS, &ok);
      if (!ok) {
        char log[2048] = {};
        gl.GetShaderInfoLog(shaders[i], sizeof log, nullptr, log);
        return std::string(i ? "fragment" : "vertex") + " shader: " + log;
      }
    }
    GLuint p = gl.CreateProgram();
    gl.AttachShader(p, shaders[0]);
    gl.AttachShader(p, shaders[1]);
    gl.LinkProgram(p);
    gl.DeleteShader(shaders[0]);
    gl.DeleteShader(shaders[1]);
    GLint ok = 0;
    gl.GetProgramiv(p, GL_LINK_STATUS, &ok);
    if (!ok) {
      char log[2048] = {};
      gl.GetProgramInfoLog(p, sizeof log, nullptr, log);
      gl.DeleteProgram(p);
      return std::string("link: ") + log;
    }
    *program = p;
    return {};
  }

  GLint loc(GLuint prog, const char* name) { return gl.GetUniformLocation(prog, name); }

  std::string setup_framebuffers() {
    const int w = options.width, h = options.height;
    GLint max_samples = 0;
    gl.GetIntegerv(GL_MAX_SAMPLES, &max_samples);
    samples = options.msaa_samples > 1 ? std::min(options.msaa_samples, int(max_samples)) : 0;
    if (samples < 2) samples = 0;
    gl.GenFramebuffers(1, &fbo);
    gl.BindFramebuffer(GL_FRAMEBUFFER, fbo);
    gl.GenRenderbuffers(1, &color_rb);
    gl.BindRenderbuffer(GL_RENDERBUFFER, color_rb);
    gl.RenderbufferStorageMultisample(GL_RENDERBUFFER, samples, GL_RGBA8, w, h);
    gl.FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color_rb);
    gl.GenRenderbuffers(1, &depth_rb);
    gl.BindRenderbuffer(GL_RENDERBUFFER, depth_rb);
    gl.RenderbufferStorageMultisample(GL_RENDERBUFFER, samples, GL_DEPTH_COMPONENT24, w, h);
    gl.FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth_rb);
    if (gl.CheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
      return "framebuffer " + std::to_string(w) + "x" + std::to_string(h) + " is incomplete";
    if (samples) {
      gl.GenFramebuffers(1, &resolve_fbo);
      gl.BindFramebuffer(GL_FRAMEBUFFER, resolve_fbo);
      gl.GenRenderbuffers(1, &resolve_rb);
      gl.BindRenderbuffer(GL_RENDERBUFFER, resolve_rb);
      gl.RenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, w, h);
      gl.FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, resolve_rb);
      if (gl.CheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
        return "resolve framebuffer is incomplete";
    }
    gl.BindFramebuffer(GL_FRAMEBUFFER, fbo);
    return {};
  }

  std::string init() {
    std::string err;
    context = create_offscreen_context(&err);
    if (!context) return err;
    if (std::string missing = gl.load(*context); !missing.empty())
      return "GL entry point " + missing + " is missing";
    const char* renderer = reinterpret_cast<const char*>(gl.GetString(GL_RENDERER));
    const char* version = reinterpret_cast<const char*>(gl.GetString(GL_VERSION));
    description = std::string(renderer ? renderer : "?") + ", OpenGL " + (version ? version : "?") +
                  " (" + context->backend() + ")";
    GLfloat range[2] = {1, 64};
    gl.GetFloatv(GL_POINT_SIZE_RANGE, range);
    max_point_size = range[1];

    if (!(err = compile(shaders::kBackgroundVs, shaders::kBackgroundFs, &background_prog))
             .empty() ||
        !(err = compile(shaders::kParticleVs, shaders::kParticleFs, &particle_prog)).empty() ||
        !(err = compile(shaders::kWallVs, shaders::kWallFs, &wall_prog)).empty() ||
        !(err = compile(shaders::kEdgeVs, shaders::kEdgeFs, &edge_prog)).empty())
      return err;

    gl.GenVertexArrays(1, &empty_vao);
    gl.GenVertexArrays(1, &particle_vao);
    gl.GenBuffers(2, particle_vbo);
    for (WallGl& w : walls) {
      gl.GenVertexArrays(1, &w.vao);
      gl.GenVertexArrays(1, &w.edge_vao);
      gl.GenBuffers(1, &w.vbo);
      gl.GenBuffers(1, &w.edge_vbo);
      gl.BindVertexArray(w.vao);
      gl.BindBuffer(GL_ARRAY_BUFFER, w.vbo);
      gl.EnableVertexAttribArray(0);
      gl.VertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 24, reinterpret_cast<void*>(0));
      gl.EnableVertexAttribArray(1);
      gl.VertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, 24, reinterpret_cast<void*>(12));
      gl.BindVertexArray(w.edge_vao);
      gl.BindBuffer(GL_ARRAY_BUFFER, w.edge_vbo);
      gl.EnableVertexAttribArray(0);
      gl.VertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 12, nullptr);
    }
    gl.BindVertexArray(0);

    gl.BindVertexArray(particle_vao);
    gl.BindBuffer(GL_ARRAY_BUFFER, particle_vbo[0]);
    gl.EnableVertexAttribArray(0);
    gl.VertexAttribPointer(0, 4, GL_FLOAT, GL_FALSE, 16, nullptr);
    gl.BindBuffer(GL_ARRAY_BUFFER, particle_vbo[1]);
    gl.EnableVertexAttribArray(1);
    gl.VertexAttribPointer(1, 2, GL_FLOAT, GL_FALSE, 8, nullptr);
    gl.BindVertexArray(0);

    // The colour map the legend is drawn from, as shader uniforms; the vertex
    // shader interpolates between entries like a linear texture would.
    for (const Rgb8& c : viridis_table())
      cmap.insert(cmap.end(), {c.r / 255.f, c.g / 255.f, c.b / 255.f});

    if (!(err = setup_framebuffers()).empty()) return err;

    if (options.overlay) {
      const int size = std::max(11, int(std::lround(options.height / 30.0)));
      font = Font::open(options.font_path, size, &err);
      if (!font) return err;
      small_font = Font::open(options.font_path, std::max(9, int(std::lround(size * 0.78))), &err);
      if (!small_font) return err;
    }
    if (GLenum e = gl.GetError(); e != GL_NO_ERROR)
      return "GL error " + std::to_string(e) + " while setting up";
    return {};
  }

  void upload_wall(const WallMesh& mesh, WallGl* w) {
    if (mesh.vertices == w->vertices && mesh.indices == w->indices) return;
    w->vertices = mesh.vertices;
    w->indices = mesh.indices;
    WallGeometry g = build_wall_geometry(mesh);
    gl.BindBuffer(GL_ARRAY_BUFFER, w->vbo);
    gl.BufferData(GL_ARRAY_BUFFER, g.soup.size() * sizeof(float), g.soup.data(), GL_STATIC_DRAW);
    w->corners = GLsizei(g.soup.size() / 6);
    gl.BindBuffer(GL_ARRAY_BUFFER, w->edge_vbo);
    gl.BufferData(GL_ARRAY_BUFFER, g.edges.size() * sizeof(float), g.edges.data(), GL_STATIC_DRAW);
    w->edge_points = GLsizei(g.edges.size() / 3);
  }

  // Packs the particles to draw (all, or the culler's list, nearest first)
  // into two interleaved arrays (x, y, z, r) and (scalar, contact): two
  // attribute streams fetch faster in llvmpipe's single-threaded vertex stage
  // than four.
  size_t upload_particles(const Snapshot& s, const std::vector<uint32_t>* subset) {
    const size_t n = subset ? subset->size() : s.particle_count();
    pos_radius.resize(4 * n);
    values.resize(2 * n);
    const bool has_scalar = s.scalar.size() == s.particle_count();
    const bool has_contact = s.contact.size() == s.particle_count();
    for (size_t k = 0; k < n; ++k) {
      const size_t i = subset ? (*subset)[k] : k;
      pos_radius[4 * k] = s.positions[3 * i];
      pos_radius[4 * k + 1] = s.positions[3 * i + 1];
      pos_radius[4 * k + 2] = s.positions[3 * i + 2];
      pos_radius[4 * k + 3] = s.radius[i];
      values[2 * k] = has_scalar ? s.scalar[i] : 0.f;
      values[2 * k + 1] = has_contact ? float(s.contact[i]) : 0.f;
    }
    // Orphan and refill each buffer: the driver never waits on the last frame.
    gl.BindBuffer(GL_ARRAY_BUFFER, particle_vbo[0]);
    gl.BufferData(GL_ARRAY_BUFFER, GLsizeiptr(pos_radius.size() * 4), nullptr, GL_STREAM_DRAW);
    gl.BufferData(GL_ARRAY_BUFFER, GLsizeiptr(pos_radius.size() * 4), pos_radius.data(),
                  GL_STREAM_DRAW);
    gl.BindBuffer(GL_ARRAY_BUFFER, particle_vbo[1]);
    gl.BufferData(GL_ARRAY_BUFFER, GLsizeiptr(values.size() * 4), nullptr, GL_STREAM_DRAW);
    gl.BufferData(GL_ARRAY_BUFFER, GLsizeiptr(values.size() * 4), values.data(), GL_STREAM_DRAW);
    return n;
  }

  // Default azimuth/elevation of each preset, degrees.
  void camera_angles(float* az, float* el) const {
    switch (options.camera) {
      case CameraPreset::kFront:
        *az = 0, *el = 8;
        break;
      case CameraPreset::kTop:
        *az = 0, *el = 90;
        break;
      case CameraPreset::kIso:
      case CameraPreset::kOrbit:
        *az = -35, *el = 28;
        break;
    }
    if (options.camera == CameraPreset::kOrbit) *az += float(options.orbit_deg);
    if (options.elevation_deg >= 0) *el = float(options.elevation_deg);
  }

  void draw_overlay(Image& image, const Snapshot& s, float lo, float hi);
  Status render(const Snapshot& s, Image* image);
};

Status Renderer::Impl::render(const Snapshot& s, Image* image) {
  if (std::string why = validate_snapshot(s); !why.empty()) return backend_error(why);
  if (!context->make_current()) return backend_error("cannot make the GL context current");
  const int w = options.width, h = options.height;

  float az = 0, el = 0;
  camera_angles(&az, &el);
  const Bounds bounds = s.bounds.empty() ? compute_bounds(s) : s.bounds;
  const bool legend = options.overlay;
  // Leave the legend's strip on the right free when framing.
  const float fill = legend ? 0.86f : 0.92f;
  const CameraSetup cam = frame_bounds(bounds, az, el, float(options.fov_deg), float(w) / h, fill,
                                       options.camera == CameraPreset::kOrbit);
  // Key light from the upper left, slightly in front, fixed to the camera.
  float light[3] = {-0.45f, 0.65f, 0.62f};
  const float ll = std::sqrt(light[0] * light[0] + light[1] * light[1] + light[2] * light[2]);
  for (float& c : light) c /= ll;
  float radius = 0;
  for (int k = 0; k < 3; ++k)
    radius += 0.25f * (bounds.hi[k] - bounds.lo[k]) * (bounds.hi[k] - bounds.lo[k]);
  radius = std::sqrt(std::max(radius, 0.f));

  auto t0 = Clock::now();
  const float point_scale = cam.proj.m[5] * 0.5f * h;
  const std::vector<uint32_t>* subset = nullptr;
  if (options.cull_hidden && s.particle_count() > 0) {
    CullView cv;
    cv.view = cam.view;
    cv.proj = cam.proj;
    cv.width = w;
    cv.height = h;
    cv.point_scale = point_scale;
    cv.max_point = max_point_size;
    cv.near_plane = cam.near_plane;
    cv.far_plane = cam.far_plane;
    cv.slack = samples ? 0.75f : 0.05f;
    cull_particles(s, cv, &cull_scratch, &drawn);
    subset = &drawn;
  }
  timing.cull_ms = ms_since(t0);
  t0 = Clock::now();
  const size_t n = upload_particles(s, subset);
  timing.particles_drawn = n;
  if (options.wall != WallStyle::kHidden) {
    upload_wall(s.wall, &walls[0]);
    upload_wall(s.part, &walls[1]);
  }
  timing.upload_ms = ms_since(t0);
  t0 = Clock::now();

  // Colour range: fixed by the caller, or this frame's min..max.
  float lo = options.color_min, hi = options.color_max;
  if (!(hi > lo)) {
    lo = INFINITY, hi = -INFINITY;
    for (float v : s.scalar)
      if (std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
    if (!(hi > lo)) hi = (std::isfinite(lo) ? lo : 0) + 1, lo = hi - 1;
    // Speeds start at zero; a round top keeps the legend readable.
    if (lo >= 0) lo = 0, hi = round_up_nicely(hi);
  }

  gl.BindFramebuffer(GL_FRAMEBUFFER, fbo);
  gl.Viewport(0, 0, w, h);
  gl.ClearDepth(1.0);
  gl.Clear(GL_DEPTH_BUFFER_BIT);
  if (samples) gl.Enable(GL_MULTISAMPLE);

  // 1. Background gradient (fills every pixel, so no colour clear is needed).
  gl.Disable(GL_DEPTH_TEST);
  gl.DepthMask(GL_FALSE);
  gl.Disable(GL_BLEND);
  gl.UseProgram(background_prog);
  const auto& bt = options.background_top;
  const auto& bb = options.background_bottom;
  gl.Uniform3f(loc(background_prog, "u_top"), bt[0] / 255.f, bt[1] / 255.f, bt[2] / 255.f);
  gl.Uniform3f(loc(background_prog, "u_bottom"), bb[0] / 255.f, bb[1] / 255.f, bb[2] / 255.f);
  gl.BindVertexArray(empty_vao);
  gl.DrawArrays(GL_TRIANGLES, 0, 3);

  gl.Enable(GL_DEPTH_TEST);
  gl.DepthFunc(GL_LESS);
  gl.DepthMask(GL_TRUE);
  const bool draw_wall = options.wall != WallStyle::kHidden;
  // Each mesh's own motion folded into its view matrix (rigid: normals turn with it).
  Mat4 wall_view[2];
  for (int k = 0; k < 2; ++k) {
    Mat4 model;
    std::memcpy(model.m, k == 0 ? s.wall_model : s.part_model, sizeof model.m);
    wall_view[k] = cam.view * model;
  }
  // Draws every wall mesh that has faces: mode GL_TRIANGLES its faces, GL_LINES its edges.
  auto draw_walls = [&](GLenum mode, GLuint prog) {
    for (int k = 0; k < 2; ++k) {
      const WallGl& w = walls[k];
      const GLsizei count = mode == GL_LINES ? w.edge_points : w.corners;
      if (count == 0) continue;
      gl.UniformMatrix4fv(loc(prog, "u_view"), 1, GL_FALSE, wall_view[k].m);
      gl.BindVertexArray(mode == GL_LINES ? w.edge_vao : w.vao);
      gl.DrawArrays(mode, 0, count);
    }
  };
  auto set_wall_uniforms = [&](const float* color, float opacity, float fresnel) {
    gl.UseProgram(wall_prog);
    gl.UniformMatrix4fv(loc(wall_prog, "u_proj"), 1, GL_FALSE, cam.proj.m);
    gl.Uniform3f(loc(wall_prog, "u_color"), color[0], color[1], color[2]);
    gl.Uniform3f(loc(wall_prog, "u_light"), light[0], light[1], light[2]);
    gl.Uniform1f(loc(wall_prog, "u_opacity"), opacity);
    gl.Uniform1f(loc(wall_prog, "u_fresnel"), fresnel);
    gl.Uniform1i(loc(wall_prog, "u_shading"), options.shading ? 1 : 0);
  };

  // 2. The far side of the wall (faces turned away from the camera), opaque:
  //    the inside of the vessel behind the particles.
  if (draw_wall) {
    set_wall_uniforms(kWallInnerColor, 1.f, 0.f);
    gl.Enable(GL_CULL_FACE);
    gl.CullFace(GL_FRONT);
    draw_walls(GL_TRIANGLES, wall_prog);
    gl.Disable(GL_CULL_FACE);
  }

  // 3. Particles as sphere impostors.
  if (n) {
    gl.Enable(GL_PROGRAM_POINT_SIZE);
    gl.UseProgram(particle_prog);
    gl.UniformMatrix4fv(loc(particle_prog, "u_view"), 1, GL_FALSE, cam.view.m);
    gl.UniformMatrix4fv(loc(particle_prog, "u_proj"), 1, GL_FALSE, cam.proj.m);
    gl.Uniform1f(loc(particle_prog, "u_point_scale"), point_scale);
    gl.Uniform1f(loc(particle_prog, "u_max_point"), max_point_size);
    gl.Uniform2f(loc(particle_prog, "u_range"), lo, 1.f / (hi - lo));
    gl.Uniform1i(loc(particle_prog, "u_mode"), options.color == ColorMode::kSpeed ? 0 : 1);
    gl.Uniform3fv(loc(particle_prog, "u_cmap"), 256, cmap.data());
    gl.Uniform3f(loc(particle_prog, "u_contact_color"), kContactColor.r / 255.f,
                 kContactColor.g / 255.f, kContactColor.b / 255.f);
    gl.Uniform3f(loc(particle_prog, "u_free_color"), kFreeColor.r / 255.f, kFreeColor.g / 255.f,
                 kFreeColor.b / 255.f);
    gl.Uniform1i(loc(particle_prog, "u_shading"), options.shading ? 1 : 0);
    gl.Uniform3f(loc(particle_prog, "u_light"), light[0], light[1], light[2]);
    float half[3] = {light[0], light[1], light[2] + 1.f};
    const float hl = std::sqrt(half[0] * half[0] + half[1] * half[1] + half[2] * half[2]);
    gl.Uniform3f(loc(particle_prog, "u_half"), half[0] / hl, half[1] / hl, half[2] / hl);
    gl.Uniform2f(loc(particle_prog, "u_fog"), cam.distance - 0.5f * radius,
                 cam.distance + 1.2f * radius);
    gl.Uniform1f(loc(particle_prog, "u_fog_amount"), options.shading ? 0.35f : 0.f);
    gl.BindVertexArray(particle_vao);
    gl.DrawArrays(GL_POINTS, 0, GLsizei(n));
  }

  // 4. The near side as glass: blended over everything, not writing depth, so
  //    the particles behind it stay visible.
  if (draw_wall && options.wall == WallStyle::kGlass) {
    gl.Enable(GL_BLEND);
    gl.BlendFuncSeparate(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA, GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
    gl.DepthMask(GL_FALSE);
    set_wall_uniforms(kWallColor, options.wall_opacity, 0.55f);
    gl.Enable(GL_CULL_FACE);
    gl.CullFace(GL_BACK);
    draw_walls(GL_TRIANGLES, wall_prog);
    gl.Disable(GL_CULL_FACE);
  }

  // 5. Rims and creases as thin lines, so the vessel's outline reads even
  //    where the glass is faint.
  if (draw_wall) {
    gl.Enable(GL_BLEND);
    gl.BlendFuncSeparate(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA, GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
    gl.DepthMask(GL_FALSE);
    gl.DepthFunc(GL_LEQUAL);
    gl.UseProgram(edge_prog);
    gl.UniformMatrix4fv(loc(edge_prog, "u_proj"), 1, GL_FALSE, cam.proj.m);
    gl.Uniform4f(loc(edge_prog, "u_color"), 0.85f, 0.90f, 1.0f, options.shading ? 0.55f : 1.f);
    // Anti-aliased lines: the rims are the sharpest edges in the frame.
    if (options.shading) gl.Enable(GL_LINE_SMOOTH);
    draw_walls(GL_LINES, edge_prog);
    gl.Disable(GL_LINE_SMOOTH);
  }
  gl.DepthMask(GL_TRUE);
  gl.DepthFunc(GL_LESS);
  gl.Disable(GL_BLEND);
  gl.BindVertexArray(0);

  if (samples) {
    gl.BindFramebuffer(GL_READ_FRAMEBUFFER, fbo);
    gl.BindFramebuffer(GL_DRAW_FRAMEBUFFER, resolve_fbo);
    gl.BlitFramebuffer(0, 0, w, h, 0, 0, w, h, GL_COLOR_BUFFER_BIT, GL_NEAREST);
    gl.BindFramebuffer(GL_READ_FRAMEBUFFER, resolve_fbo);
  } else {
    gl.BindFramebuffer(GL_READ_FRAMEBUFFER, fbo);
  }
  gl.Finish();
  timing.draw_ms = ms_since(t0);

  t0 = Clock::now();
  rgba.resize(size_t(w) * h * 4);
  gl.PixelStorei(GL_PACK_ALIGNMENT, 1);
  gl.ReadBuffer(GL_COLOR_ATTACHMENT0);
  gl.ReadPixels(0, 0, w, h, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
  if (GLenum e = gl.GetError(); e != GL_NO_ERROR)
    return backend_error("GL error " + std::to_string(e) + " while rendering frame " +
                         std::to_string(s.frame));
  if (image->width != w || image->height != h) image->resize(w, h);
  // GL rows run bottom-up; images top-down.
  for (int y = 0; y < h; ++y) {
    const uint8_t* src = &rgba[size_t(h - 1 - y) * w * 4];
    uint8_t* dst = image->pixel(0, y);
    for (int x = 0; x < w; ++x) {
      dst[3 * x] = src[4 * x];
      dst[3 * x + 1] = src[4 * x + 1];
      dst[3 * x + 2] = src[4 * x + 2];
    }
  }
  timing.readback_ms = ms_since(t0);

  t0 = Clock::now();
  if (options.overlay) draw_overlay(*image, s, lo, hi);
  timing.overlay_ms = ms_since(t0);
  return Status::ok();
}

void Renderer::Impl::draw_overlay(Image& img, const Snapshot& s, float lo, float hi) {
  const int w = img.width, h = img.height;
  const int m = std::max(6, h / 40);  // margin
  const Rgb8 white{235, 238, 245}, grey{170, 178, 192};

  // Time, frame and particle count, top left.
  char line1[64];
  std::snprintf(line1, sizeof line1, "t = %.3f s", s.time);
  std::string line2 =
      "frame " + std::to_string(s.frame) + "   " + format_count(s.particle_count()) + " particles";
  if (s.total_particles > s.particle_count())
    line2 = "frame " + std::to_string(s.frame) + "   " + format_count(s.particle_count()) + " of " +
            format_count(s.total_particles) + " particles";
  const int pad = m / 2;
  const int box_w = std::max(font->measure(line1), small_font->measure(line2)) + 2 * pad;
  const int box_h = font->line_height() + small_font->line_height() + 2 * pad;
  fill_rect(img, m - pad, m - pad, m - pad + box_w, m - pad + box_h, Rgb8{0, 0, 0}, 0.35f);
  font->draw(img, m, m + font->ascender(), line1, white);
  small_font->draw(img, m, m + font->line_height() + small_font->ascender(), line2, grey);

  // Legend, right edge.
  if (options.color == ColorMode::kSpeed) {
    const int bar_w = std::max(8, w / 70);
    const int bar_h = h / 2;
    const int labels_w = small_font->measure("0000.00");
    const int x0 = w - m - labels_w - bar_w - m / 2;
    const int y0 = (h - bar_h) / 2;
    const std::string title = options.color_label;
    small_font->draw(img, std::min(x0, w - m - small_font->measure(title)), y0 - m / 2, title,
                     white);
    for (int y = 0; y < bar_h; ++y) {
      const Rgb8 c = viridis(1.f - float(y) / float(bar_h - 1));
      fill_rect(img, x0, y0 + y, x0 + bar_w, y0 + y + 1, c, 1.f);
    }
    // Thin frame around the bar.
    fill_rect(img, x0 - 1, y0 - 1, x0 + bar_w + 1, y0, grey, 0.8f);
    fill_rect(img, x0 - 1, y0 + bar_h, x0 + bar_w + 1, y0 + bar_h + 1, grey, 0.8f);
    fill_rect(img, x0 - 1, y0, x0, y0 + bar_h, grey, 0.8f);
    fill_rect(img, x0 + bar_w, y0, x0 + bar_w + 1, y0 + bar_h, grey, 0.8f);
    for (const auto& [value, label] : legend_ticks(lo, hi)) {
      const double f = (value - lo) / (hi - lo);
      const int y = y0 + int(std::lround((1.0 - f) * (bar_h - 1)));
      fill_rect(img, x0 + bar_w, y, x0 + bar_w + m / 3, y + 1, grey, 1.f);
      small_font->draw(img, x0 + bar_w + m / 2, y + small_font->ascender() / 2 - 1, label, white);
    }
  } else {
    const int sw = small_font->ascender();
    const char* labels[2] = {"touching wall", "free"};
    const Rgb8 colors[2] = {kContactColor, kFreeColor};
    const int text_w = std::max(small_font->measure(labels[0]), small_font->measure(labels[1]));
    const int x0 = w - m - text_w - sw - m / 2;
    int y = h / 2 - small_font->line_height();
    for (int i = 0; i < 2; ++i) {
      fill_rect(img, x0, y - sw, x0 + sw, y, colors[i], 1.f);
      small_font->draw(img, x0 + sw + m / 2, y, labels[i], white);
      y += small_font->line_height() + m / 3;
    }
  }
}

Renderer::Renderer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Renderer::~Renderer() = default;

std::unique_ptr<Renderer> Renderer::create(const RenderOptions& options, Status* status) {
  auto fail = [&](const std::string& m) -> std::unique_ptr<Renderer> {
    if (status) *status = backend_error(m);
    return nullptr;
  };
  if (options.width < 16 || options.height < 16 || options.width > 8192 || options.height > 8192)
    return fail("image size " + std::to_string(options.width) + "x" +
                std::to_string(options.height) + " is outside 16..8192");
  if (!(options.wall_opacity >= 0 && options.wall_opacity <= 1))
    return fail("wall opacity must be in 0..1");
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  if (std::string err = impl->init(); !err.empty()) return fail("renderer: " + err);
  if (status) *status = Status::ok();
  return std::unique_ptr<Renderer>(new Renderer(std::move(impl)));
}

Status Renderer::render(const Snapshot& snapshot, Image* image) {
  return impl_->render(snapshot, image);
}
void Renderer::set_orbit_deg(double deg) {
  impl_->options.orbit_deg = deg;
}
const RenderOptions& Renderer::options() const {
  return impl_->options;
}
const FrameTiming& Renderer::last_timing() const {
  return impl_->timing;
}
std::string Renderer::gl_description() const {
  return impl_->description;
}

}  // namespace collido::render
