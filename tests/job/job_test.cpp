// The job library end to end: what a run directory holds, who owns it,
// cancellation, two jobs at once, checkpoints and resume after SIGKILL, the
// job-exec child, and scenes a hostile user would send.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "common/atomic_file.h"
#include "job/assess.h"
#include "job/checkpoint.h"
#include "job/child.h"
#include "job/job.h"
#include "job/job_log.h"
#include "job/subprocess.h"
#include "sim/mesh.h"
#include "sim/shapes.h"
#include "sim/snapshot.h"
#ifdef COLLIDO_HAVE_RENDER
#include "job/render_run.h"
#include "render/snapshot.h"
#include "render/video.h"
#include "tests/scratch.h"
#endif

namespace collido::job {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// A fresh directory per test under the temp folder (not made), and the
// spec file beside it (dir + ".spec.json"), both gone when the test passes.
std::string fresh_dir(const std::string& name) {
  const std::string dir = test::scratch_path("job_" + name);
  test::scratch_path("job_" + name + ".spec.json");
  return dir;
}

// Particles falling into a box with friction and pair contacts: every part of the state moves.
const char* kDropScene = R"({
  "wall": "box:x=6,y=6,z=6",
  "particles": {"count": 64, "radius": [0.3, 0.4]},
  "placement": {"kind": "fill", "region": {"min": [-2, -2, 1], "max": [2, 2, 5]}},
  "material": {"restitution": 0.5, "friction": 0.3, "stiffness": 1e5},
  "particle_contacts": true, "duration": 0.6, "fps": 20, "backend": "cpu"
})";

JobSpec drop_spec(const std::string& dir, int threads = 1) {
  JobSpec s;
  s.scene_json = kDropScene;
  s.out_dir = dir;
  s.threads = threads;
  s.checkpoint_interval_s = 0;
  return s;
}

// The statistics without their wall-clock column (the only one that may differ between runs).
std::vector<std::string> stats_rows(const std::string& dir) {
  std::ifstream in(dir + "/stats.csv");
  std::vector<std::string> rows;
  for (std::string l; std::getline(in, l);) rows.push_back(l.substr(0, l.rfind(',')));
  return rows;
}

TEST(Job, RunWritesEveryFrameAndAManifest) {
  const std::string dir = fresh_dir("run");
  std::vector<Progress> seen;
  Hooks hooks;
  hooks.progress = [&](const Progress& p) { seen.push_back(p); };
  const JobResult r = run_job(drop_spec(dir), hooks);
  ASSERT_TRUE(r.status) << r.status.message();
  EXPECT_EQ(r.particles, 64u);
  EXPECT_EQ(r.cost.frames, 13u);
  EXPECT_GT(r.cost.steps, 0u);
  EXPECT_GT(r.cost.peak_host_bytes, 0u);
  // The lists are built at least once, and not more often than the steps.
  EXPECT_GE(r.cost.list_builds, 1.0);
  EXPECT_LE(r.cost.list_builds, double(r.cost.steps));
  const auto rows = stats_rows(dir);
  ASSERT_EQ(rows.size(), 14u);  // header and frames 0..12
  for (size_t f = 0; f <= 12; ++f) EXPECT_EQ(rows[f + 1].substr(0, rows[f + 1].find(',')), std::to_string(f));
  EXPECT_FALSE(fs::exists(dir + "/stats.csv.partial"));
  const json m = json::parse(read_file(dir + "/result.json"));
  EXPECT_EQ(m["status"], "done");
  EXPECT_EQ(m["frames"], 13);
  EXPECT_EQ(m["cost"]["steps"], r.cost.steps);
  EXPECT_EQ(m["cost"]["list_builds"], r.cost.list_builds);
  bool has_stats = false, has_frames = false;
  for (const auto& a : m["artifacts"]) {
    const std::string path = a["path"];
    if (path == "stats.csv") has_stats = a["mime"] == "text/csv";
    if (path == "frames/") has_frames = a["count"] == 13;
  }
  EXPECT_TRUE(has_stats && has_frames) << m["artifacts"].dump();
  // Progress: every simulated frame reported, then done.
  ASSERT_FALSE(seen.empty());
  EXPECT_EQ(seen.back().stage, Stage::kDone);
  int frames = 0;
  for (const auto& p : seen) frames += p.stage == Stage::kSimulate;
  EXPECT_EQ(frames, 13);
}

TEST(Job, ARunDirectoryBelongsToOneRun) {
  const std::string dir = fresh_dir("owned");
  ASSERT_TRUE(run_job(drop_spec(dir), {}).status);
  const std::string before = read_file(dir + "/stats.csv");
  // A second run into the same directory is refused and changes nothing.
  JobResult again = run_job(drop_spec(dir), {});
  EXPECT_EQ(again.status.code(), ErrorCode::kInvalidArgument);
  EXPECT_NE(again.status.message().find("already holds files"), std::string::npos);
  EXPECT_EQ(read_file(dir + "/stats.csv"), before);
  // Replacing empties it first: no frame of the old run survives a shorter new one.
  JobSpec shorter = drop_spec(dir);
  shorter.duration = 0.1;
  shorter.dir_policy = DirPolicy::kReplace;
  ASSERT_TRUE(run_job(shorter, {}).status);
  EXPECT_FALSE(fs::exists(sim::snapshot_path(dir, 3)));
  EXPECT_EQ(stats_rows(dir).size(), 4u);
  // A folder with someone's files but no run is never emptied.
  const std::string other = fresh_dir("not_a_run");
  fs::create_directories(other);
  std::ofstream(other + "/thesis.tex") << "precious";
  JobSpec into_other = drop_spec(other);
  into_other.dir_policy = DirPolicy::kReplace;
  EXPECT_FALSE(run_job(into_other, {}).status);
  EXPECT_EQ(read_file(other + "/thesis.tex"), "precious");
}

TEST(Job, CancelStopsAtAFrameAndSaysSo) {
  const std::string dir = fresh_dir("cancel");
  std::atomic<bool> cancel{false};
  Hooks hooks;
  hooks.cancel = &cancel;
  hooks.progress = [&](const Progress& p) {
    if (p.stage == Stage::kSimulate && p.done == 3) cancel = true;
  };
  const JobResult r = run_job(drop_spec(dir), hooks);
  EXPECT_EQ(r.status.code(), ErrorCode::kCancelled);
  const json m = json::parse(read_file(dir + "/result.json"));
  EXPECT_EQ(m["status"], "cancelled");
  EXPECT_EQ(m["complete"], false);
  // stats.csv, a final name, exists only for a whole run.
  EXPECT_FALSE(fs::exists(dir + "/stats.csv"));
  EXPECT_TRUE(fs::exists(sim::snapshot_path(dir, 3)));
  EXPECT_FALSE(fs::exists(sim::snapshot_path(dir, 4)));
}

TEST(Job, TwoJobsAtOnceGiveWhatEachGivesAlone) {
  const std::string a = fresh_dir("alone_a"), b = fresh_dir("alone_b");
  ASSERT_TRUE(run_job(drop_spec(a, 2), {}).status);
  JobSpec other = drop_spec(b, 1);
  other.scene_json = R"({"wall": "wall1", "particles": {"count": 300, "radius": 1},
    "placement": {"kind": "pour"}, "particle_contacts": true, "duration": 0.3, "fps": 10,
    "backend": "cpu"})";
  ASSERT_TRUE(run_job(other, {}).status);
  const std::string a2 = fresh_dir("together_a"), b2 = fresh_dir("together_b");
  JobResult ra, rb;
  std::thread ta([&] { ra = run_job(drop_spec(a2, 2), {}); });
  std::thread tb([&] {
    JobSpec s = other;
    s.out_dir = b2;
    rb = run_job(s, {});
  });
  ta.join();
  tb.join();
  ASSERT_TRUE(ra.status && rb.status);
  EXPECT_EQ(ra.threads, 2);
  EXPECT_EQ(rb.threads, 1);
  EXPECT_EQ(ra.step_threads, 1);  // 64 particles: a small scene steps on one of its two
  EXPECT_EQ(rb.step_threads, 1);
  EXPECT_EQ(stats_rows(a), stats_rows(a2));
  EXPECT_EQ(stats_rows(b), stats_rows(b2));
  EXPECT_EQ(read_file(sim::snapshot_path(a, 12)), read_file(sim::snapshot_path(a2, 12)));
  EXPECT_EQ(read_file(sim::snapshot_path(b, 3)), read_file(sim::snapshot_path(b2, 3)));
}

TEST(Job, CheckpointsRoundTripAndDamageIsDetected) {
  const std::string dir = fresh_dir("ckpt");
  ASSERT_TRUE(run_job(drop_spec(dir), {}).status);
  auto ck = read_checkpoint(dir + "/checkpoint.bin");
  ASSERT_TRUE(ck) << ck.status().message();
  EXPECT_EQ(ck->frame, 12u);
  EXPECT_EQ(ck->state.particles, 64u);
  EXPECT_GT(ck->state.arrays.size(), 6u);  // friction and pairs: springs saved too
  EXPECT_GT(ck->state.lists.size(), 2u);   // and the neighbour lists as built
  EXPECT_FALSE(ck->method.empty());         // and the wall's representation they fit
  std::string bytes = read_file(dir + "/checkpoint.bin");
  bytes[bytes.size() / 2] ^= 1;
  ASSERT_TRUE(write_file_atomic(dir + "/damaged.bin", bytes));
  EXPECT_EQ(read_checkpoint(dir + "/damaged.bin").status().code(), ErrorCode::kParse);
  EXPECT_EQ(read_checkpoint(dir + "/none.bin").status().code(), ErrorCode::kNotFound);
  // One of the format before the engine kept its particle numbering: refused, saying so.
  bytes = read_file(dir + "/checkpoint.bin");
  bytes[7] = '1';
  ASSERT_TRUE(write_file_atomic(dir + "/older.bin", bytes));
  const auto older = read_checkpoint(dir + "/older.bin");
  ASSERT_FALSE(older);
  EXPECT_NE(older.status().message().find("another format (01"), std::string::npos)
      << older.status().message();
  // Older formats, written as the header says: each value's bytes, arrays as
  // a count and then each one's size and bytes, an FNV-1a hash of it all last.
  auto put = [](std::string* b, const auto& v) {
    b->append(reinterpret_cast<const char*>(&v), sizeof v);
  };
  auto put_arrays = [&](std::string* b, const std::vector<std::vector<uint8_t>>& arrays) {
    put(b, uint32_t(arrays.size()));
    for (const auto& a : arrays) {
      put(b, uint64_t(a.size()));
      b->append(reinterpret_cast<const char*>(a.data()), a.size());
    }
  };
  auto hashed = [&](std::string b) {
    uint64_t hash = 1469598103934665603ull;
    for (unsigned char c : b) hash = (hash ^ c) * 1099511628211ull;
    put(&b, hash);
    return b;
  };
  // One of the format before the lists were saved (02) is read, without lists.
  std::string body;
  put(&body, ck->frame), put(&body, ck->state.particles), put(&body, ck->state.time);
  put(&body, ck->state.steps), put(&body, uint8_t(ck->state.all_released));
  put_arrays(&body, ck->state.arrays);
  ASSERT_TRUE(write_file_atomic(dir + "/v2.bin", hashed("CLCKPT02" + body)));
  const auto without_lists = read_checkpoint(dir + "/v2.bin");
  ASSERT_TRUE(without_lists) << without_lists.status().message();
  EXPECT_EQ(without_lists->state.arrays, ck->state.arrays);
  EXPECT_TRUE(without_lists->state.lists.empty());
  // One of the format before the wall's method was saved (03) is read, with its lists.
  put_arrays(&body, ck->state.lists);
  const std::string v3 = hashed("CLCKPT03" + body);
  ASSERT_TRUE(write_file_atomic(dir + "/v3.bin", v3));
  const auto without_method = read_checkpoint(dir + "/v3.bin");
  ASSERT_TRUE(without_method) << without_method.status().message();
  EXPECT_EQ(without_method->state.lists, ck->state.lists);
  EXPECT_TRUE(without_method->method.empty());
  // The file written in parts as they come (no copy of it in memory) is the one
  // these rules give for the current format (04): the method and grid length last.
  put(&body, uint32_t(ck->method.size()));
  body += ck->method;
  put(&body, ck->grid_length);
  EXPECT_EQ(read_file(dir + "/checkpoint.bin"), hashed("CLCKPT04" + body));
}

// A writer that fails leaves neither the file nor its temporary behind, and the
// file that was there stays as it was.
TEST(Job, AFailedWriteInPartsLeavesTheOldFile) {
  const std::string dir = fresh_dir("atomic_parts");
  fs::create_directories(dir);
  const std::string path = dir + "/file.bin";
  ASSERT_TRUE(write_file_atomic(path, "old"));
  const Status s = write_file_atomic_with(path, [](std::FILE* f) {
    std::fputs("half of the new", f);
    errno = ENOSPC;
    return false;
  });
  EXPECT_FALSE(s);
  EXPECT_NE(s.message().find("cannot write"), std::string::npos) << s.message();
  EXPECT_EQ(read_file(path), "old");
  size_t files = 0;
  for (const auto& e : fs::directory_iterator(dir)) files += e.is_regular_file();
  EXPECT_EQ(files, 1u);
  ASSERT_TRUE(write_file_atomic_with(path, [](std::FILE* f) { return std::fputs("new", f) >= 0; }));
  EXPECT_EQ(read_file(path), "new");
}

// Runs the spec in a job-exec child and kills it with SIGKILL once it has
// written `frame`'s snapshot; false when the child finished first.
bool kill_at_frame(const std::string& spec_path, const std::string& dir, uint64_t frame) {
  auto child = ChildJob::start(COLLIDO_BINARY, spec_path);
  EXPECT_TRUE(child) << child.status().message();
  if (!child) return false;
  const pid_t pid = (*child)->pid();
  for (int i = 0; i < 20000; ++i) {
    if (fs::exists(sim::snapshot_path(dir, frame))) {
      kill(pid, SIGKILL);
      break;
    }
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  const ChildResult r = (*child)->wait(nullptr);
  return r.signal == SIGKILL;
}

TEST(Job, AKilledRunResumesToTheSameEnd) {
  const std::string ref = fresh_dir("uninterrupted");
  JobSpec ref_spec = drop_spec(ref);
  ref_spec.duration = 1.5;  // 31 frames: long enough to be killed in the middle
  ASSERT_TRUE(run_job(ref_spec, {}).status);
  const auto ref_rows = stats_rows(ref);
  const auto ref_last = sim::read_snapshot(sim::snapshot_path(ref, 30));
  ASSERT_TRUE(ref_last);

  int killed = 0;
  for (uint64_t at : {0u, 7u, 19u}) {
    const std::string dir = fresh_dir("killed_" + std::to_string(at));
    JobSpec spec = ref_spec;
    spec.out_dir = dir;
    const std::string spec_path = dir + ".spec.json";
    std::ofstream(spec_path) << spec_to_json(spec);
    if (!kill_at_frame(spec_path, dir, at)) continue;  // finished before the kill: nothing to resume
    ++killed;
    // After the kill no file under a final name is incomplete.
    EXPECT_FALSE(fs::exists(dir + "/stats.csv"));
    for (const auto& e : fs::recursive_directory_iterator(dir)) {
      const std::string name = e.path().filename().string();
      if (e.path().extension() == ".snap" && !is_temp_name(name)) {
        EXPECT_TRUE(sim::read_snapshot(e.path().string())) << e.path();
      }
      if (name == "result.json" || name == "job.json" || name == "scene.json") {
        EXPECT_FALSE(json::parse(read_file(e.path().string()), nullptr, false).is_discarded());
      }
    }
    JobSpec resume = spec;
    resume.dir_policy = DirPolicy::kResume;
    const JobResult r = run_job(resume, {});
    ASSERT_TRUE(r.status) << r.status.message();
    EXPECT_EQ(stats_rows(dir), ref_rows) << "killed at frame " << at;
    const auto last = sim::read_snapshot(sim::snapshot_path(dir, 30));
    ASSERT_TRUE(last);
    ASSERT_EQ(last->size(), ref_last->size());
    double worst = 0;
    for (size_t i = 0; i < last->size(); ++i)
      worst = std::max({worst, std::fabs(double(last->x[i]) - ref_last->x[i]) / ref_last->r[i],
                        std::fabs(double(last->y[i]) - ref_last->y[i]) / ref_last->r[i],
                        std::fabs(double(last->z[i]) - ref_last->z[i]) / ref_last->r[i]});
    EXPECT_LE(worst, 1e-9) << "killed at frame " << at;
    // In fact the same bytes: the restored run is the uninterrupted one.
    EXPECT_EQ(read_file(sim::snapshot_path(dir, 30)), read_file(sim::snapshot_path(ref, 30)));
  }
  EXPECT_GE(killed, 2);
}

// Killed after its last frame, before its manifest (while rendering, say): the
// resumed run finds its statistics under their final name and ends as the
// uninterrupted one did; a wall chosen automatically stays the one the state
// was made with; and the resumed run's cost is not taken for a measure.
TEST(Job, ARunKilledAfterItsLastFrameResumes) {
  const std::string dir = fresh_dir("after_last");
  JobSpec spec = drop_spec(dir);
  json scene = json::parse(kDropScene);
  scene["method"] = "auto";
  spec.scene_json = scene.dump();
  const JobResult first = run_job(spec, {});
  ASSERT_TRUE(first.status) << first.status.message();
  const auto rows = stats_rows(dir);
  ASSERT_EQ(rows.size(), 14u);  // the header and 13 frames
  const auto ck = read_checkpoint(dir + "/checkpoint.bin");
  ASSERT_TRUE(ck) << ck.status().message();
  EXPECT_EQ(ck->frame, 12u);
  EXPECT_EQ(ck->method, first.method);
  EXPECT_TRUE(job_measure_from_manifest(read_file(dir + "/result.json")));
  fs::remove(dir + "/result.json");

  JobSpec resume = spec;
  resume.dir_policy = DirPolicy::kResume;
  const JobResult r = run_job(resume, {});
  ASSERT_TRUE(r.status) << r.status.message();
  EXPECT_EQ(r.resumed_from_frame, 12u);
  EXPECT_EQ(r.method, first.method);
  EXPECT_NE(r.choice.find("kept from the run's first attempt"), std::string::npos) << r.choice;
  EXPECT_EQ(stats_rows(dir), rows);
  EXPECT_FALSE(fs::exists(dir + "/stats.csv.partial"));
  const auto measure = job_measure_from_manifest(read_file(dir + "/result.json"));
  ASSERT_FALSE(measure);
  EXPECT_NE(measure.status().message().find("resumed"), std::string::npos);
}

// A run on a wall file resumes only on the wall it started with: the file
// replaced since is refused with the reason (the saved state and its wall
// lists belong to the first wall); put back, the run resumes.
TEST(Job, AResumedRunRefusesAWallFileChangedSinceItStarted) {
  const std::string dir = fresh_dir("changed_wall");
  const std::string meshes = fresh_dir("changed_wall_meshes");
  fs::create_directories(meshes);
  ASSERT_TRUE(sim::save_stl(sim::make_box(6, 6, 6), meshes + "/vessel.stl"));
  JobSpec spec = drop_spec(dir);
  json scene = json::parse(kDropScene);
  scene["wall"] = {{"file", "vessel.stl"}};
  spec.scene_json = scene.dump();
  spec.scene_dir = meshes;
  ASSERT_TRUE(run_job(spec, {}).status);
  fs::remove(dir + "/result.json");  // as if killed before its manifest
  sim::TriangleMesh other = sim::make_box(6, 6, 6);
  for (auto& v : other.vertices) v.z *= 1.5;
  ASSERT_TRUE(sim::save_stl(other, meshes + "/vessel.stl"));
  JobSpec resume = spec;
  resume.dir_policy = DirPolicy::kResume;
  const JobResult refused = run_job(resume, {});
  ASSERT_FALSE(refused.status);
  EXPECT_EQ(refused.status.message().rfind("wall: ", 0), 0u) << refused.status.message();
  EXPECT_NE(refused.status.message().find("not the wall this run started with"), std::string::npos)
      << refused.status.message();
  ASSERT_TRUE(sim::save_stl(sim::make_box(6, 6, 6), meshes + "/vessel.stl"));
  const JobResult resumed = run_job(resume, {});
  ASSERT_TRUE(resumed.status) << resumed.status.message();
  EXPECT_EQ(resumed.resumed_from_frame, 12u);
}

// A command's output past what is read of it is a failure, not a silent cut
// (an squeue listing cut short would hide running jobs), and a command gets
// no descriptor of the caller's but its pipes (a server's port among them).
TEST(Job, ACommandsOutputIsWholeOrAFailureAndItInheritsNoDescriptor) {
  auto small = run_command({"echo", "hi"}, 30);
  ASSERT_TRUE(small);
  EXPECT_TRUE(small->ok());
  EXPECT_EQ(small->out, "hi\n");
  auto big = run_command({"head", "-c", "3000000", "/dev/zero"}, 30);
  ASSERT_TRUE(big);
  EXPECT_TRUE(big->truncated);
  EXPECT_FALSE(big->ok());
  EXPECT_NE(big->describe_failure().find("1 MiB"), std::string::npos) << big->describe_failure();
  const int opened = ::open("/dev/null", O_RDONLY);  // no close-on-exec
  const int leaked = ::fcntl(opened, F_DUPFD, 20);
  ::close(opened);
  auto fds = run_command({"/bin/sh", "-c", "ls /proc/self/fd"}, 30);
  ::close(leaked);
  ASSERT_TRUE(fds && fds->ok());
  std::istringstream listed(fds->out);
  for (int fd; listed >> fd;) EXPECT_NE(fd, leaked) << fds->out;
}

// A job's process (ChildJob starts it so) is in a group of its own: Ctrl-C on
// the service's terminal reaches the service, which stops the job to resume
// it later, not the job, which died failed. Other children stay in the
// caller's group (Ctrl-C on calibrate stops its children). Each child is told
// its parent's pid.
TEST(Job, AJobsChildIsInAProcessGroupOfItsOwn) {
  for (bool own : {true, false}) {
    auto child = Subprocess::start(
        {"/bin/sh", "-c", "cut -d' ' -f5 /proc/self/stat >&3; echo \"$COLLIDO_PARENT_PID\" >&3"}, 3,
        "", {}, own);
    ASSERT_TRUE(child) << child.status().message();
    std::vector<std::string> lines;
    const ExitInfo e = (*child)->wait([&](const std::string& l) { lines.push_back(l); });
    EXPECT_EQ(e.exit_code, 0);
    ASSERT_EQ(lines.size(), 2u);
    EXPECT_EQ(std::stol(lines[0]) != long(getpgrp()), own);
    EXPECT_EQ(lines[1], std::to_string(getpid()));
  }
}

TEST(Job, ASpawnedChildGetsTheReportPipeAndNothingElseOfTheParent) {
  // A parent as the service is: SIGPIPE ignored, a descriptor without close-on-exec.
  struct sigaction old {};
  struct sigaction ignore {};
  ignore.sa_handler = SIG_IGN;
  sigaction(SIGPIPE, &ignore, &old);
  const int opened = ::open("/dev/null", O_RDONLY);
  const int leaked = ::fcntl(opened, F_DUPFD, 10);  // above the report pipe's 3
  ::close(opened);
  ASSERT_GE(leaked, 10);
  ::setenv("COLLIDO_TEST_KEPT", "kept", 1);
  ::setenv("COLLIDO_TEST_REPLACED", "old", 1);
  auto child = Subprocess::start(
      {"/bin/sh", "-c",
       "ls /proc/self/fd | tr '\\n' ' ' >&3; echo >&3; grep SigIgn /proc/self/status >&3; "
       "echo \"$COLLIDO_TEST_KEPT $COLLIDO_TEST_REPLACED $COLLIDO_TEST_NEW\" >&3"},
      3, "", {"COLLIDO_TEST_REPLACED=new", "COLLIDO_TEST_NEW=added"});
  ASSERT_TRUE(child) << child.status().message();
  std::vector<std::string> lines;
  const ExitInfo e = (*child)->wait([&](const std::string& l) { lines.push_back(l); });
  ::close(leaked);
  sigaction(SIGPIPE, &old, nullptr);
  EXPECT_EQ(e.exit_code, 0);
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_EQ(lines[2], "kept new added");  // the parent's environment, with the overrides
  std::istringstream fds(lines[0]);
  for (int fd; fds >> fd;) EXPECT_NE(fd, leaked) << lines[0];  // (ls's own directory may show)
  // SigIgn is a hex mask; SIGPIPE (13) is bit 12.
  const unsigned long ignored = std::stoul(lines[1].substr(lines[1].find(':') + 1), nullptr, 16);
  EXPECT_EQ(ignored & (1ul << (SIGPIPE - 1)), 0ul) << lines[1];
}

// A child that goes on after a cancel (a frame that never ends, here one that
// ignores SIGTERM) is killed once the grace has passed.
TEST(Job, ACancelledChildThatGoesOnIsKilled) {
  auto child = Subprocess::start({"/bin/sh", "-c", "trap '' TERM; echo ready >&3; exec sleep 60"}, 3,
                                 "", {});
  ASSERT_TRUE(child) << child.status().message();
  std::atomic<bool> cancel{false};
  const ExitInfo e = (*child)->wait(
      [&](const std::string& line) {
        if (line == "ready") cancel = true;
      },
      &cancel, SIGTERM, 0.5);
  EXPECT_EQ(e.signal, SIGKILL);
}

TEST(Job, JobExecReportsProgressAndRefusesBadSpecs) {
  const std::string dir = fresh_dir("exec");
  const std::string spec_path = dir + ".spec.json";
  std::ofstream(spec_path) << spec_to_json(drop_spec(dir));
  auto child = ChildJob::start(COLLIDO_BINARY, spec_path);
  ASSERT_TRUE(child);
  int reports = 0;
  const ChildResult r = (*child)->wait([&](const Progress&) { ++reports; });
  EXPECT_TRUE(r.status) << r.status.message();
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_GE(reports, 13);
  EXPECT_GT(r.peak_host_bytes, 1u << 20);
  EXPECT_TRUE(fs::exists(dir + "/result.json"));

  for (const std::string& bad : {std::string("{\"scene\": "), std::string("{\"out_dir\": \"x\"}"),
                                 std::string("[1, 2]")}) {
    const std::string path = test::scratch_path("job_exec.bad.json");
    std::ofstream(path) << bad;
    auto c = ChildJob::start(COLLIDO_BINARY, path);
    ASSERT_TRUE(c);
    const ChildResult br = (*c)->wait(nullptr);
    EXPECT_EQ(br.exit_code, 2) << bad;
    EXPECT_FALSE(br.status) << bad;
  }
  auto missing = ChildJob::start(COLLIDO_BINARY, dir + ".missing.json");
  ASSERT_TRUE(missing);
  EXPECT_EQ((*missing)->wait(nullptr).exit_code, 2);
}

TEST(Job, CancelReachesAJobInAChild) {
  const std::string dir = fresh_dir("exec_cancel");
  JobSpec spec = drop_spec(dir);
  spec.duration = 50;  // long: it must be stopped, not finish
  const std::string spec_path = dir + ".spec.json";
  std::ofstream(spec_path) << spec_to_json(spec);
  auto child = ChildJob::start(COLLIDO_BINARY, spec_path);
  ASSERT_TRUE(child);
  std::atomic<bool> cancel{false};
  const ChildResult r = (*child)->wait(
      [&](const Progress& p) {
        if (p.stage == Stage::kSimulate && p.done >= 2) cancel = true;
      },
      &cancel);
  EXPECT_EQ(r.status.code(), ErrorCode::kCancelled) << r.status.message();
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(json::parse(read_file(dir + "/result.json"))["status"], "cancelled");
}

// Scenes a hostile user would send: each is refused at once with the figures,
// before anything large is allocated or any file is written.
TEST(Job, ScenesBeyondTheBudgetAreRefusedBeforeTheyStart) {
  struct Case {
    const char* scene;
    const char* says;
  } cases[] = {
      // A radius 1e-4 of the wall: binning would visit 2.2e10 (triangle, cell) pairs.
      {R"({"wall": "wall1", "particles": {"count": 10, "radius": 0.01}, "placement": {"kind": "pour"}})",
       "(triangle, cell) pairs"},
      // Dividing wall1 for tiny particles: billions of pieces.
      {R"({"wall": "wall1", "particles": {"count": 10, "radius": 0.01}, "placement": {"kind": "pour"},
          "method": "midpoint4"})",
       "dividing the wall"},
      // 2^28 particles with friction and pairs: far beyond this machine's memory.
      {R"({"wall": "box:x=1e4,y=1e4,z=1e4", "particles": {"count": 268435456, "radius": 5},
          "material": {"friction": 0.3}, "particle_contacts": true})",
       "GiB of memory"},
  };
  for (const Case& c : cases) {
    const std::string dir = fresh_dir("hostile");
    JobSpec s;
    s.scene_json = c.scene;
    s.out_dir = dir;
    const JobResult r = run_job(s, {});
    EXPECT_EQ(r.status.code(), ErrorCode::kResourceExhausted) << c.scene << r.status.message();
    EXPECT_NE(r.status.message().find(c.says), std::string::npos) << r.status.message();
    // A refusal, not a stall: no particle was placed and the engine never started.
    EXPECT_EQ(r.particles, 0u) << c.scene;
    EXPECT_EQ(r.cost.steps, 0u) << c.scene;
    EXPECT_FALSE(fs::exists(dir));
  }
}

// STL files carry no unit and CAD writes millimetres: a hopper given in mm
// runs as the same hopper given in metres (the physics stays SI).
TEST(Job, AHopperInMillimetresRunsAsInMetres) {
  const char* mm = R"({"wall": "funnel:r1=60,r2=300,h=400,segments=24", "length_unit": "mm",
    "particles": {"count": 150, "radius": 12},
    "placement": {"kind": "pour", "inlet": [0, 0, 420], "inlet_radius": 150, "rate": 2000,
                  "velocity": [0, 0, -500]},
    "material": {"impact_speed": 3000}, "duration": 0.2, "fps": 10, "backend": "cpu"})";
  const char* m = R"({"wall": "funnel:r1=0.06,r2=0.3,h=0.4,segments=24",
    "particles": {"count": 150, "radius": 0.012},
    "placement": {"kind": "pour", "inlet": [0, 0, 0.42], "inlet_radius": 0.15, "rate": 2000,
                  "velocity": [0, 0, -0.5]},
    "material": {"impact_speed": 3}, "duration": 0.2, "fps": 10, "backend": "cpu"})";
  JobResult r[2];
  for (int k = 0; k < 2; ++k) {
    JobSpec s;
    s.scene_json = k ? m : mm;
    s.out_dir = fresh_dir(k ? "hopper_m" : "hopper_mm");
    r[k] = run_job(s, {});
    ASSERT_TRUE(r[k].status) << r[k].status.message();
  }
  EXPECT_NEAR(r[0].time_step.stiffness, r[1].time_step.stiffness, 1e-9 * r[1].time_step.stiffness);
  EXPECT_NEAR(r[0].time_step.critical_step, r[1].time_step.critical_step,
              1e-9 * r[1].time_step.critical_step);
  // The same steps per simulated second (the automatic step follows the
  // speeds, which rounding of the millimetre wall may move by an ulp).
  EXPECT_NEAR(double(r[0].cost.steps), double(r[1].cost.steps), 0.01 * double(r[1].cost.steps));
  const json scene = json::parse(read_file(r[0].out_dir + "/scene.json"));
  EXPECT_EQ(scene["length_unit"], "mm");
  EXPECT_EQ(scene["particles"]["radius"], 12);  // written back in the document's unit
  const json manifest = json::parse(read_file(r[0].out_dir + "/result.json"));
  EXPECT_EQ(manifest["units"]["length"], "m");
  EXPECT_EQ(manifest["scene_length_unit"], "mm");
}

// A rotation without a centre turns about the wall's box centre, in the
// document's unit: the job sets it when it loads the wall, and writes it into
// the run's scene.json, which the renderer reads to turn the wall.
TEST(Job, ARotationWithoutACentreTurnsAboutTheWall) {
  JobSpec s;
  s.scene_json = R"({"wall": "cylinder:r=50,h=40,segments=24,axis=y,dz=100", "length_unit": "mm",
    "particles": {"count": 20, "radius": 4},
    "placement": {"kind": "fill", "region": {"min": [-30, 5, 80], "max": [30, 35, 120]}},
    "wall_motion": {"kind": "rotate", "axis": [0, 1, 0], "rpm": 30},
    "duration": 0.05, "fps": 20, "backend": "cpu"})";
  s.out_dir = fresh_dir("own_centre");
  auto a = assess_job(s);
  ASSERT_TRUE(a) << a.status().message();
  const sim::Vec3d c = a->resolved.scene.dynamics.wall_motion.center;
  EXPECT_NEAR(c.x, 0, 1e-12);
  EXPECT_NEAR(c.y, 0.02, 1e-12);  // the drum runs from y = 0 to 40 mm
  EXPECT_NEAR(c.z, 0.1, 1e-12);
  EXPECT_FALSE(a->resolved.scene.motion_center_auto);
  const JobResult r = run_job(s, {});
  ASSERT_TRUE(r.status) << r.status.message();
  const json scene = json::parse(read_file(r.out_dir + "/scene.json"));
  ASSERT_TRUE(scene["wall_motion"].contains("center")) << scene.dump();
  EXPECT_NEAR(scene["wall_motion"]["center"][1].get<double>(), 20, 1e-9);  // millimetres
  EXPECT_NEAR(scene["wall_motion"]["center"][2].get<double>(), 100, 1e-9);
}

// One part of a union turns: the job finds its triangles and box, turns it
// about its own centre, and the run keeps every particle in the still cup.
TEST(Job, APaddleTurnsInAStillCup) {
  JobSpec s;
  s.scene_json = R"({"wall": "cylinder:r=0.1,h=0.12,segments=32,caps=bottom+box:x=0.15,y=0.012,z=0.04,dz=0.006",
    "particles": {"count": 60, "radius": 0.005},
    "placement": {"kind": "fill", "region": {"min": [-0.06, -0.06, 0.05], "max": [0.06, 0.06, 0.08]}},
    "material": {"friction": 0.3, "impact_speed": 1},
    "wall_motion": {"kind": "rotate", "axis": [0, 0, 1], "rpm": 60, "part": 2},
    "duration": 0.3, "fps": 10, "backend": "cpu"})";
  s.out_dir = fresh_dir("paddle");
  auto a = assess_job(s);
  ASSERT_TRUE(a) << a.status().message();
  const sim::WallMotion& m = a->resolved.scene.dynamics.wall_motion;
  EXPECT_EQ(m.part_begin, 94u);  // the cup: 32 sides of two triangles, a floor of 30
  EXPECT_EQ(m.part_end, 106u);   // the box's 12
  EXPECT_NEAR(m.part_box.center().z, 0.026, 1e-12);
  EXPECT_NEAR(m.center.z, 0.026, 1e-12);  // no centre given: the paddle's own
  const JobResult r = run_job(s, {});
  ASSERT_TRUE(r.status) << r.status.message();
  const json manifest = json::parse(read_file(r.out_dir + "/result.json"));
  EXPECT_EQ(manifest["particles"], 60);
  EXPECT_EQ(manifest["escaped"], 0);
  EXPECT_EQ(manifest["invalid"], 0);
  auto scene = json::parse(read_file(r.out_dir + "/scene.json"));
  EXPECT_EQ(scene["wall_motion"]["part"], 2);
  // A part of a wall that is one shape, or a file, is refused before the run.
  s.scene_json = R"({"wall": "cylinder:r=0.1,h=0.12", "particles": {"count": 10, "radius": 0.005},
    "wall_motion": {"kind": "rotate", "part": 1}, "duration": 0.1, "backend": "cpu"})";
  auto bad = assess_job(s);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.status().message().find("not a union"), std::string::npos) << bad.status().message();
}

// method: auto for a pour is timed where its particles go (near the wall),
// not at its inlet, and says so; a fill is timed as placed.
TEST(Job, AutomaticChoiceForAPourIsTimedNearTheWall) {
  for (const bool pour : {true, false}) {
    const std::string dir = fresh_dir(pour ? "auto_pour" : "auto_fill");
    JobSpec spec = drop_spec(dir);
    spec.scene_json = pour ? R"({
      "wall": "box:x=6,y=6,z=6", "particles": {"count": 64, "radius": 0.3},
      "placement": {"kind": "pour", "inlet": [0, 0, 5], "inlet_radius": 2, "rate": 50},
      "material": {"stiffness": 1e5}, "duration": 0.1, "fps": 20, "backend": "cpu",
      "method": "auto"})"
                           : R"({
      "wall": "box:x=6,y=6,z=6", "particles": {"count": 64, "radius": 0.3},
      "placement": {"kind": "fill", "region": {"min": [-2, -2, 1], "max": [2, 2, 5]}},
      "material": {"stiffness": 1e5}, "duration": 0.1, "fps": 20, "backend": "cpu",
      "method": "auto"})";
    const JobResult r = run_job(spec, Hooks{});
    ASSERT_TRUE(r.status) << r.status.message();
    const json m = json::parse(read_file(dir + "/result.json"));
    const std::string choice = m["method"]["automatic_choice"];
    EXPECT_EQ(choice.rfind("timed near the wall, where the pour's particles go: ", 0) == 0, pour)
        << choice;
    EXPECT_NE(choice.find("bvh/particle"), std::string::npos) << choice;  // a candidate
  }
}

TEST(Job, SpecsRoundTripThroughJson) {
  JobSpec s = drop_spec("/tmp/x", 3);
  s.render = true;
  s.render_settings.width = 320;
  s.render_settings.gif = false;
  s.budget.wall_cells = 1e6;
  auto back = spec_from_json(spec_to_json(s));
  ASSERT_TRUE(back) << back.status().message();
  EXPECT_EQ(back->threads, 3);
  EXPECT_EQ(back->render_settings.width, 320);
  EXPECT_FALSE(back->render_settings.gif);
  EXPECT_EQ(back->budget.wall_cells, 1e6);
  EXPECT_EQ(json::parse(back->scene_json), json::parse(kDropScene));
  EXPECT_EQ(spec_from_json(R"({"scene": {}, "out_dir": "d", "speed": 1})").status().message(),
            "speed: unknown key of the job spec");
  EXPECT_EQ(spec_from_json(R"({"scene": {}, "out_dir": "d", "threads": "8"})").status().message(),
            "threads: expected an integer");
}

#ifdef COLLIDO_HAVE_RENDER
// The renderer draws a moving wall through one model matrix: it must put every
// vertex where the engine's pose does (a turn about an off-centre axis, an oscillation).
// A turning paddle in a still cup is drawn turned, the cup where it stands.
TEST(RenderRun, AMovingPartIsDrawnWhereTheMotionHasIt) {
  scene::Scene sc;
  sc.wall = "cylinder:r=0.1,h=0.12,segments=32,caps=bottom+box:x=0.15,y=0.012,z=0.04,dz=0.006";
  sc.dynamics.wall_motion.kind = sim::WallMotionKind::kRotate;
  sc.dynamics.wall_motion.angular_speed = 2 * M_PI;  // a turn a second
  sc.dynamics.wall_motion.part = 2;
  sc.motion_center_auto = true;
  auto wall = load_scene_wall(&sc);
  ASSERT_TRUE(wall) << wall.status().message();
  const sim::WallMotion& m = sc.dynamics.wall_motion;
  // As the renderer gets them: the cup and the paddle apart, each with its model matrix.
  const sim::Vec3d origin{0.01, -0.02, 0.03};  // render coordinates are world minus this
  render::Snapshot snap;
  set_render_wall(*wall, m, origin, &snap);
  pose_render_wall(m, 0.25, origin, &snap);  // a quarter turn
  auto drawn = [&](const render::WallMesh& mesh, const float* model) {
    sim::TriangleMesh out;
    for (size_t v = 0; v + 2 < mesh.vertices.size(); v += 3) {
      const float* p = &mesh.vertices[v];
      sim::Vec3d w;
      double* c[3] = {&w.x, &w.y, &w.z};
      for (int r = 0; r < 3; ++r)
        *c[r] = double(model[r]) * p[0] + double(model[4 + r]) * p[1] + double(model[8 + r]) * p[2] +
                double(model[12 + r]) + (r == 0 ? origin.x : r == 1 ? origin.y : origin.z);
      out.vertices.push_back(w);
    }
    return out;
  };
  const sim::Bounds3d paddle = sim::mesh_bounds(drawn(snap.part, snap.part_model));
  EXPECT_NEAR(paddle.extent().x, 0.012, 1e-6);  // it lay along x, now along y (float vertices)
  EXPECT_NEAR(paddle.extent().y, 0.15, 1e-6);
  EXPECT_NEAR(paddle.lo.z, 0.006, 1e-6);
  const sim::TriangleMesh cup = drawn(snap.wall, snap.wall_model);
  const sim::TriangleMesh cup0 = sim::mesh_range(*wall, m.part_begin, m.part_end, false);
  ASSERT_EQ(cup.vertices.size(), cup0.vertices.size());
  for (size_t v = 0; v < cup.vertices.size(); ++v)
    EXPECT_LT(length(cup.vertices[v] - cup0.vertices[v]), 1e-7) << v;
}

TEST(RenderRun, WallModelMatrixPlacesTheWallWhereTheEngineDoes) {
  sim::WallMotion turn;
  turn.kind = sim::WallMotionKind::kRotate;
  turn.axis = {0, 1, 1};
  turn.center = {3, -2, 5};
  turn.angular_speed = 0.7;
  sim::WallMotion shake;
  shake.kind = sim::WallMotionKind::kOscillate;
  shake.axis = {0, 0, 2};
  shake.amplitude = 0.4;
  shake.frequency = 3;
  const sim::Vec3d origin{10, 20, -4}, v{1.5, -2.5, 7};
  for (const sim::WallMotion& m : {turn, shake}) {
    const sim::WallPose pose = m.pose(0.9);
    float mat[16];
    wall_model_matrix(pose, origin, mat);
    const sim::Vec3d r = v - origin;
    const sim::Vec3d want = pose.to_world(v) - origin;
    const double got[3] = {mat[0] * r.x + mat[4] * r.y + mat[8] * r.z + mat[12],
                           mat[1] * r.x + mat[5] * r.y + mat[9] * r.z + mat[13],
                           mat[2] * r.x + mat[6] * r.y + mat[10] * r.z + mat[14]};
    EXPECT_NEAR(got[0], want.x, 1e-5);
    EXPECT_NEAR(got[1], want.y, 1e-5);
    EXPECT_NEAR(got[2], want.z, 1e-5);
    EXPECT_EQ(mat[3], 0.f);
    EXPECT_EQ(mat[15], 1.f);
  }
}

TEST(Job, RenderedJobHasVideosAndALoopingGif) {
  const std::string dir = fresh_dir("render");
  JobSpec s = drop_spec(dir);
  s.render = true;
  s.render_settings.width = 160;
  s.render_settings.height = 96;
  s.render_settings.gif_width = 80;
  s.render_settings.png_every = 0;
  const JobResult r = run_job(s, {});
  ASSERT_TRUE(r.status) << r.status.message();
  render::VideoInfo mp4, gif;
  ASSERT_TRUE(render::probe_video(dir + "/render/video.mp4", &mp4));
  EXPECT_EQ(mp4.frames, 13);
  ASSERT_TRUE(render::probe_video(dir + "/render/loop.gif", &gif));
  EXPECT_EQ(gif.codec, "gif");
  EXPECT_EQ(gif.width, 80);
  EXPECT_EQ(gif.frames, 7);  // 20 fps kept at 10: every second frame of 13
  const json m = json::parse(read_file(dir + "/result.json"));
  int videos = 0;
  for (const auto& a : m["artifacts"]) videos += a["role"] == "video" || a["role"] == "gif";
  EXPECT_EQ(videos, 3);
}
#endif

}  // namespace
}  // namespace collido::job
