// SPDX-License-Identifier: MIT
#include "hedger_test_util.h"

#include <math.h>
#include <string.h>

double ht_normal(uint64_t* s) {
  double u1 = ht_uniform(s, 0.0, 1.0);
  const double u2 = ht_uniform(s, 0.0, 1.0);
  if (u1 < 1e-300) u1 = 1e-300;
  return sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2);
}

int ht_same_saved(const hedger_t* a, const hedger_t* b) {
  const size_t n = hedger_serialized_size(a);
  if (n == 0 || n != hedger_serialized_size(b)) return 0;
  uint8_t* ba = malloc(n);
  uint8_t* bb = malloc(n);
  const int same = ba != NULL && bb != NULL && hedger_save(a, ba, n, NULL) == HEDGER_OK &&
                   hedger_save(b, bb, n, NULL) == HEDGER_OK && memcmp(ba, bb, n) == 0;
  free(ba);
  free(bb);
  return same;
}

void ht_insert_gentle_teacher(hedger_t* h, int n, uint64_t* rs) {
  for (int i = 0; i < n; ++i) {
    const double s = ht_uniform(rs, -1.0, 1.0);
    const double a = 0.5 * s + 0.2 * ht_normal(rs);
    const double q = 2.0 + 0.2 * s - (a - 0.8 * s) * (a - 0.8 * s) + 0.005 * ht_normal(rs);
    if (hedger_insert(h, &s, a, q, 0, NULL) != HEDGER_OK) abort();
  }
  if (hedger_observe_reward(h, 1.0) != HEDGER_OK) abort();
}
