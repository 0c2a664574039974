// Files that appear under their final name only when complete. A writer puts
// its bytes under a unique temporary name in the same folder and renames it
// into place (rename is atomic within a file system), so a process killed at
// any moment leaves either the old file, the whole new one, or a temporary
// that is_temp_name() recognises and a later run removes. Header-only, so every
// module can use it without linking anything.
#pragma once

#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <string>

#include "common/status.h"

namespace collido {

// "<path>.tmp-<pid>-<n>": unique among the writers of this process (n counts)
// and of other live processes (the pid).
inline std::string temp_path_for(const std::string& path) {
  static std::atomic<unsigned long long> counter{0};
  return path + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter++);
}

// True for a name temp_path_for() made (or the older "<name>.tmpNNNN" form).
inline bool is_temp_name(const std::string& name) {
  const size_t at = name.rfind(".tmp");
  if (at == std::string::npos || at == 0) return false;
  for (size_t i = at + 4; i < name.size(); ++i)
    if (!((name[i] >= '0' && name[i] <= '9') || name[i] == '-')) return false;
  return true;
}

// Writes `bytes` to `path` through a temporary name; the file is closed on every path.
inline Status write_file_atomic(const std::string& path, const std::string& bytes) {
  const std::string tmp = temp_path_for(path);
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) return io_error("cannot create " + tmp);
  const bool wrote = std::fwrite(bytes.data(), 1, bytes.size(), f) == bytes.size();
  const bool closed = std::fclose(f) == 0;
  if (!wrote || !closed) {
    std::remove(tmp.c_str());
    return io_error("cannot write " + path + " (disk full?)");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    return io_error("cannot rename " + tmp + " to " + path);
  }
  return Status::ok();
}

}  // namespace collido
