#include "sim/vtp_io.h"

#include <cstdio>
#include <sstream>

#include "common/atomic_file.h"

namespace collido::sim {

// Both files are built in memory and renamed into place whole.
Status write_vtp(const std::string& path, const Snapshot& s) {
  std::ostringstream out;
  const size_t n = s.size();
  char buf[128];
  out << "<?xml version=\"1.0\"?>\n"
         "<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\">\n<PolyData>\n"
      << "<Piece NumberOfPoints=\"" << n << "\" NumberOfVerts=\"" << n << "\">\n"
      << "<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
  for (size_t i = 0; i < n; ++i) {
    std::snprintf(buf, sizeof buf, "%.9g %.9g %.9g\n", s.origin.x + s.x[i], s.origin.y + s.y[i],
                  s.origin.z + s.z[i]);
    out << buf;
  }
  out << "</DataArray>\n</Points>\n<PointData Scalars=\"radius\" Vectors=\"velocity\">\n"
      << "<DataArray type=\"Float32\" Name=\"radius\" format=\"ascii\">\n";
  for (size_t i = 0; i < n; ++i) out << s.r[i] << '\n';
  out << "</DataArray>\n<DataArray type=\"Float32\" Name=\"velocity\" NumberOfComponents=\"3\" "
         "format=\"ascii\">\n";
  for (size_t i = 0; i < n; ++i) out << s.vx[i] << ' ' << s.vy[i] << ' ' << s.vz[i] << '\n';
  out << "</DataArray>\n<DataArray type=\"UInt8\" Name=\"contact\" format=\"ascii\">\n";
  for (size_t i = 0; i < n; ++i) out << int(s.contact[i]) << '\n';
  // One vertex cell per point, so ParaView draws them without a filter.
  out << "</DataArray>\n</PointData>\n<Verts>\n<DataArray type=\"Int64\" Name=\"connectivity\" "
         "format=\"ascii\">\n";
  for (size_t i = 0; i < n; ++i) out << i << '\n';
  out << "</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n";
  for (size_t i = 0; i < n; ++i) out << i + 1 << '\n';
  out << "</DataArray>\n</Verts>\n</Piece>\n</PolyData>\n</VTKFile>\n";
  return write_file_atomic(path, out.str());
}

Status write_pvd(const std::string& path, const std::vector<PvdEntry>& entries) {
  std::ostringstream out;
  out << "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"1.0\">\n<Collection>\n";
  char buf[64];
  for (const PvdEntry& e : entries) {
    std::snprintf(buf, sizeof buf, "%.9g", e.time);
    out << "<DataSet timestep=\"" << buf << "\" file=\"" << e.file << "\"/>\n";
  }
  out << "</Collection>\n</VTKFile>\n";
  return write_file_atomic(path, out.str());
}

}  // namespace collido::sim
