#include "job/stats_file.h"

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "common/atomic_file.h"

namespace collido::job {

const char* const kStatsHeader =
    "frame,time_s,substeps,dt_min_s,dt_max_s,active,waiting,held,escaped,invalid,wall_contacts,"
    "particle_contacts,touching_wall,kinetic_J,potential_J,elastic_J,total_J,max_speed_m_s,"
    "max_overlap,history_overflow,wall_ms\n";

StatsFile::~StatsFile() { close(); }

void StatsFile::close() {
  if (f_) std::fclose(f_);
  f_ = nullptr;
}

Status StatsFile::create(const std::string& partial_path) {
  close();
  path_ = partial_path;
  f_ = std::fopen(path_.c_str(), "wb");
  if (!f_) return io_error(path_ + ": cannot create: " + std::strerror(errno));
  if (std::fputs(kStatsHeader, f_) < 0 || std::fflush(f_) != 0)
    return io_error(path_ + ": cannot write");
  return Status::ok();
}

Status StatsFile::resume(const std::string& partial_path, uint64_t last_frame,
                         std::vector<double>* times) {
  close();
  path_ = partial_path;
  std::ifstream in(path_, std::ios::binary);
  if (!in) return not_found(path_ + ": missing, cannot resume the statistics");
  std::stringstream all;
  all << in.rdbuf();
  const std::string text = all.str();
  std::string kept = kStatsHeader;
  times->clear();
  size_t at = text.find('\n');
  if (at == std::string::npos || text.compare(0, at + 1, kStatsHeader) != 0)
    return parse_error(path_ + ": not a statistics file of this version");
  ++at;
  while (at < text.size()) {
    const size_t end = text.find('\n', at);
    if (end == std::string::npos) break;  // a row cut by the kill
    const std::string row = text.substr(at, end - at + 1);
    const uint64_t frame = std::strtoull(row.c_str(), nullptr, 10);
    if (frame > last_frame) break;
    const size_t comma = row.find(',');
    times->push_back(std::strtod(row.c_str() + comma + 1, nullptr));
    kept += row;
    at = end + 1;
  }
  if (times->size() != last_frame + 1)
    return parse_error(path_ + ": holds " + std::to_string(times->size()) +
                       " whole rows, the checkpoint needs " + std::to_string(last_frame + 1));
  if (Status s = write_file_atomic(path_, kept); !s) return s;
  f_ = std::fopen(path_.c_str(), "ab");
  if (!f_) return io_error(path_ + ": cannot reopen");
  return Status::ok();
}

Status StatsFile::append(const sim::FrameStats& s, double wall_ms) {
  if (!f_) return io_error("statistics file is not open");
  const int n = std::fprintf(
      f_,
      "%llu,%.9g,%llu,%.6g,%.6g,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%.9g,%.9g,%.9g,%.9g,%.6g,%.6g,"
      "%llu,%.3f\n",
      (unsigned long long)s.frame, s.time, (unsigned long long)s.substeps, s.dt_min, s.dt_max,
      (unsigned long long)s.active, (unsigned long long)s.waiting, (unsigned long long)s.held,
      (unsigned long long)s.escaped,
      (unsigned long long)s.invalid, (unsigned long long)s.wall_contacts,
      (unsigned long long)s.particle_contacts, (unsigned long long)s.touching_wall, s.kinetic,
      s.potential, s.elastic, s.total_energy(), s.max_speed, s.max_overlap,
      (unsigned long long)s.history_overflow, wall_ms);
  if (n < 0 || std::fflush(f_) != 0) return io_error(path_ + ": cannot write: " + std::strerror(errno));
  return Status::ok();
}

Status StatsFile::finish(const std::string& final_path) {
  if (!f_) return io_error("statistics file is not open");
  const bool ok = std::fclose(f_) == 0;
  f_ = nullptr;
  if (!ok) return io_error(path_ + ": cannot close");
  if (std::rename(path_.c_str(), final_path.c_str()) != 0)
    return io_error("cannot rename " + path_ + " to " + final_path);
  return Status::ok();
}

}  // namespace collido::job
