// SPDX-License-Identifier: MIT
// Helpers shared by the white-box HEDGER tests (C++, lib/hedger/src included): the tests' seeded
// generator and whether two forms of one computation can be compared bit for bit.
#ifndef HEDGER_TEST_INTERNAL_HPP
#define HEDGER_TEST_INTERNAL_HPP

#include <cstdint>

namespace ht {

/// splitmix64 (the C tests' ht_next()): fixed seeds, no other source of randomness.
inline uint64_t splitmix(uint64_t& s) {
  uint64_t z = (s += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

/// Uniform in [0, 1).
inline double uniform(uint64_t& s) { return static_cast<double>(splitmix(s) >> 11) * 0x1.0p-53; }

/// Two forms of one sum of products agree bit for bit where the compiler cannot fuse a multiply
/// and an add (x86-64 without FMA, the host builds); elsewhere (AArch64 contracts a * b + c by
/// default, in each copy of the code as it sees fit) they agree to rounding only.
#if defined(__x86_64__) && !defined(__FMA__)
constexpr bool kExact = true;
#else
constexpr bool kExact = false;
#endif

}  // namespace ht

#endif  // HEDGER_TEST_INTERNAL_HPP
