// SPDX-License-Identifier: MIT
// xoshiro256** (Blackman & Vigna) seeded through splitmix64; Box-Muller normals.
#include "rng/rng.h"

#include <math.h>

uint64_t rng_splitmix64(uint64_t* state) {
  uint64_t z = (*state += 0x9E3779B97F4A7C15ULL);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

void rng_seed(rng_t* rng, uint64_t seed) {
  uint64_t sm = seed;
  for (int i = 0; i < 4; ++i) {
    rng->s[i] = rng_splitmix64(&sm);
  }
  // splitmix64 is a bijection of its counter, so four consecutive outputs are never all zero;
  // kept as a guard because an all-zero xoshiro state would emit zeros forever.
  if ((rng->s[0] | rng->s[1] | rng->s[2] | rng->s[3]) == 0U) {
    rng->s[0] = 1U;
  }
  rng->spare_normal = 0.0;
  rng->has_spare = 0U;
}

static uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

uint64_t rng_next_u64(rng_t* rng) {
  uint64_t* s = rng->s;
  const uint64_t result = rotl(s[1] * 5U, 7) * 9U;
  const uint64_t t = s[1] << 17;
  s[2] ^= s[0];
  s[3] ^= s[1];
  s[1] ^= s[2];
  s[0] ^= s[3];
  s[2] ^= t;
  s[3] = rotl(s[3], 45);
  return result;
}

double rng_uniform(rng_t* rng) {
  return (double)(rng_next_u64(rng) >> 11) * 0x1.0p-53;
}

double rng_uniform_range(rng_t* rng, double lo, double hi) {
  const double u = rng_uniform(rng);
  if (!(hi > lo)) {
    return lo;
  }
  return lo + (hi - lo) * u;
}

uint32_t rng_below(rng_t* rng, uint32_t n) {
  if (n == 0U) {
    return 0U;
  }
  // Lemire's multiply-shift with rejection: unbiased, usually one draw.
  const uint32_t threshold = (uint32_t)(0U - n) % n;  // 2^32 mod n
  for (;;) {
    const uint64_t x = rng_next_u64(rng) >> 32;
    const uint64_t m = x * (uint64_t)n;
    if ((uint32_t)m >= threshold) {
      return (uint32_t)(m >> 32);
    }
  }
}

double rng_normal(rng_t* rng) {
  if (rng->has_spare != 0U) {
    rng->has_spare = 0U;
    return rng->spare_normal;
  }
  // 1 - u lies in (0, 1], so the logarithm is finite.
  const double u1 = 1.0 - rng_uniform(rng);
  const double u2 = rng_uniform(rng);
  const double r = sqrt(-2.0 * log(u1));
  const double a = 6.283185307179586476925 * u2;
  rng->spare_normal = r * sin(a);
  rng->has_spare = 1U;
  return r * cos(a);
}
