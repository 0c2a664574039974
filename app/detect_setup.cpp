#include "app/detect_setup.h"

#include <cmath>
#include <cstdio>
#include <sstream>

#include "job/wall_source.h"
#include "sim/octree.h"
#include "sim/parallel.h"
#include "sim/particles.h"

namespace collido::app {

int build_detect_setup(const ParsedArgs& args, const std::string& command, DetectSetup* out) {
  std::string err;
  out->wall_spec = args.get("wall", "wall1");
  auto wall = job::load_wall(out->wall_spec, &out->wall_report);
  if (!wall) {
    std::fprintf(stderr, "collidoscope %s: %s\n", command.c_str(), wall.status().message().c_str());
    return exit_code(wall.status());  // a missing file or a bad spec is bad input: 2
  }
  out->wall = std::move(*wall);

  const int64_t threads = args.get_int("threads", 0, &err);
  if (!err.empty()) return usage_error(command, err);
  if (threads < 0 || threads > 4096) return usage_error(command, "--threads must be in [0, 4096]");
  out->pool = std::make_unique<sim::ThreadPool>(static_cast<int>(threads));

  sim::DetectConfig& cfg = out->config;
  cfg.pool = out->pool.get();
  if (args.has("method") && !sim::parse_method(args.get("method"), &cfg.method))
    return usage_error(command,
                       "unknown --method '" + args.get("method") +
                           "' (gravity, circumcircle, midpoint4, bin, bvh, octree, reference)");
  if (args.has("traversal") && !sim::parse_traversal(args.get("traversal"), &cfg.traversal))
    return usage_error(command, "unknown --traversal '" + args.get("traversal") + "' (particle, wall)");
  if (args.has("precision") && !sim::parse_precision(args.get("precision"), &cfg.precision))
    return usage_error(command, "unknown --precision '" + args.get("precision") + "' (exact, float)");
  sim::Backend wanted = sim::Backend::kCpu;
  if (args.has("backend") && !sim::parse_backend(args.get("backend"), &wanted))
    return usage_error(command, "unknown --backend '" + args.get("backend") + "' (cpu, cuda)");
  cfg.backend = cfg.method == sim::Method::kReference ? sim::Backend::kCpu : sim::usable_backend(wanted, &out->backend_note);
  if (!out->backend_note.empty()) std::fprintf(stderr, "collidoscope %s: note: %s\n", command.c_str(), out->backend_note.c_str());
  cfg.grid_length = args.get_double("grid-length", 0, &err);
  if (!err.empty()) return usage_error(command, err);
  if (args.has("grid-length") && !(cfg.grid_length > 0))
    return usage_error(command, "--grid-length must be a positive length");

  // Particles: a count (random, reproducible) or a CSV file.
  const std::string pspec = args.get("particles", "");
  out->particles_spec = pspec;
  if (pspec.empty()) return kExitOk;
  double r_lo = args.get_double("radius", 1.0, &err), r_hi = r_lo;
  if (!err.empty()) return usage_error(command, err);
  if (args.has("radius-range")) {
    const std::string rr = args.get("radius-range");
    const auto colon = rr.find(':');
    char* e1 = nullptr;
    char* e2 = nullptr;
    if (colon == std::string::npos) return usage_error(command, "--radius-range expects A:B");
    std::string a = rr.substr(0, colon), b = rr.substr(colon + 1);
    r_lo = std::strtod(a.c_str(), &e1);
    r_hi = std::strtod(b.c_str(), &e2);
    if (e1 == a.c_str() || *e1 || e2 == b.c_str() || *e2) return usage_error(command, "--radius-range expects A:B, two numbers");
  }
  if (!(r_lo > 0) || !(r_hi >= r_lo) || !std::isfinite(r_hi))
    return usage_error(command, "radii must satisfy 0 < A <= B");
  const bool is_count = pspec.find_first_not_of("0123456789eE+-.") == std::string::npos;
  if (is_count) {
    const int64_t n = args.get_int("particles", 0, &err);
    if (!err.empty()) return usage_error(command, err);
    if (n <= 0 || n > 2'000'000'000) return usage_error(command, "--particles must be in [1, 2e9]");
    const int64_t seed = args.get_int("seed", 1, &err);
    if (!err.empty()) return usage_error(command, err);
    out->particles = sim::random_particles(static_cast<size_t>(n), sim::mesh_bounds(out->wall), r_lo, r_hi,
                                           static_cast<uint64_t>(seed));
    cfg.r_max = r_hi;
  } else {
    auto p = sim::load_particles_csv(pspec);
    if (!p) {
      std::fprintf(stderr, "collidoscope %s: %s\n", command.c_str(), p.status().message().c_str());
      return exit_code(p.status());
    }
    out->particles = std::move(*p);
    cfg.r_max = sim::max_radius(out->particles);
  }
  return kExitOk;
}

std::string json_escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '"' || c == '\\') o += '\\', o += c;
    else if (static_cast<unsigned char>(c) < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", c);
      o += buf;
    } else o += c;
  }
  return o;
}

std::string detect_summary_json(const DetectSetup& s, const sim::PrepareInfo& info, const sim::DetectResult& r) {
  std::ostringstream o;
  o.precision(6);
  const auto& t = r.times;
  o << "{\"wall\":\"" << json_escape(s.wall_spec) << "\",\"wall_format\":\"" << s.wall_report.format
    << "\",\"triangles_in_file\":" << s.wall_report.triangles_in
    << ",\"dropped_zero_area\":" << s.wall_report.dropped_zero_area
    << ",\"triangles_before_division\":" << info.triangles_original
    << ",\"triangles_after_division\":" << info.triangles_used
    << ",\"particles\":" << s.particles.size() << ",\"r_max\":" << s.config.r_max
    << ",\"method\":\"" << sim::to_string(s.config.method) << "\",\"traversal\":\""
    << sim::to_string(s.config.traversal) << "\",\"precision\":\""
    << sim::to_string(s.config.precision) << "\",\"backend\":\"" << sim::to_string(s.config.backend)
    << "\",\"grid_length\":" << info.grid_length << ",\"cells\":" << info.cells
    << ",\"buckets\":" << info.buckets << ",\"hashed_grid\":" << (info.hashed ? "true" : "false")
    << ",\"bin_entries\":" << info.bin_entries << ",\"tree_nodes\":" << info.bvh_nodes
    << ",\"tree_depth\":" << info.bvh_depth << ",\"octree_leaves\":" << info.octree_leaves
    << ",\"octree_entries\":" << info.octree_entries
    << ",\"octree_wide_entries\":" << info.octree_wide_entries
    << ",\"octree_long_leaves\":" << info.octree_long_leaves << ",\"contacts\":" << r.contact_count
    << ",\"colliding_particles\":" << r.colliding_particles << ",\"band_pairs\":" << r.band_pairs
    << ",\"area_error\":" << info.area_error << ",\"time_ms\":{\"prepare\":" << info.prepare_ms
    << ",\"hash\":" << t.hash_ms << ",\"sort\":" << t.sort_ms << ",\"cells\":" << t.cells_ms
    << ",\"traverse\":" << t.traverse_ms << ",\"finalize\":" << t.finalize_ms
    << ",\"frame\":" << t.frame_ms << ",\"download\":" << t.download_ms << "}";
  if (!s.backend_note.empty()) o << ",\"note\":\"" << json_escape(s.backend_note) << "\"";
  o << "}";
  return o.str();
}

std::string detect_summary_text(const DetectSetup& s, const sim::PrepareInfo& info, const sim::DetectResult& r) {
  std::ostringstream o;
  char line[256];
  std::snprintf(line, sizeof line, "wall        %s (%s): %zu triangles", s.wall_spec.c_str(),
                s.wall_report.format.c_str(), info.triangles_original);
  o << line;
  if (s.wall_report.dropped_zero_area) o << ", " << s.wall_report.dropped_zero_area << " zero-area dropped";
  o << "\n";
  std::snprintf(line, sizeof line, "method      %s, %s traversal, %s precision, %s; %zu triangles after division\n",
                sim::to_string(s.config.method), sim::to_string(s.config.traversal),
                sim::to_string(s.config.precision), sim::to_string(s.config.backend), info.triangles_used);
  o << line;
  if (info.bvh_nodes)  // the tree: no grid to describe
    std::snprintf(line, sizeof line, "particles   %zu, r_max %g; a tree of %llu nodes, %d levels deep\n",
                  s.particles.size(), s.config.r_max, static_cast<unsigned long long>(info.bvh_nodes),
                  info.bvh_depth);
  else if (info.octree_leaves)  // the octree: its cells, and the leaves they split into
    std::snprintf(line, sizeof line,
                  "particles   %zu, r_max %g; grid length %g, %llu cells%s, %llu split: %llu "
                  "leaves listing %llu (%llu of them over %u)\n",
                  s.particles.size(), s.config.r_max, info.grid_length,
                  static_cast<unsigned long long>(info.cells), info.hashed ? " (hashed)" : "",
                  static_cast<unsigned long long>(info.octree_splits),
                  static_cast<unsigned long long>(info.octree_leaves),
                  static_cast<unsigned long long>(info.octree_entries),
                  static_cast<unsigned long long>(info.octree_long_leaves), sim::kOctreeLongList);
  else
    std::snprintf(line, sizeof line, "particles   %zu, r_max %g; grid length %g, %llu cells%s\n", s.particles.size(),
                  s.config.r_max, info.grid_length, static_cast<unsigned long long>(info.cells),
                  info.hashed ? " (hashed)" : "");
  o << line;
  std::snprintf(line, sizeof line, "contacts    %llu, colliding particles %llu; %llu pairs %s\n",
                static_cast<unsigned long long>(r.contact_count),
                static_cast<unsigned long long>(r.colliding_particles),
                static_cast<unsigned long long>(r.band_pairs),
                s.config.precision == sim::Precision::kExact
                    ? "within float's error band of touching, re-decided in double"
                    : "decided in float within its error band (may be wrong: use --precision exact)");
  o << line;
  const auto& t = r.times;
  std::snprintf(line, sizeof line,
                "time (ms)   prepare %.3f | frame %.3f = hash %.3f + sort %.3f + cells %.3f + traverse %.3f + "
                "finalize %.3f\n",
                info.prepare_ms, t.frame_ms, t.hash_ms, t.sort_ms, t.cells_ms, t.traverse_ms, t.finalize_ms);
  o << line;
  return o.str();
}

}  // namespace collido::app
