// A number for a message: "0.5", "1e+05", not "0.500000". Shared by the modules that
// name bad values in their errors (sim's placement, scene's reader). Header-only.
#pragma once

#include <sstream>
#include <string>

namespace collido {

inline std::string number_text(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

}  // namespace collido
