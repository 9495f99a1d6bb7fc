// SPDX-License-Identifier: MIT
// Private byte-order helpers of lib/proto (little- and big-endian loads and stores).
#ifndef PROTO_BYTES_H
#define PROTO_BYTES_H

#include <stdint.h>

static inline uint16_t proto_le16(const uint8_t* p) {
  return (uint16_t)((unsigned)p[0] | ((unsigned)p[1] << 8));
}
static inline uint32_t proto_le32(const uint8_t* p) {
  return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}
static inline uint32_t proto_be32(const uint8_t* p) {
  return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | (uint32_t)p[3];
}
static inline uint16_t proto_be16(const uint8_t* p) {
  return (uint16_t)(((unsigned)p[0] << 8) | (unsigned)p[1]);
}
static inline void proto_put_le16(uint8_t* p, uint16_t v) {
  p[0] = (uint8_t)(v & 0xFFU);
  p[1] = (uint8_t)(v >> 8);
}
static inline void proto_put_le32(uint8_t* p, uint32_t v) {
  p[0] = (uint8_t)(v & 0xFFU);
  p[1] = (uint8_t)((v >> 8) & 0xFFU);
  p[2] = (uint8_t)((v >> 16) & 0xFFU);
  p[3] = (uint8_t)(v >> 24);
}
static inline void proto_put_be32(uint8_t* p, uint32_t v) {
  p[0] = (uint8_t)(v >> 24);
  p[1] = (uint8_t)((v >> 16) & 0xFFU);
  p[2] = (uint8_t)((v >> 8) & 0xFFU);
  p[3] = (uint8_t)(v & 0xFFU);
}
static inline void proto_put_be16(uint8_t* p, uint16_t v) {
  p[0] = (uint8_t)(v >> 8);
  p[1] = (uint8_t)(v & 0xFFU);
}
// Two's-complement reinterpretation without implementation-defined conversion.
static inline int32_t proto_i32(uint32_t u) {
  return (u <= 0x7FFFFFFFU) ? (int32_t)u : (int32_t)(u - 0x80000000U) - (int32_t)0x7FFFFFFF - 1;
}
static inline uint32_t proto_u32(int32_t i) { return (uint32_t)i; }

#endif  // PROTO_BYTES_H
