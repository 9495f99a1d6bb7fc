// SPDX-License-Identifier: MIT
/// fw/timing.h — Tick timing statistics: compute time over a sliding window (p50, p99, max,
/// overruns) and deadline accounting against the absolute schedule (wake-up lateness, late
/// starts, missed periods, the longest gap between tick starts).
///
/// Two times describe a tick k of a real-time loop with period P: its scheduled start S_k (the
/// absolute deadline S_0 + k·P of the monotonic clock) and its actual start A_k (when the tick
/// thread got the CPU and the tick began). Then
///   lateness L_k  = A_k − S_k (the scheduler's and the machine's share: wake-up latency,
///                   preemption, an earlier tick that ran long);
///   compute  C_k  = end of the tick − A_k (the tick's own work);
///   late start    : L_k > the late threshold (config late_start_threshold_s);
///   missed periods: floor(L_k / P) scheduled starts that passed while tick k had not started
///                   (the loop skips them: they never get a tick of their own);
///   overrun       : A_k + C_k > S_k + P (the tick ended after the next scheduled start);
///   gap           : A_k − A_{k−1}, P when every tick is on time.
/// In lockstep a tick starts when the emulator's data arrived: there is no schedule, and only the
/// compute time is recorded.
///
/// Transparent fixed-size struct (no allocation, usable as a member or a static). Recording is
/// O(1); fw_timing_summary() is O(FW_TIMING_WINDOW) (selections over a copy of the windows), so
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
  // Deadline accounting (real time only).
  int32_t late_window_us[FW_TIMING_WINDOW]; ///< ring of the latest wake-up latenesses
  uint32_t late_next;                   ///< its write position
  uint32_t late_filled;                 ///< its valid entries
  int64_t period_us;                    ///< P
  int64_t late_threshold_us;            ///< lateness above this is a late start
  int64_t late_starts;                  ///< ticks that started late (monotonic)
  int64_t missed_periods;               ///< scheduled starts without a tick of their own (monotonic)
  int32_t late_max_ever_us;             ///< largest lateness since start
  int32_t gap_max_ever_us;              ///< longest interval between consecutive tick starts
  int64_t last_start_us;                ///< A_{k−1}; < 0 before the first tick
} fw_timing_t;

/// Summary over the current window; all zero before the first tick.
typedef struct fw_timing_summary_s {
  int32_t p50_us;
  int32_t p99_us;
  int32_t max_us;       ///< longest tick in the window
  int32_t max_ever_us;  ///< longest tick since start
  int64_t ticks;
  int64_t overruns;
  int32_t late_p99_us;      ///< wake-up lateness, nearest-rank p99 over the window
  int32_t late_max_us;      ///< largest lateness in the window
  int32_t late_max_ever_us; ///< largest lateness since start
  int64_t late_starts;
  int64_t missed_periods;
  int32_t gap_max_ever_us;  ///< longest interval between tick starts since start
} fw_timing_summary_t;

/// Resets everything. period_us: the schedule's period P (> 0); late_threshold_us: lateness
/// above which a start counts as late (≥ 0).
void fw_timing_init(fw_timing_t* t, int64_t period_us, int64_t late_threshold_us);

/// Records the start of a tick of the real-time schedule: scheduled start S_k and actual start
/// A_k [µs, monotonic clock]. A start before its schedule (a clock anomaly) counts as on time.
void fw_timing_record_start(fw_timing_t* t, int64_t scheduled_us, int64_t start_us);

/// Records one tick that took compute_us; `overrun` counts a missed deadline. Negative times
/// (a clock anomaly) are recorded as 0.
void fw_timing_record(fw_timing_t* t, int64_t compute_us, bool overrun);

/// Percentiles use the nearest-rank definition over the window; lateness fields are zero until
/// fw_timing_record_start() was called.
fw_timing_summary_t fw_timing_summary(fw_timing_t* t);

#ifdef __cplusplus
}
#endif

#endif  // FW_TIMING_H
