// This process's own memory since it was exec'd, from /proc/self/status.
//
// getrusage()'s ru_maxrss will not do for a child: Linux carries the peak of
// the memory it was spawned from (the parent's, until exec) into it, so a job
// started by a service holding a gigabyte would report a gigabyte or more.
// VmHWM belongs to the address space exec made, so it is the child's own.
#pragma once

#include <sys/resource.h>

#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <string>

namespace collido {

struct ProcessMemory {
  double peak_resident_bytes = 0;  // VmHWM: the peak resident set
  double file_backed_bytes = 0;    // RssFile: resident pages backed by files (shared libraries)
};

// Zeros where /proc is not there to read.
inline ProcessMemory own_process_memory() {
  ProcessMemory m;
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmHWM:", 0) == 0) m.peak_resident_bytes = 1024.0 * std::strtod(line.c_str() + 6, nullptr);
    if (line.rfind("RssFile:", 0) == 0) m.file_backed_bytes = 1024.0 * std::strtod(line.c_str() + 8, nullptr);
  }
  return m;
}

// The peak resident set of this process since exec, bytes; getrusage()'s
// figure only where /proc cannot be read.
inline uint64_t own_peak_resident_bytes() {
  const double hwm = own_process_memory().peak_resident_bytes;
  if (hwm > 0) return uint64_t(hwm);
  struct rusage ru {};
  getrusage(RUSAGE_SELF, &ru);
  return uint64_t(ru.ru_maxrss) * 1024;  // KiB on Linux
}

}  // namespace collido
