// SPDX-License-Identifier: MIT
// Small helpers shared by the proto unit tests: hex literals and a deterministic generator.
#ifndef PROTO_TEST_UTIL_H
#define PROTO_TEST_UTIL_H

#include <stddef.h>
#include <stdint.h>

// Parses "02 00 1b ..." (spaces optional) into out; returns the byte count (aborts the test
// program on a malformed literal: these are fixed strings in the tests).
static inline size_t test_hex(const char* s, uint8_t* out, size_t cap) {
  size_t n = 0;
  int half = -1;
  for (; *s != '\0'; ++s) {
    int v;
    if (*s >= '0' && *s <= '9') {
      v = *s - '0';
    } else if (*s >= 'a' && *s <= 'f') {
      v = *s - 'a' + 10;
    } else if (*s >= 'A' && *s <= 'F') {
      v = *s - 'A' + 10;
    } else {
      continue;
    }
    if (half < 0) {
      half = v;
    } else {
      if (n >= cap) {
        __builtin_trap();
      }
      out[n++] = (uint8_t)(half * 16 + v);
      half = -1;
    }
  }
  if (half >= 0) {
    __builtin_trap();
  }
  return n;
}

// xorshift32 with a fixed seed per test: reproducible "random" bytes.
static inline uint32_t test_rand(uint32_t* state) {
  uint32_t x = *state;
  x ^= x << 13;
  x ^= x >> 17;
  x ^= x << 5;
  *state = x;
  return x;
}

// |a - b| <= eps for doubles (this CMocka has no assert_double_equal); eps 0 means exact.
#define ASSERT_NEAR(a, b, eps) \
  assert_true(fabs((double)(a) - (double)(b)) <= (double)(eps))

#endif  // PROTO_TEST_UTIL_H
