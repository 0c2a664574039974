// `collidoscope run` end to end: the run directory it writes, and errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "app/cli.h"
#include "app/commands.h"
#include "job/child.h"
#include "job/job.h"
#include "sim/snapshot.h"
#include "tests/scratch.h"
#include "tests/stats_csv.h"

namespace collido::app {
namespace {

namespace fs = std::filesystem;

std::string write_scene(const std::string& name, const std::string& json) {
  const std::string path = test::scratch_path(name);
  std::ofstream(path) << json;
  return path;
}

std::vector<std::string> lines(const std::string& path) {
  std::ifstream in(path);
  std::vector<std::string> out;
  for (std::string l; std::getline(in, l);) out.push_back(l);
  return out;
}

TEST(CliRun, WritesSnapshotsStatisticsAndParaViewFrames) {
  const std::string scene = write_scene("drop.json", R"({
    "wall": "box:x=6,y=6,z=6",
    "particles": {"count": 27, "radius": 0.4},
    "placement": {"kind": "fill", "region": {"min": [-2, -2, 1], "max": [2, 2, 5]}},
    "material": {"restitution": 0.5, "friction": 0.3, "stiffness": 1e6},
    "particle_contacts": true, "duration": 0.5, "fps": 10, "backend": "cpu"
  })");
  const std::string dir = test::scratch_path("run_drop");
  ASSERT_EQ(cmd_run({scene, "--out", dir, "--vtp", "--quiet"}), kExitOk);
  for (const char* f :
       {"wall.stl", "scene.json", "result.json", "stats.csv", "frames.pvd", "vtp/frame_000005.vtp"})
    EXPECT_TRUE(fs::exists(fs::path(dir) / f)) << f;
  const auto stats = lines(dir + "/stats.csv");
  ASSERT_EQ(stats.size(), 1u + 6u);  // header, frame 0 and five frames
  EXPECT_EQ(stats[0].rfind("frame,time_s,substeps", 0), 0u);
  for (uint64_t f = 0; f <= 5; ++f) {
    auto snap = sim::read_snapshot(sim::snapshot_path(dir, f));
    ASSERT_TRUE(snap) << snap.status().message();
    EXPECT_EQ(snap->size(), 27u);
    EXPECT_NEAR(snap->time, 0.1 * double(f), 1e-9);
  }
  // The particles fell: the last frame's are lower than the first's and some touch the floor.
  auto first = sim::read_snapshot(sim::snapshot_path(dir, 0)),
       last = sim::read_snapshot(sim::snapshot_path(dir, 5));
  double z0 = 0, z5 = 0;
  int touching = 0;
  for (size_t i = 0; i < 27; ++i) z0 += first->z[i], z5 += last->z[i], touching += last->contact[i];
  EXPECT_LT(z5, z0);
  EXPECT_GT(touching, 0);
  std::stringstream pvd;
  pvd << std::ifstream(dir + "/frames.pvd").rdbuf();
  EXPECT_NE(pvd.str().find("vtp/frame_000005.vtp"), std::string::npos);
}

// Every example scene in scenes/ loads, places its particles and runs a first frame.
TEST(CliRun, ExampleScenesRun) {
  int seen = 0;
  for (const auto& e : fs::directory_iterator(COLLIDO_SCENES)) {
    if (e.path().extension() != ".json") continue;
    ++seen;
    const std::string dir = test::scratch_path("example_" + e.path().stem().string());
    EXPECT_EQ(cmd_run({e.path().string(), "--out", dir, "--duration", "0.04", "--backend", "cpu",
                       "--quiet"}),
              kExitOk)
        << e.path();
    EXPECT_TRUE(fs::exists(sim::snapshot_path(dir, 1))) << e.path();
  }
  EXPECT_GE(seen, 3);
}

// Every example scene that pours or jets its particles shows them reach the
// wall within its duration: wall2's pour fell for 3 s from the top of the
// hopper and touched nothing (its cone is 4.7 s down). Twenty particles
// without particle contacts stand in for the scene's count (the first ones
// released land when the scene's would). A contact is told by the energy it
// takes: in free fall the total stays put (releases only add to it), and a
// bounce off the wall loses some. Frame ends alone can miss it: twenty
// particles off wall2's cone bounced into its outlet between two frames.
// Escaped particles leave the sums, so only the frames before any escapes count.
TEST(CliRun, ExamplePoursReachTheWallWithinTheirDuration) {
  int seen = 0;
  for (const auto& e : fs::directory_iterator(COLLIDO_SCENES)) {
    if (e.path().extension() != ".json") continue;
    std::ifstream in(e.path());
    nlohmann::json scene = nlohmann::json::parse(in);
    const std::string kind = scene["placement"].value("kind", "fill");
    if (kind != "pour" && kind != "jet") continue;
    ++seen;
    scene["particles"]["count"] = 20;
    scene["particle_contacts"] = false;
    job::JobSpec spec;
    spec.scene_json = scene.dump();
    spec.scene_dir = COLLIDO_SCENES;
    spec.out_dir = test::scratch_path("reach_" + e.path().stem().string());
    spec.dir_policy = job::DirPolicy::kReplace;
    const job::JobResult r = job::run_job(spec, {});
    ASSERT_TRUE(r.status) << e.path() << ": " << r.status.message();
    const test::StatsCsv stats = test::read_stats_csv(spec.out_dir);
    const size_t escaped = stats.column("escaped"), total = stats.column("total_J");
    ASSERT_LT(std::max(escaped, total), stats.names.size());
    double most = 0, lost = 0;  // the largest total so far, and the largest share lost since
    for (const std::vector<double>& frame : stats.rows) {
      if (frame[escaped] > 0) break;
      most = std::max(most, frame[total]);
      if (most > 0) lost = std::max(lost, (most - frame[total]) / most);
    }
    EXPECT_GT(lost, 0.01) << e.path() << ": nothing touched the wall in "
                          << scene["duration"].get<double>() << " s";
  }
  EXPECT_GE(seen, 3);
}

// One rule for exit codes: bad input (arguments, scenes, files that are
// missing or do not fit) exits 2, a run that fails exits 1.
TEST(CliRun, BadInputExitsTwo) {
  EXPECT_EQ(cmd_run({}), kExitUsage);
  EXPECT_EQ(cmd_run({"--help"}), kExitOk);
  EXPECT_EQ(cmd_run({"/nonexistent/scene.json"}), kExitUsage);
  EXPECT_EQ(cmd_run({write_scene("bad_key.json", R"({"wall": "wall1", "speed": 3})")}), kExitUsage);
  EXPECT_EQ(cmd_run({write_scene("bad_json.json", R"({"wall": )")}), kExitUsage);
  const std::string ok =
      write_scene("ok.json", R"({"wall": "wall1", "particles": {"count": 5}, "duration": 0.01})");
  // Into a folder that does not exist: a refusal is the flag's, not the folder's.
  const std::string unused = test::scratch_path("run_unused");
  EXPECT_EQ(cmd_run({ok, "--out", unused, "--backend", "quantum"}), kExitUsage);
  // --duration is held to the scene's own timing limits (scene::check_timing).
  for (const char* d : {"0", "-1", "1e6", "nan"})
    EXPECT_EQ(cmd_run({ok, "--out", unused, "--duration", d}), kExitUsage) << d;
  // Integers past their range are refused, not wrapped (4294967297 would be 1
  // as an int); a checkpoint interval job.json could not keep for --resume too.
  for (const std::vector<std::string>& flags :
       std::vector<std::vector<std::string>>{{"--threads", "4294967297"},
                                             {"--threads", "-1"},
                                             {"--checkpoint-every", "inf"},
                                             {"--checkpoint-every", "nan"},
                                             {"--video", "--width", "4294968576"}}) {
    std::vector<std::string> args = {ok, "--out", unused, "--quiet"};
    args.insert(args.end(), flags.begin(), flags.end());
    EXPECT_EQ(cmd_run(args), kExitUsage) << flags[0] << " " << flags.back();
  }
  EXPECT_FALSE(fs::exists(unused));
  // A wall that does not exist, and more particles than the vessel holds.
  const std::string dir = test::scratch_path("run_fail");
  EXPECT_EQ(cmd_run({write_scene("nowall.json", R"({"wall": {"file": "missing.stl"}})"), "--out",
                     dir, "--quiet"}),
            kExitUsage);
  EXPECT_EQ(cmd_run({write_scene("full.json",
                                 R"({"wall": "box:x=2,y=2,z=2", "particles": {"count": 1000}})"),
                     "--out", dir, "--quiet"}),
            kExitUsage);
  // Input that is refused leaves nothing behind.
  EXPECT_FALSE(fs::exists(dir));
}

TEST(CliRun, AFixedStepBeyondTheStableBoundIsWarnedAboutAndStillReported) {
  const std::string scene = write_scene("coarse.json", R"({
    "wall": "box:x=6,y=6,z=6", "particles": {"count": 8, "radius": 0.4},
    "material": {"stiffness": 1e6}, "time_step": 0.05, "duration": 0.5, "fps": 10, "backend": "cpu"
  })");
  const std::string dir = test::scratch_path("run_coarse");
  ASSERT_EQ(cmd_run({scene, "--out", dir, "--quiet"}), kExitOk);
  std::stringstream run;
  run << std::ifstream(dir + "/result.json").rdbuf();
  EXPECT_NE(run.str().find("\"beyond_stable\": true"), std::string::npos) << run.str();
}

// `job-exec` as a cluster node runs it: progress appended to a file (with the
// job's peak memory), and --resume continuing the run a requeued job left.
TEST(CliJobExec, ProgressFileAndResumeAsOnAClusterNode) {
  const std::string dir = test::scratch_path("job_exec_node");
  job::JobSpec spec;
  spec.scene_json = R"({"wall": "box:x=6,y=6,z=6", "particles": {"count": 8, "radius": 0.4},
    "placement": {"kind": "fill"}, "duration": 0.3, "fps": 10, "backend": "cpu"})";
  spec.out_dir = dir + "/run";
  spec.threads = 1;
  const std::string spec_path = write_scene("job_exec_node.json", job::spec_to_json(spec));
  const std::string progress = dir + "/progress.jsonl";
  fs::create_directories(dir);
  EXPECT_EQ(cmd_job_exec({spec_path, "--progress-fd", "1", "--progress-file", progress}), kExitUsage);
  EXPECT_EQ(cmd_job_exec({spec_path, "--progress-file", "/nonexistent/dir/p.jsonl"}), kExitUsage);

  // Nothing to resume yet: --resume starts the run.
  ASSERT_EQ(cmd_job_exec({spec_path, "--resume", "--progress-file", progress}), kExitOk);
  std::vector<job::ReportLine> reports;
  for (const std::string& l : lines(progress)) reports.push_back(job::parse_report_line(l));
  ASSERT_GE(reports.size(), 4u);
  EXPECT_EQ(reports.back().kind, job::ReportLine::Kind::kStatus);
  EXPECT_TRUE(reports.back().status);
  EXPECT_EQ(reports.front().kind, job::ReportLine::Kind::kProgress);
  EXPECT_GT(reports.front().peak_host_bytes, 1000000u);  // the job's own peak so far
  const size_t first_run = reports.size();

  // Again, as a cluster job submitted a second time would be: --resume takes
  // the run there (the spec says kRefuse for a directory that holds files),
  // and the new lines follow the first run's.
  const auto manifest = lines(dir + "/run/result.json");
  ASSERT_EQ(cmd_job_exec({spec_path, "--resume", "--progress-file", progress}), kExitOk);
  const auto after = lines(progress);
  EXPECT_GT(after.size(), first_run);
  // The run had finished: it is left as it was, and the job says so.
  EXPECT_EQ(lines(dir + "/run/result.json"), manifest);
  bool said = false;
  for (const std::string& l : after) said = said || l.find("is complete: nothing to resume") != std::string::npos;
  EXPECT_TRUE(said);
  EXPECT_EQ(cmd_job_exec({spec_path, "--progress-file", progress}), kExitUsage);  // no --resume: refused
}

}  // namespace
}  // namespace collido::app
