// Running a test file's scene functions on the GPU as a second suite: the
// backend under test is CPU by default; a suite derived from GpuSuite switches
// it to CUDA for its tests and skips them where no GPU is usable.
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "sim/detect.h"

namespace collido::sim {

// The backend the scene functions of this test program run on.
inline Backend& backend_under_test() {
  static Backend backend = Backend::kCpu;
  return backend;
}

class GpuSuite : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string why;
    if (!cuda_available(&why)) GTEST_SKIP() << "no GPU: " << why;
    backend_under_test() = Backend::kCuda;
  }
  void TearDown() override { backend_under_test() = Backend::kCpu; }
};

}  // namespace collido::sim
