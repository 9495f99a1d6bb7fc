// SPDX-License-Identifier: MIT
// Sliding-window tick statistics and deadline accounting; percentiles by quickselect over a
// scratch copy.
#include "fw/timing.h"

#include <string.h>

void fw_timing_init(fw_timing_t* t, int64_t period_us, int64_t late_threshold_us) {
  memset(t, 0, sizeof *t);
  t->period_us = period_us > 0 ? period_us : 1;
  t->late_threshold_us = late_threshold_us > 0 ? late_threshold_us : 0;
  t->last_start_us = -1;
}

// A duration clamped to [0, INT32_MAX] µs (negative = a clock anomaly).
static int32_t clamp_us(int64_t us) {
  if (us > INT32_MAX) {
    return INT32_MAX;
  }
  return us > 0 ? (int32_t)us : 0;
}

void fw_timing_record_start(fw_timing_t* t, int64_t scheduled_us, int64_t start_us) {
  const int64_t late = start_us > scheduled_us ? start_us - scheduled_us : 0;
  const int32_t v = clamp_us(late);
  t->late_window_us[t->late_next] = v;
  t->late_next = (t->late_next + 1U) % FW_TIMING_WINDOW;
  if (t->late_filled < FW_TIMING_WINDOW) {
    t->late_filled++;
  }
  if (late > t->late_threshold_us) {
    t->late_starts++;
  }
  t->missed_periods += late / t->period_us;
  if (v > t->late_max_ever_us) {
    t->late_max_ever_us = v;
  }
  if (t->last_start_us >= 0) {
    const int32_t gap = clamp_us(start_us - t->last_start_us);
    if (gap > t->gap_max_ever_us) {
      t->gap_max_ever_us = gap;
    }
  }
  t->last_start_us = start_us;
}

void fw_timing_record(fw_timing_t* t, int64_t compute_us, bool overrun) {
  const int32_t v = clamp_us(compute_us);
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

// Nearest rank: the ceil(p*n)-th smallest, as a 0-based index (n > 0).
static uint32_t rank_p50(uint32_t n) { return (n + 1U) / 2U - 1U; }
static uint32_t rank_p99(uint32_t n) { return (uint32_t)((99U * n + 99U) / 100U) - 1U; }

// Copies the first n entries of window into scratch; returns their maximum.
static int32_t copy_max(int32_t* scratch, const int32_t* window, uint32_t n) {
  memcpy(scratch, window, n * sizeof(int32_t));
  int32_t mx = 0;
  for (uint32_t i = 0; i < n; ++i) {
    if (scratch[i] > mx) {
      mx = scratch[i];
    }
  }
  return mx;
}

fw_timing_summary_t fw_timing_summary(fw_timing_t* t) {
  fw_timing_summary_t s;
  memset(&s, 0, sizeof s);
  s.ticks = t->ticks;
  s.overruns = t->overruns;
  s.max_ever_us = t->max_ever_us;
  s.late_max_ever_us = t->late_max_ever_us;
  s.late_starts = t->late_starts;
  s.missed_periods = t->missed_periods;
  s.gap_max_ever_us = t->gap_max_ever_us;
  const uint32_t n = t->filled;
  if (n > 0U) {
    s.max_us = copy_max(t->scratch_us, t->window_us, n);
    s.p50_us = select_kth(t->scratch_us, n, rank_p50(n));
    s.p99_us = select_kth(t->scratch_us, n, rank_p99(n));
  }
  const uint32_t m = t->late_filled;
  if (m > 0U) {
    s.late_max_us = copy_max(t->scratch_us, t->late_window_us, m);
    s.late_p99_us = select_kth(t->scratch_us, m, rank_p99(m));
  }
  return s;
}
