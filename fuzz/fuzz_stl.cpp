// STL bytes (ASCII or binary, any header) into the engine's mesh loader.
#include <cstdint>
#include <string>

#include "sim/mesh.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  collido::sim::MeshReport report;
  auto mesh = collido::sim::parse_stl(bytes, "fuzz.stl", &report);
  if (mesh)
    for (const auto& t : mesh->triangles)
      for (uint32_t v : t)
        if (v >= mesh->vertices.size()) __builtin_trap();  // an index outside the mesh
  return 0;
}
