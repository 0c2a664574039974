// The resource predictor: training on a run log, predicting a configuration, range
// warnings, saving and loading, and reading a configuration from JSON.
#include "gvm/predictor.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "gvm/evaluate.h"
#include "tests/scratch.h"

namespace collido::gvm {
namespace {

// One trained predictor shared by the tests (training takes a fraction of a second).
const ResourcePredictor& trained() {
  static const ResourcePredictor model = [] {
    auto split = split_rows(synthetic_run_log(100, 1), 0.7, 1);
    GvmOptions opt;
    opt.epochs = 200;
    auto p = ResourcePredictor::train(split->train, split->validation, opt, nullptr);
    EXPECT_TRUE(p) << p.status().message();
    return p ? *p : ResourcePredictor();
  }();
  return model;
}

RunConfig typical(Backend b) {
  RunConfig c;
  c.particles = 20000;
  c.triangles = 5000;
  c.triangles_original = 1000;
  c.wall_area = 4e4;  // as synthetic_run_log makes them: 40 per triangle, box 0.5 A^1.5
  c.wall_box_volume = 4e6;
  c.method = Method::kGravity;
  c.traversal = Traversal::kParticle;
  c.frames = 10;
  c.backend = b;
  c.device = b == Backend::kCuda ? "synthetic-gpu" : "synthetic-cpu";
  c.threads = b == Backend::kCuda ? 1 : 16;
  return c;
}

bool contains(const std::vector<std::string>& lines, const std::string& what) {
  for (const auto& l : lines)
    if (l.find(what) != std::string::npos) return true;
  return false;
}

TEST(Predictor, PredictsFinitePositiveCostsInRange) {
  for (Backend b : {Backend::kCpu, Backend::kCuda}) {
    auto p = trained().predict(typical(b));
    ASSERT_TRUE(p) << p.status().message();
    EXPECT_TRUE(p->in_range()) << (p->warnings.empty() ? "" : p->warnings[0]);
    EXPECT_GT(p->measure.time_per_frame_s, 0.0);
    EXPECT_GT(p->measure.total_time_s, 0.0);
    EXPECT_GT(p->measure.peak_host_bytes, 1e6);
    EXPECT_GE(p->measure.gpu_load, 0.0);
    EXPECT_LE(p->measure.gpu_load, 1.0);
    if (b == Backend::kCpu) {
      // A CPU run has no device: exactly zero, not a learned small number.
      EXPECT_EQ(p->measure.peak_device_bytes, 0.0);
      EXPECT_EQ(p->measure.gpu_load, 0.0);
    } else {
      EXPECT_GT(p->measure.peak_device_bytes, 1e6);
    }
  }
}

TEST(Predictor, MoreParticlesCostMoreTime) {
  RunConfig small = typical(Backend::kCpu), big = small;
  big.particles = 500000;
  EXPECT_GT(trained().predict_measure(big).time_per_frame_s,
            trained().predict_measure(small).time_per_frame_s);
}

TEST(Predictor, WarnsAboutEveryInputOutsideTheTrainedRange) {
  RunConfig c = typical(Backend::kCuda);
  c.particles = 1000000000;
  c.method = Method::kReference;  // the synthetic log never runs the reference
  c.device = "Quantum 9000";
  auto p = trained().predict(c);
  ASSERT_TRUE(p);
  EXPECT_FALSE(p->in_range());
  EXPECT_TRUE(contains(p->warnings, "particles = 1000000000 is above the trained range"));
  EXPECT_TRUE(contains(p->warnings, "method 'reference' is not in the training data"));
  EXPECT_TRUE(contains(p->warnings, "device 'Quantum 9000' is not in the training data"));
  // A billion particles also put the near-wall particle count (a geometry feature) out.
  EXPECT_TRUE(contains(p->warnings, "log10_near_wall_particles = "));
  EXPECT_EQ(p->warnings.size(), 4u);
  EXPECT_TRUE(std::isfinite(p->measure.time_per_frame_s));

  c = typical(Backend::kCpu);
  c.frames = 100000;
  p = trained().predict(c);
  ASSERT_TRUE(p);
  ASSERT_EQ(p->warnings.size(), 1u);
  EXPECT_NE(p->warnings[0].find("frames = 100000 is above"), std::string::npos);
}

TEST(Predictor, TrainsOnACpuOnlyLog) {
  std::vector<RunRecord> cpu;
  for (const auto& r : synthetic_run_log(80, 8))
    if (r.config.backend == Backend::kCpu) cpu.push_back(r);
  ASSERT_GT(cpu.size(), 20u);
  GvmOptions opt;
  opt.epochs = 20;
  auto p = ResourcePredictor::train(cpu, {}, opt, nullptr);
  ASSERT_TRUE(p) << p.status().message();
  auto pr = p->predict(typical(Backend::kCuda));
  ASSERT_TRUE(pr);
  EXPECT_EQ(pr->measure.peak_device_bytes, 0.0);
  EXPECT_TRUE(contains(pr->warnings, "backend 'cuda' is not in the training data"));
  EXPECT_TRUE(std::isfinite(pr->measure.time_per_frame_s));
}

TEST(Predictor, OneEnsemblePerOutputAndTheSameModelEveryTime) {
  std::vector<RunRecord> cpu;
  for (const auto& r : synthetic_run_log(80, 8))
    if (r.config.backend == Backend::kCpu) cpu.push_back(r);
  GvmOptions opt;
  opt.epochs = 10;
  opt.ensemble = 3;
  // Machines train on several threads; the model must not depend on their timing.
  auto a = ResourcePredictor::train(cpu, {}, opt, nullptr);
  auto b = ResourcePredictor::train(cpu, {}, opt, nullptr);
  ASSERT_TRUE(a && b);
  ASSERT_EQ(a->machines().size(), kOutputCount);
  for (size_t k = 0; k < 3; ++k) EXPECT_EQ(a->machines()[k].size(), 3u) << k;
  // A CPU-only log has no device memory or GPU load to learn.
  EXPECT_TRUE(a->machines()[3].empty());
  EXPECT_TRUE(a->machines()[4].empty());
  EXPECT_EQ(a->to_json(), b->to_json());
  opt.ensemble = 0;
  EXPECT_FALSE(ResourcePredictor::train(cpu, {}, opt, nullptr));
}

TEST(Predictor, RejectsInvalidConfiguration) {
  RunConfig c = typical(Backend::kCpu);
  c.particles = 0;
  auto p = trained().predict(c);
  ASSERT_FALSE(p);
  EXPECT_NE(p.status().message().find("particles"), std::string::npos);
  EXPECT_FALSE(ResourcePredictor().predict(typical(Backend::kCpu)));  // untrained
}

TEST(Predictor, SaveAndLoadGiveBitIdenticalPredictions) {
  const std::string path = test::scratch_path("gvm_predictor_test.json");
  ASSERT_TRUE(trained().save(path));
  auto back = ResourcePredictor::load(path);
  ASSERT_TRUE(back) << back.status().message();
  for (const auto& row : synthetic_run_log(50, 99)) {
    double a[kOutputCount], b[kOutputCount];
    measure_to_array(trained().predict_measure(row.config), a);
    measure_to_array(back->predict_measure(row.config), b);
    EXPECT_EQ(std::memcmp(a, b, sizeof a), 0);
  }
  EXPECT_EQ(back->to_json(), trained().to_json());
  EXPECT_EQ(back->features().devices(), trained().features().devices());
}

// Time per frame (the steady cost of a frame) and the memory peaks do not depend on how
// many frames a run has, so their machines never read it; total time does.
TEST(Predictor, OnlyPerRunOutputsReadTheFrameCount) {
  RunConfig c = typical(Backend::kCuda);
  c.frames = 2;
  const RunMeasure few = trained().predict_measure(c);
  c.frames = 200;
  const RunMeasure many = trained().predict_measure(c);
  EXPECT_EQ(few.time_per_frame_s, many.time_per_frame_s);
  EXPECT_EQ(few.peak_host_bytes, many.peak_host_bytes);
  EXPECT_EQ(few.peak_device_bytes, many.peak_device_bytes);
  EXPECT_NE(few.total_time_s, many.total_time_s);
}

TEST(Predictor, CorruptModelFilesAreErrors) {
  EXPECT_FALSE(ResourcePredictor::from_json("[1, 2"));
  EXPECT_FALSE(ResourcePredictor::from_json(R"({"kind": "something else"})"));
  std::string text = trained().to_json();
  // Version 1 models (one machine for every output) and version 2 ones (the frame count
  // fed to every output) must be retrained.
  const size_t v = text.find("\"version\": 3");
  ASSERT_NE(v, std::string::npos);
  for (const char* old_version : {"\"version\": 1", "\"version\": 2"}) {
    auto old = ResourcePredictor::from_json(text.substr(0, v) + old_version + text.substr(v + 12));
    ASSERT_FALSE(old);
    EXPECT_NE(old.status().message().find("retrain"), std::string::npos);
  }
  // A device list that no longer matches the machine's inputs.
  const size_t at = text.find("\"synthetic-cpu\"");
  ASSERT_NE(at, std::string::npos);
  text.insert(at, "\"extra-device\", ");
  auto r = ResourcePredictor::from_json(text);
  ASSERT_FALSE(r);
  EXPECT_NE(r.status().message().find("feature"), std::string::npos) << r.status().message();
  // Missing: not found (bad input), told from a file there that cannot be read.
  EXPECT_EQ(ResourcePredictor::load("/nonexistent/model.json").status().code(),
            ErrorCode::kNotFound);
}

// Integer fields holding floats too large for the type (UBSan caught a plain
// cast of these) are parse errors that name the field.
TEST(Predictor, IntegerFieldsOutOfRangeAreErrorsNotCasts) {
  const std::string text = trained().to_json();
  for (const char* field : {"\"version\": 3", "\"hidden\": ", "\"epochs\": ", "\"seed\": "}) {
    const size_t at = text.find(field);
    ASSERT_NE(at, std::string::npos) << field;
    const size_t value = text.find(':', at) + 2, end = text.find_first_of(",\n}", value);
    for (const char* bad : {"1e300", "-1e300", "3.5", "99999999999999999999"}) {
      const std::string doc = text.substr(0, value) + bad + text.substr(end);
      auto r = ResourcePredictor::from_json(doc);
      ASSERT_FALSE(r) << field << " = " << bad;
      EXPECT_EQ(r.status().code(), ErrorCode::kParse) << r.status().message();
    }
  }
}

TEST(Predictor, ReadsConfigurationJson) {
  auto c = run_config_from_json(
      R"({"particles": 1e6, "triangles": 99612, "method": "circumcircle",
          "traversal": "wall", "frames": 100, "backend": "cuda", "mesh": "wall1.stl",
          "radius": 1, "wall_area": 47027.1, "wall_box_volume": 1061208})",
      &trained());
  ASSERT_TRUE(c) << c.status().message();
  EXPECT_EQ(c->particles, 1000000);
  EXPECT_EQ(c->triangles_original, 99612);  // defaults to the triangle count
  EXPECT_EQ(c->method, Method::kCircumcircle);
  EXPECT_EQ(c->traversal, Traversal::kWall);
  EXPECT_EQ(c->device, "synthetic-gpu");  // the model's usual device for cuda
  EXPECT_EQ(c->threads, 1);
  EXPECT_EQ(c->radius, 1.0);
  EXPECT_EQ(c->wall_area, 47027.1);
  EXPECT_EQ(c->wall_box_volume, 1061208.0);

  // Geometry is required: the model's costs depend on it and no default fits every wall.
  auto no_geometry = run_config_from_json(
      R"({"particles": 10, "triangles": 1, "method": "bin", "traversal": "wall",
          "frames": 1, "backend": "cpu", "radius": 1, "wall_area": 5})",
      nullptr);
  ASSERT_FALSE(no_geometry);
  EXPECT_NE(no_geometry.status().message().find("lacks \"wall_box_volume\""), std::string::npos)
      << no_geometry.status().message();
  auto zero_radius = run_config_from_json(
      R"({"particles": 10, "triangles": 1, "method": "bin", "traversal": "wall",
          "frames": 1, "backend": "cpu", "radius": 0, "wall_area": 5, "wall_box_volume": 9})",
      nullptr);
  ASSERT_FALSE(zero_radius);
  EXPECT_NE(zero_radius.status().message().find("\"radius\" must be a number > 0"),
            std::string::npos)
      << zero_radius.status().message();

  auto missing = run_config_from_json(R"({"particles": 10})", nullptr);
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.status().message().find("\"triangles\""), std::string::npos);
  auto fractional = run_config_from_json(
      R"({"particles": 10.5, "triangles": 1, "method": "bin", "traversal": "wall",
          "frames": 1, "backend": "cpu"})",
      nullptr);
  ASSERT_FALSE(fractional);
  EXPECT_NE(fractional.status().message().find("particles"), std::string::npos);
  auto bad_method = run_config_from_json(
      R"({"particles": 10, "triangles": 1, "method": "fast", "traversal": "wall",
          "frames": 1, "backend": "cpu"})",
      nullptr);
  ASSERT_FALSE(bad_method);
  EXPECT_NE(bad_method.status().message().find("method"), std::string::npos);
  EXPECT_FALSE(run_config_from_json("[]", nullptr));
  EXPECT_FALSE(run_config_from_json("{", nullptr));
}

TEST(Predictor, InvalidUtf8DeviceNamesDoNotThrow) {
  auto rows = synthetic_run_log(20, 3);
  rows[0].config.device = "bad \xff\xfe name";
  GvmOptions opt;
  opt.epochs = 2;
  auto p = ResourcePredictor::train(rows, {}, opt, nullptr);
  ASSERT_TRUE(p);
  auto back = ResourcePredictor::from_json(p->to_json());
  EXPECT_TRUE(back) << back.status().message();
  RunConfig c = rows[0].config;
  auto pr = p->predict(c);
  ASSERT_TRUE(pr);
  EXPECT_FALSE(prediction_to_json(c, *pr).empty());
}

TEST(Predictor, PredictionJsonHasEveryField) {
  RunConfig c = typical(Backend::kCuda);
  c.particles = 1000000000;
  auto p = trained().predict(c);
  ASSERT_TRUE(p);
  const std::string j = prediction_to_json(c, *p);
  for (const char* key :
       {"\"time_per_frame_s\"", "\"total_time_s\"", "\"peak_host_bytes\"", "\"peak_device_bytes\"",
        "\"gpu_load\"", "\"in_range\": false", "\"warnings\"", "\"particles\": 1000000000"})
    EXPECT_NE(j.find(key), std::string::npos) << key << " in " << j;
}

}  // namespace
}  // namespace collido::gvm
