// Parametric wall specs ("cylinder:r=50,h=100", unions with "+") into the
// shape builder. Specs that ask for enormous meshes must be refused, not built.
#include <cstdint>
#include <string>

#include "sim/shapes.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size > 4096) return 0;
  const std::string spec(reinterpret_cast<const char*>(data), size);
  auto mesh = collido::sim::make_shape(spec);
  if (mesh && mesh->triangles.size() != mesh->source_ids.size()) __builtin_trap();
  return 0;
}
