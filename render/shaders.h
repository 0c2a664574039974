// GLSL 3.30 core sources of the renderer. Internal to render/.
#pragma once

namespace collido::render::shaders {

// A full-screen triangle with a vertical gradient; no vertex buffer needed.
inline constexpr const char* kBackgroundVs = R"(#version 330 core
out float v_t;
void main() {
  vec2 p = vec2((gl_VertexID & 1) * 4.0 - 1.0, (gl_VertexID & 2) * 2.0 - 1.0);
  v_t = p.y * 0.5 + 0.5;
  gl_Position = vec4(p, 0.0, 1.0);
}
)";
inline constexpr const char* kBackgroundFs = R"(#version 330 core
in float v_t;
uniform vec3 u_top;
uniform vec3 u_bottom;
out vec4 o_color;
void main() { o_color = vec4(mix(u_bottom, u_top, clamp(v_t, 0.0, 1.0)), 1.0); }
)";

// Particles: one point per particle, drawn as a lit sphere in the fragment
// shader with its true depth, so spheres intersect each other and the wall
// correctly (the same impostor ParaView's point-gaussian sphere mode uses).
// llvmpipe shades vertices and sets up points on one thread, so the vertex
// stage is kept lean: no texture fetch (the colour map is a uniform array) and
// six varyings, with fog folded into the colour.
inline constexpr const char* kParticleVs = R"(#version 330 core
layout(location = 0) in vec4 a_pos_radius;  // x, y, z, radius
layout(location = 1) in vec2 a_value;       // scalar, contact flag
uniform mat4 u_view;
uniform mat4 u_proj;
uniform float u_point_scale;  // pixels per world unit at eye distance 1
uniform float u_max_point;    // largest point size the driver draws
uniform vec2 u_range;         // scalar at the low end, 1 / (high - low)
uniform int u_mode;           // 0: colour map by scalar, 1: contact colours
uniform vec3 u_cmap[256];
uniform vec3 u_contact_color;
uniform vec3 u_free_color;
uniform vec2 u_fog;           // eye distances where depth cueing starts and ends
uniform float u_fog_amount;
out vec4 v_color;   // rgb, and the window-depth offset of the sphere's front
out vec2 v_shape;   // point-square to sphere scale, fog factor
void main() {
  float r = a_pos_radius.w;
  vec4 eye = u_view * vec4(a_pos_radius.xyz, 1.0);
  vec4 clip = u_proj * eye;
  gl_Position = clip;
  float dist = max(-eye.z, 1e-6);
  float diameter = 2.0 * r * u_point_scale / dist;
  // One extra pixel so the silhouette is not cut by the square's edge.
  float size = min(diameter + 1.0, u_max_point);
  gl_PointSize = size;
  // Window depth of the sphere's nearest point minus that of its centre; the
  // fragment shader scales it by the surface's z to get each pixel's depth.
  vec4 front = u_proj * vec4(eye.xy, eye.z + r, 1.0);
  float dz = 0.5 * (front.z / front.w - clip.z / clip.w);
  vec3 c;
  if (u_mode == 0) {
    float t = clamp((a_value.x - u_range.x) * u_range.y, 0.0, 1.0) * 255.0;
    int i = min(int(t), 254);
    c = mix(u_cmap[i], u_cmap[i + 1], t - float(i));
  } else {
    c = a_value.y > 0.5 ? u_contact_color : u_free_color;
  }
  v_color = vec4(c, dz);
  float fog = clamp((dist - u_fog.x) / max(u_fog.y - u_fog.x, 1e-6), 0.0, 1.0);
  v_shape = vec2(size / max(diameter, 1e-6), 1.0 - u_fog_amount * fog);
}
)";
inline constexpr const char* kParticleFs = R"(#version 330 core
in vec4 v_color;
in vec2 v_shape;
uniform int u_shading;
uniform vec3 u_light;    // direction towards the key light, eye space
uniform vec3 u_half;     // Blinn half vector of the key light and the view
out vec4 o_color;
void main() {
  vec2 p = (gl_PointCoord * 2.0 - 1.0) * v_shape.x;
  p.y = -p.y;
  float d2 = dot(p, p);
  if (d2 > 1.0) discard;
  float z = sqrt(1.0 - d2);
  gl_FragDepth = gl_FragCoord.z + v_color.a * z;
  if (u_shading == 0) {
    o_color = vec4(v_color.rgb, 1.0);
    return;
  }
  vec3 n = vec3(p, z);
  float diffuse = max(dot(n, u_light), 0.0);
  // x^48 by squaring: llvmpipe turns pow() into exp2/log2 polynomials.
  float s1 = max(dot(n, u_half), 0.0);
  float s2 = s1 * s1, s4 = s2 * s2, s8 = s4 * s4, s16 = s8 * s8;
  float spec = s16 * s16 * s16;
  // Darken toward the silhouette a little so touching balls stay apart.
  float rim = 0.75 + 0.25 * z;
  vec3 c = v_color.rgb * (0.3 + 0.75 * diffuse) * rim + vec3(0.45) * spec;
  o_color = vec4(c * v_shape.y, 1.0);
}
)";

// The wall: smooth normals within a crease angle, lit on both sides.
inline constexpr const char* kWallVs = R"(#version 330 core
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec3 a_normal;
uniform mat4 u_view;
uniform mat4 u_proj;
out vec3 v_normal;
out vec3 v_pos;
void main() {
  vec4 eye = u_view * vec4(a_pos, 1.0);
  v_pos = eye.xyz;
  v_normal = mat3(u_view) * a_normal;
  gl_Position = u_proj * eye;
}
)";
inline constexpr const char* kWallFs = R"(#version 330 core
in vec3 v_normal;
in vec3 v_pos;
uniform vec3 u_color;
uniform vec3 u_light;
uniform float u_opacity;   // base opacity; 1 draws an opaque surface
uniform float u_fresnel;   // extra opacity at grazing angles (glass rims)
uniform int u_shading;
out vec4 o_color;
void main() {
  vec3 n = normalize(v_normal);
  vec3 v = normalize(-v_pos);
  if (dot(n, v) < 0.0) n = -n;  // two-sided: light the side we see
  if (u_shading == 0) {
    o_color = vec4(u_color, u_opacity);
    return;
  }
  float ndv = clamp(dot(n, v), 0.0, 1.0);
  float diffuse = max(dot(n, u_light), 0.0);
  vec3 h = normalize(u_light + v);
  float s1 = max(dot(n, h), 0.0);
  float s2 = s1 * s1, s4 = s2 * s2, s8 = s4 * s4, s16 = s8 * s8;
  float spec = s16 * s16;
  vec3 c = u_color * (0.35 + 0.65 * diffuse) + vec3(0.5) * spec;
  float edge = (1.0 - ndv) * (1.0 - ndv) * (1.0 - ndv);
  float a = clamp(u_opacity + u_fresnel * edge + 0.6 * spec * u_fresnel, 0.0, 1.0);
  o_color = vec4(c, a);
}
)";

// Crease and boundary edges of the wall as thin lines (rims, corners).
inline constexpr const char* kEdgeVs = R"(#version 330 core
layout(location = 0) in vec3 a_pos;
uniform mat4 u_view;
uniform mat4 u_proj;
void main() {
  gl_Position = u_proj * u_view * vec4(a_pos, 1.0);
  // Lines lie exactly on the wall's edges; pull them a hair toward the camera
  // so they do not fight with the faces they bound (seen as dashed rims).
  gl_Position.z -= 4e-4 * gl_Position.w;
}
)";
inline constexpr const char* kEdgeFs = R"(#version 330 core
uniform vec4 u_color;
out vec4 o_color;
void main() { o_color = u_color; }
)";

}  // namespace collido::render::shaders
