// The detection half of the study: every method x traversal x grid length x
// precision on wall1, wall2 and the third-party meshes, with particles uniform
// in the box and within 1e-4 r of touching, timed and compared pair by pair
// with the double-precision reference at zero tolerance.
#include <algorithm>
#include <cmath>
#include <filesystem>

#include "sim/accuracy.h"
#include "sim/auto_choice.h"
#include "sim/particles.h"
#include "sim/shapes.h"
#include "study/study.h"

namespace collido::study {
namespace {

struct Scene {
  std::string name;
  sim::TriangleMesh mesh;
  double r_lo, r_hi;
};

Expected<std::vector<Scene>> study_scenes(const StudyOptions& o) {
  std::vector<Scene> out;
  // The paper's walls with its radii (r_max = 1).
  for (const char* wall : {"wall1", "wall2"}) {
    auto mesh = sim::make_shape(wall);
    if (!mesh) return mesh.status();
    out.push_back({wall, std::move(*mesh), 0.5, 1.0});
  }
  std::vector<std::string> files;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(o.mesh_dir, ec))
    if (e.path().extension() == ".stl") files.push_back(e.path().filename().string());
  if (ec) return invalid_argument("study: cannot read the mesh folder " + o.mesh_dir + " (" + ec.message() + ")");
  std::sort(files.begin(), files.end());
  for (const auto& f : files) {
    if (o.quick && f != "teapot_trimesh.stl") continue;  // one third-party mesh is enough for a quick look
    auto mesh = sim::load_stl(o.mesh_dir + "/" + f);
    if (!mesh) return mesh.status();
    // Radii on the mesh's own scale: 2 % of its diagonal at most, so triangle
    // sizes against the radius vary from mesh to mesh as real files do.
    const double r = 0.02 * sim::length(sim::mesh_bounds(*mesh).extent());
    out.push_back({f.substr(0, f.size() - 4), std::move(*mesh), 0.5 * r, r});
  }
  return out;
}

// Times a setting as the automatic choice does (sim::fastest_frame_ms), so the
// two measure alike: the fastest of at least `repeats` frames and 20 ms.
Status time_frames(sim::Detector& det, int repeats, double* ms, uint64_t* band) {
  det.set_frame_options(false, false);
  sim::DetectResult r;
  if (Status s = sim::fastest_frame_ms(det, repeats, ms, &r); !s) return s;
  *band = r.band_pairs;
  return Status::ok();
}

std::string verdict_of(const sim::ContactDiff& d) {
  if (d.missed + d.borderline > 0) return "loses_contacts";
  if (d.invented > 0) return "invents_contacts";
  return "exact";
}

}  // namespace

Status run_detect_study(const StudyOptions& o, std::vector<DetectRow>* rows) {
  auto scenes = study_scenes(o);
  if (!scenes) return scenes.status();
  const bool cuda = o.backend == sim::Backend::kCuda;
  // Quick: one count, and the grid sweep only for the methods auto may choose.
  std::vector<size_t> counts = o.quick ? std::vector<size_t>{10000}
                                       : std::vector<size_t>{1000, 10000, 100000};
  if (!o.quick && cuda) counts.push_back(1000000);
  if (o.max_particles > 0) {
    counts.erase(std::remove_if(counts.begin(), counts.end(), [&](size_t n) { return n > o.max_particles; }),
                 counts.end());
    if (counts.empty()) counts.push_back(o.max_particles);
  }
  const int repeats = o.quick ? 5 : 9;
  const sim::Method methods[] = {sim::Method::kBin, sim::Method::kGravity, sim::Method::kCircumcircle,
                                 sim::Method::kMidpoint4, sim::Method::kBvh};
  for (const Scene& sc : *scenes) {
    if (!o.scenes.empty() && std::find(o.scenes.begin(), o.scenes.end(), sc.name) == o.scenes.end()) continue;
    // The particle sets and the reference's contacts, once per scene.
    struct Set {
      std::string placement;
      size_t n;
      sim::Particles p;
      std::vector<sim::Contact> ref;
    };
    std::vector<Set> sets;
    for (const char* placement : {"uniform", "near"})
      for (size_t n : counts) {
        Set s{placement, n, {}, {}};
        s.p = std::string(placement) == "uniform"
                  ? sim::random_particles(n, sim::mesh_bounds(sc.mesh), sc.r_lo, sc.r_hi, 17)
                  : sim::particles_touching(sc.mesh, n, sc.r_lo, sc.r_hi, 1e-4, 17);
        sim::DetectConfig rc;
        rc.method = sim::Method::kReference;
        rc.r_max = sc.r_hi;
        rc.pool = o.pool;
        auto ref = sim::Detector::create(sc.mesh, rc, n);
        if (!ref) return ref.status();
        if (Status st = (*ref)->set_particles(s.p); !st) return st;
        sim::DetectResult rr;
        if (Status st = (*ref)->detect(&rr); !st) return st;
        DetectRow row;
        row.backend = "cpu", row.scene = sc.name, row.placement = placement;
        row.triangles = row.triangles_used = sc.mesh.triangles.size();
        row.particles = n, row.method = "reference", row.traversal = "particle", row.precision = "double";
        row.prepare_ms = (*ref)->info().prepare_ms, row.frame_ms = rr.times.frame_ms;
        row.contacts = rr.contact_count, row.verdict = "exact";
        rows->push_back(row);
        s.ref = std::move(rr.contacts);
        sets.push_back(std::move(s));
      }
    const size_t first_row = rows->size();
    for (sim::Method m : methods)
      for (sim::Traversal tr : {sim::Traversal::kParticle, sim::Traversal::kWall})
        for (double gf : sim::kAutoGridFactors) {
          if (o.quick && gf != 2 && (m == sim::Method::kGravity || m == sim::Method::kMidpoint4)) continue;
          // A method without a grid (the tree) walks from the particles: one setting, grid 0.
          if (!sim::uses_grid(m)) {
            if (tr == sim::Traversal::kWall || gf != sim::kAutoGridFactors[0]) continue;
            gf = 0;
          }
          sim::DetectConfig cfg;
          cfg.method = m, cfg.traversal = tr, cfg.backend = o.backend, cfg.pool = o.pool;
          cfg.r_max = sc.r_hi, cfg.grid_length = gf * sc.r_hi;
          cfg.precision = sim::Precision::kExact, cfg.time_stages = false;
          auto det = sim::Detector::create(sc.mesh, cfg, counts.back());
          DetectRow base;
          base.backend = sim::to_string(o.backend), base.scene = sc.name;
          base.triangles = sc.mesh.triangles.size(), base.method = sim::to_string(m);
          base.traversal = sim::to_string(tr), base.grid_factor = gf, base.grid_length = cfg.grid_length;
          if (!det) {
            for (const Set& s : sets)
              for (const char* prec : {"exact", "float"}) {
                DetectRow row = base;
                row.placement = s.placement, row.particles = s.n, row.precision = prec;
                row.verdict = "failed", row.note = det.status().message();
                rows->push_back(row);
              }
            continue;
          }
          const sim::PrepareInfo& info = (*det)->info();
          base.triangles_used = info.triangles_used, base.prepare_ms = info.prepare_ms;
          const double inputs = 16.0 * double(counts.back()) + 36.0 * double(info.triangles_original);
          base.extra_bytes_per_particle = (double(info.device_bytes) - inputs) / double(counts.back());
          for (const Set& s : sets) {
            if (Status st = (*det)->set_particles(s.p); !st) return st;
            for (sim::Precision prec : {sim::Precision::kExact, sim::Precision::kFloat}) {
              (void)(*det)->set_precision(prec);
              DetectRow row = base;
              row.placement = s.placement, row.particles = s.n, row.precision = sim::to_string(prec);
              if (Status st = time_frames(**det, repeats, &row.frame_ms, &row.band_pairs); !st) return st;
              sim::DetectResult got;
              (*det)->set_frame_options(true, false);
              if (Status st = (*det)->detect(&got); !st) return st;
              const sim::ContactDiff d = sim::compare_contacts(sc.mesh, s.p, s.ref, got.contacts, 0.0);
              row.contacts = s.ref.size(), row.missed = d.missed + d.borderline, row.invented = d.invented;
              row.max_distance_error = d.max_distance_error / sc.r_hi;
              row.verdict = verdict_of(d);
              rows->push_back(row);
            }
            (void)(*det)->set_precision(sim::Precision::kExact);
          }
          if (o.progress)
            o.progress("  " + sc.name + ": " + sim::to_string(m) + "/" + sim::to_string(tr) +
                       (gf > 0 ? " grid " + std::to_string(gf).substr(0, 3) + " r_max" : ""));
        }
    // What the automatic choice picks for each set, marked on the matching row.
    for (const Set& s : sets) {
      sim::DetectConfig base;
      base.backend = o.backend, base.pool = o.pool, base.r_max = sc.r_hi;
      auto choice = sim::choose_detection(sc.mesh, s.p, base, sim::AutoRequest{});
      if (!choice) return choice.status();
      for (size_t k = first_row; k < rows->size(); ++k) {
        DetectRow& r = (*rows)[k];
        if (r.placement == s.placement && r.particles == s.n && r.precision == "exact" &&
            r.method == sim::to_string(choice->method) && r.traversal == sim::to_string(choice->traversal) &&
            std::fabs(r.grid_length - choice->grid_length) <= 1e-9 * choice->grid_length)
          r.is_auto = true;
      }
    }
    if (o.progress)
      o.progress("detection: " + sc.name + " (" + std::to_string(sc.mesh.triangles.size()) + " triangles) done");
  }
  return Status::ok();
}

}  // namespace collido::study
