#include "render/camera.h"

#include <algorithm>
#include <cmath>

namespace collido::render {
namespace {

constexpr float kPi = 3.14159265358979f;

void normalize(float v[3]) {
  const float l = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  if (l > 0)
    for (int i = 0; i < 3; ++i) v[i] /= l;
}
void cross(const float a[3], const float b[3], float out[3]) {
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}
float dot(const float a[3], const float b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// Camera basis for a direction: back points from the target to the eye.
void basis(float az, float el, float back[3], float right[3], float up[3]) {
  back[0] = std::sin(az) * std::cos(el);
  back[1] = -std::cos(az) * std::cos(el);
  back[2] = std::sin(el);
  // Looking straight down, +z is no use as "up"; take the horizontal direction
  // away from the viewer instead, so a top view keeps the front at the bottom.
  float world_up[3] = {0, 0, 1};
  if (std::fabs(std::cos(el)) < 1e-3f) {
    world_up[0] = -std::sin(az);
    world_up[1] = std::cos(az);
    world_up[2] = 0;
  }
  cross(world_up, back, right);
  normalize(right);
  cross(back, right, up);
}

// Smallest distance from the target at which every corner of the box fits.
float fit_distance(const float half[3], float az, float el, float tan_x, float tan_y) {
  float back[3], right[3], up[3];
  basis(az, el, back, right, up);
  float d = 0;
  for (int c = 0; c < 8; ++c) {
    const float p[3] = {(c & 1) ? half[0] : -half[0], (c & 2) ? half[1] : -half[1],
                        (c & 4) ? half[2] : -half[2]};
    const float toward = dot(p, back);
    d = std::max(d, std::fabs(dot(p, right)) / tan_x + toward);
    d = std::max(d, std::fabs(dot(p, up)) / tan_y + toward);
  }
  return d;
}

}  // namespace

Mat4 Mat4::identity() {
  Mat4 r{};
  r.m[0] = r.m[5] = r.m[10] = r.m[15] = 1;
  return r;
}

Mat4 operator*(const Mat4& a, const Mat4& b) {
  Mat4 r{};
  for (int c = 0; c < 4; ++c)
    for (int row = 0; row < 4; ++row) {
      float s = 0;
      for (int k = 0; k < 4; ++k) s += a.m[k * 4 + row] * b.m[c * 4 + k];
      r.m[c * 4 + row] = s;
    }
  return r;
}

Mat4 look_at(const float eye[3], const float target[3], const float up_hint[3]) {
  float f[3] = {target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]};
  normalize(f);
  float s[3], u[3];
  cross(f, up_hint, s);
  normalize(s);
  cross(s, f, u);
  Mat4 r = Mat4::identity();
  r.m[0] = s[0];
  r.m[4] = s[1];
  r.m[8] = s[2];
  r.m[1] = u[0];
  r.m[5] = u[1];
  r.m[9] = u[2];
  r.m[2] = -f[0];
  r.m[6] = -f[1];
  r.m[10] = -f[2];
  r.m[12] = -dot(s, eye);
  r.m[13] = -dot(u, eye);
  r.m[14] = dot(f, eye);
  return r;
}

Mat4 perspective(float fovy, float aspect, float near, float far) {
  const float f = 1.f / std::tan(fovy / 2);
  Mat4 r{};
  r.m[0] = f / aspect;
  r.m[5] = f;
  r.m[10] = (far + near) / (near - far);
  r.m[11] = -1;
  r.m[14] = 2 * far * near / (near - far);
  return r;
}

CameraSetup frame_bounds(const Bounds& bounds, float azimuth_deg, float elevation_deg,
                         float fovy_deg, float aspect, float fill, bool orbit) {
  float center[3], half[3];
  for (int k = 0; k < 3; ++k) {
    float lo = bounds.lo[k], hi = bounds.hi[k];
    if (bounds.empty()) lo = -1, hi = 1;
    center[k] = 0.5f * (lo + hi);
    half[k] = std::max(0.5f * (hi - lo), 1e-6f);
  }
  // A flat box (a single particle, a plane) still needs some depth to frame.
  const float biggest = std::max({half[0], half[1], half[2]});
  for (int k = 0; k < 3; ++k) half[k] = std::max(half[k], 1e-3f * biggest);

  const float az = azimuth_deg * kPi / 180.f;
  const float el = std::clamp(elevation_deg, -90.f, 90.f) * kPi / 180.f;
  const float fovy = std::clamp(fovy_deg, 1.f, 150.f) * kPi / 180.f;
  const float tan_y = std::tan(fovy / 2) * fill;
  const float tan_x = std::tan(fovy / 2) * aspect * fill;

  float d = 0;
  if (orbit) {
    for (int i = 0; i < 72; ++i)
      d = std::max(d, fit_distance(half, 2 * kPi * i / 72, el, tan_x, tan_y));
  } else {
    d = fit_distance(half, az, el, tan_x, tan_y);
  }
  const float radius = std::sqrt(half[0] * half[0] + half[1] * half[1] + half[2] * half[2]);
  d = std::max(d, 1e-3f * radius);

  float back[3], right[3], up[3];
  basis(az, el, back, right, up);
  CameraSetup cam{};
  for (int k = 0; k < 3; ++k) {
    cam.target[k] = center[k];
    cam.eye[k] = center[k] + d * back[k];
  }
  cam.distance = d;
  // Particles may leave the box (splashes); keep a margin of one box radius.
  cam.near_plane = std::max(d - 2 * radius, 1e-3f * d);
  cam.far_plane = d + 2 * radius;
  cam.view = look_at(cam.eye, cam.target, up);
  cam.proj = perspective(fovy, aspect, cam.near_plane, cam.far_plane);
  return cam;
}

}  // namespace collido::render
