// `collidoscope gvm ...` (train the resource predictor, make a synthetic log) and
// `collidoscope predict` (the predicted cost of one configuration).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "app/cli.h"
#include "app/commands.h"
#include "common/atomic_file.h"
#include "gvm/gvm.h"
#ifdef COLLIDO_HAVE_JOB_COST
#include "job/job_log.h"
#endif

namespace collido::app {

namespace {

namespace g = collido::gvm;

bool read_text(const std::string& path, std::string* out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::ostringstream ss;
  ss << in.rdbuf();
  *out = ss.str();
  return true;
}

std::string human_seconds(double s) {
  char buf[32];
  if (s < 1e-3)
    std::snprintf(buf, sizeof buf, "%.3g us", s * 1e6);
  else if (s < 1.0)
    std::snprintf(buf, sizeof buf, "%.3g ms", s * 1e3);
  else
    std::snprintf(buf, sizeof buf, "%.4g s", s);
  return buf;
}

std::string percent(const g::OutputError& e) {
  if (e.rows == 0) return "n/a";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f", e.mape_percent);
  return buf;
}

// Mean wall-clock microseconds of one call of f, over enough calls for ~0.2 s.
template <class F>
double time_per_call_us(F&& f) {
  using clock = std::chrono::steady_clock;
  size_t calls = 0;
  const auto t0 = clock::now();
  double elapsed = 0.0;
  do {
    for (int i = 0; i < 1000; ++i) f(calls++);
    elapsed = std::chrono::duration<double>(clock::now() - t0).count();
  } while (elapsed < 0.2);
  return elapsed / static_cast<double>(calls) * 1e6;
}

// Keeps the optimiser from dropping benchmarked calls.
volatile double g_sink = 0.0;

#ifdef COLLIDO_HAVE_JOB_COST
// Whether a CSV file is a job log (its header says so); false when it cannot be read,
// which the detection reader then reports.
bool is_job_log(const std::string& path) {
  std::ifstream in(path);
  std::string header;
  return std::getline(in, header) && job::log_kind(header + "\n") == job::LogKind::kJob;
}
#endif

// ---- gvm train -------------------------------------------------------------------------

const std::vector<FlagSpec>& train_flags() {
  static const std::vector<FlagSpec> specs = {
      {"logs", true, "run log or job log CSV to train on (required; see docs/gvm.md)"},
      {"out", true, "where to write the model JSON (required)"},
      {"hidden", true, "hidden neurons (default 16; a job log 12)"},
      {"epochs", true,
       "epochs; one epoch = one proposal per parameter (default 2000; a job log 800)"},
      {"seed", true, "seed of the machine's signs, start and proposals (default 1)"},
      {"delta", true, "largest Monte Carlo step, fraction of a parameter's range (default 0.1)"},
      {"fixed-delta", false, "keep the step at --delta instead of adapting it per epoch"},
      {"beta-max", true, "gain range [-B, B] of each hidden neuron (default 3)"},
      {"ensemble", true, "machines per output, from different seeds, averaged (default 3)"},
      {"activation", true, "softsign, tanh or sigmoid (default softsign)"},
      {"split-seed", true, "seed of the 70/30 train/validation split (default 1)"},
      {"folds", true, "job log: machines per cost, one per fold held out (default 5)"},
      {"coverage", true, "job log: share of held-out runs the interval holds (default 0.8)"},
      {"splits", true, "job log: 70/30 splits scored, seeds split-seed.. (default 1)"},
      {"resample", true,
       "job log: train the written model on this many of the log's rows, "
       "drawn without repeats (timing runs)"},
      {"curve", true, "write every epoch's train/validation loss to this CSV"},
      {"predictions", true,
       "write the validation rows with every model's predictions to this "
       "CSV (a job log: the first split's, with the GVM's p10, p50, p90)"},
      {"mlp-epochs", true, "epochs of the back-propagation baseline (default 10000)"},
      {"help", false, "show this help"},
  };
  return specs;
}

int gvm_train(const Args& args) {
  const char* cmd = "gvm train";
  std::string error;
  auto parsed = parse_args(args, train_flags(), &error);
  if (!parsed) return usage_error(cmd, error);
  if (parsed->has("help")) {
    print_help(
        "usage: collidoscope gvm train --logs RUNS.csv --out MODEL.json [options]\n\n"
        "Trains the general vector machines (an ensemble per output) on 70% of the logged\n"
        "runs, scores them and three baselines (the paper's linear fit in triangles, least\n"
        "squares on log features, a back-propagation MLP) on the other 30%, and writes the\n"
        "model. A job log (`calibrate --jobs`) trains the job cost model instead: per cost\n"
        "one GVM per fold, the folds' held-out residuals setting the 10-90 % interval.",
        train_flags());
    return kExitOk;
  }
  if (!parsed->positional().empty())
    return usage_error(cmd, "unexpected argument '" + parsed->positional()[0] + "'");
  if (!parsed->has("logs")) return usage_error(cmd, "--logs RUNS.csv is required");
  if (!parsed->has("out")) return usage_error(cmd, "--out MODEL.json is required");

  g::CompareOptions opt;
  opt.gvm.hidden = parsed->get_int32("hidden", opt.gvm.hidden, &error);
  opt.gvm.epochs = parsed->get_int32("epochs", opt.gvm.epochs, &error);
  opt.gvm.seed = static_cast<uint64_t>(parsed->get_int("seed", 1, &error));
  opt.gvm.delta = parsed->get_double("delta", opt.gvm.delta, &error);
  opt.gvm.beta_max = parsed->get_double("beta-max", opt.gvm.beta_max, &error);
  opt.gvm.ensemble = parsed->get_int32("ensemble", opt.gvm.ensemble, &error);
  opt.split_seed = static_cast<uint64_t>(parsed->get_int("split-seed", 1, &error));
  opt.mlp.epochs = parsed->get_int32("mlp-epochs", opt.mlp.epochs, &error);
  if (!error.empty()) return usage_error(cmd, error);
  opt.gvm.adaptive_delta = !parsed->has("fixed-delta");
  if (parsed->has("activation")) {
    auto a = g::parse_activation(parsed->get("activation"));
    if (!a) return usage_error(cmd, "--activation must be softsign, tanh or sigmoid");
    opt.gvm.activation = *a;
  }
  if (opt.gvm.hidden < 1 || opt.gvm.hidden > 4096)
    return usage_error(cmd, "--hidden must be in 1..4096");
  if (opt.gvm.epochs < 1 || opt.gvm.epochs > 1000000)
    return usage_error(cmd, "--epochs must be in 1..1000000");
  if (!(opt.gvm.delta > 0.0 && opt.gvm.delta <= 1.0))
    return usage_error(cmd, "--delta must be in (0, 1]");
  if (!(opt.gvm.beta_max > 0.0 && opt.gvm.beta_max <= 1000.0))
    return usage_error(cmd, "--beta-max must be in (0, 1000]");
  if (opt.gvm.ensemble < 1 || opt.gvm.ensemble > 1000)
    return usage_error(cmd, "--ensemble must be in 1..1000");
  if (opt.mlp.epochs < 0) return usage_error(cmd, "--mlp-epochs must be >= 0");

  const std::string log_path = parsed->get("logs");
#ifdef COLLIDO_HAVE_JOB_COST
  if (is_job_log(log_path)) return gvm_train_jobs(*parsed, log_path);
#endif
  for (const char* job_only : {"folds", "coverage", "splits", "resample"})
    if (parsed->has(job_only))
      return usage_error(cmd, std::string("--") + job_only + " is for job logs; " + log_path +
                                  " is a run log of detection frames");
  auto rows = g::read_run_log(log_path);
  if (!rows) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, rows.status().message().c_str());
    return exit_code(rows.status());
  }
  auto cmp = g::train_and_compare(*rows, opt);
  if (!cmp) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, cmp.status().message().c_str());
    return kExitFailure;
  }
  const auto& rep = cmp->gvm_report;
  const auto& mp = cmp->gvm.machines()[1][0].params();  // total time reads every input
  size_t machines = 0;
  for (const auto& ms : cmp->gvm.machines()) machines += ms.size();
  size_t varying = 0;
  for (size_t i = 0; i < mp.inputs; ++i) varying += mp.in_max[i] > mp.in_min[i];
  std::printf("%zu runs from %s: %zu train, %zu validation (split seed %llu)\n", rows->size(),
              log_path.c_str(), cmp->split.train.size(), cmp->split.validation.size(),
              static_cast<unsigned long long>(opt.split_seed));
  std::printf(
      "GVM: %zu machines (%d per output with values), each %d hidden %s neurons, beta in "
      "[-%g, %g], %zu inputs (%zu vary), 1 output; %d epochs, delta %g, seed %llu\n",
      machines, opt.gvm.ensemble, opt.gvm.hidden, g::activation_name(opt.gvm.activation),
      opt.gvm.beta_max, opt.gvm.beta_max, mp.inputs, varying, opt.gvm.epochs, opt.gvm.delta,
      static_cast<unsigned long long>(opt.gvm.seed));

  // Loss on stdout at about ten epochs (first, last, evenly between); all of them with --curve.
  std::printf("%7s  %12s  %15s  %8s\n", "epoch", "train loss", "validation loss", "accepted");
  const size_t n = rep.curve.size();
  const size_t stride = std::max<size_t>(1, n / 10);
  for (size_t e = 0; e < n; ++e) {
    if (e != 0 && e + 1 != n && (e + 1) % stride != 0) continue;
    const auto& c = rep.curve[e];
    std::printf("%7d  %12.4e  %15.4e  %7.1f%%\n", c.epoch, c.train_loss, c.validation_loss,
                100.0 * c.acceptance);
  }
  std::printf(
      "trained in %s (%lld proposals, %.1f%% kept); loss = mean squared error of the "
      "targets scaled to [0,1], averaged over the machines\n",
      human_seconds(rep.seconds).c_str(), static_cast<long long>(rep.proposals),
      rep.proposals ? 100.0 * rep.accepted / rep.proposals : 0.0);

  if (parsed->has("curve")) {
    const std::string path = parsed->get("curve");
    if (Status st = write_loss_curve(path, rep.curve); !st) {
      std::fprintf(stderr, "collidoscope %s: %s\n", cmd, st.message().c_str());
      return kExitFailure;
    }
    std::printf("loss curve: %s (%zu epochs)\n", path.c_str(), n);
  }

  const auto& names = g::measure_names();
  if (parsed->has("predictions")) {
    // The validation rows as run-log rows, then MODEL_OUTPUT columns: what each model
    // predicted for them, to look at the misses row by row (or chart them).
    const std::string path = parsed->get("predictions");
    const auto& va = cmp->split.validation;
    std::ostringstream out;
    for (size_t i = 0; i <= va.size(); ++i) {
      out << (i == 0 ? g::run_log_header() : g::format_run_log_row(va[i - 1]));
      for (const auto& s : cmp->scores) {
        double p[g::kOutputCount];
        if (i > 0) g::measure_to_array(s.validation_predictions[i - 1], p);
        for (size_t k = 0; k < names.size(); ++k) {
          char cell[64];
          if (i == 0)
            std::snprintf(cell, sizeof cell, ",%s_%s", s.name.c_str(), names[k].c_str());
          else
            std::snprintf(cell, sizeof cell, ",%.9g", p[k]);
          out << cell;
        }
      }
      out << '\n';
    }
    if (Status st = write_file_atomic(path, out.str()); !st) {
      std::fprintf(stderr, "collidoscope %s: %s\n", cmd, st.message().c_str());
      return kExitFailure;
    }
    std::printf("validation predictions: %s (%zu rows)\n", path.c_str(), va.size());
  }

  auto table = [&](const char* title, bool validation) {
    std::printf("\n%s MAPE %% (rows with a nonzero value)\n%-15s", title, "model");
    for (const auto& nm : names) std::printf(" %17s", nm.c_str());
    std::printf(" %9s\n", "fit time");
    for (const auto& s : cmp->scores) {
      std::printf("%-15s", s.name.c_str());
      const auto& e = validation ? s.validation : s.train;
      for (size_t k = 0; k < names.size(); ++k) std::printf(" %17s", percent(e[k]).c_str());
      std::printf(" %9s\n", human_seconds(s.fit_seconds).c_str());
    }
  };
  table("validation", true);
  // A percentage of a small load is large for a small miss; say the miss in load too.
  std::printf("validation GPU load mean absolute error:");
  for (const auto& s : cmp->scores)
    std::printf("  %s %.3f", s.name.c_str(), s.validation[g::kOutputCount - 1].mean_abs);
  std::printf("\n");
  table("training", false);

  // The figure that matters for the service: one prediction, costs only and with checks.
  const auto& va = cmp->split.validation;
  const double us_fast = time_per_call_us([&](size_t i) {
    g_sink = g_sink + cmp->gvm.predict_measure(va[i % va.size()].config).time_per_frame_s;
  });
  const double us_full = time_per_call_us([&](size_t i) {
    auto p = cmp->gvm.predict(va[i % va.size()].config);
    g_sink = g_sink + p->measure.time_per_frame_s;
  });
  std::printf("\nprediction time: %.2f us per configuration (%.2f us with range checks)\n", us_fast,
              us_full);

  const std::string out_path = parsed->get("out");
  if (auto s = cmp->gvm.save(out_path); !s) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, s.message().c_str());
    return kExitFailure;
  }
  std::printf("model: %s\n", out_path.c_str());
  return kExitOk;
}

// ---- gvm synth -------------------------------------------------------------------------

const std::vector<FlagSpec>& synth_flags() {
  static const std::vector<FlagSpec> specs = {
      {"out", true, "where to write the run log CSV (required)"},
      {"rows", true, "number of runs (default 100)"},
      {"seed", true, "seed (default 1)"},
      {"help", false, "show this help"},
  };
  return specs;
}

int gvm_synth(const Args& args) {
  const char* cmd = "gvm synth";
  std::string error;
  auto parsed = parse_args(args, synth_flags(), &error);
  if (!parsed) return usage_error(cmd, error);
  if (parsed->has("help")) {
    print_help(
        "usage: collidoscope gvm synth --out RUNS.csv [--rows N] [--seed S]\n\n"
        "Writes a run log from a made-up cost model, to try `gvm train` before real runs\n"
        "exist. Its numbers are not measurements of the engine.",
        synth_flags());
    return kExitOk;
  }
  if (!parsed->positional().empty())
    return usage_error(cmd, "unexpected argument '" + parsed->positional()[0] + "'");
  if (!parsed->has("out")) return usage_error(cmd, "--out RUNS.csv is required");
  const int64_t n = parsed->get_int("rows", 100, &error);
  const int64_t seed = parsed->get_int("seed", 1, &error);
  if (!error.empty()) return usage_error(cmd, error);
  if (n < 1 || n > 10000000) return usage_error(cmd, "--rows must be in 1..10000000");
  auto rows = g::synthetic_run_log(static_cast<size_t>(n), static_cast<uint64_t>(seed));
  if (auto s = g::write_run_log(parsed->get("out"), rows); !s) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, s.message().c_str());
    return kExitFailure;
  }
  std::printf("%lld synthetic runs (made-up cost model, not measurements): %s\n",
              static_cast<long long>(n), parsed->get("out").c_str());
  return kExitOk;
}

// ---- gvm merge -------------------------------------------------------------------------

const std::vector<FlagSpec>& merge_flags() {
  static const std::vector<FlagSpec> specs = {
      {"out", true, "where to write the merged run log CSV (required)"},
      {"help", false, "show this help"},
  };
  return specs;
}

int gvm_merge(const Args& args) {
  const char* cmd = "gvm merge";
  std::string error;
  auto parsed = parse_args(args, merge_flags(), &error);
  if (!parsed) return usage_error(cmd, error);
  if (parsed->has("help")) {
    print_help(
        "usage: collidoscope gvm merge RUNS.csv... --out MERGED.csv\n\n"
        "Concatenates run logs and combines the rows of one configuration (equal in every\n"
        "input column), as `calibrate` combines its repeats: for detection frames the\n"
        "smallest time per frame and the fastest run's total time and GPU load, for jobs the\n"
        "median of each time and of the GPU load; the largest memory. Sweeps with the same\n"
        "seed on one machine become one log with their passes.",
        merge_flags());
    return kExitOk;
  }
  if (parsed->positional().empty()) return usage_error(cmd, "expects one or more RUNS.csv");
  if (!parsed->has("out")) return usage_error(cmd, "--out MERGED.csv is required");
#ifdef COLLIDO_HAVE_JOB_COST
  {
    size_t jobs = 0;
    for (const std::string& path : parsed->positional()) jobs += is_job_log(path);
    if (jobs == parsed->positional().size())
      return gvm_merge_jobs(parsed->positional(), parsed->get("out"));
    if (jobs > 0)
      return usage_error(cmd, "job logs and detection run logs cannot be merged into one");
  }
#endif
  std::vector<g::RunRecord> all;
  for (const std::string& path : parsed->positional()) {
    auto rows = g::read_run_log(path);
    if (!rows) {
      std::fprintf(stderr, "collidoscope %s: %s\n", cmd, rows.status().message().c_str());
      return exit_code(rows.status());
    }
    all.insert(all.end(), rows->begin(), rows->end());
  }
  const auto merged = g::merge_repeats(all);
  if (auto s = g::write_run_log(parsed->get("out"), merged); !s) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, s.message().c_str());
    return kExitFailure;
  }
  std::printf("%zu rows from %zu logs -> %zu configurations: %s\n", all.size(),
              parsed->positional().size(), merged.size(), parsed->get("out").c_str());
  return kExitOk;
}

void print_gvm_usage() {
  std::printf(
      "usage: collidoscope gvm SUBCOMMAND [options]   (SUBCOMMAND --help for its options)\n\n"
      "  train   train the resource predictor on a run log and compare it with baselines\n"
      "  synth   write a synthetic run log (made-up costs) to try train with\n"
      "  merge   combine run logs; repeated configurations become one row\n"
#ifdef COLLIDO_HAVE_JOB_COST
      "  replay  a job cost model on a job log in its order, alone and with the pace\n"
#endif
  );
}

// ---- predict ---------------------------------------------------------------------------

const std::vector<FlagSpec>& predict_flags() {
  static const std::vector<FlagSpec> specs = {
      {"model", true,
       "model JSON written by `gvm train` (required for a detection configuration; a scene "
       "defaults to bench/data/job_model_BACKEND.json)"},
      {"json", false, "print the prediction as JSON"},
      {"bench", false, "also time one prediction (mean over many)"},
      {"backend", true, "scene: auto, cpu or cuda (default: the scene's)"},
      {"threads", true, "scene: CPU threads of the job (default: the model's usual)"},
      {"duration", true, "scene: simulated seconds instead of the scene's"},
      {"video", false, "scene: price rendering too (as `run --video`)"},
      {"formats", true, "scene with --video: mp4,webm,gif or none (default all three)"},
      {"width", true, "scene with --video: frame width in pixels"},
      {"height", true, "scene with --video: frame height in pixels"},
      {"help", false, "show this help"},
  };
  return specs;
}

}  // namespace

Status write_loss_curve(const std::string& path, const std::vector<gvm::EpochLoss>& curve) {
  std::string text = "epoch,train_loss,validation_loss,acceptance\n";
  char line[128];
  for (const auto& c : curve) {
    std::snprintf(line, sizeof line, "%d,%.9g,%.9g,%.6f\n", c.epoch, c.train_loss,
                  c.validation_loss, c.acceptance);
    text += line;
  }
  return write_file_atomic(path, text);
}

int cmd_gvm(const Args& args) {
  if (args.empty()) {
    print_gvm_usage();
    return kExitUsage;
  }
  const std::string& sub = args[0];
  if (sub == "--help" || sub == "-h" || sub == "help") {
    print_gvm_usage();
    return kExitOk;
  }
  const Args rest(args.begin() + 1, args.end());
  if (sub == "train") return gvm_train(rest);
  if (sub == "synth") return gvm_synth(rest);
  if (sub == "merge") return gvm_merge(rest);
#ifdef COLLIDO_HAVE_JOB_COST
  if (sub == "replay") return gvm_replay(rest);
#endif
  return usage_error("gvm", "unknown subcommand '" + sub + "' (train, synth, merge, replay)");
}

int cmd_predict(const Args& args) {
  const char* cmd = "predict";
  std::string error;
  auto parsed = parse_args(args, predict_flags(), &error);
  if (!parsed) return usage_error(cmd, error);
  if (parsed->has("help")) {
    print_help(
        "usage: collidoscope predict SCENE.json [--model JOB_MODEL.json] [--backend B] [--video]\n"
        "       collidoscope predict CONFIG.json --model MODEL.json [--json] [--bench]\n\n"
        "SCENE.json: a scene of `collidoscope run` (or a job spec of `job-exec`), priced by\n"
        "  the job cost model: total time, time per frame, peak host and device memory, GPU\n"
        "  load and output bytes, each with its 10-90 % interval, and a line for every input\n"
        "  outside the jobs the model was trained on.\n"
        "CONFIG.json: detection frames, priced by the detection predictor:\n"
        "  {\"particles\": 1e6, \"triangles\": 99612, \"method\": \"circumcircle\",\n"
        "  \"traversal\": \"particle\", \"frames\": 100, \"backend\": \"cuda\", \"radius\": 1,\n"
        "  \"wall_area\": 9.4e4, \"wall_box_volume\": 1.1e6} (largest particle radius, wall\n"
        "  area, wall bounding box grown by the radius; world units); optional\n"
        "  \"triangles_original\", \"device\", \"threads\" (default: the model's usual host).\n"
        "Each model file says which kind it is and refuses the other kind of input.\n"
        "Exit codes: 0 predicted (even with warnings), 2 bad arguments, configuration\n"
        "values or a missing or malformed file, 1 a file there that could not be read.",
        predict_flags());
    return kExitOk;
  }
  if (parsed->positional().size() != 1)
    return usage_error(cmd, "expects exactly one SCENE.json or CONFIG.json (see --help)");
  const std::string config_path = parsed->positional()[0];
  std::string text;
  if (!read_text(config_path, &text)) {
    std::fprintf(stderr, "collidoscope %s: cannot open %s\n", cmd, config_path.c_str());
    return exit_code(open_failure(config_path, "cannot open"));  // missing: 2
  }
#ifdef COLLIDO_HAVE_JOB_COST
  {
    // A scene (it has a wall or a placement) or a job spec is a job.
    const nlohmann::json doc = nlohmann::json::parse(text, nullptr, false);
    if (doc.is_object() && (doc.contains("wall") || doc.contains("placement") || doc.contains("scene")))
      return predict_scene(*parsed, config_path, text);
  }
#endif
  for (const char* scene_only : {"backend", "threads", "duration", "video", "formats", "width", "height"})
    if (parsed->has(scene_only))
      return usage_error(cmd, std::string("--") + scene_only + " is for scene files; " +
                                  config_path + " is a detection configuration");
  if (!parsed->has("model")) return usage_error(cmd, "--model MODEL.json is required");

  auto model = g::ResourcePredictor::load(parsed->get("model"));
  if (!model) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, model.status().message().c_str());
    return exit_code(model.status());
  }
  auto config = g::run_config_from_json(text, &*model);
  if (!config) return usage_error(cmd, config_path + ": " + config.status().message());
  auto pred = model->predict(*config);
  if (!pred) return usage_error(cmd, pred.status().message());

  if (parsed->has("json")) {
    std::printf("%s\n", g::prediction_to_json(*config, *pred).c_str());
  } else {
    const g::RunConfig& c = *config;
    const g::RunMeasure& m = pred->measure;
    std::printf("%lld particles, %lld triangles (%s, %s traversal), %lld frames, %s",
                static_cast<long long>(c.particles), static_cast<long long>(c.triangles),
                g::method_name(c.method), g::traversal_name(c.traversal),
                static_cast<long long>(c.frames), g::backend_name(c.backend));
    if (!c.device.empty()) std::printf(" on %s", c.device.c_str());
    std::printf("\n  time per frame      %s\n", human_seconds(m.time_per_frame_s).c_str());
    std::printf("  total time          %s\n", human_seconds(m.total_time_s).c_str());
    std::printf("  peak host memory    %s\n", human_bytes(m.peak_host_bytes).c_str());
    std::printf("  peak device memory  %s\n", human_bytes(m.peak_device_bytes).c_str());
    std::printf("  GPU load            %.2f\n", m.gpu_load);
    for (const auto& w : pred->warnings)
      std::printf("warning: %s; the prediction is an extrapolation\n", w.c_str());
  }
  if (parsed->has("bench")) {
    const double us = time_per_call_us(
        [&](size_t) { g_sink = g_sink + model->predict_measure(*config).time_per_frame_s; });
    std::fprintf(parsed->has("json") ? stderr : stdout, "prediction time: %.2f us\n", us);
  }
  return kExitOk;
}

}  // namespace collido::app
