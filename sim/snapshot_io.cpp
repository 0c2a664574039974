#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <utility>

#include "common/atomic_file.h"
#include "sim/snapshot.h"

namespace collido::sim {
namespace {

// The format is little-endian; swap on the (rare) big-endian host.
constexpr bool kHostLittle = __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__;

template <class T>
T swap_bytes(T v) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  for (size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(b[i], b[sizeof(T) - 1 - i]);
  std::memcpy(&v, b, sizeof(T));
  return v;
}
template <class T>
T to_le(T v) {
  return kHostLittle ? v : swap_bytes(v);
}

struct FileCloser {
  void operator()(FILE* f) const {
    if (f) std::fclose(f);
  }
};
using File = std::unique_ptr<FILE, FileCloser>;

template <class T>
void put(std::string& buf, T v) {
  v = to_le(v);
  buf.append(reinterpret_cast<const char*>(&v), sizeof v);
}

bool write_floats(FILE* f, const std::vector<float>& a) {
  if (a.empty()) return true;  // an empty vector's data() may be null, which fwrite must not get
  if (kHostLittle) return std::fwrite(a.data(), sizeof(float), a.size(), f) == a.size();
  for (float v : a) {
    v = swap_bytes(v);
    if (std::fwrite(&v, sizeof v, 1, f) != 1) return false;
  }
  return true;
}

template <class T>
T get(const unsigned char* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  return to_le(v);
}

}  // namespace

void Snapshot::resize(size_t n) {
  for (auto* a : {&x, &y, &z, &r, &vx, &vy, &vz}) a->assign(n, 0.f);
  contact.assign(n, 0);
}

std::string snapshot_path(const std::string& run_dir, uint64_t frame) {
  char name[40];
  std::snprintf(name, sizeof name, "frame_%06llu.snap", static_cast<unsigned long long>(frame));
  return run_dir + "/frames/" + name;
}

Status write_snapshot(const std::string& path, const Snapshot& s) {
  const size_t n = s.size();
  for (const auto* a : {&s.y, &s.z, &s.r, &s.vx, &s.vy, &s.vz})
    if (a->size() != n)
      return invalid_argument("write_snapshot " + path + ": arrays differ in length");
  if (s.contact.size() != n)
    return invalid_argument("write_snapshot " + path + ": contact array differs in length");
  if (n > kSnapshotMaxParticles)
    return invalid_argument("write_snapshot " + path + ": too many particles");

  std::string header;
  header.append(kSnapshotMagic, 8);
  put<uint32_t>(header, kSnapshotVersion);
  put<uint32_t>(header, static_cast<uint32_t>(n));
  put<uint64_t>(header, s.frame);
  put<double>(header, s.time);
  put<double>(header, s.origin.x);
  put<double>(header, s.origin.y);
  put<double>(header, s.origin.z);

  const std::string tmp = temp_path_for(path);
  File f(std::fopen(tmp.c_str(), "wb"));
  if (!f) return io_error("write_snapshot: cannot create " + tmp);
  bool ok = std::fwrite(header.data(), 1, header.size(), f.get()) == header.size();
  for (const auto* a : {&s.x, &s.y, &s.z, &s.r, &s.vx, &s.vy, &s.vz})
    ok = ok && write_floats(f.get(), *a);
  ok = ok && (n == 0 || std::fwrite(s.contact.data(), 1, n, f.get()) == n);
  ok = ok && std::fflush(f.get()) == 0;
  ok = std::fclose(f.release()) == 0 && ok;
  if (!ok) {
    std::remove(tmp.c_str());
    return io_error("write_snapshot " + path + ": write failed (disk full?)");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    return io_error("write_snapshot: cannot rename " + tmp + " to " + path);
  }
  return Status::ok();
}

namespace {

// Reads and checks the header; on success *n is the particle count and the
// file position is at the first array.
Status read_header(FILE* f, const std::string& path, Snapshot* s, uint32_t* n) {
  unsigned char h[kSnapshotHeaderBytes];
  if (std::fseek(f, 0, SEEK_END) != 0) return io_error(path + ": cannot seek");
  const long size = std::ftell(f);
  std::rewind(f);
  if (size < 0) return io_error(path + ": cannot tell its size");
  if (static_cast<size_t>(size) < kSnapshotHeaderBytes) {
    if (size >= 8 && std::fread(h, 1, 8, f) == 8 && std::memcmp(h, kSnapshotMagic, 8) != 0)
      return parse_error(path + ": not a Collidoscope snapshot (bad magic)");
    return parse_error(path + ": truncated snapshot (" + std::to_string(size) +
                       " bytes, the header alone is " + std::to_string(kSnapshotHeaderBytes) + ")");
  }
  if (std::fread(h, 1, kSnapshotHeaderBytes, f) != kSnapshotHeaderBytes)
    return io_error(path + ": read failed");
  if (std::memcmp(h, kSnapshotMagic, 8) != 0)
    return parse_error(path + ": not a Collidoscope snapshot (bad magic)");
  const uint32_t version = get<uint32_t>(h + 8);
  if (version != kSnapshotVersion)
    return parse_error(path + ": snapshot version " + std::to_string(version) +
                       " is not supported (this build reads version " +
                       std::to_string(kSnapshotVersion) + ")");
  *n = get<uint32_t>(h + 12);
  if (*n > kSnapshotMaxParticles)
    return parse_error(path + ": particle count " + std::to_string(*n) +
                       " is implausible (corrupt header)");
  const uint64_t expected = kSnapshotHeaderBytes + uint64_t(*n) * kSnapshotBytesPerParticle;
  if (static_cast<uint64_t>(size) < expected)
    return parse_error(path + ": truncated snapshot: " + std::to_string(*n) + " particles need " +
                       std::to_string(expected) + " bytes, the file has " + std::to_string(size));
  if (static_cast<uint64_t>(size) > expected)
    return parse_error(path + ": snapshot has " + std::to_string(size - expected) +
                       " unexpected trailing bytes for " + std::to_string(*n) + " particles");
  s->frame = get<uint64_t>(h + 16);
  s->time = get<double>(h + 24);
  s->origin = {get<double>(h + 32), get<double>(h + 40), get<double>(h + 48)};
  if (!std::isfinite(s->time) || !std::isfinite(s->origin.x) || !std::isfinite(s->origin.y) ||
      !std::isfinite(s->origin.z))
    return parse_error(path + ": time or origin is not finite");
  return Status::ok();
}

}  // namespace

Expected<Snapshot> read_snapshot_header(const std::string& path) {
  File f(std::fopen(path.c_str(), "rb"));
  if (!f) return io_error("cannot open snapshot " + path);
  Snapshot s;
  uint32_t n = 0;
  if (Status st = read_header(f.get(), path, &s, &n); !st) return st;
  return s;
}

Expected<Snapshot> read_snapshot(const std::string& path) {
  File f(std::fopen(path.c_str(), "rb"));
  if (!f) return io_error("cannot open snapshot " + path);
  Snapshot s;
  uint32_t n = 0;
  if (Status st = read_header(f.get(), path, &s, &n); !st) return st;
  s.resize(n);
  static const char* const kNames[] = {"x", "y", "z", "r", "vx", "vy", "vz"};
  std::vector<float>* arrays[] = {&s.x, &s.y, &s.z, &s.r, &s.vx, &s.vy, &s.vz};
  for (int a = 0; a < 7; ++a) {
    std::vector<float>& v = *arrays[a];
    if (std::fread(v.data(), sizeof(float), n, f.get()) != n)
      return io_error(path + ": read failed in array " + kNames[a]);
    for (uint32_t i = 0; i < n; ++i) {
      if (!kHostLittle) v[i] = swap_bytes(v[i]);
      if (!std::isfinite(v[i]))
        return parse_error(path + ": " + kNames[a] + " of particle " + std::to_string(i) +
                           " is not finite");
    }
  }
  if (std::fread(s.contact.data(), 1, n, f.get()) != n)
    return io_error(path + ": read failed in array contact");
  for (uint32_t i = 0; i < n; ++i) {
    if (s.r[i] < 0)
      return parse_error(path + ": radius of particle " + std::to_string(i) + " is negative");
    if (s.contact[i] > 1)
      return parse_error(path + ": contact flag of particle " + std::to_string(i) + " is " +
                         std::to_string(s.contact[i]) + " (expected 0 or 1)");
  }
  return s;
}

}  // namespace collido::sim
