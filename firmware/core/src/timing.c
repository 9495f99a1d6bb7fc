// SPDX-License-Identifier: MIT
// Sliding-window tick statistics; percentiles by quickselect over a scratch copy.
#include "fw/timing.h"

#include <string.h>

void fw_timing_init(fw_timing_t* t) { memset(t, 0, sizeof *t); }

void fw_timing_record(fw_timing_t* t, int64_t compute_us, bool overrun) {
  int32_t v = 0;
  if (compute_us > INT32_MAX) {
    v = INT32_MAX;
  } else if (compute_us > 0) {
    v = (int32_t)compute_us;
  }
  t->window_us[t->next] = v;
  t->next = (t->next + 1U) % FW_TIMING_WINDOW;
  if (t->filled < FW_TIMING_WINDOW) {
    t->filled++;
  }
  t->ticks++;
  if (overrun) {
    t->overruns++;
  }
  if (v > t->max_ever_us) {
    t->max_ever_us = v;
  }
}

// k-th smallest (0-based) of a[0..n-1], reordering a. Hoare partition, middle pivot: O(n) expected;
// timing values are not adversarial.
static int32_t select_kth(int32_t* a, uint32_t n, uint32_t k) {
  uint32_t lo = 0;
  uint32_t hi = n - 1U;
  while (lo < hi) {
    const int32_t pivot = a[lo + (hi - lo) / 2U];
    uint32_t i = lo;
    uint32_t j = hi;
    while (i <= j) {
      while (a[i] < pivot) {
        ++i;
      }
      while (a[j] > pivot) {
        --j;
      }
      if (i <= j) {
        const int32_t tmp = a[i];
        a[i] = a[j];
        a[j] = tmp;
        ++i;
        if (j == 0U) {
          break;
        }
        --j;
      }
    }
    if (k <= j) {
      hi = j;
    } else if (k >= i) {
      lo = i;
    } else {
      return a[k];
    }
  }
  return a[k];
}

fw_timing_summary_t fw_timing_summary(fw_timing_t* t) {
  fw_timing_summary_t s;
  memset(&s, 0, sizeof s);
  s.ticks = t->ticks;
  s.overruns = t->overruns;
  s.max_ever_us = t->max_ever_us;
  const uint32_t n = t->filled;
  if (n == 0U) {
    return s;
  }
  memcpy(t->scratch_us, t->window_us, n * sizeof(int32_t));
  int32_t mx = 0;
  for (uint32_t i = 0; i < n; ++i) {
    if (t->scratch_us[i] > mx) {
      mx = t->scratch_us[i];
    }
  }
  s.max_us = mx;
  // Nearest rank: the ceil(p*n)-th smallest.
  const uint32_t k50 = (n + 1U) / 2U - 1U;
  const uint32_t k99 = (uint32_t)((99U * n + 99U) / 100U) - 1U;
  s.p50_us = select_kth(t->scratch_us, n, k50);
  s.p99_us = select_kth(t->scratch_us, n, k99);
  return s;
}
