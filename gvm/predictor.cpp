#include "common/atomic_file.h"
#include "gvm/predictor.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include "gvm/json_io.h"

namespace collido::gvm {

namespace {

void encode_table(const std::vector<RunRecord>& rows, const FeatureSpace& f, Matrix* x, Matrix* y) {
  *x = Matrix(rows.size(), f.input_count());
  *y = Matrix(rows.size(), kOutputCount);
  for (size_t r = 0; r < rows.size(); ++r) {
    f.encode_inputs(rows[r].config, x->row(r));
    encode_outputs(rows[r].measure, rows[r].config.backend, y->row(r));
  }
}

// Seed of member m of output k's ensemble: distinct for every (seed, k, m).
uint64_t member_seed(uint64_t seed, size_t k, int m) {
  uint64_t z = seed + 0x9E3779B97F4A7C15ull * (1 + k * 1024 + static_cast<uint64_t>(m));
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

std::string count_text(double log10_value) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.0f", std::pow(10.0, log10_value));
  return buf;
}

}  // namespace

Expected<ResourcePredictor> ResourcePredictor::train(const std::vector<RunRecord>& train,
                                                     const std::vector<RunRecord>& validation,
                                                     const GvmOptions& options,
                                                     TrainReport* report) {
  for (const auto* set : {&train, &validation})
    for (size_t r = 0; r < set->size(); ++r) {
      Status s = validate((*set)[r].config);
      if (s) s = validate((*set)[r].measure);
      if (!s) return invalid_argument("row " + std::to_string(r + 1) + ": " + s.message());
    }
  if (train.size() < 2) return invalid_argument("training needs at least 2 rows");
  if (options.ensemble < 1 || options.ensemble > 1000)
    return invalid_argument("ensemble must be in 1..1000");
  ResourcePredictor p;
  p.features_ = FeatureSpace::from_rows(train);
  Matrix x, y, vx, vy;
  encode_table(train, p.features_, &x, &y);
  encode_table(validation, p.features_, &vx, &vy);

  // One task per (output, member); an output no training row has a value for (device
  // memory in a CPU-only log) gets no machines and predicts 0.
  struct Task {
    Task(size_t k, int m, const Matrix& xk, const Matrix& yk, const Matrix& vxk, const Matrix& vyk)
        : output(k), member(m), x(xk), y(yk), vx(vxk), vy(vyk) {}
    size_t output;
    int member;
    const Matrix &x, &y, &vx, &vy;  // the output's inputs (masked) and its one target
    Expected<Machine> machine = invalid_argument("not trained");
    TrainReport report;
  };
  std::vector<Matrix> xs(kOutputCount), ys(kOutputCount), vxs(kOutputCount), vys(kOutputCount);
  std::vector<Task> tasks;
  for (size_t k = 0; k < kOutputCount; ++k) {
    bool any = false;
    for (size_t r = 0; r < y.rows(); ++r) any = any || !std::isnan(y(r, k));
    if (!any) continue;
    xs[k] = x;
    vxs[k] = vx;
    for (size_t r = 0; r < x.rows(); ++r) mask_inputs(k, xs[k].row(r), x.cols());
    for (size_t r = 0; r < vx.rows(); ++r) mask_inputs(k, vxs[k].row(r), vx.cols());
    ys[k] = Matrix(y.rows(), 1);
    vys[k] = Matrix(vy.rows(), 1);
    for (size_t r = 0; r < y.rows(); ++r) ys[k](r, 0) = y(r, k);
    for (size_t r = 0; r < vy.rows(); ++r) vys[k](r, 0) = vy(r, k);
    for (int m = 0; m < options.ensemble; ++m)
      tasks.emplace_back(k, m, xs[k], ys[k], vxs[k], vys[k]);
  }
  const auto t0 = std::chrono::steady_clock::now();
  // Each task owns its seed and its slot, so threads change the wall time, not the result.
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t i; (i = next.fetch_add(1)) < tasks.size();) {
      Task& t = tasks[i];
      GvmOptions o = options;
      o.seed = member_seed(options.seed, t.output, t.member);
      t.machine = Machine::train(t.x, t.y, t.vx, t.vy, o, &t.report, p.features_.input_names(),
                                 {output_feature_names()[t.output]});
    }
  };
  const size_t n_threads =
      std::min<size_t>(tasks.size(), std::max(1u, std::thread::hardware_concurrency()));
  std::vector<std::thread> pool;
  for (size_t i = 1; i < n_threads; ++i) pool.emplace_back(work);
  work();
  for (auto& th : pool) th.join();

  TrainReport local;
  TrainReport& rep = report ? *report : local;
  rep = TrainReport{};
  p.machines_.assign(kOutputCount, {});
  for (Task& t : tasks) {
    if (!t.machine) return t.machine.status();
    p.machines_[t.output].push_back(std::move(*t.machine));
    rep.proposals += t.report.proposals;
    rep.accepted += t.report.accepted;
    // The curve: per epoch, the mean over every machine (each is one output's loss).
    if (rep.curve.empty()) rep.curve.assign(t.report.curve.size(), {0, 0.0, 0.0, 0.0});
    for (size_t e = 0; e < t.report.curve.size(); ++e) {
      const EpochLoss& c = t.report.curve[e];
      const double w = 1.0 / static_cast<double>(tasks.size());
      rep.curve[e].epoch = c.epoch;
      rep.curve[e].train_loss += w * c.train_loss;
      rep.curve[e].validation_loss += w * c.validation_loss;  // NaN without validation rows
      rep.curve[e].acceptance += w * c.acceptance;
    }
  }
  rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  p.training_rows_ = train.size();
  p.options_ = options;
  if (!rep.curve.empty()) {
    p.train_loss_ = rep.curve.back().train_loss;
    p.validation_loss_ = rep.curve.back().validation_loss;
  }
  // Per backend, the most common device, then that device's most common thread count.
  for (Backend b : {Backend::kCpu, Backend::kCuda}) {
    std::map<std::string, int> devices;
    for (const auto& r : train)
      if (r.config.backend == b) ++devices[r.config.device];
    if (devices.empty()) continue;
    auto dev = std::max_element(devices.begin(), devices.end(),
                                [](auto& a, auto& c) { return a.second < c.second; });
    std::map<int64_t, int> threads;
    for (const auto& r : train)
      if (r.config.backend == b && r.config.device == dev->first) ++threads[r.config.threads];
    auto th = std::max_element(threads.begin(), threads.end(),
                               [](auto& a, auto& c) { return a.second < c.second; });
    p.usual_.push_back({b, dev->first, th->first});
  }
  return p;
}

RunMeasure ResourcePredictor::predict_measure(const RunConfig& c) const {
  double x[64];
  std::vector<double> big;
  double* xp = x;
  if (features_.input_count() > 64) {
    big.resize(features_.input_count());
    xp = big.data();
  }
  features_.encode_inputs(c, xp);
  double y[kOutputCount];
  // An output without machines (never trained, or no values in training) predicts 0.
  // The inputs an output does not read (mask_inputs) need no masking here: they were
  // constant in its training rows, and a machine scales a constant input to 0 whatever
  // its value.
  for (size_t k = 0; k < kOutputCount; ++k) {
    y[k] = 0.0;
    if (k >= machines_.size() || machines_[k].empty()) continue;
    for (const Machine& m : machines_[k]) {
      double yk;
      m.predict(xp, &yk);
      y[k] += yk;
    }
    y[k] /= static_cast<double>(machines_[k].size());
  }
  return decode_outputs(y, c.backend);
}

Expected<Prediction> ResourcePredictor::predict(const RunConfig& c) const {
  if (Status s = validate(c); !s) return s;
  // Total time reads every input (output_uses_input), so its machines know every range.
  if (machines_.size() <= 1 || machines_[1].empty())
    return invalid_argument("the predictor has not been trained");
  Prediction out;
  out.measure = predict_measure(c);
  const std::vector<double> x = features_.encode_inputs(c);
  const char* count_names[] = {"particles", "triangles", "triangles_original", "frames", "threads"};
  const int64_t counts[] = {c.particles, c.triangles, c.triangles_original, c.frames,
                            std::max<int64_t>(c.threads, 1)};
  for (const RangeIssue& issue : machines_[1][0].check_range(x.data())) {
    const size_t i = issue.input;
    std::string msg;
    if (i <= FeatureSpace::kLogThreads) {
      msg = std::string(count_names[i]) + " = " + std::to_string(counts[i]) + " is " +
            (issue.value < issue.min ? "below" : "above") + " the trained range [" +
            count_text(issue.min) + ", " + count_text(issue.max) + "]";
    } else if (i < FeatureSpace::kMethodFirst) {
      msg = features_.input_names()[i] + " = " + std::to_string(issue.value) + " is " +
            (issue.value < issue.min ? "below" : "above") + " the trained range [" +
            std::to_string(issue.min) + ", " + std::to_string(issue.max) + "]";
    } else if (i >= FeatureSpace::kMethodFirst && i < FeatureSpace::kTraversal) {
      if (issue.value == 1.0)
        msg = std::string("method '") + method_name(c.method) + "' is not in the training data";
    } else if (i == FeatureSpace::kTraversal) {
      msg = std::string("traversal '") + traversal_name(c.traversal) +
            "' is not in the training data";
    } else if (i == FeatureSpace::kBackend) {
      msg = std::string("backend '") + backend_name(c.backend) + "' is not in the training data";
    }
    if (!msg.empty()) out.warnings.push_back(msg);
  }
  if (!features_.knows_device(c.device)) {
    std::string known;
    for (const auto& d : features_.devices()) known += (known.empty() ? "'" : ", '") + d + "'";
    out.warnings.push_back("device '" + c.device + "' is not in the training data (trained on " +
                           known + ")");
  }
  return out;
}

std::optional<RunConfig> ResourcePredictor::usual_host(Backend b) const {
  for (const auto& u : usual_)
    if (u.backend == b) {
      RunConfig c;
      c.backend = b;
      c.device = u.device;
      c.threads = u.threads;
      return c;
    }
  return std::nullopt;
}

std::string ResourcePredictor::to_json() const {
  nlohmann::json j;
  j["kind"] = "collidoscope-resource-predictor";
  j["version"] = 3;
  j["devices"] = features_.devices();
  j["usual"] = nlohmann::json::array();
  for (const auto& u : usual_)
    j["usual"].push_back(
        {{"backend", backend_name(u.backend)}, {"device", u.device}, {"threads", u.threads}});
  j["training"] = {{"rows", training_rows_},
                   {"hidden", options_.hidden},
                   {"epochs", options_.epochs},
                   {"seed", options_.seed},
                   {"delta", options_.delta},
                   {"adaptive_delta", options_.adaptive_delta},
                   {"activation", activation_name(options_.activation)},
                   {"beta_max", options_.beta_max},
                   {"ensemble", options_.ensemble},
                   {"train_loss", train_loss_}};
  // NaN (no validation rows) has no JSON spelling; leave the field out instead.
  if (std::isfinite(validation_loss_)) j["training"]["validation_loss"] = validation_loss_;
  // machines[k]: output k's ensemble (output_feature_names() order), maybe empty.
  j["machines"] = nlohmann::json::array();
  for (const auto& ms : machines_) {
    nlohmann::json arr = nlohmann::json::array();
    for (const Machine& m : ms) arr.push_back(machine_to_json(m.params()));
    j["machines"].push_back(arr);
  }
  // Device names come from logs; invalid UTF-8 is replaced rather than thrown about.
  return j.dump(1, ' ', false, nlohmann::json::error_handler_t::replace);
}

Expected<ResourcePredictor> ResourcePredictor::from_json(const std::string& text) {
  nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) return parse_error("model file is not valid JSON");
  ResourcePredictor p;
  try {
    // The job cost model (job/cost_model.h) writes model files too: say which is which.
    if (j.is_object() && j.value("kind", "") == "collidoscope-job-cost-model")
      return invalid_argument(
          "this model file prices jobs (kind collidoscope-job-cost-model, trained on a job "
          "log), not detection frames: give it a scene file (`collidoscope predict SCENE.json "
          "--model MODEL.json`), or train a detection model on a calibration log of detection "
          "frames");
    if (!j.is_object() || j.value("kind", "") != "collidoscope-resource-predictor")
      return parse_error("not a collidoscope resource-predictor model");
    // Version 1 held one machine for all outputs, version 2 fed the frame count to every
    // output (see output_uses_input); such models must be retrained.
    if (integer_at<int>(j, "version") != 3)
      return parse_error("unsupported model version " + j.at("version").dump() +
                         " (retrain with `collidoscope gvm train`)");
    p.features_ = FeatureSpace::with_devices(j.at("devices").get<std::vector<std::string>>());
    for (const auto& u : j.at("usual")) {
      auto b = parse_backend(u.at("backend").get<std::string>());
      if (!b) return parse_error("unknown backend in model: " + u.at("backend").dump());
      p.usual_.push_back({*b, u.at("device").get<std::string>(), integer_at<int64_t>(u, "threads")});
    }
    const auto& t = j.at("training");
    p.training_rows_ = integer_at<size_t>(t, "rows");
    p.options_.hidden = integer_at<int>(t, "hidden");
    p.options_.epochs = integer_at<int>(t, "epochs");
    p.options_.seed = integer_at<uint64_t>(t, "seed");
    p.options_.delta = t.at("delta").get<double>();
    p.options_.adaptive_delta = t.value("adaptive_delta", true);
    auto act = parse_activation(t.at("activation").get<std::string>());
    if (act) p.options_.activation = *act;
    p.options_.beta_max = t.at("beta_max").get<double>();
    p.options_.ensemble = integer_at<int>(t, "ensemble");
    p.train_loss_ = t.at("train_loss").get<double>();
    p.validation_loss_ = t.value("validation_loss", std::nan(""));
  } catch (const std::exception& e) {  // nlohmann's type errors and BadField
    return parse_error(std::string("model JSON: ") + e.what());
  }
  if (!j.contains("machines") || !j["machines"].is_array() || j["machines"].size() != kOutputCount)
    return parse_error("model JSON needs 'machines', one list per output");
  for (size_t k = 0; k < kOutputCount; ++k) {
    const nlohmann::json& list = j["machines"][k];
    if (!list.is_array())
      return parse_error("model JSON: machines[" + std::to_string(k) + "] is not a list");
    p.machines_.emplace_back();
    for (const auto& mj : list) {
      auto params = machine_from_json(mj);
      if (!params) return params.status();
      auto m = Machine::from_params(std::move(*params));
      if (!m) return m.status();
      if (m->outputs() != 1 || m->params().input_names != p.features_.input_names())
        return parse_error("model machine does not match its feature list");
      p.machines_[k].push_back(std::move(*m));
    }
  }
  if (p.machines_[0].empty() || p.machines_[1].empty())
    return parse_error("model JSON has no machine for the time per frame or the total time");
  return p;
}

Status ResourcePredictor::save(const std::string& path) const {
  // Write then rename, so a reader never sees half a model (and a failed write leaves no temporary
  // file).
  return write_file_atomic(path, to_json() + "\n");
}

Expected<ResourcePredictor> ResourcePredictor::load(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return open_failure(path, "cannot open model '" + path + "'");
  std::ostringstream ss;
  ss << in.rdbuf();
  auto p = from_json(ss.str());
  if (!p) return Status(p.status().code(), path + ": " + p.status().message());
  return p;
}

}  // namespace collido::gvm

namespace collido::gvm {

namespace {

// A JSON number that is a whole count (1e6 is fine, 1.5 is not).
bool json_count(const nlohmann::json& v, int64_t* out) {
  if (v.is_number_integer()) {
    *out = v.get<int64_t>();
    return true;
  }
  if (v.is_number_float()) {
    const double d = v.get<double>();
    if (std::isfinite(d) && d == std::floor(d) && std::abs(d) < 9.0e18) {
      *out = static_cast<int64_t>(d);
      return true;
    }
  }
  return false;
}

}  // namespace

Expected<RunConfig> run_config_from_json(const std::string& text, const ResourcePredictor* model) {
  nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) return parse_error("configuration is not valid JSON");
  if (!j.is_object()) return parse_error("configuration must be a JSON object");
  // A scene file of `collidoscope run` is a job: the job cost model prices it
  // (job/cost_model.h); this predictor is calibrated on detection frames and must not
  // pretend to cost one.
  if (j.contains("wall") || j.contains("placement"))
    return invalid_argument(
        "this is a scene file of `collidoscope run`, a job: the job cost model prices it "
        "(`collidoscope predict SCENE.json` with a job model); this detection-frame predictor "
        "reads a detection configuration (particles, triangles, method, traversal, frames, "
        "backend, radius, wall_area, wall_box_volume; see `collidoscope predict --help`)");
  RunConfig c;
  auto count = [&](const char* key, int64_t* out, bool required) -> Status {
    if (!j.contains(key))
      return required ? invalid_argument(std::string("configuration lacks \"") + key + "\"")
                      : Status::ok();
    if (!json_count(j[key], out))
      return invalid_argument(std::string("\"") + key + "\" must be a whole number, got " +
                              j[key].dump());
    return Status::ok();
  };
  auto word = [&](const char* key, std::string* out) -> Status {
    if (!j.contains(key))
      return invalid_argument(std::string("configuration lacks \"") + key + "\"");
    if (!j[key].is_string())
      return invalid_argument(std::string("\"") + key + "\" must be a string, got " +
                              j[key].dump());
    *out = j[key].get<std::string>();
    return Status::ok();
  };
  // Geometry has no sensible default: the model's costs depend on it.
  auto positive = [&](const char* key, double* out) -> Status {
    if (!j.contains(key))
      return invalid_argument(std::string("configuration lacks \"") + key + "\"");
    if (!j[key].is_number() || !std::isfinite(j[key].get<double>()) || j[key].get<double>() <= 0)
      return invalid_argument(std::string("\"") + key + "\" must be a number > 0, got " +
                              j[key].dump());
    *out = j[key].get<double>();
    return Status::ok();
  };
  std::string method, traversal, backend;
  for (Status s : {count("particles", &c.particles, true), count("triangles", &c.triangles, true),
                   count("frames", &c.frames, true), word("method", &method),
                   word("traversal", &traversal), word("backend", &backend)})
    if (!s) return s;
  auto m = parse_method(method);
  if (!m)
    return invalid_argument(
        "\"method\" must be gravity|circumcircle|midpoint4|bin|reference, got \"" + method + "\"");
  auto t = parse_traversal(traversal);
  if (!t) return invalid_argument("\"traversal\" must be wall|particle, got \"" + traversal + "\"");
  auto b = parse_backend(backend);
  if (!b) return invalid_argument("\"backend\" must be cpu|cuda, got \"" + backend + "\"");
  c.method = *m;
  c.traversal = *t;
  c.backend = *b;
  for (Status s : {positive("radius", &c.radius), positive("wall_area", &c.wall_area),
                   positive("wall_box_volume", &c.wall_box_volume)})
    if (!s) return s;
  c.triangles_original = c.triangles;
  if (Status s = count("triangles_original", &c.triangles_original, false); !s) return s;
  if (model)
    if (auto usual = model->usual_host(c.backend)) {
      c.device = usual->device;
      c.threads = usual->threads;
    }
  if (j.contains("device")) {
    if (!j["device"].is_string())
      return invalid_argument("\"device\" must be a string, got " + j["device"].dump());
    c.device = j["device"].get<std::string>();
  }
  if (Status s = count("threads", &c.threads, false); !s) return s;
  if (Status s = validate(c); !s) return s;
  return c;
}

std::string prediction_to_json(const RunConfig& c, const Prediction& p) {
  nlohmann::json j;
  j["time_per_frame_s"] = p.measure.time_per_frame_s;
  j["total_time_s"] = p.measure.total_time_s;
  j["peak_host_bytes"] = p.measure.peak_host_bytes;
  j["peak_device_bytes"] = p.measure.peak_device_bytes;
  j["gpu_load"] = p.measure.gpu_load;
  j["in_range"] = p.in_range();
  j["warnings"] = p.warnings;
  j["config"] = {{"particles", c.particles},
                 {"triangles", c.triangles},
                 {"triangles_original", c.triangles_original},
                 {"radius", c.radius},
                 {"wall_area", c.wall_area},
                 {"wall_box_volume", c.wall_box_volume},
                 {"method", method_name(c.method)},
                 {"traversal", traversal_name(c.traversal)},
                 {"frames", c.frames},
                 {"backend", backend_name(c.backend)},
                 {"device", c.device},
                 {"threads", c.threads}};
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace collido::gvm
