// SPDX-License-Identifier: MIT
/// sim/rflex_dev.h — An emulated rFLEX base controller (B21r): host packets in, stuffed report
/// packets out, as bytes in memory (transport-agnostic).
///
/// Every packet goes through lib/proto (proto/rflex.h): host bytes are framed by
/// rflex_decoder_push (raw DLEN framing and ESC NUL stuffing both accepted) and classified with
/// rflex_classify; every output packet is built by rflex_make_* and encoded with
/// rflex_encode(..., RFLEX_DEVICE_STUFFED), so each 0x1B inside a packet leaves as `ESC NUL`.
///
/// Behaviour (protocols.md A):
/// - MOT_AXIS_SET_DIR (axis 0 translation, 1 rotation): sets the axis command
///   (velocity counts / K_d [m/s] or / K_a [rad/s]) and its acceleration limit (acc counts /
///   K_d or K_a; an acceleration of 0 keeps the previous limit). A rotation SET_DIR is the end
///   of a command cycle: sim_rflex_feed stops right after it and reports it (lockstep advance).
/// - MOT_BRAKE_SET / RELEASE: while the brake is engaged both axes are commanded to 0. The
///   brake is engaged at power-up (config), so a controller must release it to move.
/// - MOT_SET_DEFAULTS: both commands 0, acceleration limits back to the defaults.
/// - MOT_SYSTEM_REPORT_REQ (period µs, axis mask): odometry reports, one MOT_SYSTEM_REPORT per
///   axis in the mask; period 0 or mask 0 switches them off. Paced (real-time): every period.
///   Lockstep: whenever the emulator calls sim_rflex_emit_odometry (once per control period).
/// - DIO_REPORTS_REQ on the DIO port (period, 0 = off): while on,
///   a DIO_REPORT is sent for each bump panel whose state changed (address 0x40 + panel, value =
///   the pressed-segment bits, 0 on release).
/// - SYS_STATUS request: SYS_STATUS reply (timestamp, battery raw, brake).
/// - SONAR_RUN (including the short SONAR opcode-0 "DIO off" packet of older drivers, which
///   protocols.md A.2 says to ignore), IR_RUN, JSTK, SET_POS and unknown packets are consumed
///   without an answer or effect.
/// - Command watchdog: when no SET_DIR arrived for watchdog_s of simulated time, both axes are
///   commanded to 0 (counted once per silence) until the next SET_DIR.
/// - Report fields: rv 0; timestamp = simulated time in 4 ms ticks (wraps at 2^32); position =
///   round(odometry × K) as a wrapping int32 (translation: signed distance rolled; rotation:
///   bearing = accumulated heading change); velocity = round(axis velocity × K); acceleration =
///   the axis's current acceleration limit in counts/s^2; torque = the last commanded torque.
///   Packet ids count up from 0 (wrapping).
/// - Silence (fault injection): until the given time nothing is sent and packets are ignored.
///
/// Memory: sim_rflex_create allocates one object (about 20 KiB). Not thread-safe.
#ifndef B21R_SIM_RFLEX_DEV_H
#define B21R_SIM_RFLEX_DEV_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include <proto/rflex.h>

#ifdef __cplusplus
extern "C" {
#endif

#define SIM_RFLEX_PANELS 14  ///< bump panels: 0..5 enclosure, 6..13 base skirt (DIO 0x40..0x4D)

/// Configuration. Defaults: sim_rflex_config_default.
typedef struct sim_rflex_config {
  rflex_b21r_params_t params;   ///< K_d, K_a, default accelerations [rflex_b21r_params_default]
  double watchdog_s;            ///< command watchdog [1.0]; 0 disables it
  bool brake_at_power_up;       ///< brake engaged until BRAKE_RELEASE [true]
  double battery_v;             ///< reported battery voltage [24.6]
  bool paced;                   ///< real-time: bytes leave at `baud`, reports at their period [false]
  uint32_t baud;                ///< line rate for pacing [115200]
} sim_rflex_config_t;

/// What the base reports from the body (filled by the emulator from the plant).
typedef struct sim_rflex_sample {
  double odo_trans_m;      ///< translation axis position since the last reset [m]
  double odo_rot_rad;      ///< rotation axis position (accumulated heading change) since the last reset [rad]
  double odo_trans_at_reset_m;  ///< translation axis position at the last reset [m]
  double odo_rot_at_reset_rad;  ///< rotation axis position at the last reset [rad]
  double v_mps;            ///< translation axis velocity
  double omega_radps;      ///< rotation axis velocity
  uint8_t panels[SIM_RFLEX_PANELS];  ///< pressed-segment bits per bump panel (0 = released)
} sim_rflex_sample_t;

/// The axis commands in force (after brake and watchdog).
typedef struct sim_rflex_command {
  double v_mps;
  double omega_radps;
  double accel_trans_mps2;
  double accel_rot_radps2;
} sim_rflex_command_t;

/// Counters (never decrease).
typedef struct sim_rflex_counters {
  uint64_t packets_in;        ///< valid packets received
  uint64_t set_dir;           ///< SET_DIR packets
  uint64_t unanswered;        ///< packets consumed without effect (sonar, IR, unknown, ...)
  uint64_t reports;           ///< MOT_SYSTEM_REPORT packets sent
  uint64_t dio_reports;       ///< DIO_REPORT packets sent
  uint64_t watchdog_trips;    ///< times the watchdog stopped the base
  uint64_t ignored_silent;    ///< packets ignored while silent
  uint64_t queue_overflows;   ///< packets dropped because the output queue was full
} sim_rflex_counters_t;

typedef struct sim_rflex sim_rflex_t;

/// Fills the defaults documented above. O(1).
void sim_rflex_config_default(sim_rflex_config_t* cfg);

/// Creates a base. NULL on invalid config (rflex_b21r_params_check, non-finite numbers).
sim_rflex_t* sim_rflex_create(const sim_rflex_config_t* cfg);
void sim_rflex_destroy(sim_rflex_t* d);

/// Host -> base bytes received at t_s. Consumes bytes until all n are used or a rotation
/// SET_DIR completed; returns the bytes consumed and sets *cycle_end (may be NULL) to 1 in the
/// latter case (the caller advances time in lockstep, then feeds the rest). O(n).
size_t sim_rflex_feed(sim_rflex_t* d, const uint8_t* bytes, size_t n, double t_s, int* cycle_end);

/// Base -> host bytes available by t_s (all when unpaced). O(bytes).
size_t sim_rflex_drain(sim_rflex_t* d, uint8_t* out, size_t cap, double t_s);

/// The commands in force at t_s (applies the watchdog). O(1).
void sim_rflex_get_command(sim_rflex_t* d, double t_s, sim_rflex_command_t* out);

/// True when odometry reports are on (period > 0 and mask != 0).
bool sim_rflex_odometry_on(const sim_rflex_t* d);

/// Real-time service: sends odometry when its period has elapsed and DIO reports for changed
/// panels. O(1).
void sim_rflex_poll(sim_rflex_t* d, const sim_rflex_sample_t* s, double t_s);

/// Queues one MOT_SYSTEM_REPORT per axis in the mask (if reports are on), then DIO reports for
/// changed panels (if DIO is on). Lockstep: once per control period. O(1).
void sim_rflex_emit_odometry(sim_rflex_t* d, const sim_rflex_sample_t* s, double t_s);

/// Queues DIO reports for panels that changed since the last report (if DIO is on). O(panels).
void sim_rflex_emit_dio(sim_rflex_t* d, const sim_rflex_sample_t* s, double t_s);

/// Nothing is sent and packets are ignored until t_s (fault injection); 0 ends it.
void sim_rflex_set_silent_until(sim_rflex_t* d, double t_s);

/// Brake state (1 = engaged).
bool sim_rflex_brake(const sim_rflex_t* d);

const sim_rflex_counters_t* sim_rflex_get_counters(const sim_rflex_t* d);

#ifdef __cplusplus
}
#endif

#endif  // B21R_SIM_RFLEX_DEV_H
