#include "job/checkpoint.h"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <fstream>

#include "common/atomic_file.h"

namespace collido::job {
namespace {

// The last two characters are the format: 04 holds the wall's method and grid
// length after the lists; 03 (read still) did not; 03 holds the neighbour lists
// after the arrays; 02 (read still: its lists are built afresh) did not; 02 holds
// the engine's particle numbering among the arrays (01, before particles were
// renumbered by cell, did not).
constexpr char kMagic[8] = {'C', 'L', 'C', 'K', 'P', 'T', '0', '4'};
constexpr char kMagicWithoutMethod[8] = {'C', 'L', 'C', 'K', 'P', 'T', '0', '3'};
constexpr char kMagicWithoutLists[8] = {'C', 'L', 'C', 'K', 'P', 'T', '0', '2'};
// Longer than any method's name: a longer one means a damaged file.
constexpr uint32_t kMaxMethodName = 64;
// More than any run holds; a larger count or size means a damaged file.
constexpr uint32_t kMaxArrays = 64;

constexpr uint64_t kFnvOffset = 1469598103934665603ull, kFnvPrime = 1099511628211ull;

uint64_t fnv1a(const char* bytes, size_t n, uint64_t h = kFnvOffset) {
  for (size_t i = 0; i < n; ++i) h = (h ^ static_cast<unsigned char>(bytes[i])) * kFnvPrime;
  return h;
}

// Writes a checkpoint's parts to the file as they come, hashing them on the way:
// the file is the same as one assembled in memory first, without that copy of the
// state (as large as the engine's arrays: 2.3 MiB for a pour of 6,000 particles).
class HashedWriter {
 public:
  explicit HashedWriter(std::FILE* f) : f_(f) {}
  void bytes(const void* p, size_t n) {
    if (!ok_ || n == 0) return;
    hash_ = fnv1a(static_cast<const char*>(p), n, hash_);
    ok_ = std::fwrite(p, 1, n, f_) == n;
  }
  template <class T>
  void put(const T& v) {
    bytes(&v, sizeof v);
  }
  // The hash of everything before it, then nothing more.
  bool finish() {
    const uint64_t h = hash_;
    bytes(&h, sizeof h);
    return ok_;
  }

 private:
  std::FILE* f_;
  uint64_t hash_ = kFnvOffset;
  bool ok_ = true;
};

class Reader {
 public:
  explicit Reader(const std::string& b) : b_(b) {}
  template <class T>
  bool get(T* v) {
    if (b_.size() - at_ < sizeof(T)) return false;
    std::memcpy(v, b_.data() + at_, sizeof(T));
    at_ += sizeof(T);
    return true;
  }
  bool bytes(size_t n, std::vector<uint8_t>* out) {
    if (b_.size() - at_ < n) return false;
    out->assign(b_.begin() + long(at_), b_.begin() + long(at_ + n));
    at_ += n;
    return true;
  }
  size_t at() const { return at_; }

 private:
  const std::string& b_;
  size_t at_ = 0;
};

}  // namespace

Status write_checkpoint(const std::string& path, const Checkpoint& c) {
  // On the disk when this returns (the files it speaks for went first, job.cpp).
  return write_file_atomic_with(
      path,
      [&](std::FILE* f) {
        HashedWriter w(f);
        w.bytes(kMagic, sizeof kMagic);
        w.put(c.frame);
        w.put(c.state.particles);
        w.put(c.state.time);
        w.put(c.state.steps);
        w.put(uint8_t(c.state.all_released));
        for (const auto* arrays : {&c.state.arrays, &c.state.lists}) {
          w.put(uint32_t(arrays->size()));
          for (const auto& a : *arrays) {
            w.put(uint64_t(a.size()));
            w.bytes(a.data(), a.size());
          }
        }
        w.put(uint32_t(c.method.size()));
        w.bytes(c.method.data(), c.method.size());
        w.put(c.grid_length);
        return w.finish();
      },
      Durability::kSynced);
}

Expected<Checkpoint> read_checkpoint(const std::string& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return not_found(path + ": no checkpoint");
  // Read straight into one buffer of the file's size: a resumed job's peak holds
  // the file once beside the state it becomes, not three times.
  std::string b(size_t(std::max<std::streamoff>(in.tellg(), 0)), '\0');
  in.seekg(0);
  if (!in.read(b.data(), std::streamsize(b.size())))
    return io_error(path + ": cannot read the checkpoint");
  auto damaged = [&](const char* why) { return parse_error(path + ": damaged checkpoint (" + why + ")"); };
  auto is = [&](const char* magic) {
    return b.size() >= sizeof kMagic && std::memcmp(b.data(), magic, sizeof kMagic) == 0;
  };
  const bool without_lists = is(kMagicWithoutLists);
  const bool without_method = without_lists || is(kMagicWithoutMethod);
  if (b.size() >= sizeof kMagic && std::memcmp(b.data(), kMagic, 6) == 0 && !is(kMagic) &&
      !without_method)
    return parse_error(path + ": a checkpoint of another format (" + b.substr(6, 2) +
                       ", this version reads " + std::string(kMagic + 6, 2) +
                       "): run the scene again from its start");
  if (b.size() < sizeof kMagic + 8 || (!is(kMagic) && !without_method))
    return damaged("not a checkpoint");
  uint64_t stored = 0;
  std::memcpy(&stored, b.data() + b.size() - 8, 8);
  if (fnv1a(b.data(), b.size() - 8) != stored) return damaged("checksum");
  Reader r(b);
  char magic[8];
  r.get(&magic);
  Checkpoint c;
  uint8_t released = 0;
  if (!r.get(&c.frame) || !r.get(&c.state.particles) || !r.get(&c.state.time) ||
      !r.get(&c.state.steps) || !r.get(&released))
    return damaged("header");
  c.state.all_released = released != 0;
  for (auto* arrays : {&c.state.arrays, &c.state.lists}) {
    if (arrays == &c.state.lists && without_lists) break;
    uint32_t count = 0;
    if (!r.get(&count) || count > kMaxArrays) return damaged("header");
    arrays->resize(count);
    for (auto& a : *arrays) {
      uint64_t n = 0;
      if (!r.get(&n) || n > b.size() || !r.bytes(size_t(n), &a)) return damaged("arrays");
    }
  }
  if (!without_method) {
    uint32_t len = 0;
    std::vector<uint8_t> name;
    if (!r.get(&len) || len > kMaxMethodName || !r.bytes(len, &name) || !r.get(&c.grid_length))
      return damaged("method");
    c.method.assign(name.begin(), name.end());
  }
  if (r.at() + 8 != b.size()) return damaged("length");
  return c;
}

}  // namespace collido::job
