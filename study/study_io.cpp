// The study's files: two CSV tables (what the chart script reads) and one
// JSON document with both tables and the machine they were measured on.
#include <cstdio>
#include <sstream>

#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "study/study.h"

namespace collido::study {
namespace {

std::string num(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

}  // namespace

Status write_study(const std::string& dir, const std::vector<DetectRow>& detect,
                   const std::vector<DynamicsRow>& dynamics, const std::string& machine) {
  std::ostringstream d;
  d << "backend,scene,triangles,placement,particles,method,traversal,grid_factor,grid_length,precision,"
       "triangles_used,prepare_ms,frame_ms,extra_bytes_per_particle,contacts,missed,invented,"
       "max_distance_error,band_pairs,verdict,auto\n";
  nlohmann::json jd = nlohmann::json::array();
  for (const DetectRow& r : detect) {
    d << r.backend << ',' << r.scene << ',' << r.triangles << ',' << r.placement << ',' << r.particles << ','
      << r.method << ',' << r.traversal << ',' << num(r.grid_factor) << ',' << num(r.grid_length) << ','
      << r.precision << ',' << r.triangles_used << ',' << num(r.prepare_ms) << ',' << num(r.frame_ms) << ','
      << num(r.extra_bytes_per_particle) << ',' << r.contacts << ',' << r.missed << ',' << r.invented << ','
      << num(r.max_distance_error) << ',' << r.band_pairs << ',' << r.verdict << ',' << (r.is_auto ? 1 : 0)
      << '\n';
    jd.push_back({{"backend", r.backend}, {"scene", r.scene}, {"triangles", r.triangles},
                  {"placement", r.placement}, {"particles", r.particles}, {"method", r.method},
                  {"traversal", r.traversal}, {"grid_factor", r.grid_factor}, {"grid_length", r.grid_length},
                  {"precision", r.precision}, {"triangles_used", r.triangles_used},
                  {"prepare_ms", r.prepare_ms}, {"frame_ms", r.frame_ms},
                  {"extra_bytes_per_particle", r.extra_bytes_per_particle}, {"contacts", r.contacts},
                  {"missed", r.missed}, {"invented", r.invented},
                  {"max_distance_error", r.max_distance_error}, {"band_pairs", r.band_pairs},
                  {"verdict", r.verdict}, {"auto", r.is_auto}, {"note", r.note}});
  }
  std::ostringstream y;
  y << "backend,scene,method,dt_factor,speed_factor,particle_contacts,dt,steps,trajectory_error,energy_drift,"
       "restitution_error,friction_error,escaped,tunnelled,invalid,warnings,verdict\n";
  nlohmann::json jy = nlohmann::json::array();
  for (const DynamicsRow& r : dynamics) {
    auto opt = [](double v) { return v < 0 ? std::string() : num(v); };
    y << r.backend << ',' << r.scene << ',' << r.method << ',' << num(r.dt_factor) << ','
      << num(r.speed_factor) << ',' << (r.particle_contacts ? 1 : 0) << ',' << num(r.dt) << ',' << r.steps
      << ',' << num(r.trajectory_error) << ',' << num(r.energy_drift) << ',' << opt(r.restitution_error)
      << ',' << opt(r.friction_error) << ',' << r.escaped << ',' << r.tunnelled << ',' << r.invalid << ','
      << r.warnings << ',' << r.verdict << '\n';
    nlohmann::json row = {{"backend", r.backend}, {"scene", r.scene}, {"method", r.method},
                          {"dt_factor", r.dt_factor}, {"speed_factor", r.speed_factor},
                          {"particle_contacts", r.particle_contacts}, {"dt", r.dt}, {"steps", r.steps},
                          {"energy_drift", r.energy_drift}, {"escaped", r.escaped},
                          {"tunnelled", r.tunnelled}, {"invalid", r.invalid}, {"warnings", r.warnings},
                          {"verdict", r.verdict}};
    // JSON has no infinity: a run that blew up has no trajectory error to give.
    row["trajectory_error"] = std::isfinite(r.trajectory_error) ? nlohmann::json(r.trajectory_error) : nullptr;
    if (r.restitution_error >= 0) row["restitution_error"] = r.restitution_error;
    if (r.friction_error >= 0) row["friction_error"] = r.friction_error;
    if (!std::isfinite(r.energy_drift)) row["energy_drift"] = nullptr;
    jy.push_back(row);
  }
  const nlohmann::json doc = {{"machine", machine}, {"detect", jd}, {"dynamics", jy}};
  if (Status s = write_file_atomic(dir + "/study_detect.csv", d.str()); !s) return s;
  if (Status s = write_file_atomic(dir + "/study_dynamics.csv", y.str()); !s) return s;
  return write_file_atomic(dir + "/study.json", doc.dump(1) + "\n");
}

}  // namespace collido::study
