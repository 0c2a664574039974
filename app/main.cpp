// collidoscope: the command line of the engine, renderer, predictor and service.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "app/cli.h"
#include "app/commands.h"
#include "sim/parallel.h"

namespace {

struct Command {
  const char* name;
  int (*run)(const collido::app::Args&);
  const char* summary;
};

const std::vector<Command>& commands() {
  using namespace collido::app;
  static const std::vector<Command> table = {
      {"detect", cmd_detect, "particle-wall collision detection on one frame"},
#ifdef COLLIDO_HAVE_RUN
      {"run", cmd_run, "run a scene's collision frames (and --video render them)"},
      {"job-exec", cmd_job_exec, "run one job from its spec (what the service starts)"},
#endif
      {"bench", cmd_bench, "benchmarks: bench detect | bench run | bench render"},
#ifdef COLLIDO_HAVE_STUDY
      {"study", cmd_study, "speed against accuracy, and where each method fails (docs/study.md)"},
#endif
#ifdef COLLIDO_HAVE_RENDER
      {"render", cmd_render, "render snapshots into PNG frames and video"},
#endif
#ifdef COLLIDO_HAVE_SERVICE
      {"serve", cmd_serve, "the REST service: API, job queue and workers, result links"},
      {"admin", cmd_admin, "make the service's first administrator: admin create NAME"},
#endif
#ifdef COLLIDO_HAVE_GVM
      {"gvm", cmd_gvm, "train the time/memory predictor: gvm train"},
      {"predict", cmd_predict, "predict time and memory of a configuration"},
#endif
#ifdef COLLIDO_HAVE_CALIBRATE
      {"calibrate", cmd_calibrate, "run a sweep of real configurations into a log"},
      // Hidden (no summary): one run of a sweep, started by calibrate itself.
      {"calibrate-exec", cmd_calibrate_exec, nullptr},
#endif
  };
  return table;
}

void print_usage() {
  std::printf("usage: collidoscope COMMAND [options]   (COMMAND --help for its options)\n\n");
  for (const auto& c : commands())
    if (c.summary) std::printf("  %-10s %s\n", c.name, c.summary);
}

}  // namespace

int main(int argc, char** argv) {
  // Before any thread starts: llvmpipe's rasterizer threads follow the CPUs
  // this process may use (render/render.h says why the renderer does not set it).
  setenv("LP_NUM_THREADS", std::to_string(collido::sim::usable_cpus()).c_str(), /*overwrite=*/0);
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h") ||
      !std::strcmp(argv[1], "help")) {
    print_usage();
    return argc < 2 ? collido::app::kExitUsage : collido::app::kExitOk;
  }
  const std::string name = argv[1];
  collido::app::Args rest(argv + 2, argv + argc);
  for (const auto& c : commands())
    if (name == c.name) return c.run(rest);
  std::fprintf(stderr, "collidoscope: unknown command '%s' (see collidoscope --help)\n",
               name.c_str());
  return collido::app::kExitUsage;
}
