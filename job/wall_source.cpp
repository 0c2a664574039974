#include "job/wall_source.h"

#include <sys/stat.h>

#include <algorithm>
#include <cctype>

#include "sim/shapes.h"
#if defined(COLLIDO_HAVE_MESH_IMPORT)
#include "mesh_import/mesh_import.h"
#endif

namespace collido::job {

namespace {
bool is_file(const std::string& p) {
  struct stat st;
  return ::stat(p.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}
std::string lower_ext(const std::string& p) {
  auto dot = p.rfind('.');
  std::string e = dot == std::string::npos ? "" : p.substr(dot + 1);
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e;
}
}  // namespace

bool is_shape_spec(const std::string& spec) { return bool(sim::make_shape(spec)); }

sim::Expected<sim::TriangleMesh> load_wall(const std::string& spec, sim::MeshReport* report) {
  if (is_file(spec)) {
    if (lower_ext(spec) == "stl") return sim::load_stl(spec, report);
#if defined(COLLIDO_HAVE_MESH_IMPORT)
    return mesh_import::import_mesh(spec, report);
#else
    return sim::invalid_argument(spec + ": only STL walls are supported in this build");
#endif
  }
  auto mesh = sim::make_shape(spec);
  if (!mesh) {
    const bool looks_like_path = spec.find('/') != std::string::npos || spec.find('.') != std::string::npos;
    if (looks_like_path && spec.find(':') == std::string::npos)
      return sim::not_found(spec + ": no such file");
    return mesh.status();
  }
  if (report) {
    report->format = "generated";
    report->triangles_in = mesh->triangles.size();
    report->vertices_after_weld = mesh->vertices.size();
  }
  return mesh;
}

}  // namespace collido::job
