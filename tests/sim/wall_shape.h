// A built-in wall for a test, failing the test (not aborting it) on a bad spec.
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "sim/shapes.h"

namespace collido::sim {

inline TriangleMesh shape(const std::string& spec) {
  auto m = make_shape(spec);
  EXPECT_TRUE(m.has_value()) << spec;
  return m ? std::move(*m) : TriangleMesh{};
}

}  // namespace collido::sim
