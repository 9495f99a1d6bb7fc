// SPDX-License-Identifier: MIT
/// rng/rng.h — Small seeded pseudo-random generator (xoshiro256**, seeded by splitmix64).
///
/// Every random choice of the product (example-policy gains, the simulated human driver,
/// training start poses, exploration noise, emulator noise) draws from an explicit instance of
/// this generator, so a run is a function of its seeds. The sequence for a given seed is fixed
/// forever (tests pin it): changing the algorithm is a breaking change.
///
/// Memory: 40 bytes, caller-owned, no allocation. Not thread-safe per instance; use one instance
/// per thread or stream. All functions O(1).
#ifndef B21R_RNG_H
#define B21R_RNG_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Generator state. Treat as opaque; copy it to fork a stream.
typedef struct rng {
  uint64_t s[4];          ///< xoshiro256** state, never all zero after rng_seed
  double spare_normal;    ///< second value of the last Box-Muller pair
  uint8_t has_spare;      ///< 1 if spare_normal holds an unused value
} rng_t;

/// Seeds the generator: the four state words are the first four outputs of splitmix64(seed).
/// Every seed (including 0) is valid and gives an independent-looking stream.
void rng_seed(rng_t* rng, uint64_t seed);

/// Next 64 random bits.
uint64_t rng_next_u64(rng_t* rng);

/// Uniform double in [0, 1) with 53 random bits.
double rng_uniform(rng_t* rng);

/// Uniform double in [lo, hi) (returns lo if hi <= lo).
double rng_uniform_range(rng_t* rng, double lo, double hi);

/// Uniform integer in [0, n) without modulo bias; returns 0 for n == 0.
uint32_t rng_below(rng_t* rng, uint32_t n);

/// Standard normal variate N(0, 1) (Box-Muller; the second value of each pair is kept in the
/// state and returned by the next call). Always finite.
double rng_normal(rng_t* rng);

/// splitmix64 step: advances *state and returns a well-mixed 64-bit value. Used to derive
/// independent seeds (per run, per stream) from one master seed.
uint64_t rng_splitmix64(uint64_t* state);

#ifdef __cplusplus
}
#endif

#endif  // B21R_RNG_H
