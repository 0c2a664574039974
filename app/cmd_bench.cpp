// `collidoscope bench TARGET`: dispatches to the benchmark of each module.
#include <cstdio>

#include "app/cli.h"
#include "app/commands.h"

namespace collido::app {

int cmd_bench(const Args& args) {
  const std::string targets = "detect, run"
#ifdef COLLIDO_HAVE_RENDER
                              ", render"
#endif
      ;
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::printf("usage: collidoscope bench TARGET [options]   (TARGET --help)\ntargets: %s\n", targets.c_str());
    return args.empty() ? kExitUsage : kExitOk;
  }
  const Args rest(args.begin() + 1, args.end());
  if (args[0] == "detect") return bench_detect(rest);
  if (args[0] == "run") return bench_run(rest);
#ifdef COLLIDO_HAVE_RENDER
  if (args[0] == "render") return bench_render(rest);
#endif
  return usage_error("bench", "unknown target '" + args[0] + "' (" + targets + ")");
}

}  // namespace collido::app
