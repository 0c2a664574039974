#include "sim/shapes.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <map>
#include <set>

namespace collido::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

struct Builder {
  TriangleMesh mesh;
  uint32_t vertex(Vec3d p) {
    mesh.vertices.push_back(p);
    return static_cast<uint32_t>(mesh.vertices.size() - 1);
  }
  void tri(uint32_t a, uint32_t b, uint32_t c) {
    mesh.source_ids.push_back(static_cast<uint32_t>(mesh.triangles.size()));
    mesh.triangles.push_back({a, b, c});
  }
};

// A ring of `n` vertices at height z; a zero radius gives one apex vertex.
std::vector<uint32_t> ring(Builder& b, double r, double z, int n) {
  if (r == 0) return std::vector<uint32_t>(n, b.vertex({0, 0, z}));
  std::vector<uint32_t> ids(n);
  for (int i = 0; i < n; ++i) {
    double a = 2 * kPi * i / n;
    ids[i] = b.vertex({r * std::cos(a), r * std::sin(a), z});
  }
  return ids;
}

// A cap as a fan from the ring's first vertex: n - 2 triangles, no centre vertex.
void cap(Builder& b, const std::vector<uint32_t>& r, bool facing_up) {
  const int n = static_cast<int>(r.size());
  for (int i = 1; i + 1 < n; ++i) {
    if (facing_up)
      b.tri(r[0], r[i], r[i + 1]);
    else
      b.tri(r[0], r[i + 1], r[i]);
  }
}

TriangleMesh lathe(double r0, double r1, double h, int n, Caps caps) {
  Builder b;
  auto lo = ring(b, r0, 0, n), hi = ring(b, r1, h, n);
  for (int i = 0; i < n; ++i) {
    int j = (i + 1) % n;
    if (r0 > 0) b.tri(lo[i], lo[j], hi[j]);
    if (r1 > 0) b.tri(lo[i], hi[j], hi[i]);
  }
  if (r0 > 0 && (caps == Caps::kBoth || caps == Caps::kBottom)) cap(b, lo, false);
  if (r1 > 0 && (caps == Caps::kBoth || caps == Caps::kTop)) cap(b, hi, true);
  return b.mesh;
}

}  // namespace

TriangleMesh make_cylinder(double r, double h, int segments, Caps caps) {
  return lathe(r, r, h, segments, caps);
}

TriangleMesh make_cone(double r_bottom, double r_top, double h, int segments, Caps caps) {
  return lathe(r_bottom, r_top, h, segments, caps);
}

TriangleMesh make_box(double sx, double sy, double sz) {
  Builder b;
  const double x = sx / 2, y = sy / 2;
  uint32_t v[8];
  for (int i = 0; i < 8; ++i)
    v[i] = b.vertex({(i & 1) ? x : -x, (i & 2) ? y : -y, (i & 4) ? sz : 0.0});
  // Each face as two triangles, corners counter-clockwise seen from outside.
  const int faces[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& f : faces) {
    b.tri(v[f[0]], v[f[1]], v[f[2]]);
    b.tri(v[f[0]], v[f[2]], v[f[3]]);
  }
  return b.mesh;
}

TriangleMesh make_sphere(double r, int subdivisions) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Vec3d> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                          {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  std::vector<std::array<uint32_t, 3>> f = {
      {0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
      {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
      {3, 8, 9},  {4, 9, 5},  {2, 4, 11},  {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (auto& p : v) p = p * (1.0 / length(p));
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> mid;
    auto midpoint = [&](uint32_t a, uint32_t b) {
      auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      Vec3d m = (v[a] + v[b]) * 0.5;
      v.push_back(m * (1.0 / length(m)));
      return mid[key] = static_cast<uint32_t>(v.size() - 1);
    };
    std::vector<std::array<uint32_t, 3>> next;
    next.reserve(f.size() * 4);
    for (const auto& tri : f) {
      const uint32_t a = midpoint(tri[0], tri[1]);
      const uint32_t b = midpoint(tri[1], tri[2]);
      const uint32_t c = midpoint(tri[2], tri[0]);
      next.push_back({tri[0], a, c});
      next.push_back({tri[1], b, a});
      next.push_back({tri[2], c, b});
      next.push_back({a, b, c});
    }
    f.swap(next);
  }
  TriangleMesh m;
  for (const auto& p : v) m.vertices.push_back({p.x * r, p.y * r, p.z * r + r});
  m.triangles = f;
  for (size_t i = 0; i < f.size(); ++i) m.source_ids.push_back(static_cast<uint32_t>(i));
  return m;
}

void translate(TriangleMesh& mesh, Vec3d d) {
  for (auto& v : mesh.vertices) v = v + d;
}

namespace {

// Welds a union whose parts share boundary rings into one closed surface.
TriangleMesh weld_union(const std::vector<TriangleMesh>& parts) {
  std::vector<std::array<Vec3d, 3>> soup;
  for (const auto& p : parts)
    for (size_t t = 0; t < p.triangles.size(); ++t) soup.push_back({p.corner(t, 0), p.corner(t, 1), p.corner(t, 2)});
  return weld_soup(soup, {}, 1e-9, nullptr);
}

}  // namespace

TriangleMesh make_wall2() {
  const int n = 128;
  // Body: open at the bottom, where the funnel continues it.
  TriangleMesh body = make_cylinder(50, 100, n, Caps::kTop);
  // Funnel from the outlet (r = 10, z = -50) up to the body (r = 50, z = 0).
  TriangleMesh funnel = make_cone(10, 50, 50, n, Caps::kNone);
  translate(funnel, {0, 0, -50});
  // Outlet pipe, closed at its bottom.
  TriangleMesh outlet = make_cylinder(10, 50, n, Caps::kBottom);
  translate(outlet, {0, 0, -100});
  TriangleMesh vessel = weld_union({body, funnel, outlet});
  // Beam pipe hanging from the lid into the vessel, a closed body of its own.
  TriangleMesh beam = make_cylinder(8, 60, n, Caps::kBoth);
  translate(beam, {0, 0, 39});
  append_mesh(vessel, beam);
  return vessel;
}

namespace {

struct ShapeArgs {
  std::map<std::string, double> num;
  std::string caps = "";
  char axis = 'z';  // a lathed shape's axis
};

Expected<ShapeArgs> parse_params(const std::string& kind, const std::string& params,
                                 const std::set<std::string>& allowed) {
  ShapeArgs out;
  size_t pos = 0;
  while (pos < params.size()) {
    size_t comma = params.find(',', pos);
    std::string item = params.substr(pos, comma == std::string::npos ? std::string::npos : comma - pos);
    pos = comma == std::string::npos ? params.size() : comma + 1;
    if (item.empty()) continue;
    size_t eq = item.find('=');
    if (eq == std::string::npos) return invalid_argument(kind + ": expected key=value, got '" + item + "'");
    std::string key = item.substr(0, eq), value = item.substr(eq + 1);
    if (!allowed.count(key) && key != "dx" && key != "dy" && key != "dz")
      return invalid_argument(kind + ": unknown parameter '" + key + "'");
    if (key == "axis") {
      if (value != "x" && value != "y" && value != "z")
        return invalid_argument(kind + ": axis must be x, y or z, got '" + value + "'");
      out.axis = value[0];
      continue;
    }
    if (key == "caps") {
      if (value != "both" && value != "none" && value != "top" && value != "bottom")
        return invalid_argument(kind + ": caps must be both, none, top or bottom, got '" + value + "'");
      out.caps = value;
      continue;
    }
    char* end = nullptr;
    double v = std::strtod(value.c_str(), &end);
    if (end == value.c_str() || *end != '\0' || !std::isfinite(v))
      return invalid_argument(kind + ": " + key + " must be a finite number, got '" + value + "'");
    // An offset far past the shape's own size leaves it in float's rounding
    // (box:dx=1e20 came out flat along x, and a fill blamed its region).
    if ((key == "dx" || key == "dy" || key == "dz") && !(std::fabs(v) <= 1e9))
      return invalid_argument(kind + ": " + key + " must lie within +-1e9, got '" + value + "'");
    out.num[key] = v;
  }
  return out;
}

Caps caps_of(const std::string& s, Caps fallback) {
  if (s == "both") return Caps::kBoth;
  if (s == "none") return Caps::kNone;
  if (s == "top") return Caps::kTop;
  if (s == "bottom") return Caps::kBottom;
  return fallback;
}

// Most triangles one wall spec may make; make_shape explains why.
constexpr size_t kMaxShapeTriangles = size_t(1) << 21;

// One shape of a spec; `budget` is how many triangles it may still make, checked
// from its parameters before anything is built.
Expected<TriangleMesh> make_one(const std::string& spec, size_t budget) {
  const size_t colon = spec.find(':');
  const std::string kind = spec.substr(0, colon);
  const std::string params = colon == std::string::npos ? "" : spec.substr(colon + 1);
  auto get = [](const ShapeArgs& a, const char* k, double d) {
    auto it = a.num.find(k);
    return it == a.num.end() ? d : it->second;
  };
  auto positive = [&](const char* k, double v) -> Status {
    if (!(v > 0) || v > 1e9) return invalid_argument(kind + ": " + k + " must be in (0, 1e9], got " + std::to_string(v));
    return Status::ok();
  };
  auto segs = [&](double v) -> Status {
    if (v < 3 || v > 100000 || v != std::floor(v))
      return invalid_argument(kind + ": segments must be an integer in [3, 100000], got " + std::to_string(v));
    return Status::ok();
  };
  auto fits = [&](double triangles) -> Status {
    if (triangles > double(budget))
      return invalid_argument("wall spec: the shapes add up to more than " +
                              std::to_string(kMaxShapeTriangles) + " triangles");
    return Status::ok();
  };

  TriangleMesh mesh;
  ShapeArgs a;
  if (kind == "wall1" || kind == "wall2") {
    auto p = parse_params(kind, params, {});
    if (!p) return p.status();
    a = *p;
    mesh = kind == "wall1" ? make_cylinder(50, 100, 40) : make_wall2();
  } else if (kind == "cylinder") {
    auto p = parse_params(kind, params, {"r", "h", "segments", "caps", "axis"});
    if (!p) return p.status();
    a = *p;
    double r = get(a, "r", 50), h = get(a, "h", 100), n = get(a, "segments", 40);
    for (Status s : {positive("r", r), positive("h", h), segs(n), fits(4 * n)})
      if (!s) return s;
    mesh = make_cylinder(r, h, static_cast<int>(n), caps_of(a.caps, Caps::kBoth));
  } else if (kind == "cone" || kind == "funnel") {
    auto p = parse_params(kind, params, {"r1", "r2", "h", "segments", "caps", "axis"});
    if (!p) return p.status();
    a = *p;
    double r1 = get(a, "r1", 10), r2 = get(a, "r2", kind == "cone" ? 0 : 40), h = get(a, "h", 30),
           n = get(a, "segments", 64);
    if (r1 < 0 || r2 < 0 || (r1 == 0 && r2 == 0) || r1 > 1e9 || r2 > 1e9)
      return invalid_argument(kind + ": radii must be >= 0, not both zero");
    for (Status s : {positive("h", h), segs(n), fits(4 * n)})
      if (!s) return s;
    mesh = make_cone(r1, r2, h, static_cast<int>(n),
                     caps_of(a.caps, kind == "funnel" ? Caps::kNone : Caps::kBoth));
  } else if (kind == "box") {
    auto p = parse_params(kind, params, {"x", "y", "z"});
    if (!p) return p.status();
    a = *p;
    double x = get(a, "x", 100), y = get(a, "y", 100), z = get(a, "z", 100);
    for (Status s : {positive("x", x), positive("y", y), positive("z", z)})
      if (!s) return s;
    mesh = make_box(x, y, z);
  } else if (kind == "sphere") {
    auto p = parse_params(kind, params, {"r", "subdivisions"});
    if (!p) return p.status();
    a = *p;
    double r = get(a, "r", 50), s = get(a, "subdivisions", 3);
    if (Status st = positive("r", r); !st) return st;
    if (s < 0 || s > 8 || s != std::floor(s))
      return invalid_argument("sphere: subdivisions must be an integer in [0, 8]");
    if (Status st = fits(20 * std::pow(4.0, s)); !st) return st;
    mesh = make_sphere(r, static_cast<int>(s));
  } else {
    return invalid_argument("unknown shape '" + kind +
                            "' (cylinder, cone, funnel, box, sphere, wall1, wall2)");
  }
  // A lathed shape along x or y (a drum lies on its side): turned by a proper
  // rotation, so the triangles keep facing the way they did.
  if (a.axis != 'z')
    for (Vec3d& v : mesh.vertices)
      v = a.axis == 'y' ? Vec3d{v.x, v.z, -v.y} : Vec3d{v.z, v.y, -v.x};
  translate(mesh, {get(a, "dx", 0), get(a, "dy", 0), get(a, "dz", 0)});
  return mesh;
}

}  // namespace

Expected<TriangleMesh> make_shape(const std::string& spec, std::vector<size_t>* part_starts) {
  if (part_starts) part_starts->clear();
  // A union of many finely divided parts would take a worker minutes to build
  // (the fuzzer found one): the parts and the triangles they add up to are bounded.
  constexpr size_t kMaxParts = 64;
  TriangleMesh out;
  size_t pos = 0, parts = 0;
  while (pos <= spec.size()) {
    if (++parts > kMaxParts)
      return invalid_argument("wall spec: a union of more than " + std::to_string(kMaxParts) +
                              " shapes");
    size_t plus = spec.find('+', pos);
    std::string part = spec.substr(pos, plus == std::string::npos ? std::string::npos : plus - pos);
    auto m = make_one(part, kMaxShapeTriangles - std::min(kMaxShapeTriangles, out.triangles.size()));
    if (!m) return m.status();
    if (part_starts) part_starts->push_back(out.triangles.size());
    append_mesh(out, *m);
    if (plus == std::string::npos) break;
    pos = plus + 1;
  }
  return out;
}

}  // namespace collido::sim
