// Scratch paths for tests: fresh when a test asks for one, removed when the
// test passes, kept (and named in the output) when it fails, for a look.
// Without this, every run of the suite left its databases, jobs and videos
// under /tmp (1.3 GB after a few dozen runs on the development machine).
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <string>
#include <system_error>
#include <vector>

namespace collido::test {

// Removes the paths handed out during a test when the test ends: a gtest
// listener, so it runs after the fixture's TearDown and destructor (servers
// and daemons stopped, files closed), whichever helper made the path.
class ScratchCleaner : public ::testing::EmptyTestEventListener {
 public:
  // The one cleaner of this test binary, added to gtest's listeners (which
  // own it) on first use.
  static ScratchCleaner& get() {
    static ScratchCleaner* const cleaner = [] {
      auto* c = new ScratchCleaner;
      ::testing::UnitTest::GetInstance()->listeners().Append(c);
      return c;
    }();
    return *cleaner;
  }

  // Whether the path is new to this test (asked again, it is the same one).
  bool add(const std::string& path) {
    std::lock_guard<std::mutex> lock(mu_);
    if (std::find(paths_.begin(), paths_.end(), path) != paths_.end()) return false;
    paths_.push_back(path);
    return true;
  }

  void OnTestEnd(const ::testing::TestInfo& info) override {
    std::vector<std::string> paths;
    {
      std::lock_guard<std::mutex> lock(mu_);
      paths.swap(paths_);
    }
    for (const std::string& p : paths) {
      if (info.result()->Failed()) {
        std::printf("[ scratch  ] kept %s\n", p.c_str());
      } else {
        std::error_code ec;  // best effort: a test may have removed it itself
        std::filesystem::remove_all(p, ec);
      }
    }
  }

 private:
  std::mutex mu_;
  std::vector<std::string> paths_;
};

// A path under the temp folder named for `name` and this process (tests of
// one binary may run side by side under ctest): "run" -> /tmp/run_PID,
// "scene.json" -> /tmp/scene_PID.json. Nothing is there when a test first
// asks for it (the same name asked again within the test is left as it is);
// it goes when the test passes.
inline std::string scratch_path(const std::string& name) {
  const size_t dot = name.find('.');
  const std::string stem = name.substr(0, dot);
  const std::string ext = dot == std::string::npos ? "" : name.substr(dot);
  const std::filesystem::path p =
      std::filesystem::temp_directory_path() / (stem + "_" + std::to_string(::getpid()) + ext);
  if (ScratchCleaner::get().add(p.string())) {
    std::error_code ec;
    std::filesystem::remove_all(p, ec);
  }
  return p.string();
}

// scratch_path, made as an empty folder.
inline std::string scratch_dir(const std::string& name) {
  const std::string p = scratch_path(name);
  std::filesystem::create_directories(p);
  return p;
}

}  // namespace collido::test
