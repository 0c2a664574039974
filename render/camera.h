// Camera math of the renderer: column-major 4x4 matrices (as GL takes them) and
// automatic framing of a box. Internal to render/, but free of GL so tests can
// check it.
#pragma once

#include "render/snapshot.h"

namespace collido::render {

struct Mat4 {
  float m[16];  // column-major: element (row r, column c) is m[c * 4 + r]
  static Mat4 identity();
};
Mat4 operator*(const Mat4& a, const Mat4& b);

// Right-handed view matrix looking from eye at target.
Mat4 look_at(const float eye[3], const float target[3], const float up[3]);
// OpenGL perspective projection; fovy in radians, near/far > 0 in world units.
Mat4 perspective(float fovy, float aspect, float near, float far);

struct CameraSetup {
  Mat4 view, proj;
  float eye[3];
  float target[3];
  float distance;  // eye to target, world units
  float near_plane, far_plane;
};

// Frames bounds from the direction given by azimuth (degrees, 0 = from -y,
// growing counter-clockwise seen from above) and elevation (degrees above the
// horizon), so the whole box fits into fill (0..1) of the smaller image side.
// When orbit is true the distance is the largest over all azimuths, so the
// box does not breathe while the camera circles it.
CameraSetup frame_bounds(const Bounds& bounds, float azimuth_deg, float elevation_deg,
                         float fovy_deg, float aspect, float fill, bool orbit);

}  // namespace collido::render
