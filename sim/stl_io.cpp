// STL reading and writing. ASCII and binary are told apart by size: a binary
// file is exactly 84 + 50 N bytes, whatever its header says (many binary
// exporters begin the header with "solid", which fools the keyword test).
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

#include "common/atomic_file.h"
#include "sim/mesh.h"

namespace collido::sim {
namespace {

constexpr size_t kBinaryHeader = 84;
constexpr size_t kBinaryRecord = 50;
// Refuse files that claim more triangles than any sane wall (and than the
// 32-bit ids we report contacts with).
constexpr uint64_t kMaxTriangles = 200'000'000;

uint32_t read_u32(const unsigned char* p) {
  return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}
float read_f32(const unsigned char* p) {
  uint32_t u = read_u32(p);
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}

bool finite3(const Vec3d& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

Expected<TriangleMesh> finish(std::vector<std::array<Vec3d, 3>>& soup, const char* format,
                              const std::string& name, MeshReport* report) {
  if (soup.empty()) return parse_error(name + ": the file holds no triangles");
  MeshReport local;
  TriangleMesh mesh = weld_soup(soup, {}, 0.0, &local);
  local.format = format;
  if (report) *report = local;
  if (mesh.triangles.empty())
    return parse_error(name + ": all " + std::to_string(soup.size()) +
                       " triangles have zero area");
  return mesh;
}

Expected<TriangleMesh> parse_binary(const std::string& bytes, const std::string& name,
                                    MeshReport* report) {
  const auto* data = reinterpret_cast<const unsigned char*>(bytes.data());
  const uint32_t n = read_u32(data + 80);
  std::vector<std::array<Vec3d, 3>> soup(n);
  for (uint32_t t = 0; t < n; ++t) {
    const unsigned char* rec = data + kBinaryHeader + size_t(t) * kBinaryRecord + 12;  // skip normal
    for (int k = 0; k < 3; ++k) {
      Vec3d v{read_f32(rec + 12 * k), read_f32(rec + 12 * k + 4), read_f32(rec + 12 * k + 8)};
      if (!finite3(v))
        return parse_error(name + ": triangle " + std::to_string(t) + " has a non-finite coordinate");
      soup[t][k] = v;
    }
  }
  return finish(soup, "stl-binary", name, report);
}

// Reads one whitespace-separated token, counting lines for error messages.
class Tokenizer {
 public:
  explicit Tokenizer(const std::string& s) : s_(s) {}
  bool next(std::string& tok) {
    while (pos_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[pos_]))) {
      if (s_[pos_] == '\n') ++line_;
      ++pos_;
    }
    if (pos_ >= s_.size()) return false;
    size_t start = pos_;
    while (pos_ < s_.size() && !std::isspace(static_cast<unsigned char>(s_[pos_]))) ++pos_;
    tok.assign(s_, start, pos_ - start);
    return true;
  }
  // Skips the rest of the current line (the solid's name may contain spaces).
  void skip_line() {
    while (pos_ < s_.size() && s_[pos_] != '\n') ++pos_;
  }
  size_t line() const { return line_; }

 private:
  const std::string& s_;
  size_t pos_ = 0;
  size_t line_ = 1;
};

bool iequals(const std::string& a, const char* b) {
  size_t n = std::strlen(b);
  if (a.size() != n) return false;
  for (size_t i = 0; i < n; ++i)
    if (std::tolower(static_cast<unsigned char>(a[i])) != b[i]) return false;
  return true;
}

Expected<TriangleMesh> parse_ascii(const std::string& bytes, const std::string& name,
                                   MeshReport* report) {
  Tokenizer tk(bytes);
  std::vector<std::array<Vec3d, 3>> soup;
  std::string tok;
  auto where = [&](const std::string& what) {
    return parse_error(name + ": line " + std::to_string(tk.line()) + ", triangle " +
                       std::to_string(soup.size()) + ": " + what);
  };
  auto expect = [&](const char* word) -> bool { return tk.next(tok) && iequals(tok, word); };
  bool in_solid = false;
  // A token as an error quotes it: printable ASCII only, at most 32 characters.
  auto quoted = [](const std::string& t) {
    std::string out;
    for (size_t i = 0; i < t.size() && i < 32; ++i) {
      const unsigned char c = static_cast<unsigned char>(t[i]);
      if (c >= 0x20 && c < 0x7f) {
        out += char(c);
      } else {
        char hex[8];
        std::snprintf(hex, sizeof hex, "\\x%02x", c);
        out += hex;
      }
    }
    return t.size() > 32 ? out + "..." : out;
  };
  while (tk.next(tok)) {
    if (iequals(tok, "solid")) {
      tk.skip_line();
      in_solid = true;
    } else if (iequals(tok, "endsolid")) {
      tk.skip_line();
      in_solid = false;
    } else if (iequals(tok, "facet")) {
      if (!in_solid) return where("'facet' outside a solid");
      if (!expect("normal")) return where("expected 'normal' after 'facet'");
      for (int k = 0; k < 3; ++k)
        if (!tk.next(tok)) return where("truncated normal");
      if (!expect("outer") || !expect("loop")) return where("expected 'outer loop'");
      std::array<Vec3d, 3> tri{};
      for (int k = 0; k < 3; ++k) {
        if (!expect("vertex")) return where("expected 'vertex' (a facet has exactly 3)");
        double c[3];
        for (double& x : c) {
          if (!tk.next(tok)) return where("truncated vertex");
          char* end = nullptr;
          x = std::strtod(tok.c_str(), &end);
          if (end == tok.c_str() || *end != '\0') return where("bad number '" + quoted(tok) + "'");
          if (!std::isfinite(x)) return where("non-finite coordinate '" + quoted(tok) + "'");
        }
        tri[k] = {c[0], c[1], c[2]};
      }
      if (!expect("endloop")) return where("expected 'endloop'");
      if (!expect("endfacet")) return where("expected 'endfacet'");
      soup.push_back(tri);
    } else {
      return where("unexpected '" + quoted(tok) + "'");
    }
  }
  if (in_solid && soup.empty()) return where("truncated: no facet before the end of the file");
  // Cut between two facets, a file would load with the rest of its wall missing.
  if (in_solid) return where("truncated: no 'endsolid' after the last facet");
  return finish(soup, "stl-ascii", name, report);
}

}  // namespace

Expected<TriangleMesh> parse_stl(const std::string& bytes, const std::string& name,
                                 MeshReport* report) {
  if (bytes.empty()) return parse_error(name + ": empty file");
  if (bytes.size() >= kBinaryHeader) {
    const uint64_t n = read_u32(reinterpret_cast<const unsigned char*>(bytes.data()) + 80);
    if (n <= kMaxTriangles && bytes.size() == kBinaryHeader + n * kBinaryRecord)
      return parse_binary(bytes, name, report);
  }
  size_t first = 0;
  while (first < bytes.size() && std::isspace(static_cast<unsigned char>(bytes[first]))) ++first;
  // Text never holds a NUL; a binary file whose header begins with "solid"
  // (SolidWorks writes them) and whose size is off is a damaged binary file.
  if (bytes.compare(first, 5, "solid") == 0 && bytes.find('\0') == std::string::npos)
    return parse_ascii(bytes, name, report);
  if (bytes.size() < kBinaryHeader)
    return parse_error(name + ": truncated: " + std::to_string(bytes.size()) +
                       " bytes, shorter than a binary STL header (84) and not ASCII STL");
  const uint64_t n = read_u32(reinterpret_cast<const unsigned char*>(bytes.data()) + 80);
  const uint64_t whole = (bytes.size() - kBinaryHeader) / kBinaryRecord;
  return parse_error(name + ": truncated or not STL: the header announces " + std::to_string(n) +
                     " triangles (" + std::to_string(kBinaryHeader + n * kBinaryRecord) +
                     " bytes) but the file has " + std::to_string(bytes.size()) +
                     " bytes; triangle " + std::to_string(whole) + " is incomplete");
}

Expected<TriangleMesh> load_stl(const std::string& path, MeshReport* report) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return open_failure(path, path + ": cannot open for reading");
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) return io_error(path + ": read error");
  return parse_stl(ss.str(), path, report);
}

std::string stl_bytes(const TriangleMesh& mesh) {
  std::string out(80, '\0');
  const char header[] = "binary STL written by collidoscope";
  std::memcpy(out.data(), header, sizeof header - 1);
  const uint32_t n = static_cast<uint32_t>(mesh.triangles.size());
  out.append(reinterpret_cast<const char*>(&n), 4);
  out.reserve(84 + 50 * size_t(n));
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    Vec3d a = mesh.corner(t, 0), b = mesh.corner(t, 1), c = mesh.corner(t, 2);
    Vec3d nrm = cross(b - a, c - a);
    double len = length(nrm);
    if (len > 0) nrm = nrm * (1.0 / len);
    const float rec[12] = {float(nrm.x), float(nrm.y), float(nrm.z), float(a.x),
                           float(a.y),   float(a.z),   float(b.x),   float(b.y),
                           float(b.z),   float(c.x),   float(c.y),   float(c.z)};
    out.append(reinterpret_cast<const char*>(rec), sizeof rec);
    out.append(2, '\0');  // attribute bytes
  }
  return out;
}

Status save_stl(const TriangleMesh& mesh, const std::string& path) {
  return write_file_atomic(path, stl_bytes(mesh));
}

}  // namespace collido::sim
