// method/grid_length auto: the fastest of the measured candidates, and exact.
#include "sim/auto_choice.h"

#include <gtest/gtest.h>

#include "sim/accuracy.h"
#include "sim/particles.h"
#include "sim/shapes.h"

namespace collido::sim {
namespace {

// A detector whose frames take the times it is told, logging its turns: its
// first frame after another detector ran is slower (cold caches).
class ScriptedDetector : public Detector {
 public:
  ScriptedDetector(int id, double warm_ms, std::vector<int>* log, int fail_at = -1)
      : Detector(DetectConfig{}), id_(id), warm_ms_(warm_ms), log_(log), fail_at_(fail_at) {}
  Status set_particles(const Particles&) override { return Status::ok(); }
  Status detect(DetectResult* out) override {
    const bool cold = log_->empty() || log_->back() != id_;
    log_->push_back(id_);
    if (++calls_ == fail_at_) return invalid_argument("scripted failure");
    *out = DetectResult{};
    out->times.frame_ms = cold ? 2 * warm_ms_ : warm_ms_;
    return Status::ok();
  }
  int calls() const { return calls_; }

 private:
  int id_;
  double warm_ms_;
  std::vector<int>* log_;
  int fail_at_, calls_ = 0;
};

TEST(AutoChoice, FramesAreTimedInTurnsAndEachDetectorStopsWhenItHasItsOwn) {
  std::vector<int> log;
  ScriptedDetector fast(0, 0.05, &log), slow(1, 10.0, &log), failing(2, 1.0, &log, 5);
  std::vector<double> ms;
  std::vector<Status> status;
  fastest_frames_ms({&fast, nullptr, &slow, &failing}, kAutoMinFrames, &ms, &status);
  // The fastest frame is a warm one: the cold first frame of each turn never counts.
  EXPECT_DOUBLE_EQ(ms[0], 0.05);
  EXPECT_DOUBLE_EQ(ms[2], 10.0);
  EXPECT_TRUE(status[0] && status[1] && status[2]);
  EXPECT_FALSE(status[3]);  // failed at its fifth frame and was dropped
  EXPECT_EQ(failing.calls(), 5);
  // The slow one has its frames and its 20 ms after the minimum: a warm-up and
  // kAutoMinFrames frames, not the hundreds the fast one needs for its 20 ms.
  EXPECT_EQ(slow.calls(), 1 + kAutoMinFrames);
  EXPECT_EQ(fast.calls(), 1 + kAutoMaxFrames);
  // After the warm-ups the detectors take turns of kAutoFramesPerTurn frames
  // in a row (the failing one's last turn ends at its failure), and the fast
  // one runs on alone once the others have their frames.
  ASSERT_GE(log.size(), 3u);
  EXPECT_EQ(std::vector<int>(log.begin(), log.begin() + 3), (std::vector<int>{0, 1, 2}));
  using Runs = std::vector<std::pair<int, int>>;  // (detector, frames in a row)
  Runs runs;
  for (size_t k = 3; k < log.size(); ++k)
    if (!runs.empty() && runs.back().first == log[k])
      ++runs.back().second;
    else
      runs.push_back({log[k], 1});
  const Runs expected_start{{0, 3}, {1, 3}, {2, 3}, {0, 3}, {1, 3},
                                                        {2, 1}, {0, 3}, {1, 3}};
  ASSERT_EQ(runs.size(), expected_start.size() + 1);
  EXPECT_EQ(Runs(runs.begin(), runs.end() - 1), expected_start);
  EXPECT_EQ(runs.back().first, 0);  // alone until its 200 frames
}

TEST(AutoChoice, PicksTheFastestCandidateAndSaysWhy) {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  const Particles p = particles_near_surface(wall, 20000, 0.5, 1, 0.5, 1.5, 3);
  DetectConfig base;
  base.r_max = 1;
  auto c = choose_detection(wall, p, base, AutoRequest{});
  ASSERT_TRUE(c) << c.status().message();
  // The CPU times bin at the four grid lengths (division never won there) and the tree once.
  ASSERT_EQ(c->candidates.size(), 5u);
  for (const auto& k : c->candidates) {
    EXPECT_EQ(k.method, &k == &c->candidates.back() ? Method::kBvh : Method::kBin);
    EXPECT_TRUE(k.error.empty()) << k.error;
    EXPECT_GE(k.frame_ms, 0);
  }
  EXPECT_EQ(c->candidates.back().grid_length, 0.0) << "the tree has no grid";
  double best = 1e300;
  for (const auto& k : c->candidates) best = std::min(best, k.frame_ms);
  bool chosen_is_best = false;
  for (const auto& k : c->candidates)
    chosen_is_best |= k.grid_length == c->grid_length && k.method == c->method && k.frame_ms == best;
  EXPECT_TRUE(chosen_is_best);
  EXPECT_NE(c->reason.find("bin/particle 1 r_max"), std::string::npos) << c->reason;
  EXPECT_NE(c->reason.find("bvh/particle "), std::string::npos) << c->reason;
  EXPECT_NE(c->reason.find("tried"), std::string::npos) << c->reason;
  // What it picked gives the reference's contacts.
  DetectConfig cfg = base;
  cfg.method = c->method, cfg.traversal = c->traversal, cfg.grid_length = c->grid_length;
  DetectConfig rc = base;
  rc.method = Method::kReference;
  DetectResult got, ref;
  auto d = Detector::create(wall, cfg, p.size());
  auto r = Detector::create(wall, rc, p.size());
  ASSERT_TRUE(d && r);
  ASSERT_TRUE((*d)->set_particles(p) && (*d)->detect(&got));
  ASSERT_TRUE((*r)->set_particles(p) && (*r)->detect(&ref));
  const ContactDiff diff = compare_contacts(wall, p, ref.contacts, got.contacts, 0.0);
  EXPECT_EQ(diff.missed + diff.invented + diff.borderline, 0u);
}

TEST(AutoChoice, AFixedMethodOrGridIsKept) {
  const TriangleMesh wall = make_box(10, 10, 10);
  const Particles p = random_particles(2000, mesh_bounds(wall), 0.5, 1, 4);
  DetectConfig base;
  base.r_max = 1, base.method = Method::kCircumcircle, base.grid_length = 3;
  AutoRequest only_grid;
  only_grid.method = false;
  auto c = choose_detection(wall, p, base, only_grid);
  ASSERT_TRUE(c);
  EXPECT_EQ(c->method, Method::kCircumcircle);
  AutoRequest only_method;
  only_method.grid_length = false;
  c = choose_detection(wall, p, base, only_method);
  ASSERT_TRUE(c);
  EXPECT_DOUBLE_EQ(c->grid_length, 3);
  EXPECT_EQ(c->candidates.size(), 2u);  // CPU: bin at the given grid, and the tree
  EXPECT_NE(c->reason.find("bin/particle 3 r_max"), std::string::npos) << c->reason;
  EXPECT_NE(c->reason.find("bvh/particle "), std::string::npos) << c->reason;
}

// A candidate the caller refuses (a run's memory budget) is never prepared:
// it is listed with the reason and the choice is among the others.
TEST(AutoChoice, ARefusedCandidateIsNotTimed) {
  const TriangleMesh wall = make_box(10, 10, 10);
  const Particles p = random_particles(2000, mesh_bounds(wall), 0.5, 1, 4);
  DetectConfig base;
  base.r_max = 1;
  AutoRequest req;
  int asked = 0;
  req.admit = [&](Method m, double grid) {
    ++asked;
    return m == Method::kBin && grid < 2.5 ? resource_exhausted("over the budget") : Status::ok();
  };
  auto c = choose_detection(wall, p, base, req);
  ASSERT_TRUE(c) << c.status().message();
  EXPECT_GT(asked, 0);
  EXPECT_FALSE(c->method == Method::kBin && c->grid_length < 2.5) << c->reason;
  size_t refused = 0;
  for (const AutoCandidate& k : c->candidates) {
    const bool over = k.method == Method::kBin && k.grid_length < 2.5;
    EXPECT_EQ(k.error == "over the budget", over) << to_string(k.method) << " " << k.grid_length;
    if (over) {
      ++refused;
      EXPECT_EQ(k.frame_ms, 0);  // never timed
    }
  }
  EXPECT_EQ(refused, 3u);  // grids of 1, 1.5 and 2 r_max
  // Every one refused: no choice, and the reason why.
  req.admit = [](Method, double) { return resource_exhausted("over the budget"); };
  auto none = choose_detection(wall, p, base, req);
  ASSERT_FALSE(none);
  EXPECT_NE(none.status().message().find("over the budget"), std::string::npos);
}

// Division is worth timing only on the GPU and for triangles large against
// the radius; bin and the tree always; the octree on the GPU, for detection.
TEST(AutoChoice, DivisionIsACandidateOnlyWhereItCanWin) {
  const TriangleMesh wall = make_cylinder(50, 100, 40);
  using M = std::vector<Method>;
  EXPECT_EQ(auto_method_candidates(wall, 1, Backend::kCpu), (M{Method::kBin, Method::kBvh}));
  EXPECT_EQ(auto_method_candidates(wall, 1, Backend::kCuda),
            (M{Method::kBin, Method::kBvh, Method::kOctree, Method::kCircumcircle}));
  EXPECT_EQ(auto_method_candidates(make_sphere(1, 4), 1, Backend::kCuda),
            (M{Method::kBin, Method::kBvh, Method::kOctree}));
  // The dynamics cannot read the octree.
  EXPECT_EQ(auto_method_candidates(wall, 1, Backend::kCuda, /*for_dynamics=*/true),
            (M{Method::kBin, Method::kBvh, Method::kCircumcircle}));
}

}  // namespace
}  // namespace collido::sim
