// The job side of `collidoscope gvm train`, `gvm merge` and `predict`: a job log
// trains the job cost model (job/cost_model.h), compared with the baselines on 70/30
// splits; a scene file is priced by it. cmd_gvm.cpp sends job logs and scene files here.
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
#include "gvm/rng.h"
#include "job/assess.h"
#include "job/cost_model.h"
#include "job/job_log.h"
#include "sim/detect.h"

#ifndef COLLIDO_DATA_DIR
#define COLLIDO_DATA_DIR "bench/data"
#endif

namespace collido::app {

namespace {

std::string seconds_text(double s) {
  char buf[32];
  if (s < 1e-3)
    std::snprintf(buf, sizeof buf, "%.3g us", s * 1e6);
  else if (s < 1.0)
    std::snprintf(buf, sizeof buf, "%.3g ms", s * 1e3);
  else if (s < 3600)
    std::snprintf(buf, sizeof buf, "%.4g s", s);
  else
    std::snprintf(buf, sizeof buf, "%.3g h", s / 3600);
  return buf;
}

std::string pct(double v) {
  if (std::isnan(v)) return "n/a";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f", v);
  return buf;
}

volatile double g_sink = 0.0;

template <class F>
double us_per_call(F&& f) {
  using clock = std::chrono::steady_clock;
  size_t calls = 0;
  const auto t0 = clock::now();
  double elapsed = 0.0;
  do {
    for (int i = 0; i < 200; ++i) f(calls++);
    elapsed = std::chrono::duration<double>(clock::now() - t0).count();
  } while (elapsed < 0.2);
  return elapsed / double(calls) * 1e6;
}

// The six costs' short column names.
const char* kShort[job::kJobOutputs] = {"total", "per-frame", "host-mem", "device-mem", "gpu-load",
                                        "output"};

void print_errors_header() {
  std::printf("%-14s", "model");
  for (const char* s : kShort) std::printf(" %10s", s);
  std::printf(" %9s %9s\n", "host>5%lo", "fit");
}

void print_errors(const job::JobModelScore& s, bool validation) {
  const job::JobErrors& e = validation ? s.validation : s.train;
  std::printf("%-14s", s.name.c_str());
  for (size_t k = 0; k < job::kJobOutputs; ++k) std::printf(" %10s", pct(e.mape[k]).c_str());
  std::printf(" %8s%% %9s\n", pct(100 * e.host_under5).c_str(), seconds_text(s.fit_seconds).c_str());
}

// The first split's validation jobs as job-log rows, then the GVM's p10, p50 and p90
// of each cost: to look at the misses job by job (or chart them).
Status write_job_predictions(const std::string& path, const job::JobComparison& cmp) {
  std::string text;
  for (size_t i = 0; i <= cmp.validation.size(); ++i) {
    text += i == 0 ? job::job_log_header() : job::format_job_log_row(cmp.validation[i - 1]);
    if (i == 0) {
      for (const char* k : kShort)
        text += std::string(",gvm_") + k + "_p10,gvm_" + k + "_p50,gvm_" + k + "_p90";
    } else {
      auto pr = cmp.model.predict(cmp.validation[i - 1].inputs);
      if (!pr) return pr.status();
      const job::CostInterval* c[job::kJobOutputs] = {&pr->total_s,          &pr->per_frame_s,
                                                      &pr->peak_host_bytes,  &pr->peak_device_bytes,
                                                      &pr->gpu_load,         &pr->output_bytes};
      char cell[96];
      for (const auto* iv : c) {
        std::snprintf(cell, sizeof cell, ",%.9g,%.9g,%.9g", iv->p10, iv->p50, iv->p90);
        text += cell;
      }
    }
    text += '\n';
  }
  return write_file_atomic(path, text);
}

}  // namespace

int gvm_train_jobs(const ParsedArgs& p, const std::string& log_path) {
  const char* cmd = "gvm train";
  std::string error;
  job::JobCostOptions opt;
  opt.gvm.hidden = p.get_int32("hidden", opt.gvm.hidden, &error);
  opt.gvm.epochs = p.get_int32("epochs", opt.gvm.epochs, &error);
  opt.gvm.seed = uint64_t(p.get_int("seed", 1, &error));
  opt.gvm.delta = p.get_double("delta", opt.gvm.delta, &error);
  opt.gvm.beta_max = p.get_double("beta-max", opt.gvm.beta_max, &error);
  opt.folds = p.get_int32("folds", opt.folds, &error);
  opt.coverage = p.get_double("coverage", opt.coverage, &error);
  const int64_t split_seed = p.get_int("split-seed", 1, &error);
  const int64_t splits = p.get_int("splits", 1, &error);
  const int mlp_epochs = p.get_int32("mlp-epochs", 10000, &error);
  const int64_t resample = p.get_int("resample", 0, &error);
  if (!error.empty()) return usage_error(cmd, error);
  opt.gvm.adaptive_delta = !p.has("fixed-delta");
  if (p.has("activation")) {
    auto a = gvm::parse_activation(p.get("activation"));
    if (!a) return usage_error(cmd, "--activation must be softsign, tanh or sigmoid");
    opt.gvm.activation = *a;
  }
  if (opt.gvm.hidden < 1 || opt.gvm.hidden > 4096) return usage_error(cmd, "--hidden must be in 1..4096");
  if (opt.gvm.epochs < 1 || opt.gvm.epochs > 1000000)
    return usage_error(cmd, "--epochs must be in 1..1000000");
  if (opt.folds < 2 || opt.folds > 20) return usage_error(cmd, "--folds must be in 2..20");
  if (!(opt.coverage > 0 && opt.coverage < 1)) return usage_error(cmd, "--coverage must be in (0, 1)");
  if (splits < 0 || splits > 100) return usage_error(cmd, "--splits must be in 0..100");
  if (mlp_epochs < 0) return usage_error(cmd, "--mlp-epochs must be >= 0");
  if (p.has("ensemble"))
    return usage_error(cmd, "--ensemble is for detection logs (a job model's members are its "
                            "folds: --folds)");

  auto rows = job::read_job_log(log_path);
  if (!rows) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, rows.status().message().c_str());
    return exit_code(rows.status());
  }
  if (rows->empty()) {
    std::fprintf(stderr, "collidoscope %s: %s holds no job\n", cmd, log_path.c_str());
    return kExitFailure;
  }
  // Drawn without repeats: a job twice in the set lands in two folds, and its
  // "held-out" residuals (the intervals, the memory margin) would be its own.
  if (resample < 0 || uint64_t(resample) > rows->size())
    return usage_error(cmd, "--resample must be in 0.." + std::to_string(rows->size()) +
                                " (the log's rows; drawn without repeats)");
  size_t cuda = 0;
  for (const auto& r : *rows) cuda += r.inputs.backend == "cuda";
  std::printf("job log %s: %zu jobs (%zu cpu, %zu cuda)\n", log_path.c_str(), rows->size(),
              rows->size() - cuda, cuda);
  std::printf("GVM: per cost %d machines (one per fold held out), each %d hidden %s neurons, "
              "beta in [-%g, %g]; %d epochs; interval = out-of-fold residual quantiles "
              "(%.0f %% coverage)\n",
              opt.folds, opt.gvm.hidden, gvm::activation_name(opt.gvm.activation), opt.gvm.beta_max,
              opt.gvm.beta_max, opt.gvm.epochs, 100 * opt.coverage);

  // Held-out comparison on each split seed: split_seed .. split_seed + splits - 1.
  const size_t K = job::kJobOutputs;
  std::vector<std::vector<job::JobModelScore>> all;
  for (int64_t s = 0; s < splits; ++s) {
    const uint64_t seed = uint64_t(split_seed + s);
    auto cmp = job::compare_job_models(*rows, opt, seed, mlp_epochs);
    if (!cmp) {
      std::fprintf(stderr, "collidoscope %s: %s\n", cmd, cmp.status().message().c_str());
      return kExitFailure;
    }
    std::printf("\nsplit seed %llu: %zu train, %zu validation; GVM trained in %s (%lld proposals, "
                "%.1f%% kept)\n",
                (unsigned long long)seed, cmp->train.size(), cmp->validation.size(),
                seconds_text(cmp->report.seconds).c_str(), (long long)cmp->report.proposals,
                cmp->report.proposals ? 100.0 * cmp->report.accepted / cmp->report.proposals : 0.0);
    if (s == 0 && p.has("curve")) {
      if (Status st = write_loss_curve(p.get("curve"), cmp->report.curve); !st) {
        std::fprintf(stderr, "collidoscope %s: %s\n", cmd, st.message().c_str());
        return kExitFailure;
      }
    }
    if (s == 0 && p.has("predictions")) {
      if (auto st = write_job_predictions(p.get("predictions"), *cmp); !st) {
        std::fprintf(stderr, "collidoscope %s: %s\n", cmd, st.message().c_str());
        return kExitFailure;
      }
      std::printf("validation predictions: %s (%zu rows)\n", p.get("predictions").c_str(),
                  cmp->validation.size());
    }
    std::printf("validation MAPE %%:\n");
    print_errors_header();
    for (const auto& sc : cmp->scores) print_errors(sc, true);
    const job::JobErrors& gv = cmp->scores[0].validation;
    std::printf("gvm interval [p10, p90] holds:");
    for (size_t k = 0; k < K; ++k)
      if (!std::isnan(gv.coverage[k])) std::printf(" %s %.0f%%", kShort[k], 100 * gv.coverage[k]);
    std::printf("\n");
    if (cuda)
      std::printf("gvm device memory under-predicted by > 5 %%: %.1f%% of cuda rows\n",
                  100 * gv.device_under5);
    all.push_back(cmp->scores);
  }
  if (splits > 1) {
    std::printf("\nmean over %lld splits, validation MAPE %%:\n", (long long)splits);
    print_errors_header();
    for (size_t m = 0; m < all[0].size(); ++m) {
      job::JobModelScore mean;
      mean.name = all[0][m].name;
      for (size_t k = 0; k < K; ++k) mean.validation.mape[k] = 0, mean.validation.coverage[k] = 0;
      for (const auto& sc : all) {
        for (size_t k = 0; k < K; ++k) {
          mean.validation.mape[k] += sc[m].validation.mape[k] / double(all.size());
          mean.validation.coverage[k] += sc[m].validation.coverage[k] / double(all.size());
        }
        mean.validation.host_under5 += sc[m].validation.host_under5 / double(all.size());
        mean.validation.device_under5 += sc[m].validation.device_under5 / double(all.size());
        mean.fit_seconds += sc[m].fit_seconds / double(all.size());
      }
      print_errors(mean, true);
      if (m == 0) {
        std::printf("  gvm interval [p10, p90] holds (mean):");
        for (size_t k = 0; k < K; ++k)
          if (!std::isnan(mean.validation.coverage[k]))
            std::printf(" %s %.0f%%", kShort[k], 100 * mean.validation.coverage[k]);
        std::printf("\n");
        if (cuda)
          std::printf("  gvm device memory under-predicted by > 5 %% (mean): %.1f%%\n",
                      100 * mean.validation.device_under5);
      }
    }
    // Whether the GVM beats every baseline on every split, cost by cost.
    std::printf("gvm better than every baseline on every split:");
    for (size_t k = 0; k < K; ++k) {
      if (std::isnan(all[0][0].validation.mape[k])) continue;
      bool every = true;
      for (const auto& sc : all)
        for (size_t m = 1; m < sc.size(); ++m)
          every = every && sc[0].validation.mape[k] < sc[m].validation.mape[k];
      std::printf(" %s %s", kShort[k], every ? "yes" : "NO");
    }
    std::printf("\n");
  }

  // The model written: trained on every row (or, for timing, a resample of them).
  std::vector<job::JobRecord> final_rows = *rows;
  if (resample > 0) {
    gvm::Rng rng{uint64_t(split_seed)};
    // The first `resample` of a Fisher-Yates shuffle: distinct rows.
    for (size_t i = 0; i < size_t(resample); ++i)
      std::swap(final_rows[i], final_rows[i + rng.below(final_rows.size() - i)]);
    final_rows.resize(size_t(resample));
  }
  job::JobTrainReport rep;
  auto model = job::JobCostModel::train(final_rows, opt, &rep);
  if (!model) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, model.status().message().c_str());
    return kExitFailure;
  }
  std::printf("\nmodel trained on %s%zu rows in %s\n", resample > 0 ? "a resample of " : "all ",
              final_rows.size(), seconds_text(rep.seconds).c_str());
  std::printf("interval (out-of-fold residual quantiles, model space):");
  for (size_t k = 0; k < K; ++k)
    std::printf(" %s [%+.3f, %+.3f]", kShort[k], model->residual_lo(k), model->residual_hi(k));
  std::printf("\nshare of the GVM's correction kept over the prior: total %.2f, per-frame %.2f\n",
              model->gvm_weight(0), model->gvm_weight(1));
  std::printf("memory's point raised by (log10) host %.4f, device %.4f\n", model->point_offset(2),
              model->point_offset(3));
  const auto& rs = *rows;
  const double us_point = us_per_call([&](size_t i) {
    double out[job::kJobOutputs];
    model->predict_point(rs[i % rs.size()].inputs, out);
    g_sink = g_sink + out[0];
  });
  const double us_full = us_per_call([&](size_t i) {
    auto pr = model->predict(rs[i % rs.size()].inputs);
    if (pr) g_sink = g_sink + pr->total_s.p50;  // (a backend a resample left out has no model)
  });
  std::printf("prediction time: %.2f us (%.2f us with intervals and the range check)\n", us_point,
              us_full);
  const std::string out_path = p.get("out");
  if (Status s = model->save(out_path); !s) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, s.message().c_str());
    return kExitFailure;
  }
  std::printf("model: %s\n", out_path.c_str());
  return kExitOk;
}

int gvm_merge_jobs(const std::vector<std::string>& paths, const std::string& out) {
  std::vector<job::JobRecord> all;
  for (const std::string& path : paths) {
    auto rows = job::read_job_log(path);
    if (!rows) {
      std::fprintf(stderr, "collidoscope gvm merge: %s\n", rows.status().message().c_str());
      return exit_code(rows.status());
    }
    all.insert(all.end(), rows->begin(), rows->end());
  }
  const auto merged = job::merge_job_repeats(all);
  if (Status s = job::write_job_log(out, merged); !s) {
    std::fprintf(stderr, "collidoscope gvm merge: %s\n", s.message().c_str());
    return kExitFailure;
  }
  std::printf("%zu job rows from %zu logs -> %zu jobs: %s\n", all.size(), paths.size(),
              merged.size(), out.c_str());
  return kExitOk;
}

int gvm_replay(const Args& args) {
  const char* cmd = "gvm replay";
  static const std::vector<FlagSpec> flags = {
      {"model", true, "job cost model JSON (required)"},
      {"help", false, "show this help"},
  };
  std::string error;
  auto parsed = parse_args(args, flags, &error);
  if (!parsed) return usage_error(cmd, error);
  if (parsed->has("help")) {
    print_help(
        "usage: collidoscope gvm replay JOBS.csv --model MODEL.json\n\n"
        "Prices every job of a job log in the log's order, as the service meets jobs: by\n"
        "the model alone, and scaled by the machine's pace as the service scales its\n"
        "prices (the median of measured over predicted total time of the " +
            std::to_string(job::kPaceWindow) +
            " jobs before\n"
            "it, where they lean one way beyond chance; docs/service.md).\n"
        "Prints the total time's mean absolute percentage error and how often the 10-90 %\n"
        "interval holds, both ways: a log swept on a day the machine ran slower or faster\n"
        "than the model's own shows what the pace gives.",
        flags);
    return kExitOk;
  }
  if (parsed->positional().size() != 1) return usage_error(cmd, "expects one JOBS.csv");
  if (!parsed->has("model")) return usage_error(cmd, "--model MODEL.json is required");
  // A missing or malformed file is bad input (2), as for every command; a
  // file that cannot be read, or a log the model prices none of, a failure (1).
  auto fail = [&](const Status& why) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, why.message().c_str());
    return exit_code(why);
  };
  auto model = job::JobCostModel::load(parsed->get("model"));
  if (!model) return fail(model.status());
  auto rows = job::read_job_log(parsed->positional()[0]);
  if (!rows) return fail(rows.status());
  const job::PaceReplay r = job::replay_with_pace(*model, *rows);
  if (r.jobs == 0) return fail(backend_error("no job of the log could be priced by this model"));
  std::printf("%zu of %zu jobs priced; total time:\n", r.jobs, rows->size());
  std::printf("  model alone:        MAPE %5.1f %%, 10-90 %% interval holds %3.0f %%\n", r.mape,
              100 * r.holds);
  std::printf("  scaled by the pace: MAPE %5.1f %%, 10-90 %% interval holds %3.0f %% (pace after the last job: %.3f)\n",
              r.paced_mape, 100 * r.paced_holds, r.last_factor);
  return kExitOk;
}

int predict_scene(const ParsedArgs& p, const std::string& path, const std::string& text) {
  const char* cmd = "predict";
  std::string error;
  job::JobSpec spec;
  const nlohmann::json doc = nlohmann::json::parse(text, nullptr, false);
  if (doc.is_object() && doc.contains("scene") && doc.contains("out_dir")) {
    // A job spec, as `job-exec` and the service read it.
    auto s = job::spec_from_json(text);
    if (!s) return usage_error(cmd, path + ": " + s.status().message());
    spec = std::move(*s);
  } else {
    spec.scene_json = text;
    const auto slash = path.rfind('/');
    spec.scene_dir = slash == std::string::npos ? "" : path.substr(0, slash);
  }
  if (p.has("backend")) spec.backend = p.get("backend");
  if (!spec.backend.empty() && spec.backend != "auto" && spec.backend != "cpu" &&
      spec.backend != "cuda")
    return usage_error(cmd, "--backend must be auto, cpu or cuda");
  if (p.has("duration")) {
    spec.duration = p.get_double("duration", 0, &error);
    if (!(spec.duration > 0)) return usage_error(cmd, "--duration must be a positive number of seconds");
  }
  int threads = p.get_int32("threads", 0, &error);
  if (threads < 0) return usage_error(cmd, "--threads must be >= 0");
  if (p.has("video")) {
    spec.render = true;
    job::RenderSettings& rs = spec.render_settings;
    rs.mp4 = rs.webm = rs.gif = false;
    const std::string list = p.get("formats", "mp4,webm,gif");
    std::stringstream ss(list);
    std::string f;
    while (std::getline(ss, f, ',')) {
      if (f == "mp4") rs.mp4 = true;
      else if (f == "webm") rs.webm = true;
      else if (f == "gif") rs.gif = true;
      else if (f != "none") return usage_error(cmd, "--formats: '" + f + "' is not mp4, webm, gif or none");
    }
    rs.width = p.get_int32("width", rs.width, &error);
    rs.height = p.get_int32("height", rs.height, &error);
  }
  if (!error.empty()) return usage_error(cmd, error);
  auto a = job::assess_job(spec);
  if (!a) {
    std::fprintf(stderr, "collidoscope %s: %s: %s\n", cmd, path.c_str(), a.status().message().c_str());
    return exit_code(a.status());
  }
  // The backend the job would run on: the spec's or the scene's; "auto" as the job
  // resolves it (the GPU when one is usable here).
  const scene::Scene& sc = a->resolved.scene;
  std::string backend = sim::to_string(sc.dynamics.backend);
  if (sc.backend_auto) {
    std::string why;
    backend = sim::to_string(sim::usable_backend(sim::Backend::kCuda, &why));
  }
  const std::string model_path =
      p.get("model", std::string(COLLIDO_DATA_DIR) + "/job_model_" + backend + ".json");
  auto model = job::JobCostModel::load(model_path);
  if (!model) {
    std::fprintf(stderr, "collidoscope %s: %s\n", cmd, model.status().message().c_str());
    if (!p.has("model"))
      std::fprintf(stderr,
                   "  (the %s job model is made by `collidoscope calibrate --jobs --backend %s "
                   "--out jobs.csv` and `collidoscope gvm train --logs jobs.csv --out %s`; "
                   "or give one with --model)\n",
                   backend.c_str(), backend.c_str(), model_path.c_str());
    return exit_code(model.status()) == kExitUsage && model.status().code() != ErrorCode::kNotFound
               ? kExitUsage
               : kExitFailure;
  }
  auto pred = model->predict(*a, backend, threads);
  if (!pred) return usage_error(cmd, pred.status().message());
  if (p.has("json")) {
    nlohmann::json j = job::to_json(*pred);
    j["model"] = model_path;
    std::printf("%s\n", j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace).c_str());
  } else {
    const job::JobInputs in = job::job_inputs(*a, backend, pred->device, pred->threads);
    std::printf("%s: %llu particles (%s), %llu frames of %.4g s, %llu steps (%llu a frame, step "
                "%.3g s), %s%s%s\n",
                in.wall.c_str(), (unsigned long long)in.particles, in.placement.c_str(),
                (unsigned long long)in.frames, in.duration / double(in.frames),
                (unsigned long long)in.steps, (unsigned long long)in.steps_per_frame, in.step_s,
                in.method.c_str(), in.particle_contacts ? ", particle contacts" : "",
                in.friction > 0 ? ", friction" : "");
    if (in.renders())
      std::printf("render %dx%d, videos: %s\n", in.render_width, in.render_height, in.formats.c_str());
    std::printf("%s on %s, %d thread%s; model %s\n", backend.c_str(), pred->device.c_str(),
                pred->threads, pred->threads == 1 ? "" : "s", model_path.c_str());
    std::printf("%-20s %12s %12s %12s\n", "", "p10", "p50", "p90");
    auto row = [](const char* name, const job::CostInterval& c, bool bytes, bool time) {
      auto f = [&](double v) {
        if (bytes) return human_bytes(v);
        if (time) return seconds_text(v);
        char buf[32];
        std::snprintf(buf, sizeof buf, "%.3f", v);
        return std::string(buf);
      };
      std::printf("%-20s %12s %12s %12s\n", name, f(c.p10).c_str(), f(c.p50).c_str(), f(c.p90).c_str());
    };
    row("total time", pred->total_s, false, true);
    row("time per frame", pred->per_frame_s, false, true);
    row("peak host memory", pred->peak_host_bytes, true, false);
    row("peak device memory", pred->peak_device_bytes, true, false);
    row("GPU load", pred->gpu_load, false, false);
    row("output", pred->output_bytes, true, false);
    for (const std::string& r : pred->outside_reasons)
      std::printf("outside the training data: %s\n", r.c_str());
    if (pred->outside_training)
      std::printf("the figures are an extrapolation beyond the jobs the model was trained on\n");
    if (const std::string w = job::landing_warning(*a); !w.empty())
      std::printf("warning: %s\n", w.c_str());
  }
  if (p.has("bench")) {
    const job::JobInputs in = job::job_inputs(*a, backend, pred->device, pred->threads);
    const double us = us_per_call([&](size_t) { g_sink = g_sink + model->predict(in)->total_s.p50; });
    std::fprintf(p.has("json") ? stderr : stdout, "prediction time: %.2f us\n", us);
  }
  return kExitOk;
}

}  // namespace collido::app
