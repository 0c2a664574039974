// The study command end to end on a small matrix: the tables it writes say
// what the study claims (exact rows exact, float rows flagged, the automatic
// choice exact and marked), and bad arguments are usage errors. No timings.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "app/cli.h"
#include "app/commands.h"
#include "tests/scratch.h"

namespace collido::app {
namespace {

std::vector<std::map<std::string, std::string>> read_csv(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::vector<std::string> header;
  std::vector<std::map<std::string, std::string>> rows;
  auto split = [](const std::string& s) {
    std::vector<std::string> out;
    std::stringstream ss(s);
    for (std::string f; std::getline(ss, f, ',');) out.push_back(f);
    if (!s.empty() && s.back() == ',') out.push_back("");
    return out;
  };
  if (std::getline(in, line)) header = split(line);
  while (std::getline(in, line)) {
    const auto f = split(line);
    EXPECT_EQ(f.size(), header.size()) << line;
    std::map<std::string, std::string> row;
    for (size_t i = 0; i < header.size() && i < f.size(); ++i) row[header[i]] = f[i];
    rows.push_back(row);
  }
  return rows;
}

TEST(CmdStudy, QuickDetectionOnWall1) {
  const std::string out = test::scratch_path("cmd_study_test_wall1");
  // The half not run (--only detect) keeps what an earlier study wrote of it.
  std::filesystem::create_directories(out);
  std::ofstream(out + "/study_dynamics.csv") << "scene\nkept\n";
  std::ofstream(out + "/study.json")
      << R"({"machine": "earlier", "detect": [], "dynamics": [{"scene": "kept"}]})";
  ASSERT_EQ(cmd_study({"--quick", "--only", "detect", "--scenes", "wall1", "--max-particles", "1000",
                       "--meshes", COLLIDO_TEST_DATA "/meshes", "--out", out, "--threads", "2"}),
            kExitOk);
  const auto rows = read_csv(out + "/study_detect.csv");
  ASSERT_FALSE(rows.empty());
  int exact = 0, float_wrong = 0, autos = 0;
  for (const auto& r : rows) {
    EXPECT_EQ(r.at("scene"), "wall1");
    EXPECT_EQ(r.at("particles"), "1000");
    if (r.at("precision") == "exact" || r.at("precision") == "double") {
      EXPECT_EQ(r.at("verdict"), "exact") << r.at("method") << " " << r.at("grid_factor");
      ++exact;
    } else if (r.at("verdict") != "exact") {
      EXPECT_EQ(r.at("placement"), "near");  // float goes wrong only near touching
      EXPECT_NE(r.at("band_pairs"), "0");    // and says it decided pairs in doubt
      ++float_wrong;
    }
    if (r.at("method") != "reference") {  // two timed passes, frame_ms the faster
      EXPECT_GT(std::stod(r.at("frame_ms")), 0);
      EXPECT_GE(std::stod(r.at("frame_ms_other_pass")), std::stod(r.at("frame_ms")));
    }
    if (r.at("auto") == "1") {
      ++autos;
      EXPECT_EQ(r.at("precision"), "exact");
      EXPECT_EQ(r.at("verdict"), "exact");
    }
  }
  EXPECT_GT(exact, 0);
  EXPECT_GT(float_wrong, 0) << "within 1e-4 r of touching, float precision should be caught out";
  EXPECT_EQ(autos, 2);  // one automatic choice per placement
  std::ifstream json(out + "/study.json");
  ASSERT_TRUE(json.good());
  std::stringstream doc;
  doc << json.rdbuf();
  EXPECT_NE(doc.str().find("\"kept\""), std::string::npos) << "the dynamics rows were kept";
  EXPECT_NE(doc.str().find("\"wall1\""), std::string::npos) << "the detection rows were written";
  std::ifstream dynamics(out + "/study_dynamics.csv");
  std::stringstream kept;
  kept << dynamics.rdbuf();
  EXPECT_EQ(kept.str(), "scene\nkept\n");
}

// A scene name that matches nothing fails and names the scenes there are,
// instead of writing empty tables over a study.
TEST(CmdStudy, AnUnknownSceneIsBadInputThatNamesTheScenes) {
  testing::internal::CaptureStderr();
  EXPECT_EQ(cmd_study({"--quick", "--only", "detect", "--scenes", "teapot", "--meshes",
                       COLLIDO_TEST_DATA "/meshes", "--out",
                       test::scratch_path("cmd_study_test_unknown")}),
            kExitUsage);
  const std::string said = testing::internal::GetCapturedStderr();
  EXPECT_NE(said.find("no detection scene 'teapot' (wall1, wall2, teapot_trimesh)"),
            std::string::npos)
      << said;
}

TEST(CmdStudy, BadArgumentsExitTwo) {
  EXPECT_EQ(cmd_study({}), kExitUsage);  // no --out
  EXPECT_EQ(cmd_study({"--out", "x", "--only", "both"}), kExitUsage);
  EXPECT_EQ(cmd_study({"--out", "x", "--backend", "tpu"}), kExitUsage);
  EXPECT_EQ(cmd_study({"--out", "x", "--max-particles", "-5"}), kExitUsage);
  EXPECT_EQ(cmd_study({"--out", "x", "--threads", "many"}), kExitUsage);
}

TEST(CmdStudy, AMissingMeshFolderIsBadInputThatSaysSo) {
  testing::internal::CaptureStderr();
  EXPECT_EQ(cmd_study({"--quick", "--only", "detect", "--meshes", "/nonexistent/meshes", "--out",
                       test::scratch_path("cmd_study_test_missing")}),
            kExitUsage);
  const std::string said = testing::internal::GetCapturedStderr();
  EXPECT_NE(said.find("cannot read the mesh folder /nonexistent/meshes"), std::string::npos) << said;
}

}  // namespace
}  // namespace collido::app
