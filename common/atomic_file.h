// Files that appear under their final name only when complete. A writer puts
// its bytes under a unique temporary name in the same folder and renames it
// into place (rename is atomic within a file system), so a process killed at
// any moment leaves either the old file, the whole new one, or a temporary
// that is_temp_name() recognises and a later run removes. Header-only, so every
// module can use it without linking anything.
#pragma once

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>

#include "common/status.h"

namespace collido {

// Why a file could not be opened for reading: not_found where nothing is at
// the path (bad input, which the command line answers with exit code 2), else
// an I/O error (a file there that cannot be read).
inline Status open_failure(const std::string& path, std::string message) {
  struct stat st;
  const bool missing = ::stat(path.c_str(), &st) != 0 && errno == ENOENT;
  return missing ? not_found(std::move(message)) : io_error(std::move(message));
}

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

// How far a write is carried before it returns. kSynced also survives the
// machine going down (a node lost under a cluster job): the bytes reach the
// disk before the rename, and the rename before the call returns; a process
// killed at any moment needs neither, since the kernel keeps what it wrote.
enum class Durability { kProcess, kSynced };

// Flushes a folder's entries (a rename in it) to the disk; errors ignored: not
// every file system can open a folder for it.
inline void sync_folder_of(const std::string& path) {
  const size_t slash = path.rfind('/');
  const std::string dir = slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  (void)::fsync(fd);
  ::close(fd);
}

// Everything written to the file system that holds `dir` on its disk.
inline Status sync_file_system(const std::string& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return io_error(dir + ": cannot open: " + std::strerror(errno));
  const int rc = ::syncfs(fd);
  const int e = errno;
  ::close(fd);
  if (rc != 0) return io_error(dir + ": cannot sync: " + std::strerror(e));
  return Status::ok();
}

// Writes to `path` through a temporary name what write(FILE*) puts there (it
// answers false when a write failed, errno set): a large file goes out in parts
// without a copy of it in memory. The file is closed on every path.
template <class Write>
inline Status write_file_atomic_with(const std::string& path, Write&& write,
                                     Durability durability = Durability::kProcess) {
  const std::string tmp = temp_path_for(path);
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) return io_error("cannot create " + tmp + ": " + std::strerror(errno));
  bool wrote = write(f);
  if (wrote && durability == Durability::kSynced)
    wrote = std::fflush(f) == 0 && ::fsync(::fileno(f)) == 0;
  const int write_errno = errno;
  const bool closed = std::fclose(f) == 0;
  if (!wrote || !closed) {
    const int e = !wrote ? write_errno : errno;
    std::remove(tmp.c_str());
    return io_error("cannot write " + path + ": " + std::strerror(e));
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int e = errno;
    std::remove(tmp.c_str());
    return io_error("cannot rename " + tmp + " to " + path + ": " + std::strerror(e));
  }
  if (durability == Durability::kSynced) sync_folder_of(path);
  return Status::ok();
}

// Writes `bytes` to `path` through a temporary name; the file is closed on every path.
inline Status write_file_atomic(const std::string& path, const std::string& bytes,
                                Durability durability = Durability::kProcess) {
  return write_file_atomic_with(
      path,
      [&](std::FILE* f) { return std::fwrite(bytes.data(), 1, bytes.size(), f) == bytes.size(); },
      durability);
}

}  // namespace collido
