// SPDX-License-Identifier: MIT
/// fw/timing.h — Tick timing statistics over a sliding window: p50, p99, max and overruns.
///
/// Transparent fixed-size struct (no allocation, usable as a member or a static). Recording is
/// O(1); fw_timing_summary() is O(FW_TIMING_WINDOW) (a selection over a copy of the window), so
/// call it at the STATUS rate. Not thread-safe: owned by the tick.
#ifndef FW_TIMING_H
#define FW_TIMING_H

#include <stdbool.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Ticks in the sliding window (about 100 s at 10 Hz).
#define FW_TIMING_WINDOW 1024U

typedef struct fw_timing {
  int32_t window_us[FW_TIMING_WINDOW];  ///< ring of the latest tick compute times
  int32_t scratch_us[FW_TIMING_WINDOW]; ///< work space of fw_timing_summary
  uint32_t next;                        ///< ring write position
  uint32_t filled;                      ///< valid entries (≤ FW_TIMING_WINDOW)
  int64_t ticks;                        ///< ticks recorded (monotonic)
  int64_t overruns;                     ///< ticks that missed their deadline (monotonic)
  int32_t max_ever_us;                  ///< longest tick since start
} fw_timing_t;

/// Summary over the current window; all zero before the first tick.
typedef struct fw_timing_summary_s {
  int32_t p50_us;
  int32_t p99_us;
  int32_t max_us;       ///< longest tick in the window
  int32_t max_ever_us;  ///< longest tick since start
  int64_t ticks;
  int64_t overruns;
} fw_timing_summary_t;

void fw_timing_init(fw_timing_t* t);

/// Records one tick that took compute_us; `overrun` counts a missed deadline. Negative times
/// (a clock anomaly) are recorded as 0.
void fw_timing_record(fw_timing_t* t, int64_t compute_us, bool overrun);

/// Percentiles use the nearest-rank definition over the window.
fw_timing_summary_t fw_timing_summary(fw_timing_t* t);

#ifdef __cplusplus
}
#endif

#endif  // FW_TIMING_H
