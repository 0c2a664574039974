#include "gvm/run_log.h"

#include "common/atomic_file.h"
#include "gvm/csv.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>

namespace collido::gvm {

const char* method_name(Method m) {
  switch (m) {
    case Method::kGravity:
      return "gravity";
    case Method::kCircumcircle:
      return "circumcircle";
    case Method::kMidpoint4:
      return "midpoint4";
    case Method::kBin:
      return "bin";
    case Method::kReference:
      return "reference";
  }
  return "?";
}
const char* traversal_name(Traversal t) {
  return t == Traversal::kWall ? "wall" : "particle";
}
const char* backend_name(Backend b) {
  return b == Backend::kCpu ? "cpu" : "cuda";
}

std::optional<Method> parse_method(const std::string& s) {
  for (Method m : kAllMethods)
    if (s == method_name(m)) return m;
  return std::nullopt;
}
std::optional<Traversal> parse_traversal(const std::string& s) {
  if (s == "wall") return Traversal::kWall;
  if (s == "particle") return Traversal::kParticle;
  return std::nullopt;
}
std::optional<Backend> parse_backend(const std::string& s) {
  if (s == "cpu") return Backend::kCpu;
  if (s == "cuda") return Backend::kCuda;
  return std::nullopt;
}

const std::vector<std::string>& run_log_columns() {
  static const std::vector<std::string> cols = {"particles",
                                                "triangles",
                                                "triangles_original",
                                                "radius",
                                                "wall_area",
                                                "wall_box_volume",
                                                "method",
                                                "traversal",
                                                "frames",
                                                "backend",
                                                "device",
                                                "threads",
                                                "time_per_frame_s",
                                                "total_time_s",
                                                "peak_host_bytes",
                                                "peak_device_bytes",
                                                "gpu_load"};
  return cols;
}

Status validate(const RunConfig& c) {
  if (c.particles < 1) return invalid_argument("particles must be >= 1");
  if (c.triangles < 1) return invalid_argument("triangles must be >= 1");
  if (c.triangles_original < 1) return invalid_argument("triangles_original must be >= 1");
  const std::pair<const char*, double> geometry[] = {
      {"radius", c.radius}, {"wall_area", c.wall_area}, {"wall_box_volume", c.wall_box_volume}};
  for (const auto& [name, v] : geometry)
    if (!std::isfinite(v) || v <= 0.0)
      return invalid_argument(std::string(name) + " must be a finite number > 0");
  if (c.frames < 1) return invalid_argument("frames must be >= 1");
  if (c.threads < 0) return invalid_argument("threads must be >= 0");
  return Status::ok();
}

Status validate(const RunMeasure& m) {
  const std::pair<const char*, double> fields[] = {{"time_per_frame_s", m.time_per_frame_s},
                                                   {"total_time_s", m.total_time_s},
                                                   {"peak_host_bytes", m.peak_host_bytes},
                                                   {"peak_device_bytes", m.peak_device_bytes},
                                                   {"gpu_load", m.gpu_load}};
  for (const auto& [name, v] : fields)
    if (!std::isfinite(v) || v < 0.0)
      return invalid_argument(std::string(name) + " must be a finite number >= 0");
  if (m.gpu_load > 1.0) return invalid_argument("gpu_load must be <= 1");
  return Status::ok();
}

Expected<std::vector<RunRecord>> parse_run_log(const std::string& text) {
  auto recs = split_csv(text);
  if (!recs) return recs.status();
  if (recs->empty()) return parse_error("line 1: empty run log, no header line");
  const CsvRecord& header = recs->front();
  std::map<std::string, size_t> where;
  for (size_t c = 0; c < header.fields.size(); ++c) {
    const std::string name = trim(header.fields[c]);
    if (where.count(name))
      return parse_error("line " + std::to_string(header.line) + ", column " +
                         std::to_string(c + 1) + ": duplicate column '" + name + "'");
    where[name] = c;
  }
  std::vector<size_t> col;
  for (const auto& name : run_log_columns()) {
    auto it = where.find(name);
    if (it == where.end())
      return parse_error("line " + std::to_string(header.line) + ": missing column '" + name + "'");
    col.push_back(it->second);
  }

  std::vector<RunRecord> rows;
  for (size_t r = 1; r < recs->size(); ++r) {
    const CsvRecord& rec = (*recs)[r];
    const std::string at_line = "line " + std::to_string(rec.line);
    if (rec.fields.size() != header.fields.size())
      return parse_error(at_line + ": " + std::to_string(rec.fields.size()) +
                         " fields, the header has " + std::to_string(header.fields.size()));
    // Returns the field of known column k and a prefix for errors about it.
    auto field = [&](size_t k, std::string* where_msg) {
      *where_msg =
          at_line + ", column " + std::to_string(col[k] + 1) + " (" + run_log_columns()[k] + ")";
      return trim(rec.fields[col[k]]);
    };
    std::string loc;
    auto bad = [&](const std::string& what, const std::string& got) {
      return parse_error(loc + ": expected " + what + ", got '" + got + "'");
    };
    RunRecord row;
    RunConfig& c = row.config;
    RunMeasure& m = row.measure;
    int64_t* ints[] = {&c.particles, &c.triangles, &c.triangles_original};
    for (size_t k = 0; k < 3; ++k) {
      std::string s = field(k, &loc);
      if (!parse_int(s, ints[k]) || *ints[k] < 1) return bad("an integer >= 1", s);
    }
    double* geometry[] = {&c.radius, &c.wall_area, &c.wall_box_volume};
    for (size_t k = 0; k < 3; ++k) {
      std::string s = field(3 + k, &loc);
      if (!parse_double(s, geometry[k]) || *geometry[k] <= 0.0) return bad("a finite number > 0", s);
    }
    {
      std::string s = field(6, &loc);
      auto v = parse_method(s);
      if (!v) return bad("gravity|circumcircle|midpoint4|bin|reference", s);
      c.method = *v;
    }
    {
      std::string s = field(7, &loc);
      auto v = parse_traversal(s);
      if (!v) return bad("wall|particle", s);
      c.traversal = *v;
    }
    {
      std::string s = field(8, &loc);
      if (!parse_int(s, &c.frames) || c.frames < 1) return bad("an integer >= 1", s);
    }
    {
      std::string s = field(9, &loc);
      auto v = parse_backend(s);
      if (!v) return bad("cpu|cuda", s);
      c.backend = *v;
    }
    c.device = field(10, &loc);
    {
      std::string s = field(11, &loc);
      if (!parse_int(s, &c.threads) || c.threads < 0) return bad("an integer >= 0", s);
    }
    double* dbl[] = {&m.time_per_frame_s, &m.total_time_s, &m.peak_host_bytes, &m.peak_device_bytes,
                     &m.gpu_load};
    for (size_t k = 0; k < 5; ++k) {
      std::string s = field(12 + k, &loc);
      if (!parse_double(s, dbl[k]) || *dbl[k] < 0.0) return bad("a finite number >= 0", s);
      if (dbl[k] == &m.gpu_load && m.gpu_load > 1.0) return bad("a load in [0, 1]", s);
    }
    rows.push_back(std::move(row));
  }
  return rows;
}

std::string run_log_header() {
  const auto& cols = run_log_columns();
  std::string out;
  for (size_t k = 0; k < cols.size(); ++k) out += (k ? "," : "") + cols[k];
  return out;
}

std::string format_run_log_row(const RunRecord& r) {
  const RunConfig& c = r.config;
  const RunMeasure& m = r.measure;
  return std::to_string(c.particles) + "," + std::to_string(c.triangles) + "," +
         std::to_string(c.triangles_original) + "," + format_double(c.radius) + "," +
         format_double(c.wall_area) + "," + format_double(c.wall_box_volume) + "," +
         method_name(c.method) + "," + traversal_name(c.traversal) + "," +
         std::to_string(c.frames) + "," + backend_name(c.backend) + "," + quote_csv(c.device) +
         "," + std::to_string(c.threads) + "," + format_double(m.time_per_frame_s) + "," +
         format_double(m.total_time_s) + "," + format_double(m.peak_host_bytes) + "," +
         format_double(m.peak_device_bytes) + "," + format_double(m.gpu_load);
}

std::string format_run_log(const std::vector<RunRecord>& rows) {
  std::string out = run_log_header() + "\n";
  for (const auto& r : rows) out += format_run_log_row(r) + "\n";
  return out;
}

namespace {
bool same_config(const RunConfig& a, const RunConfig& b) {
  return a.particles == b.particles && a.triangles == b.triangles &&
         a.triangles_original == b.triangles_original && a.radius == b.radius &&
         a.wall_area == b.wall_area && a.wall_box_volume == b.wall_box_volume &&
         a.method == b.method && a.traversal == b.traversal && a.frames == b.frames &&
         a.backend == b.backend && a.device == b.device && a.threads == b.threads;
}
}  // namespace

std::vector<RunRecord> merge_repeats(const std::vector<RunRecord>& rows) {
  std::vector<RunRecord> out;
  for (const RunRecord& r : rows) {
    auto it = std::find_if(out.begin(), out.end(),
                           [&](const RunRecord& o) { return same_config(o.config, r.config); });
    if (it == out.end()) {
      out.push_back(r);
      continue;
    }
    RunMeasure& m = it->measure;
    const RunMeasure& n = r.measure;
    m.time_per_frame_s = std::min(m.time_per_frame_s, n.time_per_frame_s);
    if (n.total_time_s < m.total_time_s) {
      m.total_time_s = n.total_time_s;
      m.gpu_load = n.gpu_load;
    }
    m.peak_host_bytes = std::max(m.peak_host_bytes, n.peak_host_bytes);
    m.peak_device_bytes = std::max(m.peak_device_bytes, n.peak_device_bytes);
  }
  return out;
}

Expected<std::vector<RunRecord>> read_run_log(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return open_failure(path, "cannot open run log '" + path + "'");
  std::ostringstream ss;
  ss << in.rdbuf();
  auto rows = parse_run_log(ss.str());
  if (!rows) return Status(rows.status().code(), path + ": " + rows.status().message());
  return rows;
}

// Through a temporary name: `gvm merge a.csv b.csv --out a.csv` reads its
// inputs first, and a write cut short would have left the log truncated.
Status write_run_log(const std::string& path, const std::vector<RunRecord>& rows) {
  return write_file_atomic(path, format_run_log(rows));
}

}  // namespace collido::gvm
