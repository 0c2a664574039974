// The scene file: defaults, every key read, errors that name the key, a
// round trip through to_json, and a fuzz of mutated documents.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "scene/scene.h"
#include "sim/particles.h"
#include "tests/scratch.h"

namespace collido::scene {
namespace {

const char* kFull = R"({
  "wall": {"shape": "wall1"},
  "particles": {"count": 500, "radius": [0.5, 1.0], "density": 1200},
  "placement": {"kind": "pour", "inlet": [0, 0, 90], "inlet_radius": 20, "rate": 1000, "velocity": [0, 0, -5]},
  "gravity": [0, 0, -3.7],
  "material": {"restitution": 0.8, "friction": 0.2, "stiffness": 1e7, "impact_speed": 12},
  "duration": 1.5, "fps": 20,
  "method": "circumcircle", "backend": "cpu",
  "particle_contacts": true, "integrator": "symplectic_euler", "time_step": 1e-5, "seed": 42,
  "output": {"vtp": true},
  "contact_model": "linear", "neighbour_skin": 0.2,
  "wall_material": {"restitution": 0.3, "friction": 0.6, "rolling_friction": 0.01},
  "wall_motion": {"kind": "rotate", "axis": [0, 0, 1], "center": [0, 0, 50], "rpm": 12}
})";

TEST(Scene, MinimalDocumentTakesDefaults) {
  auto s = parse_scene(R"({"wall": "wall1"})");
  ASSERT_TRUE(s) << s.status().message();
  EXPECT_EQ(s->wall, "wall1");
  EXPECT_FALSE(s->wall_is_file);
  EXPECT_TRUE(s->backend_auto);
  EXPECT_EQ(s->dynamics.method, sim::Method::kBin);
  EXPECT_EQ(s->placement.kind, sim::PlacementKind::kFill);
  EXPECT_EQ(s->frames(), 60u);  // 2 s at 30 fps
  EXPECT_DOUBLE_EQ(s->dynamics.gravity.z, -9.81);
}

TEST(Scene, EveryKeyIsRead) {
  auto s = parse_scene(kFull);
  ASSERT_TRUE(s) << s.status().message();
  EXPECT_EQ(s->particles.count, 500u);
  EXPECT_DOUBLE_EQ(s->particles.r_min, 0.5);
  EXPECT_DOUBLE_EQ(s->particles.r_max, 1.0);
  EXPECT_DOUBLE_EQ(s->dynamics.material.density, 1200);
  EXPECT_EQ(s->placement.kind, sim::PlacementKind::kPour);
  EXPECT_TRUE(s->placement.has_inlet);
  EXPECT_DOUBLE_EQ(s->placement.inlet.z, 90);
  EXPECT_DOUBLE_EQ(s->placement.inlet_radius, 20);
  EXPECT_DOUBLE_EQ(s->placement.rate, 1000);
  EXPECT_DOUBLE_EQ(s->placement.velocity.z, -5);
  EXPECT_DOUBLE_EQ(s->dynamics.gravity.z, -3.7);
  EXPECT_DOUBLE_EQ(s->dynamics.material.restitution, 0.8);
  EXPECT_DOUBLE_EQ(s->dynamics.material.friction, 0.2);
  EXPECT_DOUBLE_EQ(s->dynamics.material.stiffness, 1e7);
  EXPECT_DOUBLE_EQ(s->dynamics.impact_speed, 12);
  EXPECT_EQ(s->frames(), 30u);
  EXPECT_EQ(s->dynamics.method, sim::Method::kCircumcircle);
  EXPECT_FALSE(s->backend_auto);
  EXPECT_EQ(s->dynamics.backend, sim::Backend::kCpu);
  EXPECT_TRUE(s->dynamics.particle_contacts);
  EXPECT_EQ(s->dynamics.integrator, sim::Integrator::kSymplecticEuler);
  EXPECT_DOUBLE_EQ(s->dynamics.time_step, 1e-5);
  EXPECT_EQ(s->seed, 42u);
  EXPECT_TRUE(s->vtp);
  EXPECT_DOUBLE_EQ(s->dynamics.neighbour_skin, 0.2);
  EXPECT_DOUBLE_EQ(s->dynamics.wall_material.friction, 0.6);
  EXPECT_DOUBLE_EQ(s->dynamics.wall_motion.angular_speed, 12 * 2 * M_PI / 60);
}

TEST(Scene, RoundTripThroughJson) {
  auto a = parse_scene(kFull);
  ASSERT_TRUE(a);
  auto b = parse_scene(to_json(*a));
  ASSERT_TRUE(b) << b.status().message() << "\n" << to_json(*a);
  EXPECT_EQ(to_json(*a), to_json(*b));
}

void expect_error(const std::string& doc, const std::string& key) {
  auto s = parse_scene(doc);
  ASSERT_FALSE(s) << doc;
  EXPECT_EQ(s.status().message().rfind(key, 0), 0u)
      << "message '" << s.status().message() << "' should start with " << key;
}

// "auto" for the method and the grid length: chosen when the job starts,
// kept as "auto" through a round trip; a fixed grid length follows the unit.
// A pour on the default inlet is written back without an inlet_radius (the
// default is held as 0, which a document may not give).
TEST(Scene, ADefaultInletRoundTrips) {
  auto a = parse_scene(R"({"wall": "wall1", "placement": {"kind": "pour", "rate": 100}})");
  ASSERT_TRUE(a) << a.status().message();
  EXPECT_EQ(to_json(*a).find("inlet_radius"), std::string::npos) << to_json(*a);
  auto b = parse_scene(to_json(*a));
  ASSERT_TRUE(b) << b.status().message() << "\n" << to_json(*a);
  EXPECT_EQ(to_json(*a), to_json(*b));
}

TEST(Scene, MethodAndGridLengthMayBeAutomatic) {
  auto s = parse_scene(R"({"wall": "wall1", "method": "auto", "grid_length": "auto"})");
  ASSERT_TRUE(s) << s.status().message();
  EXPECT_TRUE(s->method_auto);
  EXPECT_TRUE(s->grid_auto);
  auto back = parse_scene(to_json(*s));
  ASSERT_TRUE(back) << back.status().message();
  EXPECT_TRUE(back->method_auto && back->grid_auto);
  auto mm = parse_scene(R"({"wall": "wall1", "grid_length": 3, "length_unit": "mm"})");
  ASSERT_TRUE(mm) << mm.status().message();
  EXPECT_FALSE(mm->grid_auto);
  EXPECT_DOUBLE_EQ(mm->dynamics.grid_length, 0.003);
}

// The tree over the wall's triangles is a method a scene may name, and writes back as one.
TEST(Scene, TheTreeMethodIsNamedAndWrittenBack) {
  auto s = parse_scene(R"({"wall": "wall1", "method": "bvh"})");
  ASSERT_TRUE(s) << s.status().message();
  EXPECT_EQ(s->dynamics.method, sim::Method::kBvh);
  auto back = parse_scene(to_json(*s));
  ASSERT_TRUE(back) << back.status().message();
  EXPECT_EQ(back->dynamics.method, sim::Method::kBvh);
  auto bad = parse_scene(R"({"wall": "wall1", "method": "octree"})");
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.status().message().find("bvh"), std::string::npos) << bad.status().message();
}

TEST(Scene, ErrorsNameTheKey) {
  expect_error(R"({"wall": "wall1", "colour": "red"})", "colour: unknown key");
  expect_error(R"({"wall": "wall1", "particles": {"radus": 1}})", "particles.radus: unknown key");
  expect_error(R"({"wall": "wall1", "material": {"restitution": 1.5}})", "material.restitution");
  expect_error(R"({"wall": "wall1", "material": {"restitution": 0}})", "material.restitution");
  expect_error(R"({"wall": "wall1", "material": {"friction": -1}})", "material.friction");
  expect_error(R"({"wall": "wall1", "material": {"stiffness": 1e6, "youngs_modulus": 1e9}})",
               "material");
  expect_error(R"({"wall": "wall1", "particles": {"count": 0}})", "particles.count");
  expect_error(R"({"wall": "wall1", "particles": {"count": 2.5}})", "particles.count");
  expect_error(R"({"wall": "wall1", "particles": {"count": -3}})", "particles.count");
  expect_error(R"({"wall": "wall1", "particles": {"radius": -1}})", "particles.radius");
  expect_error(R"({"wall": "wall1", "particles": {"radius": [2, 1]}})", "particles.radius");
  expect_error(R"({"wall": "wall1", "particles": {"radius": "big"}})", "particles.radius");
  expect_error(R"({"wall": "wall1", "gravity": [0, 0]})", "gravity");
  expect_error(R"({"wall": "wall1", "gravity": [0, 0, "down"]})", "gravity");
  expect_error(R"({"wall": "wall1", "duration": 0})", "duration");
  expect_error(R"({"wall": "wall1", "duration": 1e5, "fps": 1e4})", "fps");
  // A fixed step that would take days at any speed (a job answers a cancel between frames).
  expect_error(R"({"wall": "wall1", "duration": 100, "time_step": 1e-15})", "time_step");
  // No frame to write after the first: nothing would be simulated.
  expect_error(R"({"wall": "wall1", "duration": 1e-9, "fps": 0.001})", "fps");
  expect_error(R"({"wall": "wall1", "method": "magic"})", "method");
  expect_error(R"({"wall": "wall1", "method": "reference"})", "method");
  expect_error(R"({"wall": "wall1", "method": "octree"})", "method");
  expect_error(R"({"wall": "wall1", "grid_length": "big"})", "grid_length");
  expect_error(R"({"wall": "wall1", "grid_length": -1})", "grid_length");
  expect_error(R"({"wall": "wall1", "backend": "tpu"})", "backend");
  expect_error(R"({"wall": "wall1", "integrator": "rk4"})", "integrator");
  expect_error(R"({"wall": "wall1", "particle_contacts": "yes"})", "particle_contacts");
  expect_error(R"({"wall": "wall1", "placement": {"kind": "teleport"}})", "placement.kind");
  expect_error(R"({"wall": "wall1", "placement": {"kind": "jet"}})", "placement.velocity");
  expect_error(
      R"({"wall": "wall1", "placement": {"kind": "pour", "region": {"min": [0,0,0], "max": [1,1,1]}}})",
      "placement.region");
  expect_error(R"({"wall": "wall1", "placement": {"region": {"min": [0,0,0], "max": [1,-1,1]}}})",
               "placement.region");
  expect_error(R"({"wall": "wall1", "placement": {"region": {"min": [0,0,0]}}})",
               "placement.region");
  // Given, an inlet's radius is the disc's: 0 is not the default (leaving it out is).
  expect_error(R"({"wall": "wall1", "placement": {"kind": "pour", "inlet_radius": 0}})",
               "placement.inlet_radius: must be positive");
  // A rate whose first particle may leave after the scene ends.
  expect_error(R"({"wall": "wall1", "duration": 2, "placement": {"kind": "pour", "rate": 0.4}})",
               "placement.rate: 0.4 particles/s may release no particle within the scene's 2 s");
  expect_error(
      R"({"wall": "wall1", "duration": 1, "placement": {"kind": "jet", "rate": 0.5, "velocity": [0, 0, -1]}})",
      "placement.rate");
  EXPECT_TRUE(parse_scene(
      R"({"wall": "wall1", "duration": 2, "placement": {"kind": "pour", "rate": 0.5}})"));
  EXPECT_TRUE(
      parse_scene(R"({"wall": "wall1", "duration": 2, "placement": {"kind": "pour", "rate": 0}})"));
  // Any negative skin is the automatic one (docs/jobs.md), held as -1.
  auto skin = parse_scene(R"({"wall": "wall1", "neighbour_skin": -2})");
  ASSERT_TRUE(skin) << skin.status().message();
  EXPECT_EQ(skin->dynamics.neighbour_skin, -1);
  expect_error(R"({"wall": {"shape": "wall1", "file": "a.stl"}})", "wall");
  expect_error(R"({"wall": {}})", "wall");
  expect_error(R"({"particles": {"count": 5}})", "wall");
  expect_error(R"({"wall": "wall1", "output": {"png": true}})", "output.png");
  expect_error(R"([1, 2, 3])", "scene");
  expect_error(R"({"wall": "wall1",)", "scene: not valid JSON");
  expect_error("", "scene: not valid JSON");
}

// The contact model, a wall material that inherits what it does not say, and a
// moving wall; their errors name the key; a round trip keeps them.
TEST(Scene, ContactModelWallMaterialAndWallMotion) {
  auto s = parse_scene(R"({"wall": "cylinder:r=50,h=20,axis=y", "length_unit": "mm",
    "contact_model": "hertz_mindlin",
    "material": {"restitution": 0.6, "friction": 0.4, "rolling_friction": 0.02,
                 "youngs_modulus": 5e6, "poisson_ratio": 0.25},
    "wall_material": {"friction": 0.8, "youngs_modulus": 2e11},
    "wall_motion": {"kind": "rotate", "axis": [0, 1, 0], "center": [0, 10, 0], "rpm": 30}})");
  ASSERT_TRUE(s) << s.status().message();
  const sim::DynamicsConfig& d = s->dynamics;
  EXPECT_EQ(d.contact_model, sim::ContactModel::kHertzMindlin);
  EXPECT_DOUBLE_EQ(d.material.rolling_friction, 0.02);
  EXPECT_DOUBLE_EQ(d.material.poisson_ratio, 0.25);
  ASSERT_TRUE(d.wall_material_set);
  EXPECT_DOUBLE_EQ(d.wall_material.friction, 0.8);
  EXPECT_DOUBLE_EQ(d.wall_material.restitution, 0.6);  // the particles', not said
  EXPECT_DOUBLE_EQ(d.wall_material.poisson_ratio, 0.25);
  EXPECT_DOUBLE_EQ(d.wall_material.youngs_modulus, 2e11);
  EXPECT_EQ(d.wall_motion.kind, sim::WallMotionKind::kRotate);
  EXPECT_DOUBLE_EQ(d.wall_motion.angular_speed, M_PI);  // 30 rpm
  EXPECT_DOUBLE_EQ(d.wall_motion.center.y, 0.01);       // millimetres
  auto back = parse_scene(to_json(*s));
  ASSERT_TRUE(back) << back.status().message() << "\n" << to_json(*s);
  EXPECT_EQ(to_json(*s), to_json(*back));
  auto osc = parse_scene(R"({"wall": "box", "wall_motion": {"kind": "oscillate",
    "axis": [0, 0, 1], "amplitude": 0.002, "frequency": 20}})");
  ASSERT_TRUE(osc) << osc.status().message();
  EXPECT_EQ(to_json(*osc), to_json(*parse_scene(to_json(*osc))));

  // A rotation without a centre turns about the wall's box centre, which the
  // job sets when it loads the wall; until then the document leaves it out.
  auto own = parse_scene(R"({"wall": "box", "wall_motion": {"kind": "rotate", "axis": [1, 0, 0], "rpm": 6}})");
  ASSERT_TRUE(own) << own.status().message();
  EXPECT_TRUE(own->motion_center_auto);
  EXPECT_FALSE(s->motion_center_auto);  // given above
  EXPECT_EQ(to_json(*own).find("center"), std::string::npos) << to_json(*own);
  auto own_back = parse_scene(to_json(*own));
  ASSERT_TRUE(own_back);
  EXPECT_TRUE(own_back->motion_center_auto);
  EXPECT_FALSE(osc->motion_center_auto);  // a shake has no centre

  // One part of a union moves (counted from 1); it turns or shakes, never translates.
  auto paddle = parse_scene(R"({"wall": "cylinder:r=1,h=1,caps=bottom+box:x=1.5,y=0.1,z=0.4",
    "wall_motion": {"kind": "rotate", "axis": [0, 0, 1], "rpm": 30, "part": 2}})");
  ASSERT_TRUE(paddle) << paddle.status().message();
  EXPECT_EQ(paddle->dynamics.wall_motion.part, 2);
  auto paddle_back = parse_scene(to_json(*paddle));
  ASSERT_TRUE(paddle_back) << to_json(*paddle);
  EXPECT_EQ(paddle_back->dynamics.wall_motion.part, 2);
  expect_error(R"({"wall": "box", "wall_motion": {"kind": "rotate", "part": 1}})",
               "wall_motion.part: the wall is not a union");
  expect_error(R"({"wall": "box+box:dz=2", "wall_motion": {"kind": "rotate", "part": 3}})",
               "wall_motion.part: the wall has 2 parts, not 3");
  expect_error(R"({"wall": "box+box:dz=2", "wall_motion": {"kind": "translate", "velocity": [1, 0, 0],
    "part": 1}})", "wall_motion.part");  // not a key of translate
  expect_error(R"({"wall": "box+box:dz=2", "wall_motion": {"kind": "rotate", "part": 0}})",
               "wall_motion.part");

  expect_error(R"({"wall": "wall1", "contact_model": "jkr"})", "contact_model");
  expect_error(R"({"wall": "wall1", "contact_model": "hertz_mindlin", "material": {"stiffness": 1e6}})",
               "material.stiffness");
  expect_error(R"({"wall": "wall1", "material": {"poisson_ratio": 0.6}})", "material.poisson_ratio");
  expect_error(R"({"wall": "wall1", "material": {"rolling_friction": 2}})",
               "material.rolling_friction");
  expect_error(R"({"wall": "wall1", "wall_material": {"density": 3}})", "wall_material.density");
  expect_error(R"({"wall": "wall1", "wall_motion": {"kind": "spin"}})", "wall_motion.kind");
  expect_error(R"({"wall": "wall1", "wall_motion": {"kind": "rotate", "axis": [0, 0, 0]}})",
               "wall_motion.axis");
  expect_error(R"({"wall": "wall1", "wall_motion": {"kind": "rotate", "rpm": 5, "angular_speed": 1}})",
               "wall_motion");
  expect_error(R"({"wall": "wall1", "wall_motion": {"kind": "translate", "amplitude": 1}})",
               "wall_motion.amplitude");
}

TEST(Scene, WallFileIsRelativeToTheSceneFile) {
  const std::string dir = test::scratch_dir("scene_relative");
  const std::string path = dir + "/s.json";
  std::ofstream(path) << R"({"wall": {"file": "vessel.stl"}})";
  auto s = load_scene(path);
  ASSERT_TRUE(s) << s.status().message();
  EXPECT_TRUE(s->wall_is_file);
  EXPECT_EQ(s->wall, path.substr(0, path.find_last_of('/') + 1) + "vessel.stl");
  EXPECT_FALSE(load_scene(dir + "/missing.json"));
}

// "wall": "vessel.stl" (a string that names no shape) is a file too, found the same way.
TEST(Scene, WallFileWrittenAsAStringIsRelativeToTheSceneFileToo) {
  const std::string dir = test::scratch_dir("scene_dir");
  std::ofstream(dir + "/s.json") << R"({"wall": "vessel.stl"})";
  auto s = load_scene(dir + "/s.json");
  ASSERT_TRUE(s) << s.status().message();
  EXPECT_TRUE(s->wall_is_file);
  EXPECT_EQ(s->wall, dir + "/vessel.stl");
  std::ofstream(dir + "/shape.json") << R"({"wall": "wall1"})";
  auto shape = load_scene(dir + "/shape.json");
  ASSERT_TRUE(shape);
  EXPECT_FALSE(shape->wall_is_file);
  EXPECT_EQ(shape->wall, "wall1");
}

// Lengths and speeds of a document in mm or cm are held in SI; written back in the unit.
TEST(Scene, LengthUnitScalesLengthsAndSpeeds) {
  auto s = parse_scene(R"({"wall": "wall1", "length_unit": "mm",
    "particles": {"radius": [2, 4]},
    "placement": {"kind": "jet", "inlet": [0, 0, 500], "inlet_radius": 50, "velocity": [0, 0, -1000]},
    "material": {"impact_speed": 2000}, "gravity": [0, 0, -9.81]})");
  ASSERT_TRUE(s) << s.status().message();
  EXPECT_DOUBLE_EQ(s->length_scale(), 1e-3);
  EXPECT_DOUBLE_EQ(s->particles.r_min, 0.002);
  EXPECT_DOUBLE_EQ(s->particles.r_max, 0.004);
  EXPECT_DOUBLE_EQ(s->placement.inlet.z, 0.5);
  EXPECT_DOUBLE_EQ(s->placement.inlet_radius, 0.05);
  EXPECT_DOUBLE_EQ(s->placement.velocity.z, -1.0);
  EXPECT_DOUBLE_EQ(s->dynamics.impact_speed, 2.0);
  EXPECT_DOUBLE_EQ(s->dynamics.gravity.z, -9.81);  // gravity stays in m/s^2
  auto back = parse_scene(to_json(*s));
  ASSERT_TRUE(back) << back.status().message();
  EXPECT_EQ(back->length_unit, "mm");
  EXPECT_DOUBLE_EQ(back->particles.r_max, 0.004);
  EXPECT_DOUBLE_EQ(back->placement.velocity.z, -1.0);
  EXPECT_EQ(parse_scene(R"({"wall": "wall1", "length_unit": "inch"})").status().message(),
            "length_unit: \"inch\" is not m, cm or mm");
}

// Mutated documents (bytes dropped, swapped, duplicated) either parse into a
// valid scene or fail with a message; they never crash or hang.
TEST(Scene, FuzzedDocumentsNeverCrash) {
  const std::string base = kFull;
  sim::SplitMix64 rng(7);
  int parsed = 0, rejected = 0;
  for (int k = 0; k < 3000; ++k) {
    std::string doc = base;
    const int edits = 1 + int(rng.uniform() * 4);
    for (int e = 0; e < edits && !doc.empty(); ++e) {
      const size_t at = size_t(rng.uniform() * double(doc.size()));
      switch (int(rng.uniform() * 4)) {
        case 0:
          doc.erase(at, 1);
          break;
        case 1:
          doc[at] = "{}[]\",:0123456789.-eE tfn"[int(rng.uniform() * 25)];
          break;
        case 2:
          doc.insert(at, doc.substr(at, 8));
          break;
        default:
          doc[at] = char(rng.uniform() * 256);
          break;
      }
    }
    auto s = parse_scene(doc);
    if (s) {
      ++parsed;
      EXPECT_GE(s->particles.count, 1u);
      EXPECT_GT(s->particles.r_min, 0);
    } else {
      ++rejected;
      EXPECT_FALSE(s.status().message().empty());
    }
  }
  EXPECT_GT(rejected, 0);
  std::printf("fuzz: %d parsed, %d rejected\n", parsed, rejected);
}

}  // namespace
}  // namespace collido::scene
