// Cell ranges of elements sorted by bucket (paper Tables 1-2), built on a
// backend: start[b] and end[b] for every bucket that holds elements, 0 and 0
// for the others. Shared by detection's wall traversal and the dynamics' pairs.
#pragma once

#include <cstdint>

#include "sim/hd.h"

namespace collido::sim {

// Writes start[b] and end[b] for every bucket the n sorted keys skey name, into a
// table whose other buckets already hold 0 and 0; keys equal to `none` (elements
// outside the grid) belong to no bucket.
template <class B>
void set_cell_ranges(B& backend, const uint32_t* skey, size_t n, uint32_t* start, uint32_t* end,
                     uint32_t none) {
  const uint32_t count = static_cast<uint32_t>(n);
  backend.parallel_for(n, [=] COLLIDO_HD(uint32_t j) {
    const uint32_t k = skey[j];
    if (k == none) return;
    if (j == 0 || skey[j - 1] != k) start[k] = j;
    if (j + 1 == count || skey[j + 1] != k) end[k] = j + 1;
  });
}

// Zeroes the ranges set_cell_ranges wrote for these keys: a table rebuilt often
// over few elements clears the buckets it used, not all of them.
template <class B>
void clear_cell_ranges(B& backend, const uint32_t* skey, size_t n, uint32_t* start, uint32_t* end,
                       uint32_t none) {
  backend.parallel_for(n, [=] COLLIDO_HD(uint32_t j) {
    const uint32_t k = skey[j];
    if (k != none) start[k] = end[k] = 0;
  });
}

// Every bucket cleared, then the ranges of the n sorted keys.
template <class B>
void build_cell_ranges(B& backend, const uint32_t* skey, size_t n, uint32_t* start, uint32_t* end,
                       uint32_t buckets, uint32_t none) {
  backend.fill(start, buckets, 0u);
  backend.fill(end, buckets, 0u);
  set_cell_ranges(backend, skey, n, start, end, none);
}

}  // namespace collido::sim
