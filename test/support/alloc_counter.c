// SPDX-License-Identifier: MIT
// Link-time malloc wrappers that count allocations per thread (see alloc_counter.h).
#define _GNU_SOURCE 1
#include "b21r_test/alloc_counter.h"

#include <malloc.h>
#include <stdbool.h>
#include <stdlib.h>

// Declared here because the linker provides them for --wrap=<symbol>.
void* __real_malloc(size_t size);
void* __real_calloc(size_t n, size_t size);
void* __real_realloc(void* ptr, size_t size);
void* __real_aligned_alloc(size_t alignment, size_t size);
int __real_posix_memalign(void** out, size_t alignment, size_t size);
void* __real_memalign(size_t alignment, size_t size);
void* __wrap_malloc(size_t size);
void* __wrap_calloc(size_t n, size_t size);
void* __wrap_realloc(void* ptr, size_t size);
void* __wrap_aligned_alloc(size_t alignment, size_t size);
int __wrap_posix_memalign(void** out, size_t alignment, size_t size);
void* __wrap_memalign(size_t alignment, size_t size);

static _Thread_local bool tl_active;
static _Thread_local uint64_t tl_count;
static _Thread_local uint64_t tl_bytes;

static void note(size_t size) {
  if (tl_active) {
    tl_count++;
    tl_bytes += size;
  }
}

void alloc_counter_begin(void) {
  tl_count = 0;
  tl_bytes = 0;
  tl_active = true;
}

uint64_t alloc_counter_end(void) {
  tl_active = false;
  return tl_count;
}

uint64_t alloc_counter_peek(void) { return tl_count; }

uint64_t alloc_counter_bytes(void) { return tl_bytes; }

void* __wrap_malloc(size_t size) {
  note(size);
  return __real_malloc(size);
}

void* __wrap_calloc(size_t n, size_t size) {
  note(n * size);
  return __real_calloc(n, size);
}

void* __wrap_realloc(void* ptr, size_t size) {
  note(size);
  return __real_realloc(ptr, size);
}

void* __wrap_aligned_alloc(size_t alignment, size_t size) {
  note(size);
  return __real_aligned_alloc(alignment, size);
}

int __wrap_posix_memalign(void** out, size_t alignment, size_t size) {
  note(size);
  return __real_posix_memalign(out, alignment, size);
}

void* __wrap_memalign(size_t alignment, size_t size) {
  note(size);
  return __real_memalign(alignment, size);
}
