#include "job/job_log.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <utility>

#include "common/atomic_file.h"
#include "common/median.h"
#include "gvm/csv.h"
#include "job/assess.h"
#include "sim/parallel.h"

namespace collido::job {

namespace g = collido::gvm;

namespace {

bool known(const std::string& v, std::initializer_list<const char*> names) {
  for (const char* n : names)
    if (v == n) return true;
  return false;
}

// What the steps did, as result.json's cost and the log's optional columns name it:
// notes read, written and checked alike (NaN where not recorded).
constexpr std::pair<const char*, double JobMeasure::*> kMeasureNotes[] = {
    {"active_steps", &JobMeasure::active_steps},
    {"wall_contact_steps", &JobMeasure::wall_contact_steps},
    {"pair_contact_steps", &JobMeasure::pair_contact_steps},
    {"list_builds", &JobMeasure::list_builds}};

// Inputs recorded after the first logs, in their optional columns alike: NaN (an
// empty cell) where a log predates them, else >= 0.
constexpr std::pair<const char*, double JobInputs::*> kInputNotes[] = {
    {"bin_entries", &JobInputs::bin_entries},
    {"wall_buckets", &JobInputs::wall_buckets},
    {"restitution", &JobInputs::restitution},
    {"start_speed", &JobInputs::start_speed},
    {"wall_open", &JobInputs::wall_open}};

}  // namespace

bool JobInputs::has_format(const std::string& f) const {
  if (formats == "none") return false;
  std::stringstream ss(formats);
  std::string part;
  while (std::getline(ss, part, '+'))
    if (part == f) return true;
  return false;
}

JobInputs job_inputs(const JobAssessment& a, const std::string& backend, const std::string& device,
                     int threads) {
  const scene::Scene& s = a.resolved.scene;
  JobInputs in;
  in.wall = s.wall;
  if (s.wall_is_file) in.wall = s.wall.substr(s.wall.rfind('/') + 1);
  in.particles = a.particles;
  in.triangles = a.triangles;
  in.pieces = a.work.pieces;
  in.wall_cells = a.work.wall_cells;
  in.bin_entries = a.work.bin_entries;
  in.wall_buckets = a.work.wall_buckets;
  in.wall_area = a.wall_area;
  for (int i = 0; i < 3; ++i) in.box[i] = a.box[i];
  in.r_min = a.r_min;
  in.r_max = a.r_max;
  in.method = sim::to_string(s.dynamics.method);
  in.placement = sim::to_string(s.placement.kind);
  in.release_s = a.release.last_release;
  in.particle_contacts = s.dynamics.particle_contacts;
  in.friction = s.dynamics.material.friction;
  in.restitution =
      (s.dynamics.wall_material_set ? s.dynamics.wall_material : s.dynamics.material).restitution;
  in.gravity = sim::length(s.dynamics.gravity);
  in.start_speed = a.release.speed;
  in.wall_open = a.wall_closed ? 0 : 1;
  in.duration = s.duration;
  in.fps = s.fps;
  in.frames = a.frames;
  in.step_s = a.steps.step;
  in.steps_per_frame = a.steps.steps_per_frame;
  in.steps = a.steps.steps;
  if (a.render_pixels > 0) {
    in.render_width = a.resolved.render.width;
    in.render_height = a.resolved.render.height;
    in.formats.clear();
    for (const std::string& f : a.formats) in.formats += (in.formats.empty() ? "" : "+") + f;
    if (in.formats.empty()) in.formats = "none";
  }
  in.backend = backend;
  in.device = device;
  in.threads = threads > 0 ? threads : int(sim::usable_cpus());
  return in;
}

const std::vector<std::string>& job_log_optional_columns() {
  static const std::vector<std::string> cols = {
      "active_steps", "wall_contact_steps", "pair_contact_steps", "bin_entries",
      "wall_buckets", "total_s_runs",       "per_frame_s_runs",   "restitution",
      "list_builds",  "start_speed",        "wall_open"};
  return cols;
}

const std::vector<std::string>& job_log_columns() {
  static const std::vector<std::string> cols = [] {
    std::vector<std::string> c = {
        "wall",          "particles",      "triangles",       "pieces",
        "wall_cells",    "wall_area",      "box_x",           "box_y",
        "box_z",         "r_min",          "r_max",           "method",
        "placement",     "release_s",      "particle_contacts", "friction",
        "gravity",       "duration",       "fps",             "frames",
        "step_s",        "steps_per_frame", "steps",          "render_width",
        "render_height", "formats",        "backend",         "device",
        "threads",       "total_s",        "prepare_s",       "simulate_s",
        "render_s",      "per_frame_s",    "peak_host_bytes", "peak_device_bytes",
        "gpu_load",      "output_bytes",   "steps_taken",     "load_avg"};
    const auto& optional = job_log_optional_columns();  // written last
    c.insert(c.end(), optional.begin(), optional.end());
    return c;
  }();
  return cols;
}

Status validate(const JobInputs& in) {
  if (in.particles < 1) return invalid_argument("particles must be >= 1");
  if (in.triangles < 1) return invalid_argument("triangles must be >= 1");
  if (in.frames < 1) return invalid_argument("frames must be >= 1");
  if (in.steps_per_frame < 1 || in.steps < 1) return invalid_argument("steps must be >= 1");
  const std::pair<const char*, double> positive[] = {
      {"pieces", in.pieces},     {"wall_area", in.wall_area}, {"r_min", in.r_min},
      {"r_max", in.r_max},       {"duration", in.duration},   {"fps", in.fps},
      {"step_s", in.step_s}};
  for (const auto& [name, v] : positive)
    if (!std::isfinite(v) || v <= 0) return invalid_argument(std::string(name) + " must be > 0");
  const std::pair<const char*, double> nonneg[] = {{"wall_cells", in.wall_cells},
                                                   {"box_x", in.box[0]},
                                                   {"box_y", in.box[1]},
                                                   {"box_z", in.box[2]},
                                                   {"release_s", in.release_s},
                                                   {"friction", in.friction},
                                                   {"gravity", in.gravity}};
  for (const auto& [name, v] : nonneg)
    if (!std::isfinite(v) || v < 0) return invalid_argument(std::string(name) + " must be >= 0");
  for (const auto& [name, field] : kInputNotes)  // NaN: not recorded
    if (std::isinf(in.*field) || in.*field < 0)
      return invalid_argument(std::string(name) + " must be >= 0 or empty");
  if (in.restitution > 1) return invalid_argument("restitution must be <= 1 or empty");
  if (in.wall_open != 0 && in.wall_open != 1 && !std::isnan(in.wall_open))
    return invalid_argument("wall_open must be 0, 1 or empty");
  if (in.r_min > in.r_max) return invalid_argument("r_min must be <= r_max");
  if (!known(in.method, {"bin", "bvh", "gravity", "circumcircle", "midpoint4"}))
    return invalid_argument("method must be bin, gravity, circumcircle or midpoint4");
  if (!known(in.placement, {"fill", "pour", "jet"}))
    return invalid_argument("placement must be fill, pour or jet");
  if (in.render_width < 0 || in.render_height < 0 || in.render_width > 16384 ||
      in.render_height > 16384)
    return invalid_argument("render_width and render_height must be in 0..16384");
  if (in.formats != "none") {
    std::stringstream ss(in.formats);
    std::string part;
    while (std::getline(ss, part, '+'))
      if (!known(part, {"mp4", "webm", "gif"}))
        return invalid_argument("formats: '" + part + "' is not mp4, webm or gif");
  }
  if (!known(in.backend, {"cpu", "cuda"})) return invalid_argument("backend must be cpu or cuda");
  if (in.threads < 0) return invalid_argument("threads must be >= 0");
  return Status::ok();
}

Status validate(const JobMeasure& m) {
  const std::pair<const char*, double> fields[] = {
      {"total_s", m.total_s},         {"prepare_s", m.prepare_s},
      {"simulate_s", m.simulate_s},   {"render_s", m.render_s},
      {"per_frame_s", m.per_frame_s}, {"peak_host_bytes", m.peak_host_bytes},
      {"peak_device_bytes", m.peak_device_bytes}, {"gpu_load", m.gpu_load},
      {"output_bytes", m.output_bytes}, {"load_avg", m.load_avg}};
  for (const auto& [name, v] : fields)
    if (!std::isfinite(v) || v < 0) return invalid_argument(std::string(name) + " must be >= 0");
  // Learnt as logs: a time or memory of 0 would be learnt as 10^-300 and
  // squeeze every other row into a sliver of the model's range.
  for (const auto& [name, v] : {std::pair<const char*, double>{"total_s", m.total_s},
                                {"per_frame_s", m.per_frame_s},
                                {"peak_host_bytes", m.peak_host_bytes}})
    if (!(v > 0))
      return invalid_argument(std::string(name) +
                              " must be > 0 (a job that ran took time and memory)");
  for (const auto& [name, field] : kMeasureNotes)  // NaN: not recorded
    if (std::isinf(m.*field) || m.*field < 0)
      return invalid_argument(std::string(name) + " must be >= 0 or empty");
  if (m.gpu_load > 1) return invalid_argument("gpu_load must be <= 1");
  if (m.total_s_runs.size() != m.per_frame_s_runs.size())
    return invalid_argument("total_s_runs and per_frame_s_runs must list as many runs");
  for (const auto& [name, runs] :
       {std::pair<const char*, const std::vector<double>*>{"total_s_runs", &m.total_s_runs},
        {"per_frame_s_runs", &m.per_frame_s_runs}})
    for (double v : *runs)
      if (!std::isfinite(v) || v <= 0) return invalid_argument(std::string(name) + " must be > 0");
  return Status::ok();
}

namespace {

// The row's fields by column name, as text (writing) or parsed (reading).
std::string cell(const JobRecord& r, const std::string& c) {
  const JobInputs& i = r.inputs;
  const JobMeasure& m = r.measure;
  auto n = [](double v) { return g::format_double(v); };
  auto u = [](uint64_t v) { return std::to_string(v); };
  if (c == "wall") return g::quote_csv(i.wall);
  if (c == "particles") return u(i.particles);
  if (c == "triangles") return u(i.triangles);
  if (c == "pieces") return n(i.pieces);
  if (c == "wall_cells") return n(i.wall_cells);
  if (c == "wall_area") return n(i.wall_area);
  if (c == "box_x") return n(i.box[0]);
  if (c == "box_y") return n(i.box[1]);
  if (c == "box_z") return n(i.box[2]);
  if (c == "r_min") return n(i.r_min);
  if (c == "r_max") return n(i.r_max);
  if (c == "method") return i.method;
  if (c == "placement") return i.placement;
  if (c == "release_s") return n(i.release_s);
  if (c == "particle_contacts") return i.particle_contacts ? "1" : "0";
  if (c == "friction") return n(i.friction);
  if (c == "gravity") return n(i.gravity);
  if (c == "duration") return n(i.duration);
  if (c == "fps") return n(i.fps);
  if (c == "frames") return u(i.frames);
  if (c == "step_s") return n(i.step_s);
  if (c == "steps_per_frame") return u(i.steps_per_frame);
  if (c == "steps") return u(i.steps);
  if (c == "render_width") return std::to_string(i.render_width);
  if (c == "render_height") return std::to_string(i.render_height);
  if (c == "formats") return i.formats;
  if (c == "backend") return i.backend;
  if (c == "device") return g::quote_csv(i.device);
  if (c == "threads") return std::to_string(i.threads);
  if (c == "total_s") return n(m.total_s);
  if (c == "prepare_s") return n(m.prepare_s);
  if (c == "simulate_s") return n(m.simulate_s);
  if (c == "render_s") return n(m.render_s);
  if (c == "per_frame_s") return n(m.per_frame_s);
  if (c == "peak_host_bytes") return n(m.peak_host_bytes);
  if (c == "peak_device_bytes") return n(m.peak_device_bytes);
  if (c == "gpu_load") return n(m.gpu_load);
  if (c == "output_bytes") return n(m.output_bytes);
  if (c == "steps_taken") return u(m.steps_taken);
  if (c == "load_avg") return n(m.load_avg);
  auto note = [&](double v) { return std::isnan(v) ? std::string() : n(v); };
  for (const auto& [name, field] : kMeasureNotes)
    if (c == name) return note(m.*field);
  for (const auto& [name, field] : kInputNotes)
    if (c == name) return note(i.*field);
  auto runs = [&](const std::vector<double>& v) {
    std::string out;
    for (double t : v) out += (out.empty() ? "" : ";") + n(t);
    return out;
  };
  if (c == "total_s_runs") return runs(m.total_s_runs);
  if (c == "per_frame_s_runs") return runs(m.per_frame_s_runs);
  return "";
}

// Reads one field into the row; false with *what (the expected form) when it does not parse.
bool read_cell(JobRecord* r, const std::string& c, const std::string& v, std::string* what) {
  JobInputs& i = r->inputs;
  JobMeasure& m = r->measure;
  auto num = [&](double* out) {
    *what = "a finite number";
    return g::parse_double(v, out);
  };
  auto cnt = [&](uint64_t* out) {
    *what = "a whole number >= 0";
    int64_t x = 0;
    if (!g::parse_int(v, &x) || x < 0) return false;
    *out = uint64_t(x);
    return true;
  };
  auto small = [&](int* out) {
    *what = "a whole number >= 0";
    int64_t x = 0;
    if (!g::parse_int(v, &x) || x < 0 || x > (int64_t(1) << 30)) return false;
    *out = int(x);
    return true;
  };
  if (c == "wall") return i.wall = v, true;
  if (c == "particles") return cnt(&i.particles);
  if (c == "triangles") return cnt(&i.triangles);
  if (c == "pieces") return num(&i.pieces);
  if (c == "wall_cells") return num(&i.wall_cells);
  if (c == "wall_area") return num(&i.wall_area);
  if (c == "box_x") return num(&i.box[0]);
  if (c == "box_y") return num(&i.box[1]);
  if (c == "box_z") return num(&i.box[2]);
  if (c == "r_min") return num(&i.r_min);
  if (c == "r_max") return num(&i.r_max);
  if (c == "method") return i.method = v, true;
  if (c == "placement") return i.placement = v, true;
  if (c == "release_s") return num(&i.release_s);
  if (c == "particle_contacts") {
    *what = "0 or 1";
    if (v != "0" && v != "1") return false;
    i.particle_contacts = v == "1";
    return true;
  }
  if (c == "friction") return num(&i.friction);
  if (c == "gravity") return num(&i.gravity);
  if (c == "duration") return num(&i.duration);
  if (c == "fps") return num(&i.fps);
  if (c == "frames") return cnt(&i.frames);
  if (c == "step_s") return num(&i.step_s);
  if (c == "steps_per_frame") return cnt(&i.steps_per_frame);
  if (c == "steps") return cnt(&i.steps);
  if (c == "render_width") return small(&i.render_width);
  if (c == "render_height") return small(&i.render_height);
  if (c == "formats") return i.formats = v, true;
  if (c == "backend") return i.backend = v, true;
  if (c == "device") return i.device = v, true;
  if (c == "threads") return small(&i.threads);
  if (c == "total_s") return num(&m.total_s);
  if (c == "prepare_s") return num(&m.prepare_s);
  if (c == "simulate_s") return num(&m.simulate_s);
  if (c == "render_s") return num(&m.render_s);
  if (c == "per_frame_s") return num(&m.per_frame_s);
  if (c == "peak_host_bytes") return num(&m.peak_host_bytes);
  if (c == "peak_device_bytes") return num(&m.peak_device_bytes);
  if (c == "gpu_load") return num(&m.gpu_load);
  if (c == "output_bytes") return num(&m.output_bytes);
  if (c == "steps_taken") return cnt(&m.steps_taken);
  if (c == "load_avg") return num(&m.load_avg);
  auto note = [&](double* out) {  // empty: not recorded
    if (v.empty()) return *out = JobMeasure::kNotRecorded, true;
    return num(out);
  };
  for (const auto& [name, field] : kMeasureNotes)
    if (c == name) return note(&(m.*field));
  for (const auto& [name, field] : kInputNotes)
    if (c == name) return note(&(i.*field));
  auto runs = [&](std::vector<double>* out) {  // empty: the row is one run
    *what = "numbers joined by ';'";
    out->clear();
    if (v.empty()) return true;
    std::stringstream ss(v);
    std::string part;
    while (std::getline(ss, part, ';')) {
      double t = 0;
      if (!g::parse_double(g::trim(part), &t)) return false;
      out->push_back(t);
    }
    return true;
  };
  if (c == "total_s_runs") return runs(&m.total_s_runs);
  if (c == "per_frame_s_runs") return runs(&m.per_frame_s_runs);
  *what = "a known column";
  return false;
}

bool same_or_both_nan(double a, double b) { return a == b || (std::isnan(a) && std::isnan(b)); }

bool same_inputs(const JobInputs& a, const JobInputs& b) {
  return a.wall == b.wall && a.particles == b.particles && a.triangles == b.triangles &&
         a.pieces == b.pieces && a.wall_cells == b.wall_cells &&
         std::all_of(
             std::begin(kInputNotes), std::end(kInputNotes),
             [&](const auto& note) { return same_or_both_nan(a.*note.second, b.*note.second); }) &&
         a.wall_area == b.wall_area && a.box[0] == b.box[0] && a.box[1] == b.box[1] &&
         a.box[2] == b.box[2] && a.r_min == b.r_min && a.r_max == b.r_max && a.method == b.method &&
         a.placement == b.placement && a.release_s == b.release_s &&
         a.particle_contacts == b.particle_contacts && a.friction == b.friction &&
         a.gravity == b.gravity && a.duration == b.duration && a.fps == b.fps &&
         a.frames == b.frames && a.step_s == b.step_s && a.steps_per_frame == b.steps_per_frame &&
         a.steps == b.steps && a.render_width == b.render_width &&
         a.render_height == b.render_height && a.formats == b.formats && a.backend == b.backend &&
         a.device == b.device && a.threads == b.threads;
}

}  // namespace

Expected<JobMeasure> job_measure_from_manifest(const std::string& result_json,
                                               std::string* backend) {
  using nlohmann::json;
  const json r = json::parse(result_json, nullptr, false);
  if (!r.is_object() || !r.contains("cost"))
    return backend_error("the job's result.json is not a manifest with a cost");
  // A run resumed from a checkpoint measured its last attempt's time over the
  // whole run's frames and steps: no cost to learn from.
  if (r.value("resumed_from_frame", uint64_t(0)) > 0)
    return invalid_argument("the job resumed from a checkpoint: its cost covers its last attempt only");
  JobMeasure m;
  try {
    const json& c = r.at("cost");
    m.total_s = c.at("total_s").get<double>();
    m.prepare_s = c.at("prepare_s").get<double>();
    m.simulate_s = c.at("simulate_s").get<double>();
    m.render_s = c.at("render_s").get<double>();
    const double frames = c.at("frames").get<double>();
    if (!(frames > 0))
      return invalid_argument("the job wrote no frame: no cost per frame to learn from");
    m.per_frame_s = (m.simulate_s + m.render_s) / frames;
    m.peak_host_bytes = c.at("peak_host_bytes").get<double>();
    m.peak_device_bytes = c.at("peak_device_bytes").get<double>();
    // The engine's share of the simulation, as a share of the whole job.
    m.gpu_load = m.total_s > 0 ? std::min(1.0, c.at("gpu_busy_fraction").get<double>() *
                                                   m.simulate_s / m.total_s)
                               : 0.0;
    m.steps_taken = c.at("steps").get<uint64_t>();
    for (const auto& [name, field] : kMeasureNotes)
      m.*field = c.value(name, JobMeasure::kNotRecorded);
    double bytes = 0;
    for (const json& a : r.at("artifacts")) bytes += a.at("bytes").get<double>();
    m.output_bytes = bytes;
    if (backend) *backend = r.value("backend", std::string());
  } catch (const std::exception& e) {
    return backend_error(std::string("result.json: ") + e.what());
  }
  return m;
}

Expected<std::vector<JobRecord>> parse_job_log(const std::string& text) {
  auto recs = g::split_csv(text);
  if (!recs) return recs.status();
  if (recs->empty()) return parse_error("line 1: empty job log, no header line");
  const g::CsvRecord& header = recs->front();
  std::map<std::string, size_t> where;
  for (size_t c = 0; c < header.fields.size(); ++c) {
    const std::string name = g::trim(header.fields[c]);
    if (where.count(name))
      return parse_error("line " + std::to_string(header.line) + ", column " +
                         std::to_string(c + 1) + ": duplicate column '" + name + "'");
    where[name] = c;
  }
  const auto& cols = job_log_columns();
  constexpr size_t kAbsent = size_t(-1);
  std::vector<size_t> at;
  const auto& optional = job_log_optional_columns();
  for (const std::string& name : cols) {
    auto it = where.find(name);
    if (it == where.end() && std::find(optional.begin(), optional.end(), name) != optional.end()) {
      at.push_back(kAbsent);
      continue;
    }
    if (it == where.end())
      return parse_error("line " + std::to_string(header.line) + ": missing column '" + name +
                         "' (a job log; see docs/gvm.md \"Job log format\")");
    at.push_back(it->second);
  }
  std::vector<JobRecord> rows;
  for (size_t r = 1; r < recs->size(); ++r) {
    const g::CsvRecord& rec = (*recs)[r];
    const std::string line = "line " + std::to_string(rec.line);
    if (rec.fields.size() != header.fields.size())
      return parse_error(line + ": " + std::to_string(rec.fields.size()) +
                         " fields, the header has " + std::to_string(header.fields.size()));
    JobRecord row;
    for (size_t k = 0; k < cols.size(); ++k) {
      if (at[k] == kAbsent) continue;  // an optional column this log lacks: not recorded
      const std::string v = g::trim(rec.fields[at[k]]);
      std::string what;
      if (!read_cell(&row, cols[k], v, &what))
        return parse_error(line + ", column " + std::to_string(at[k] + 1) + " (" + cols[k] +
                           "): expected " + what + ", got '" + v + "'");
    }
    Status s = validate(row.inputs);
    if (s) s = validate(row.measure);
    if (!s) return parse_error(line + ": " + s.message());
    rows.push_back(std::move(row));
  }
  return rows;
}

std::string job_log_header() {
  const auto& cols = job_log_columns();
  std::string out;
  for (size_t k = 0; k < cols.size(); ++k) out += (k ? "," : "") + cols[k];
  return out;
}

std::string format_job_log_row(const JobRecord& r) {
  const auto& cols = job_log_columns();
  std::string out;
  for (size_t k = 0; k < cols.size(); ++k) out += (k ? "," : "") + cell(r, cols[k]);
  return out;
}

std::string format_job_log(const std::vector<JobRecord>& rows) {
  std::string out = job_log_header() + "\n";
  for (const JobRecord& r : rows) out += format_job_log_row(r) + "\n";
  return out;
}

Expected<std::vector<JobRecord>> read_job_log(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return open_failure(path, "cannot open job log '" + path + "'");
  std::ostringstream ss;
  ss << in.rdbuf();
  auto rows = parse_job_log(ss.str());
  if (!rows) return Status(rows.status().code(), path + ": " + rows.status().message());
  return rows;
}

Status write_job_log(const std::string& path, const std::vector<JobRecord>& rows) {
  return write_file_atomic(path, format_job_log(rows));
}

std::vector<JobRecord> merge_job_repeats(const std::vector<JobRecord>& rows) {
  std::vector<JobRecord> out;
  std::vector<std::vector<JobMeasure>> repeats;  // out[i]'s rows
  for (const JobRecord& r : rows) {
    auto it = std::find_if(out.begin(), out.end(),
                           [&](const JobRecord& o) { return same_inputs(o.inputs, r.inputs); });
    if (it == out.end()) {
      out.push_back(r);
      repeats.push_back({r.measure});
    } else {
      repeats[size_t(it - out.begin())].push_back(r.measure);
    }
  }
  for (size_t i = 0; i < out.size(); ++i) {
    const std::vector<JobMeasure>& runs = repeats[i];
    if (runs.size() < 2) continue;
    JobMeasure& m = out[i].measure;
    auto median = [&](double JobMeasure::*field) {
      std::vector<double> v;
      for (const JobMeasure& run : runs) v.push_back(run.*field);
      return median_of(std::move(v));
    };
    auto largest = [&](double JobMeasure::*field) {
      double most = 0;
      for (const JobMeasure& run : runs) most = std::max(most, run.*field);
      return most;
    };
    for (double JobMeasure::*time : {&JobMeasure::prepare_s, &JobMeasure::simulate_s,
                                     &JobMeasure::render_s, &JobMeasure::gpu_load})
      m.*time = median(time);
    for (double JobMeasure::*peak :
         {&JobMeasure::peak_host_bytes, &JobMeasure::peak_device_bytes, &JobMeasure::output_bytes})
      m.*peak = largest(peak);
    // Every run's total and time per frame (a merged row's own runs, or the row
    // itself), and their medians.
    std::vector<double> totals, per_frame;
    auto add = [](std::vector<double>* to, const std::vector<double>& merged, double own) {
      if (merged.empty()) to->push_back(own);
      to->insert(to->end(), merged.begin(), merged.end());
    };
    for (const JobMeasure& run : runs) {
      add(&totals, run.total_s_runs, run.total_s);
      add(&per_frame, run.per_frame_s_runs, run.per_frame_s);
    }
    m.total_s = median_of(totals);
    m.per_frame_s = median_of(per_frame);
    m.total_s_runs = std::move(totals);
    m.per_frame_s_runs = std::move(per_frame);
  }
  return out;
}

LogKind log_kind(const std::string& text) {
  auto recs = g::split_csv(text.substr(0, text.find('\n') + 1));
  if (!recs || recs->empty()) return LogKind::kUnknown;
  bool steps_per_frame = false, traversal = false, time_per_frame = false;
  for (const std::string& f : recs->front().fields) {
    const std::string c = g::trim(f);
    steps_per_frame = steps_per_frame || c == "steps_per_frame";
    traversal = traversal || c == "traversal";
    time_per_frame = time_per_frame || c == "time_per_frame_s";
  }
  if (steps_per_frame) return LogKind::kJob;
  if (traversal && time_per_frame) return LogKind::kDetection;
  return LogKind::kUnknown;
}

const char* to_string(LogKind k) {
  return k == LogKind::kJob ? "job" : k == LogKind::kDetection ? "detection" : "unknown";
}

}  // namespace collido::job
