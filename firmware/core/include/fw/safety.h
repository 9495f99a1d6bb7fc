// SPDX-License-Identifier: MIT
/// fw/safety.h — The safety supervisor: decides every tick whether the base must stop, and why.
///
/// The loop gathers the facts of a tick (how long each device has been silent, base faults,
/// bumpers, non-finite numbers, the teleop deadman, signals, operator pause) and calls
/// fw_safety_update() before it computes a command. When a cause is present the supervisor
/// latches a stop with the highest-priority reason and a human-readable detail; the loop then
/// commands zero velocity in that same tick, so a stop takes effect within one tick of the
/// cause being seen. The stop holds until the cause has been absent for clear_ticks ticks and
/// either auto_resume is on or the operator sent RESUME (an operator PAUSE always needs RESUME;
/// a signal never clears).
///
/// Reasons are numbered as b21r_status_t's STOP_* constants. Priority (highest first): signal,
/// device lost, base fault, bumper, non-finite value, laser silence, base silence, deadman, operator.
///
/// Transparent struct, no allocation, O(1) per tick. Not thread-safe: owned by the tick.
#ifndef FW_SAFETY_H
#define FW_SAFETY_H

#include <stdbool.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum fw_stop_reason {
  FW_STOP_NONE = 0,
  FW_STOP_LASER_SILENT = 1,
  FW_STOP_BASE_SILENT = 2,
  FW_STOP_BASE_FAULT = 3,
  FW_STOP_BUMPER = 4,
  FW_STOP_NON_FINITE = 5,
  FW_STOP_DEADMAN = 6,
  FW_STOP_SIGNAL = 7,
  FW_STOP_OPERATOR = 8,
  FW_STOP_DEVICE_LOST = 9,
  FW_STOP_TELEOP_RANGE = 10,  ///< the joystick drives, but its requests exceed the limits (refused)
  FW_STOP_REASON_COUNT = 11
} fw_stop_reason_t;

/// Capacity of the detail text, including the NUL.
#define FW_SAFETY_DETAIL_MAX 160U

/// Thresholds. In lockstep, silence is measured in ticks (the emulator's time only advances
/// with the loop); otherwise in microseconds of the monotonic clock.
typedef struct fw_safety_config {
  bool lockstep;
  int32_t laser_limit_ticks;   ///< lockstep: consecutive ticks without a scan that stop
  int32_t base_limit_ticks;    ///< lockstep: consecutive ticks without odometry that stop
  int64_t laser_limit_us;      ///< real time: age of the newest scan that stops
  int64_t base_limit_us;       ///< real time: age of the newest odometry that stops
  int32_t clear_ticks;         ///< ticks without any cause before a stop may clear (≥ 1)
  bool auto_resume;            ///< clear without an operator RESUME
} fw_safety_config_t;

/// Facts of one tick. Text pointers may be NULL; they are copied, not kept.
typedef struct fw_safety_inputs {
  int32_t laser_silent_ticks;  ///< ticks since the last complete scan (0 = one arrived now)
  int32_t base_silent_ticks;   ///< ticks since the last odometry report
  int64_t laser_age_us;        ///< now − time of the last scan
  int64_t base_age_us;         ///< now − time of the last odometry
  uint64_t laser_bad_since_scan; ///< bytes dropped + telegrams refused (CRC) since the last scan:
                               ///< a silent laser with these > 0 is reported as a corrupt stream
  int32_t laser_repeats;       ///< telegrams in a row that repeated the last scan bit for bit: a
                               ///< silent laser with this > 0 is reported as stuck
  bool device_lost;            ///< a device is gone (EOF, EIO, ENODEV, hang-up) or, in lockstep, silent
  const char* device_lost_detail; ///< e.g. "laser device lost: /dev/ttyUSB0 (EIO)"
  bool base_fault;             ///< EMCY, statusword fault, heartbeat lost, watchdog, bump-panel node silent
  const char* base_fault_detail;
  uint32_t bumper_mask;        ///< bit n = bump panel n pressed (B21r: 14 panels)
  bool non_finite;             ///< a NaN/Inf anywhere in the tick's numbers
  const char* non_finite_where;
  bool deadman_required;       ///< the joystick drives now
  bool deadman_fresh;          ///< a valid TELEOP with deadman held arrived within the timeout
  bool teleop_out_of_range;    ///< the newest TELEOP was refused for exceeding the limits
  const char* teleop_range_detail; ///< e.g. "B21R_TELEOP rotation 2.00 rad/s over the limit 1.00 rad/s"
  int signal_number;           ///< SIGINT/SIGTERM seen (0 = none)
  bool operator_pause;         ///< B21R_COMMAND PAUSE in force
  bool operator_resume;        ///< B21R_COMMAND RESUME arrived this tick
} fw_safety_inputs_t;

/// What the supervisor decided this tick.
typedef enum fw_safety_event {
  FW_SAFETY_OK = 0,        ///< no stop in force
  FW_SAFETY_STOP_BEGAN,    ///< a stop began this tick (log it)
  FW_SAFETY_STOPPED,       ///< a stop continues
  FW_SAFETY_RESUMED,       ///< the stop cleared this tick (start a new run)
} fw_safety_event_t;

typedef struct fw_safety {
  fw_safety_config_t cfg;
  bool stopped;
  int32_t reason;                      ///< fw_stop_reason_t in force (NONE when not stopped)
  char detail[FW_SAFETY_DETAIL_MAX];   ///< why, for STATUS and the log ("" when not stopped)
  int32_t clear_count;                 ///< consecutive ticks without a cause
  bool resume_requested;               ///< an operator RESUME arrived during this stop
  int64_t stops;                       ///< stops begun (monotonic)
  int64_t stops_by_reason[FW_STOP_REASON_COUNT];  ///< monotonic
} fw_safety_t;

void fw_safety_init(fw_safety_t* s, const fw_safety_config_t* cfg);

/// Evaluates one tick. O(1), no allocation (snprintf into the fixed detail buffer).
fw_safety_event_t fw_safety_update(fw_safety_t* s, const fw_safety_inputs_t* in);

/// Short name of a reason ("laser silent", ...), "" if out of range.
const char* fw_stop_reason_name(int32_t reason);

#ifdef __cplusplus
}
#endif

#endif  // FW_SAFETY_H
