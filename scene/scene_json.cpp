#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <vector>

#include "common/number_text.h"
#include "scene/scene.h"
#include "sim/shapes.h"

namespace collido::scene {

using json = nlohmann::json;

uint64_t Scene::frames() const {
  return static_cast<uint64_t>(std::ceil(duration * fps - 1e-9));
}

double Scene::length_scale() const {
  return length_unit == "mm" ? 1e-3 : length_unit == "cm" ? 1e-2 : 1.0;
}

Status check_timing(const Scene& s) {
  if (!(s.duration > 0 && s.duration <= kMaxDuration))
    return invalid_argument("duration: must lie in (0, 1e5] s");
  if (s.frames() > kMaxFrames)
    return invalid_argument("fps: duration x fps gives more than 10^6 frames");
  if (s.frames() < 1)
    return invalid_argument("fps: duration x fps gives no frame after the first");
  if (s.dynamics.time_step > 0 && s.duration / s.dynamics.time_step > kMaxFixedSteps)
    return invalid_argument("time_step: duration / time_step gives more than 10^9 steps");
  // An inlet's first particle leaves within 1 / rate of the start (at a random
  // phase of its slot), so a rate under 1 / duration may release none at all.
  const sim::PlacementSpec& pl = s.placement;
  if (pl.kind != sim::PlacementKind::kFill && pl.rate > 0 && pl.rate * s.duration < 1)
    return invalid_argument("placement.rate: " + number_text(pl.rate) +
                            " particles/s may release no particle within the scene's " +
                            number_text(s.duration) + " s; give at least " +
                            number_text(1 / s.duration) +
                            " particles/s (or 0: as fast as the inlet clears)");
  return Status::ok();
}

namespace {

std::string join(const std::string& where, const std::string& key) {
  return where.empty() ? key : where + "." + key;
}

// Reads one JSON object's keys with type checks; every error names the full key.
class ObjectReader {
 public:
  ObjectReader(const json& o, std::string where) : o_(o), where_(std::move(where)) {}

  // An error for any key not in `known`.
  Status only(std::initializer_list<const char*> known) const {
    if (!o_.is_object())
      return invalid_argument((where_.empty() ? "scene" : where_) + ": expected a JSON object");
    for (auto it = o_.begin(); it != o_.end(); ++it) {
      bool ok = false;
      for (const char* k : known) ok = ok || it.key() == k;
      if (!ok) return invalid_argument(join(where_, it.key()) + ": unknown key");
    }
    return Status::ok();
  }
  bool has(const char* key) const { return o_.contains(key); }
  const json& at(const char* key) const { return o_.at(key); }
  std::string name(const char* key) const { return join(where_, key); }

  // Optional number in [lo, hi] (left unchanged when absent).
  Status number(const char* key, double* out, double lo, double hi) const {
    if (!has(key)) return Status::ok();
    const json& v = o_.at(key);
    if (!v.is_number()) return invalid_argument(name(key) + ": expected a number");
    const double d = v.get<double>();
    if (!std::isfinite(d) || d < lo || d > hi)
      return invalid_argument(name(key) + ": " + v.dump() + " is outside [" + number_text(lo) +
                              ", " + number_text(hi) + "]");
    *out = d;
    return Status::ok();
  }
  Status integer(const char* key, uint64_t* out, uint64_t lo, uint64_t hi) const {
    if (!has(key)) return Status::ok();
    const json& v = o_.at(key);
    if (!v.is_number_unsigned() && !(v.is_number_integer() && v.get<int64_t>() >= 0))
      return invalid_argument(name(key) + ": expected a whole number >= 0");
    const uint64_t n = v.get<uint64_t>();
    if (n < lo || n > hi)
      return invalid_argument(name(key) + ": " + v.dump() + " is outside [" + std::to_string(lo) +
                              ", " + std::to_string(hi) + "]");
    *out = n;
    return Status::ok();
  }
  Status boolean(const char* key, bool* out) const {
    if (!has(key)) return Status::ok();
    if (!o_.at(key).is_boolean()) return invalid_argument(name(key) + ": expected true or false");
    *out = o_.at(key).get<bool>();
    return Status::ok();
  }
  Status string(const char* key, std::string* out) const {
    if (!has(key)) return Status::ok();
    if (!o_.at(key).is_string()) return invalid_argument(name(key) + ": expected a string");
    *out = o_.at(key).get<std::string>();
    return Status::ok();
  }
  // A vector [x, y, z] of finite numbers with |component| <= limit; *set says it was given.
  Status vec3(const char* key, sim::Vec3d* out, double limit, bool* set = nullptr) const {
    if (!has(key)) return Status::ok();
    const json& v = o_.at(key);
    if (!v.is_array() || v.size() != 3) return invalid_argument(name(key) + ": expected [x, y, z]");
    double c[3];
    for (int i = 0; i < 3; ++i) {
      if (!v[i].is_number()) return invalid_argument(name(key) + ": expected [x, y, z] of numbers");
      c[i] = v[i].get<double>();
      if (!std::isfinite(c[i]) || std::fabs(c[i]) > limit)
        return invalid_argument(name(key) + ": components must be finite and within +-" +
                                number_text(limit));
    }
    *out = {c[0], c[1], c[2]};
    if (set) *set = true;
    return Status::ok();
  }

 private:
  const json& o_;
  std::string where_;
};

#define COLLIDO_TRY(expr)          \
  do {                             \
    if (Status s_ = (expr); !s_) { \
      return s_;                   \
    }                              \
  } while (0)

constexpr double kMaxCoordinate =
    1e7;                           // m: far beyond any vessel, short of float trouble in the grid
constexpr double kMaxSpeed = 1e5;  // m/s

Status read_wall(const json& w, Scene* s) {
  if (w.is_string()) {
    s->wall = w.get<std::string>();
    s->wall_is_file = false;
  } else {
    ObjectReader r(w, "wall");
    COLLIDO_TRY(r.only({"shape", "file"}));
    if (r.has("shape") == r.has("file"))
      return invalid_argument("wall: give either \"shape\" or \"file\"");
    COLLIDO_TRY(r.string("shape", &s->wall));
    COLLIDO_TRY(r.string("file", &s->wall));
    s->wall_is_file = r.has("file");
  }
  if (s->wall.empty()) return invalid_argument("wall: empty");
  return Status::ok();
}

Status read_particles(const json& p, Scene* s) {
  ObjectReader r(p, "particles");
  COLLIDO_TRY(r.only({"count", "radius", "density"}));
  COLLIDO_TRY(r.integer("count", &s->particles.count, 1, uint64_t(1) << 28));
  if (r.has("radius")) {
    const json& v = r.at("radius");
    if (v.is_number()) {
      COLLIDO_TRY(r.number("radius", &s->particles.r_max, 1e-9, 1e4));
      s->particles.r_min = s->particles.r_max;
    } else if (v.is_array() && v.size() == 2 && v[0].is_number() && v[1].is_number()) {
      const double a = v[0].get<double>(), b = v[1].get<double>();
      if (!(a >= 1e-9 && b <= 1e4 && a <= b))
        return invalid_argument(
            "particles.radius: a range [min, max] needs 1e-9 <= min <= max <= 1e4");
      s->particles.r_min = a, s->particles.r_max = b;
    } else {
      return invalid_argument("particles.radius: expected a number or [min, max]");
    }
  }
  COLLIDO_TRY(r.number("density", &s->dynamics.material.density, 1e-6, 1e6));
  return Status::ok();
}

Status read_placement(const json& p, Scene* s) {
  ObjectReader r(p, "placement");
  COLLIDO_TRY(r.only({"kind", "region", "inlet", "inlet_radius", "rate", "velocity"}));
  sim::PlacementSpec& pl = s->placement;
  std::string kind = sim::to_string(pl.kind);
  COLLIDO_TRY(r.string("kind", &kind));
  if (!sim::parse_placement_kind(kind, &pl.kind))
    return invalid_argument("placement.kind: \"" + kind + "\" is not fill, pour or jet");
  if (r.has("region")) {
    ObjectReader g(r.at("region"), "placement.region");
    COLLIDO_TRY(g.only({"min", "max"}));
    if (!g.has("min") || !g.has("max"))
      return invalid_argument("placement.region: needs min and max");
    COLLIDO_TRY(g.vec3("min", &pl.region_lo, kMaxCoordinate));
    COLLIDO_TRY(g.vec3("max", &pl.region_hi, kMaxCoordinate));
    if (!(pl.region_lo.x < pl.region_hi.x && pl.region_lo.y < pl.region_hi.y &&
          pl.region_lo.z < pl.region_hi.z))
      return invalid_argument("placement.region: min must lie below max on every axis");
    pl.has_region = true;
  }
  COLLIDO_TRY(r.vec3("inlet", &pl.inlet, kMaxCoordinate, &pl.has_inlet));
  COLLIDO_TRY(r.number("inlet_radius", &pl.inlet_radius, 0, kMaxCoordinate));
  // Held as 0 when absent; given, it is the disc's radius and cannot be 0.
  if (r.has("inlet_radius") && !(pl.inlet_radius > 0))
    return invalid_argument(
        "placement.inlet_radius: must be positive (leave it out for the default, a third of "
        "the wall box's narrower side)");
  COLLIDO_TRY(r.number("rate", &pl.rate, 0, 1e12));
  COLLIDO_TRY(r.vec3("velocity", &pl.velocity, kMaxSpeed));
  if (pl.kind == sim::PlacementKind::kJet && !(length(pl.velocity) > 0))
    return invalid_argument("placement.velocity: a jet needs a non-zero velocity");
  if (pl.kind != sim::PlacementKind::kFill && pl.has_region)
    return invalid_argument("placement.region: only a fill has a region (a " + kind +
                            " has an inlet)");
  return Status::ok();
}

// The coefficients a particle material and a wall material share.
Status read_coefficients(const ObjectReader& r, sim::Material* mat) {
  COLLIDO_TRY(r.number("restitution", &mat->restitution, 1e-6, 1));
  COLLIDO_TRY(r.number("friction", &mat->friction, 0, 10));
  COLLIDO_TRY(r.number("rolling_friction", &mat->rolling_friction, 0, 1));
  COLLIDO_TRY(r.number("stiffness", &mat->stiffness, 0, 1e15));
  COLLIDO_TRY(r.number("youngs_modulus", &mat->youngs_modulus, 0, 1e13));
  COLLIDO_TRY(r.number("poisson_ratio", &mat->poisson_ratio, 0, 0.5));
  return Status::ok();
}

Status read_material(const json& m, Scene* s) {
  ObjectReader r(m, "material");
  COLLIDO_TRY(r.only({"restitution", "friction", "rolling_friction", "stiffness", "youngs_modulus",
                      "poisson_ratio", "impact_speed"}));
  COLLIDO_TRY(read_coefficients(r, &s->dynamics.material));
  COLLIDO_TRY(r.number("impact_speed", &s->dynamics.impact_speed, 0, kMaxSpeed));
  return Status::ok();
}

// The wall's side of particle-wall contacts; keys not given are the particles'
// (read after "material", whatever the document's order).
Status read_wall_material(const json& m, Scene* s) {
  ObjectReader r(m, "wall_material");
  COLLIDO_TRY(r.only({"restitution", "friction", "rolling_friction", "stiffness", "youngs_modulus",
                      "poisson_ratio"}));
  sim::Material& w = s->dynamics.wall_material;
  w = s->dynamics.material;
  // The wall's elasticity is its own only where given.
  w.stiffness = 0, w.youngs_modulus = 0;
  COLLIDO_TRY(read_coefficients(r, &w));
  s->dynamics.wall_material_set = true;
  return Status::ok();
}

Status read_wall_motion(const json& m, Scene* s) {
  ObjectReader r(m, "wall_motion");
  sim::WallMotion& w = s->dynamics.wall_motion;
  std::string kind = "none";
  COLLIDO_TRY(r.string("kind", &kind));
  using K = sim::WallMotionKind;
  // Each kind takes its own keys; another kind's is an unknown key here.
  if (kind == "rotate") {
    w.kind = K::kRotate;
    COLLIDO_TRY(r.only({"kind", "axis", "center", "angular_speed", "rpm", "part"}));
  } else if (kind == "translate") {
    w.kind = K::kTranslate;
    COLLIDO_TRY(r.only({"kind", "velocity"}));
  } else if (kind == "oscillate") {
    w.kind = K::kOscillate;
    COLLIDO_TRY(r.only({"kind", "axis", "amplitude", "frequency", "part"}));
  } else if (kind == "none") {
    w.kind = K::kNone;
    COLLIDO_TRY(r.only({"kind"}));
  } else {
    return invalid_argument("wall_motion.kind: \"" + kind +
                            "\" is not none, rotate, translate or oscillate");
  }
  COLLIDO_TRY(r.vec3("axis", &w.axis, 1e6));
  COLLIDO_TRY(r.vec3("center", &w.center, kMaxCoordinate));
  s->motion_center_auto = w.kind == K::kRotate && !r.has("center");
  if (r.has("angular_speed") && r.has("rpm"))
    return invalid_argument("wall_motion: give angular_speed (rad/s) or rpm, not both");
  COLLIDO_TRY(r.number("angular_speed", &w.angular_speed, -1e4, 1e4));
  // rpm within the same +-1e4 rad/s, so the document writes back (as angular_speed) and reads again.
  double rpm = 0;
  COLLIDO_TRY(r.number("rpm", &rpm, -1e4 * 60 / (2 * M_PI), 1e4 * 60 / (2 * M_PI)));
  if (r.has("rpm")) w.angular_speed = rpm * 2 * M_PI / 60;
  COLLIDO_TRY(r.vec3("velocity", &w.velocity, kMaxSpeed));
  COLLIDO_TRY(r.number("amplitude", &w.amplitude, 0, kMaxCoordinate));
  COLLIDO_TRY(r.number("frequency", &w.frequency, 0, 1e5));
  // One part of a union of shapes ("cylinder:...+box:..."), counted from 1.
  uint64_t part = 0;
  COLLIDO_TRY(r.integer("part", &part, 1, 64));
  w.part = int(part);
  if (w.part > 0) {
    size_t parts = 1;
    for (char c : s->wall) parts += c == '+';
    if (s->wall_is_file || parts < 2)
      return invalid_argument("wall_motion.part: the wall is not a union of shapes (\"a+b\"); "
                              "leave part out to move the whole wall");
    if (size_t(w.part) > parts)
      return invalid_argument("wall_motion.part: the wall has " + std::to_string(parts) +
                              " parts, not " + std::to_string(w.part));
  }
  return Status::ok();
}

// Multiplies every length and speed of the document by k (the unit to metres,
// or back for writing).
void scale_lengths(Scene* s, double k) {
  if (k == 1) return;
  s->particles.r_min *= k, s->particles.r_max *= k;
  sim::PlacementSpec& pl = s->placement;
  pl.region_lo = pl.region_lo * k, pl.region_hi = pl.region_hi * k;
  pl.inlet = pl.inlet * k;
  pl.inlet_radius *= k;
  pl.velocity = pl.velocity * k;
  s->dynamics.impact_speed *= k;
  s->dynamics.grid_length *= k;
  if (s->dynamics.neighbour_skin > 0) s->dynamics.neighbour_skin *= k;
  sim::WallMotion& w = s->dynamics.wall_motion;
  w.center = w.center * k, w.velocity = w.velocity * k, w.amplitude *= k;
}

}  // namespace

Expected<Scene> parse_scene(const std::string& text) {
  const json doc = json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (doc.is_discarded()) return parse_error("scene: not valid JSON");
  Scene s;
  ObjectReader r(doc, "");
  COLLIDO_TRY(
      r.only({"wall", "particles", "placement", "gravity", "material", "duration", "fps", "method",
              "backend", "particle_contacts", "integrator", "time_step", "seed", "output",
              "length_unit", "grid_length", "contact_model", "wall_material", "wall_motion",
              "neighbour_skin"}));
  COLLIDO_TRY(r.string("length_unit", &s.length_unit));
  if (s.length_unit != "m" && s.length_unit != "cm" && s.length_unit != "mm")
    return invalid_argument("length_unit: \"" + s.length_unit + "\" is not m, cm or mm");
  if (!r.has("wall"))
    return invalid_argument("wall: missing (a shape such as \"wall1\" or {\"file\": ...})");
  COLLIDO_TRY(read_wall(r.at("wall"), &s));
  if (r.has("particles")) COLLIDO_TRY(read_particles(r.at("particles"), &s));
  if (r.has("placement")) COLLIDO_TRY(read_placement(r.at("placement"), &s));
  if (r.has("material")) COLLIDO_TRY(read_material(r.at("material"), &s));
  if (r.has("wall_material")) COLLIDO_TRY(read_wall_material(r.at("wall_material"), &s));
  if (r.has("wall_motion")) COLLIDO_TRY(read_wall_motion(r.at("wall_motion"), &s));
  std::string model = sim::to_string(s.dynamics.contact_model);
  COLLIDO_TRY(r.string("contact_model", &model));
  if (!sim::parse_contact_model(model, &s.dynamics.contact_model))
    return invalid_argument("contact_model: \"" + model + "\" is not linear or hertz_mindlin");
  // What only the settings together decide (a Hertz scene given a spring, a zero axis).
  COLLIDO_TRY(sim::check_contact_settings(s.dynamics));
  COLLIDO_TRY(r.vec3("gravity", &s.dynamics.gravity, 1e4));
  COLLIDO_TRY(r.number("duration", &s.duration, 1e-9, kMaxDuration));
  COLLIDO_TRY(r.number("fps", &s.fps, 1e-3, 1e4));
  COLLIDO_TRY(check_timing(s));
  std::string method = sim::to_string(s.dynamics.method), backend = "auto",
              integrator = sim::to_string(s.dynamics.integrator);
  COLLIDO_TRY(r.string("method", &method));
  s.method_auto = method == "auto";
  if (!s.method_auto &&
      (!sim::parse_method(method, &s.dynamics.method) || !sim::dynamics_can_use(s.dynamics.method)))
    return invalid_argument("method: \"" + method +
                            "\" is not auto, bin, bvh, gravity, circumcircle or midpoint4");
  // The wall grid's cell edge: a length (in the scene's unit), or "auto"; absent = 2 r_max.
  if (r.has("grid_length") && r.at("grid_length").is_string()) {
    if (r.at("grid_length").get<std::string>() != "auto")
      return invalid_argument("grid_length: expected a length or \"auto\"");
    s.grid_auto = true;
  } else {
    COLLIDO_TRY(r.number("grid_length", &s.dynamics.grid_length, 1e-9, 1e9));
  }
  COLLIDO_TRY(r.string("backend", &backend));
  s.backend_auto = backend == "auto";
  if (!s.backend_auto && !sim::parse_backend(backend, &s.dynamics.backend))
    return invalid_argument("backend: \"" + backend + "\" is not auto, cpu or cuda");
  COLLIDO_TRY(r.boolean("particle_contacts", &s.dynamics.particle_contacts));
  COLLIDO_TRY(r.string("integrator", &integrator));
  if (!sim::parse_integrator(integrator, &s.dynamics.integrator))
    return invalid_argument("integrator: \"" + integrator +
                            "\" is not velocity_verlet or symplectic_euler");
  COLLIDO_TRY(r.number("time_step", &s.dynamics.time_step, 0, 1e3));
  COLLIDO_TRY(check_timing(s));  // again, with the time step
  // A length, or absent / negative for the automatic skin (0: the grid every step).
  // Any negative value: automatic (held as -1, as when absent).
  COLLIDO_TRY(r.number("neighbour_skin", &s.dynamics.neighbour_skin, -1e9, 1e9));
  if (s.dynamics.neighbour_skin < 0) s.dynamics.neighbour_skin = -1;
  COLLIDO_TRY(r.integer("seed", &s.seed, 0, UINT64_MAX));
  if (r.has("output")) {
    ObjectReader o(r.at("output"), "output");
    COLLIDO_TRY(o.only({"vtp"}));
    COLLIDO_TRY(o.boolean("vtp", &s.vtp));
  }
  scale_lengths(&s, s.length_scale());
  return s;
}

Expected<Scene> load_scene(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return io_error(path + ": cannot open");
  std::ostringstream text;
  text << in.rdbuf();
  if (text.str().size() > (size_t(16) << 20))
    return invalid_argument(path + ": a scene file over 16 MiB");
  auto scene = parse_scene(text.str());
  if (!scene) return Status(scene.status().code(), path + ": " + scene.status().message());
  const size_t slash = path.find_last_of('/');
  resolve_wall_path(&*scene, slash == std::string::npos ? "" : path.substr(0, slash));
  return scene;
}

void resolve_wall_path(Scene* s, const std::string& base_dir) {
  if (!s->wall_is_file && s->wall.find(':') == std::string::npos && !sim::make_shape(s->wall))
    s->wall_is_file = true;
  if (s->wall_is_file && !s->wall.empty() && s->wall[0] != '/' && !base_dir.empty())
    s->wall = base_dir + "/" + s->wall;
}

std::string to_json(const Scene& si) {
  // Written back in the document's own unit, so parse_scene reads the same scene.
  Scene s = si;
  scale_lengths(&s, 1 / s.length_scale());
  auto v3 = [](sim::Vec3d v) { return json::array({v.x, v.y, v.z}); };
  json j;
  j["wall"] = s.wall_is_file ? json{{"file", s.wall}} : json{{"shape", s.wall}};
  j["particles"] = {{"count", s.particles.count}, {"density", s.dynamics.material.density}};
  j["particles"]["radius"] = s.particles.r_min == s.particles.r_max
                                 ? json(s.particles.r_max)
                                 : json::array({s.particles.r_min, s.particles.r_max});
  const sim::PlacementSpec& pl = s.placement;
  j["placement"] = {{"kind", sim::to_string(pl.kind)}, {"velocity", v3(pl.velocity)}};
  if (pl.kind == sim::PlacementKind::kFill) {
    if (pl.has_region)
      j["placement"]["region"] = {{"min", v3(pl.region_lo)}, {"max", v3(pl.region_hi)}};
  } else {
    if (pl.has_inlet) j["placement"]["inlet"] = v3(pl.inlet);
    if (pl.inlet_radius > 0) j["placement"]["inlet_radius"] = pl.inlet_radius;
    j["placement"]["rate"] = pl.rate;
  }
  const sim::Material& m = s.dynamics.material;
  auto coefficients = [](const sim::Material& m) {
    return json{{"restitution", m.restitution},       {"friction", m.friction},
                {"rolling_friction", m.rolling_friction}, {"stiffness", m.stiffness},
                {"youngs_modulus", m.youngs_modulus}, {"poisson_ratio", m.poisson_ratio}};
  };
  j["material"] = coefficients(m);
  j["material"]["impact_speed"] = s.dynamics.impact_speed;
  if (s.dynamics.wall_material_set) j["wall_material"] = coefficients(s.dynamics.wall_material);
  j["contact_model"] = sim::to_string(s.dynamics.contact_model);
  const sim::WallMotion& w = s.dynamics.wall_motion;
  switch (w.kind) {
    case sim::WallMotionKind::kRotate:
      j["wall_motion"] = {{"kind", "rotate"}, {"axis", v3(w.axis)}, {"angular_speed", w.angular_speed}};
      // Left out while it is still the wall's to decide (the wall is not loaded yet).
      if (!s.motion_center_auto) j["wall_motion"]["center"] = v3(w.center);
      if (w.part > 0) j["wall_motion"]["part"] = w.part;
      break;
    case sim::WallMotionKind::kTranslate:
      j["wall_motion"] = {{"kind", "translate"}, {"velocity", v3(w.velocity)}};
      break;
    case sim::WallMotionKind::kOscillate:
      j["wall_motion"] = {{"kind", "oscillate"},
                          {"axis", v3(w.axis)},
                          {"amplitude", w.amplitude},
                          {"frequency", w.frequency}};
      if (w.part > 0) j["wall_motion"]["part"] = w.part;
      break;
    default: break;
  }
  j["gravity"] = v3(s.dynamics.gravity);
  j["duration"] = s.duration;
  j["fps"] = s.fps;
  j["method"] = s.method_auto ? "auto" : sim::to_string(s.dynamics.method);
  if (s.grid_auto)
    j["grid_length"] = "auto";
  else if (s.dynamics.grid_length > 0)
    j["grid_length"] = s.dynamics.grid_length;
  j["backend"] = s.backend_auto ? "auto" : sim::to_string(s.dynamics.backend);
  j["particle_contacts"] = s.dynamics.particle_contacts;
  j["integrator"] = sim::to_string(s.dynamics.integrator);
  j["time_step"] = s.dynamics.time_step;
  if (s.dynamics.neighbour_skin >= 0) j["neighbour_skin"] = s.dynamics.neighbour_skin;
  j["seed"] = s.seed;
  j["output"] = {{"vtp", s.vtp}};
  j["length_unit"] = s.length_unit;
  return j.dump(2);
}

}  // namespace collido::scene
