// SPDX-License-Identifier: MIT
/// fw/prefault.h — Touching memory before the loop starts, so that no page fault happens in a
/// tick (config rt_prefault).
///
/// A fresh allocation of the C library is only address space: the kernel maps a zeroed page on
/// the first write to it, a minor fault of a few microseconds each, or far more under memory
/// pressure. Writing one byte per page (its own value, so contents are kept) maps every page
/// now. With rt_lock_memory (mlockall) the pages then also stay resident.
/// Cost: one read and one write per 4 KiB page; call at start-up only, from the thread that owns
/// the memory (or before other threads use it).
#ifndef FW_PREFAULT_H
#define FW_PREFAULT_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Smallest page size of the supported targets (x86-64, AArch64 with 4 KiB pages); touching
/// more often than the real page size is harmless.
#define FW_PREFAULT_PAGE_BYTES 4096U

/// Maps every page of [p, p + n) by writing each page's first byte of the range back to itself
/// (volatile: the compiler keeps the self-assignment). NULL or n = 0: nothing. O(n / 4 KiB).
void fw_prefault(void* p, size_t n);

#ifdef __cplusplus
}
#endif

#endif  // FW_PREFAULT_H
