// SPDX-License-Identifier: MIT
// Little-endian byte codecs and CRC-32 of the libraries' save formats (internal).
//
// Internal header of lib/hedger, shared through the hedger_internal target: HEDGER's byte format
// (hedger.cpp) and the actor's (lib/actor) write and check their bytes with the same functions.
// Pure functions: no allocation, O(n) in the bytes touched.
#ifndef HEDGER_BYTES_HPP
#define HEDGER_BYTES_HPP

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>

namespace hg {

struct Crc32Table {
  uint32_t t[256];
  constexpr Crc32Table() : t() {
    for (uint32_t i = 0; i < 256; ++i) {
      uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1u) ? (0xEDB88320u ^ (c >> 1)) : (c >> 1);
      t[i] = c;
    }
  }
};
inline constexpr Crc32Table kCrc{};

/// CRC-32 register after n more bytes (start with 0xFFFFFFFF; the CRC is the register ^ 0xFFFFFFFF).
/// IEEE 802.3 (reflected 0xEDB88320), as zlib's crc32().
inline uint32_t crc32_update(uint32_t c, const uint8_t* p, size_t n) {
  for (size_t i = 0; i < n; ++i) c = kCrc.t[(c ^ p[i]) & 0xFFu] ^ (c >> 8);
  return c;
}

inline uint32_t crc32(const uint8_t* p, size_t n) { return crc32_update(0xFFFFFFFFu, p, n) ^ 0xFFFFFFFFu; }

inline uint32_t f32_bits(float f) {
  uint32_t u;
  std::memcpy(&u, &f, sizeof u);
  return u;
}

inline float bits_f32(uint32_t u) {
  float f;
  std::memcpy(&f, &u, sizeof f);
  return f;
}

inline void put_u32(uint8_t* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}
inline void put_u64(uint8_t* p, uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}
inline void put_f64(uint8_t* p, double v) {
  uint64_t u;
  std::memcpy(&u, &v, sizeof u);
  put_u64(p, u);
}
inline uint32_t get_u32(const uint8_t* p) {
  uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= static_cast<uint32_t>(p[i]) << (8 * i);
  return v;
}
inline uint64_t get_u64(const uint8_t* p) {
  uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= static_cast<uint64_t>(p[i]) << (8 * i);
  return v;
}
inline double get_f64(const uint8_t* p) {
  const uint64_t u = get_u64(p);
  double v;
  std::memcpy(&v, &u, sizeof v);
  return v;
}
/// Equal bit for bit (a saved configuration value against the instance's).
inline bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

/// True when every one of the n values is finite.
inline bool finite_all(const double* v, uint32_t n) {
  for (uint32_t i = 0; i < n; ++i) {
    if (!std::isfinite(v[i])) return false;
  }
  return true;
}

}  // namespace hg

#endif  // HEDGER_BYTES_HPP
