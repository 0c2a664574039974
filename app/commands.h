// The `collidoscope` subcommands. Each takes the arguments after its name and
// returns the process exit code (0 ok, 1 failure, 2 bad arguments).
#pragma once

#include <string>
#include <vector>

#include "common/status.h"
#ifdef COLLIDO_HAVE_GVM
#include "gvm/machine.h"
#endif

namespace collido::job {
struct RenderSettings;  // job/render_run.h
}

namespace collido::app {

using Args = std::vector<std::string>;

int cmd_detect(const Args& args);        // app/cmd_detect.cpp
int cmd_bench(const Args& args);         // app/cmd_bench.cpp (dispatches bench targets)
int bench_detect(const Args& args);      // app/bench_detect.cpp

int bench_run(const Args& args);         // app/bench_run.cpp

#ifdef COLLIDO_HAVE_RUN
int cmd_run(const Args& args);           // app/cmd_run.cpp
int cmd_job_exec(const Args& args);      // app/cmd_run.cpp
#endif

#ifdef COLLIDO_HAVE_RENDER
int cmd_render(const Args& args);        // app/cmd_render.cpp
int bench_render(const Args& args);      // app/cmd_render.cpp
#endif

// --video's "mp4,webm,gif" or "none" into *rs; false with *error otherwise (app/cmd_render.cpp).
bool parse_video_list(const std::string& list, collido::job::RenderSettings* rs, std::string* error);

#ifdef COLLIDO_HAVE_STUDY
int cmd_study(const Args& args);         // app/cmd_study.cpp
#endif

#ifdef COLLIDO_HAVE_SERVICE
int cmd_serve(const Args& args);         // app/cmd_serve.cpp
int cmd_admin(const Args& args);         // app/cmd_serve.cpp: `admin create NAME`
#endif

#ifdef COLLIDO_HAVE_GVM
int cmd_gvm(const Args& args);           // app/cmd_gvm.cpp: `gvm train`
int cmd_predict(const Args& args);       // app/cmd_gvm.cpp
// app/cmd_gvm.cpp: a training's loss curve as CSV, written whole or not at all.
Status write_loss_curve(const std::string& path, const std::vector<gvm::EpochLoss>& curve);
#endif

#ifdef COLLIDO_HAVE_JOB_COST
class ParsedArgs;
// app/cmd_cost.cpp: cmd_gvm.cpp sends job logs and scene files here.
int gvm_train_jobs(const ParsedArgs& parsed, const std::string& log_path);
int gvm_merge_jobs(const std::vector<std::string>& paths, const std::string& out);
int gvm_replay(const Args& args);  // `gvm replay`: a job cost model on a job log, with the pace
int predict_scene(const ParsedArgs& parsed, const std::string& path, const std::string& text);
#endif

#ifdef COLLIDO_HAVE_CALIBRATE
int cmd_calibrate(const Args& args);     // app/cmd_calibrate.cpp
int cmd_calibrate_exec(const Args& args);  // app/cmd_calibrate.cpp: one run of a sweep (a child)
#endif

}  // namespace collido::app
