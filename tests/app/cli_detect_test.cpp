// The detect command end to end: arguments, exit codes, CSV and JSON output.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "app/cli.h"
#include "app/commands.h"
#include "tests/scratch.h"

namespace collido::app {
namespace {

const std::string kData = COLLIDO_TEST_DATA;

std::string read(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(CliDetect, BadArgumentsExitTwo) {
  EXPECT_EQ(cmd_detect({"--particles"}), kExitUsage);
  EXPECT_EQ(cmd_detect({"--particles", "10", "--method", "magic"}), kExitUsage);
  EXPECT_EQ(cmd_detect({"--particles", "10", "--traversal", "sideways"}), kExitUsage);
  EXPECT_EQ(cmd_detect({"--particles", "10", "--grid-length", "-1"}), kExitUsage);
  EXPECT_EQ(cmd_detect({"--particles", "10", "--radius-range", "2:1"}), kExitUsage);
  EXPECT_EQ(cmd_detect({"--particles", "-5"}), kExitUsage);
  EXPECT_EQ(cmd_detect({"--particles", "10", "--frobnicate"}), kExitUsage);
  EXPECT_EQ(cmd_detect({}), kExitUsage);
  EXPECT_EQ(cmd_detect({"--help"}), kExitOk);
  EXPECT_EQ(cmd_bench({"nothing"}), kExitUsage);
  EXPECT_EQ(cmd_bench({"run", "--method", "magic"}), kExitUsage);
  EXPECT_EQ(cmd_bench({"run", "--method", "reference"}), kExitUsage);  // not a wall for dynamics
}

// A missing file or a bad wall spec is bad input, exit 2 as for every command
// (README, app/cli.h exit_code); a run that fails exits 1.
TEST(CliDetect, BadInputsExitTwo) {
  EXPECT_EQ(cmd_detect({"--particles", "10", "--wall", "/nonexistent/wall.stl"}), kExitUsage);
  EXPECT_EQ(cmd_detect({"--particles", "10", "--wall", "cylinder:r=-3"}), kExitUsage);
  EXPECT_EQ(cmd_detect({"--particles", "/nonexistent.csv"}), kExitUsage);
  EXPECT_EQ(cmd_bench({"detect", "--wall", "/nonexistent/wall.stl"}), kExitUsage);
}

TEST(CliDetect, WritesSortedContactsThatMatchTheReference) {
  const std::string dir = test::scratch_dir("cli_detect");
  const std::string csv = dir + "/p.csv";
  // Particles on wall1's side, cap and rim, and one far away.
  std::ofstream(csv) << "x,y,z,r\n50,0,50,1\n0,0,100.5,1\n50,0,100,0.8\n0,0,-50,1\n";
  for (const char* method : {"bin", "gravity", "circumcircle", "reference"}) {
    const std::string out = dir + "/contacts_" + method + ".csv";
    ASSERT_EQ(cmd_detect({"--wall", "wall1", "--particles", csv, "--method", method, "--out", out}), kExitOk);
    const std::string text = read(out);
    EXPECT_EQ(text.substr(0, 27), "particle,triangle,distance\n") << method;
    // Same pairs for every method.
    std::string pairs;
    std::istringstream lines(text);
    std::string line;
    std::getline(lines, line);
    while (std::getline(lines, line)) pairs += line.substr(0, line.rfind(',')) + ";";
    static std::string expected;
    if (expected.empty()) expected = pairs;
    EXPECT_EQ(pairs, expected) << method;
    EXPECT_NE(pairs.find("0,"), std::string::npos);
    EXPECT_EQ(pairs.find("3,"), std::string::npos) << "the far particle touches nothing";
  }
}

TEST(CliDetect, LoadsRealStlFiles) {
  EXPECT_EQ(cmd_detect({"--wall", kData + "/meshes/teapot_trimesh.stl", "--particles", "2000", "--radius", "0.2",
                        "--json"}),
            kExitOk);
  EXPECT_EQ(cmd_detect({"--wall", kData + "/meshes/plate_holes_trimesh_binary_solid_header.stl", "--particles",
                        "2000", "--method", "circumcircle", "--traversal", "wall"}),
            kExitOk);
}

}  // namespace
}  // namespace collido::app
