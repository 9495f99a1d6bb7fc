// SPDX-License-Identifier: MIT
/// b21r_test/alloc_counter.h — counts heap allocations made by the calling thread.
///
/// Every test executable links b21r::test_support, which wraps malloc, calloc, realloc,
/// aligned_alloc, posix_memalign and memalign at link time (`ld --wrap`) for all code linked
/// statically into the test (the project's libraries, Eigen, generated types) and replaces the
/// global C++ operator new family (which also covers allocations made inside libstdc++).
/// Allocations made inside other shared libraries (libc internals, liblcm) are not seen.
///
/// Typical use, proving a code path allocation-free:
/// @code
///   alloc_counter_begin();
///   for (int i = 0; i < 10000; ++i) hedger_update(...);
///   assert_int_equal(alloc_counter_end(), 0);
/// @endcode
/// Counting is per thread (thread-local) so helper threads (LCM, publishers) do not disturb it.
/// Works under AddressSanitizer (the wrappers forward to the sanitizer's allocator).
#ifndef B21R_TEST_ALLOC_COUNTER_H
#define B21R_TEST_ALLOC_COUNTER_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Starts counting this thread's allocations from zero. Nesting is not supported.
void alloc_counter_begin(void);

/// Stops counting; returns the number of allocations (calls that may return new heap memory,
/// including realloc) made by this thread since alloc_counter_begin().
uint64_t alloc_counter_end(void);

/// Allocations counted so far in the current window (counting continues).
uint64_t alloc_counter_peek(void);

/// Bytes requested in the current window (sum of sizes; realloc counts its new size).
uint64_t alloc_counter_bytes(void);

#ifdef __cplusplus
}
#endif

#endif  // B21R_TEST_ALLOC_COUNTER_H
