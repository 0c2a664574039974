// Shared by `detect` and `bench detect`: flags -> wall, particles, config; summaries.
#pragma once

#include <memory>
#include <string>

#include "app/cli.h"
#include "sim/detect.h"
#include "sim/mesh.h"
#include "sim/parallel.h"

namespace collido::app {

struct DetectSetup {
  std::string wall_spec;
  sim::TriangleMesh wall;
  sim::MeshReport wall_report;
  std::string particles_spec;
  sim::Particles particles;
  sim::DetectConfig config;
  std::unique_ptr<sim::ThreadPool> pool;  // --threads; config.pool points at it
  std::string backend_note;  // e.g. "no GPU: running on the CPU"
};

// Reads --wall, --particles, --seed, --radius, --radius-range, --method,
// --traversal, --backend, --grid-length, --threads. Returns an exit code.
int build_detect_setup(const ParsedArgs& args, const std::string& command, DetectSetup* out);

std::string detect_summary_json(const DetectSetup& s, const sim::PrepareInfo& info, const sim::DetectResult& r);
std::string detect_summary_text(const DetectSetup& s, const sim::PrepareInfo& info, const sim::DetectResult& r);

// Escapes a string for a JSON document.
std::string json_escape(const std::string& s);

}  // namespace collido::app
