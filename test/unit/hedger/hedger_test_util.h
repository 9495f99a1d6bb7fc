// SPDX-License-Identifier: MIT
// Helpers shared by the HEDGER unit tests (C): a seeded generator and instance set-up.
#ifndef HEDGER_TEST_UTIL_H
#define HEDGER_TEST_UTIL_H

#include <hedger/hedger.h>
#include <stdint.h>
#include <stdlib.h>

/// splitmix64: the tests' only source of randomness (fixed seeds).
static inline uint64_t ht_next(uint64_t* s) {
  uint64_t z = (*s += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

/// Uniform in [lo, hi).
static inline double ht_uniform(uint64_t* s, double lo, double hi) {
  return lo + (hi - lo) * ((double)(ht_next(s) >> 11) * 0x1.0p-53);
}

/// Standard normal (Box–Muller; uses two draws).
double ht_normal(uint64_t* s);

/// True when a and b hold the same learned state: the same serialized size and the same bytes
/// from hedger_save() (the tests' bit-for-bit comparison of two instances).
int ht_same_saved(const hedger_t* a, const hedger_t* b);

/// A teacher that turns too gently, on one state dimension: n points at s uniform in [-1, 1]
/// with actions a = 0.5 s + 0.2 N(0, 1) and values 2 + 0.2 s − (a − 0.8 s)² + 0.005 N(0, 1)
/// (peaked at a = 0.8 s), inserted from the stream at *rs; then a reward of 1 observed (the
/// values' bounds). Aborts if HEDGER refuses a point.
void ht_insert_gentle_teacher(hedger_t* h, int n, uint64_t* rs);

/// hedger_create() that must succeed.
static inline hedger_t* ht_create(const hedger_config_t* cfg) {
  hedger_t* h = NULL;
  if (hedger_create(&h, cfg) != HEDGER_OK) abort();
  return h;
}

#endif  // HEDGER_TEST_UTIL_H
