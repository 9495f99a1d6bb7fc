// SPDX-License-Identifier: MIT
// Internal: little-endian packing of the firmware's own file and state records.
#ifndef FW_LE_BYTES_H
#define FW_LE_BYTES_H

#include <stdint.h>
#include <string.h>

static inline void fw_put_u32(uint8_t* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) {
    p[i] = (uint8_t)(v >> (8 * i));
  }
}

static inline void fw_put_u64(uint8_t* p, uint64_t v) {
  fw_put_u32(p, (uint32_t)v);
  fw_put_u32(p + 4, (uint32_t)(v >> 32));
}

static inline uint32_t fw_get_u32(const uint8_t* p) {
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) {
    v = (v << 8) | p[i];
  }
  return v;
}

static inline uint64_t fw_get_u64(const uint8_t* p) {
  return (uint64_t)fw_get_u32(p) | ((uint64_t)fw_get_u32(p + 4) << 32);
}

// Doubles travel as their IEEE-754 bit pattern so a round trip is exact.
static inline void fw_put_f64(uint8_t* p, double d) {
  uint64_t u = 0;
  memcpy(&u, &d, sizeof u);
  fw_put_u64(p, u);
}

static inline double fw_get_f64(const uint8_t* p) {
  const uint64_t u = fw_get_u64(p);
  double d = 0.0;
  memcpy(&d, &u, sizeof d);
  return d;
}

#endif  // FW_LE_BYTES_H
