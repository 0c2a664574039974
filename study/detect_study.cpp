// The detection half of the study: every method x traversal x grid length x
// precision on wall1, wall2 and the third-party meshes, with particles uniform
// in the box and within 1e-4 r of touching, timed and compared pair by pair
// with the double-precision reference at zero tolerance.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>

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

std::string verdict_of(const sim::ContactDiff& d) {
  if (d.missed + d.borderline > 0) return "loses_contacts";
  if (d.invented > 0) return "invents_contacts";
  return "exact";
}

}  // namespace

Status run_detect_study(const StudyOptions& o, std::vector<DetectRow>* rows) {
  auto scenes = study_scenes(o);
  if (!scenes) return scenes.status();
  // A name that matches no scene is a mistake, not a study of nothing.
  for (const std::string& want : o.scenes)
    if (std::none_of(scenes->begin(), scenes->end(),
                     [&](const Scene& sc) { return sc.name == want; })) {
      std::string known;
      for (const Scene& sc : *scenes) known += (known.empty() ? "" : ", ") + sc.name;
      return invalid_argument("study: no detection scene '" + want + "' (" + known + ")");
    }
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
        // Its fastest warm frame, as every other setting's: a first frame alone
        // ran cold (0.76 ms for 10^3 particles on wall1, 0.50 for 10^4). Frames
        // again while they are cheap, within a second; a slow one (seconds
        // for the large meshes) is timed once, and its cold start is noise.
        double frame_ms = rr.times.frame_ms, spent_ms = frame_ms;
        for (int f = 1; f < sim::kAutoMinFrames && spent_ms < 1000; ++f) {
          sim::DetectResult again;
          if (Status st = (*ref)->detect(&again); !st) return st;
          frame_ms = std::min(frame_ms, again.times.frame_ms);
          spent_ms += again.times.frame_ms;
        }
        row.prepare_ms = (*ref)->info().prepare_ms, row.frame_ms = frame_ms;
        row.contacts = rr.contact_count, row.verdict = "exact";
        rows->push_back(row);
        s.ref = std::move(rr.contacts);
        sets.push_back(std::move(s));
      }
    // The settings, each prepared once for the scene's largest set.
    struct Setting {
      sim::DetectConfig cfg;
      DetectRow base;
      std::unique_ptr<sim::Detector> det;  // while its batch is measured; null: could not be prepared
    };
    std::vector<Setting> settings;
    for (sim::Method m : methods)
      for (sim::Traversal tr : {sim::Traversal::kParticle, sim::Traversal::kWall})
        for (double gf : sim::kAutoGridFactors) {
          if (o.quick && gf != 2 && (m == sim::Method::kGravity || m == sim::Method::kMidpoint4)) continue;
          // A method without a grid (the tree) walks from the particles: one setting, grid 0.
          if (!sim::uses_grid(m)) {
            if (tr == sim::Traversal::kWall || gf != sim::kAutoGridFactors[0]) continue;
            gf = 0;
          }
          Setting st;
          sim::DetectConfig& cfg = st.cfg;
          cfg.method = m, cfg.traversal = tr, cfg.backend = o.backend, cfg.pool = o.pool;
          cfg.r_max = sc.r_hi, cfg.grid_length = gf * sc.r_hi;
          cfg.precision = sim::Precision::kExact, cfg.time_stages = false;
          DetectRow& base = st.base;
          base.backend = sim::to_string(o.backend), base.scene = sc.name;
          base.triangles = sc.mesh.triangles.size(), base.method = sim::to_string(m);
          base.traversal = sim::to_string(tr), base.grid_factor = gf, base.grid_length = cfg.grid_length;
          settings.push_back(std::move(st));
        }
    // Settings timed together are held together. On the CPU that is all of
    // them (their timings drift with the machine's other work, so they share
    // the rounds). On the GPU, whose timings are steady, one method and
    // traversal at a time: 33 detectors of 10^6 particles touching wall2 hold
    // more than the H200's memory (the divided walls' pair buffers).
    std::vector<std::pair<size_t, size_t>> batches;  // [begin, end) of settings
    for (size_t i = 0; i < settings.size(); ++i) {
      const sim::DetectConfig& c = settings[i].cfg;
      if (i > 0 && (!cuda || (c.method == settings[i - 1].cfg.method &&
                              c.traversal == settings[i - 1].cfg.traversal)))
        batches.back().second = i + 1;
      else
        batches.push_back({i, i + 1});
    }
    const size_t first_row = rows->size();
    const sim::Precision precisions[] = {sim::Precision::kExact, sim::Precision::kFloat};
    for (const auto& [begin, end] : batches) {
      std::vector<sim::Detector*> dets;
      for (size_t i = begin; i < end; ++i) {
        Setting& st = settings[i];
        auto det = sim::Detector::create(sc.mesh, st.cfg, counts.back());
        if (det) {
          st.det = std::move(*det);
          const sim::PrepareInfo& info = st.det->info();
          st.base.triangles_used = info.triangles_used, st.base.prepare_ms = info.prepare_ms;
          const double inputs = 16.0 * double(counts.back()) + 36.0 * double(info.triangles_original);
          st.base.extra_bytes_per_particle = (double(info.device_bytes) - inputs) / double(counts.back());
          st.det->set_frame_options(false, false);
        } else {
          st.base.verdict = "failed", st.base.note = det.status().message();
        }
        dets.push_back(st.det.get());
      }
      for (const Set& s : sets) {
        for (sim::Detector* d : dets)
          if (d)
            if (Status e = d->set_particles(s.p); !e) return e;
        // Timing: the batch's settings in the same rounds (sim::fastest_frames_ms,
        // as the automatic choice times its candidates), so a slow spell of the
        // machine falls on all alike; and that twice per precision, passes
        // alternating exact, float, exact, float. The two passes bound what a
        // repeat of the study would measure (frame_ms and frame_ms_other_pass).
        std::vector<double> ms[2][2];  // [precision][pass]
        for (int pass = 0; pass < 2; ++pass)
          for (int p = 0; p < 2; ++p) {
            for (sim::Detector* d : dets)
              if (d) (void)d->set_precision(precisions[p]);
            std::vector<Status> status;
            sim::fastest_frames_ms(dets, sim::kAutoMinFrames, &ms[p][pass], &status);
            for (Status& e : status)
              if (!e) return e;
          }
        for (size_t i = begin; i < end; ++i) {
          Setting& st = settings[i];
          for (int p = 0; p < 2; ++p) {
            DetectRow row = st.base;
            row.placement = s.placement, row.particles = s.n, row.precision = sim::to_string(precisions[p]);
            if (!st.det) {
              rows->push_back(row);
              continue;
            }
            row.frame_ms = std::min(ms[p][0][i - begin], ms[p][1][i - begin]);
            row.frame_ms_other_pass = std::max(ms[p][0][i - begin], ms[p][1][i - begin]);
            (void)st.det->set_precision(precisions[p]);
            st.det->set_frame_options(true, false);
            sim::DetectResult got;
            if (Status e = st.det->detect(&got); !e) return e;
            st.det->set_frame_options(false, false);
            const sim::ContactDiff d = sim::compare_contacts(sc.mesh, s.p, s.ref, got.contacts, 0.0);
            row.contacts = s.ref.size(), row.missed = d.missed + d.borderline, row.invented = d.invented;
            row.band_pairs = got.band_pairs;
            row.max_distance_error = d.max_distance_error / sc.r_hi;
            row.verdict = verdict_of(d);
            rows->push_back(row);
          }
        }
        if (o.progress)
          o.progress("  " + sc.name + ": " + s.placement + ", " + std::to_string(s.n) + " particles, " +
                     std::to_string(end - begin) + " settings timed together (" + settings[begin].base.method +
                     (cuda ? "/" + settings[begin].base.traversal : std::string(" and the rest")) + ")");
      }
      for (size_t i = begin; i < end; ++i) settings[i].det.reset();  // before the next batch prepares
    }
    // What the automatic choice picks for each set, marked on the matching
    // row, and what it measured of each candidate, beside the study's passes.
    for (const Set& s : sets) {
      sim::DetectConfig base;
      base.backend = o.backend, base.pool = o.pool, base.r_max = sc.r_hi;
      auto choice = sim::choose_detection(sc.mesh, s.p, base, sim::AutoRequest{});
      if (!choice) return choice.status();
      auto same_setting = [&](const DetectRow& r, sim::Method m, sim::Traversal t, double grid) {
        return r.placement == s.placement && r.particles == s.n && r.precision == "exact" &&
               r.method == sim::to_string(m) && r.traversal == sim::to_string(t) &&
               std::fabs(r.grid_length - grid) <= 1e-9 * grid;
      };
      for (size_t k = first_row; k < rows->size(); ++k) {
        DetectRow& r = (*rows)[k];
        if (same_setting(r, choice->method, choice->traversal, choice->grid_length))
          r.is_auto = true, r.note = choice->reason;
        for (const sim::AutoCandidate& c : choice->candidates)
          if (c.error.empty() && same_setting(r, c.method, c.traversal, c.grid_length))
            r.frame_ms_choice = c.frame_ms;
      }
    }
    if (o.progress)
      o.progress("detection: " + sc.name + " (" + std::to_string(sc.mesh.triangles.size()) + " triangles) done");
  }
  return Status::ok();
}

}  // namespace collido::study
