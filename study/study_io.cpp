// The study's files: two CSV tables (what the chart script reads) and one
// JSON document with both tables and the machine they were measured on. Each
// row is built once, as an ordered JSON object, and written both ways.
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "study/study.h"

namespace collido::study {
namespace {

using Row = nlohmann::ordered_json;

// A measured number, or null where there is none to give (JSON has no infinity).
Row measured(double v, bool present = true) { return present && std::isfinite(v) ? Row(v) : Row(nullptr); }

Row row_of(const DetectRow& r) {
  return {{"backend", r.backend}, {"scene", r.scene}, {"triangles", r.triangles},
          {"placement", r.placement}, {"particles", r.particles}, {"method", r.method},
          {"traversal", r.traversal}, {"grid_factor", r.grid_factor}, {"grid_length", r.grid_length},
          {"precision", r.precision}, {"triangles_used", r.triangles_used}, {"prepare_ms", r.prepare_ms},
          {"frame_ms", r.frame_ms},
          {"frame_ms_other_pass", measured(r.frame_ms_other_pass, r.frame_ms_other_pass > 0)},
          {"frame_ms_choice", measured(r.frame_ms_choice, r.frame_ms_choice > 0)},
          {"extra_bytes_per_particle", r.extra_bytes_per_particle},
          {"contacts", r.contacts}, {"missed", r.missed}, {"invented", r.invented},
          {"max_distance_error", r.max_distance_error}, {"band_pairs", r.band_pairs},
          {"verdict", r.verdict}, {"auto", r.is_auto}, {"note", r.note}};
}

Row row_of(const DynamicsRow& r) {
  return {{"backend", r.backend}, {"scene", r.scene}, {"method", r.method}, {"dt_factor", r.dt_factor},
          {"speed_factor", r.speed_factor}, {"particle_contacts", r.particle_contacts}, {"dt", r.dt},
          {"steps", r.steps}, {"trajectory_error", measured(r.trajectory_error)},
          {"energy_drift", measured(r.energy_drift)},
          {"restitution_error", measured(r.restitution_error, r.restitution_error >= 0)},
          {"friction_error", measured(r.friction_error, r.friction_error >= 0)}, {"escaped", r.escaped},
          {"tunnelled", r.tunnelled}, {"invalid", r.invalid}, {"warnings", r.warnings},
          {"verdict", r.verdict}};
}

// One CSV field: null empty, booleans 1/0, numbers to 6 digits, text quoted
// (RFC 4180) when it holds a comma, a quote or a line break.
std::string csv_field(const Row& v) {
  if (v.is_null()) return "";
  if (v.is_boolean()) return v.get<bool>() ? "1" : "0";
  if (v.is_number_integer() || v.is_number_unsigned()) return v.dump();
  if (v.is_number()) {
    char b[32];
    std::snprintf(b, sizeof b, "%.6g", v.get<double>());
    return b;
  }
  const std::string s = v.get<std::string>();
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

// The table as CSV (header from the first row's keys) and as a JSON array.
template <class T>
std::string table(const std::vector<T>& rows, Row* json, const Row& empty_header) {
  std::ostringstream csv;
  const Row first = rows.empty() ? empty_header : row_of(rows.front());
  bool comma = false;
  for (const auto& kv : first.items()) csv << (comma ? "," : "") << kv.key(), comma = true;
  csv << '\n';
  *json = Row::array();
  for (const T& r : rows) {
    const Row row = row_of(r);
    comma = false;
    for (const auto& kv : row.items()) csv << (comma ? "," : "") << csv_field(kv.value()), comma = true;
    csv << '\n';
    json->push_back(row);
  }
  return csv.str();
}

}  // namespace

Status write_study(const std::string& dir, const std::vector<DetectRow>* detect,
                   const std::vector<DynamicsRow>* dynamics, const std::string& machine) {
  // The half not run keeps its rows from the study.json already there.
  Row doc = {{"machine", machine}, {"detect", Row::array()}, {"dynamics", Row::array()}};
  if (!detect || !dynamics) {
    std::ifstream in(dir + "/study.json");
    const Row old = in ? Row::parse(in, nullptr, /*allow_exceptions=*/false) : Row();
    for (const char* half : {"detect", "dynamics"})
      if (old.is_object() && old.contains(half) && old[half].is_array()) doc[half] = old[half];
  }
  if (detect) {
    Row rows;
    const std::string d = table(*detect, &rows, row_of(DetectRow{}));
    if (Status s = write_file_atomic(dir + "/study_detect.csv", d); !s) return s;
    doc["detect"] = rows;
  }
  if (dynamics) {
    Row rows;
    const std::string y = table(*dynamics, &rows, row_of(DynamicsRow{}));
    if (Status s = write_file_atomic(dir + "/study_dynamics.csv", y); !s) return s;
    doc["dynamics"] = rows;
  }
  return write_file_atomic(dir + "/study.json", doc.dump(1) + "\n");
}

}  // namespace collido::study
