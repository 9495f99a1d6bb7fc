// SPDX-License-Identifier: MIT
#include "hedger_test_util.h"

#include <math.h>

double ht_normal(uint64_t* s) {
  double u1 = ht_uniform(s, 0.0, 1.0);
  const double u2 = ht_uniform(s, 0.0, 1.0);
  if (u1 < 1e-300) u1 = 1e-300;
  return sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2);
}
