// stats.csv: one row per frame. While a run goes on its rows are appended to
// stats.csv.partial (flushed per row, so a viewer can chart a running job);
// the run's end renames it to stats.csv, so that name always holds every frame.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "common/status.h"
#include "sim/dynamics.h"

namespace collido::job {

extern const char* const kStatsHeader;

class StatsFile {
 public:
  StatsFile() = default;
  ~StatsFile();
  StatsFile(const StatsFile&) = delete;
  StatsFile& operator=(const StatsFile&) = delete;

  // Starts a new partial file (header only).
  Status create(const std::string& partial_path);
  // Continues a partial file after a resume: keeps the header and the whole
  // rows of frames <= last_frame, drops the rest (a row cut by a kill, frames
  // after the checkpoint); *times gets each kept row's simulated time.
  Status resume(const std::string& partial_path, uint64_t last_frame, std::vector<double>* times);
  Status append(const sim::FrameStats& s, double wall_ms);
  // Closes the partial file and renames it to final_path.
  Status finish(const std::string& final_path);
  void close();

 private:
  std::FILE* f_ = nullptr;
  std::string path_;
};

}  // namespace collido::job
