// SPDX-License-Identifier: MIT
// Helpers shared by the libFuzzer targets: a checked assertion, a reader that splits the input
// into typed fields, and an in-memory file for parsers that take a path. The targets are built
// with _GNU_SOURCE (memfd_create).
#ifndef B21R_FUZZ_UTIL_H
#define B21R_FUZZ_UTIL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

/// A property of the code under test; a violation is a finding (abort: libFuzzer saves the input).
#define FUZZ_CHECK(cond)                                                          \
  do {                                                                            \
    if (!(cond)) {                                                                \
      fprintf(stderr, "fuzz: check failed at %s:%d: %s\n", __FILE__, __LINE__, #cond); \
      abort();                                                                    \
    }                                                                             \
  } while (0)

/// Reads typed fields from the front of the input; past the end every field reads as 0.
typedef struct fuzz_in {
  const uint8_t* p;
  size_t n;
} fuzz_in_t;

static inline bool fuzz_more(const fuzz_in_t* in) { return in->n > 0; }

static inline size_t fuzz_bytes(fuzz_in_t* in, void* out, size_t want) {
  const size_t k = want < in->n ? want : in->n;
  if (out != NULL) {
    memcpy(out, in->p, k);
    memset((uint8_t*)out + k, 0, want - k);
  }
  in->p += k;
  in->n -= k;
  return k;
}

static inline uint8_t fuzz_u8(fuzz_in_t* in) {
  uint8_t v = 0;
  (void)fuzz_bytes(in, &v, 1);
  return v;
}

static inline uint16_t fuzz_u16(fuzz_in_t* in) {
  uint8_t b[2];
  (void)fuzz_bytes(in, b, 2);
  return (uint16_t)(b[0] | (b[1] << 8));
}

static inline uint32_t fuzz_u32(fuzz_in_t* in) {
  uint8_t b[4];
  (void)fuzz_bytes(in, b, 4);
  return (uint32_t)b[0] | ((uint32_t)b[1] << 8) | ((uint32_t)b[2] << 16) | ((uint32_t)b[3] << 24);
}

static inline uint64_t fuzz_u64(fuzz_in_t* in) {
  const uint64_t lo = fuzz_u32(in);
  return lo | ((uint64_t)fuzz_u32(in) << 32);
}

/// Any bit pattern, NaN and infinities included.
static inline double fuzz_f64(fuzz_in_t* in) {
  const uint64_t u = fuzz_u64(in);
  double d;
  memcpy(&d, &u, sizeof d);
  return d;
}

/// An in-memory file (memfd) holding given bytes, for parsers that open a path.
typedef struct fuzz_file {
  int fd;
  char path[64];
} fuzz_file_t;

/// Creates the file once (per process). Returns 0 or -1.
static inline int fuzz_file_open(fuzz_file_t* f, const char* name) {
  f->fd = memfd_create(name, MFD_CLOEXEC);
  if (f->fd < 0) {
    return -1;
  }
  snprintf(f->path, sizeof f->path, "/proc/self/fd/%d", f->fd);
  return 0;
}

/// Replaces the contents; returns the path to open.
static inline const char* fuzz_file_set(fuzz_file_t* f, const void* data, size_t n) {
  FUZZ_CHECK(ftruncate(f->fd, 0) == 0);
  FUZZ_CHECK(n == 0 || pwrite(f->fd, data, n, 0) == (ssize_t)n);
  return f->path;
}

#endif  // B21R_FUZZ_UTIL_H
