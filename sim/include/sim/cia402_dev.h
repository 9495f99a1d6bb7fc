// SPDX-License-Identifier: MIT
/// sim/cia402_dev.h — Two emulated CiA 402 drives (translation, rotation) on one CANopen bus:
/// host frames in, drive frames out, in memory (transport-agnostic).
///
/// Every frame goes through lib/proto (proto/canopen.h): host frames are classified and decoded
/// with canopen_classify / canopen_decode_*, the power state machine is cia402_drive_t, and
/// every drive frame is built with canopen_encode_*. The fixed PDO mapping is proto's
/// (protocols.md D.1): RPDO1 = controlword + target velocity (0x60FF), TPDO1 = statusword +
/// velocity actual (0x606C), TPDO2 = position actual (0x6064), all in drive counts.
///
/// Behaviour:
/// - Power-up / NMT reset (node or communication): boot-up heartbeat (state 0), then
///   pre-operational; the drive state machine restarts in SWITCH_ON_DISABLED.
/// - NMT start / stop / pre-operational for the node or for all nodes (node 0).
/// - RPDO1 is processed only in NMT operational: the controlword walks the CiA 402 state
///   machine; the target velocity is followed (under the profile acceleration) only in
///   OPERATION_ENABLED. Any other state, or NMT not operational, commands 0 (quick-stop ramp).
/// - SYNC: the caller decides when the TPDOs answer it (sim_cia402_emit_tpdos: at once in
///   real time; after the period's advance in lockstep). Each drive in NMT operational sends
///   TPDO1 then TPDO2; translation drive first.
/// - Heartbeat: every heartbeat_s of simulated time each drive sends its NMT state.
/// - Faults: sim_cia402_inject_fault puts a drive into FAULT and sends EMCY (error code
///   fault_code, error register 0x03); the condition itself is transient, so the master's
///   fault reset (rising edge of controlword bit 7) recovers it, and the drive then sends
///   EMCY 0x0000 (error reset).
/// - RPDO watchdog: without an RPDO1 for rpdo_timeout_s of simulated time, the drive's target
///   becomes 0 (counted) until the next RPDO1.
/// - Silence (fault injection): until the given time the drives send nothing and ignore frames.
/// - Scale (drive counts): translation K_d = 103000 counts/m, rotation K_a = 35000 counts/rad by
///   default (the rFLEX odometry factors, so both base interfaces use the same counts).
///
/// Memory: sim_cia402_create allocates one object (about 6 KiB). Not thread-safe.
#ifndef B21R_SIM_CIA402_DEV_H
#define B21R_SIM_CIA402_DEV_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include <proto/canopen.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Configuration. Defaults: sim_cia402_config_default.
typedef struct sim_cia402_config {
  uint8_t node_trans;             ///< translation drive node id [1]
  uint8_t node_rot;               ///< rotation drive node id [2]
  double trans_counts_per_m;      ///< [103000]
  double rot_counts_per_rad;      ///< [35000]
  double heartbeat_s;             ///< heartbeat producer time [0.1]; 0 = none
  double accel_trans_mps2;        ///< profile acceleration, translation [0.5]
  double accel_rot_radps2;        ///< profile acceleration, rotation [100000/35000]
  double quick_stop_trans_mps2;   ///< quick-stop deceleration, translation [1.5]
  double quick_stop_rot_radps2;   ///< quick-stop deceleration, rotation [6.0]
  double rpdo_timeout_s;          ///< RPDO watchdog [1.0]; 0 = none
  uint16_t fault_code;            ///< EMCY error code of injected faults [0x2310, over-current]
} sim_cia402_config_t;

/// What the drives report (filled by the emulator from the plant).
typedef struct sim_cia402_sample {
  double pos_trans_m;     ///< translation drive position since the last reset [m]
  double pos_rot_rad;     ///< rotation drive position since the last reset [rad]
  double v_mps;           ///< translation velocity actual
  double omega_radps;     ///< rotation velocity actual
  double pos_trans_at_reset_m;  ///< translation drive position at the last reset [m]
  double pos_rot_at_reset_rad;  ///< rotation drive position at the last reset [rad]
} sim_cia402_sample_t;

/// Axis commands in force.
typedef struct sim_cia402_command {
  double v_mps;
  double omega_radps;
  double accel_trans_mps2;
  double accel_rot_radps2;
} sim_cia402_command_t;

/// Counters (never decrease).
typedef struct sim_cia402_counters {
  uint64_t frames_in;        ///< frames received
  uint64_t frames_out;       ///< frames queued
  uint64_t syncs;            ///< SYNC frames
  uint64_t rpdos;            ///< RPDO1 frames processed
  uint64_t ignored;          ///< frames not for these drives, or not valid in the NMT state
  uint64_t emcy;             ///< EMCY frames sent
  uint64_t rpdo_timeouts;    ///< RPDO watchdog expiries
  uint64_t ignored_silent;   ///< frames ignored while silent
  uint64_t queue_overflows;  ///< frames dropped because the output queue was full
} sim_cia402_counters_t;

/// Result of feeding one frame.
typedef enum sim_cia402_event {
  SIM_CIA402_EV_NONE = 0,
  SIM_CIA402_EV_SYNC = 1,   ///< the frame was a SYNC (the caller answers with the TPDOs)
} sim_cia402_event_t;

typedef struct sim_cia402 sim_cia402_t;

/// Fills the defaults documented above. O(1).
void sim_cia402_config_default(sim_cia402_config_t* cfg);

/// Creates both drives at time 0 and queues their boot-up heartbeats. NULL on invalid config
/// (node ids not 1..127 or equal, factors <= 0, non-finite numbers).
sim_cia402_t* sim_cia402_create(const sim_cia402_config_t* cfg);
void sim_cia402_destroy(sim_cia402_t* d);

/// One host frame received at t_s. O(1).
sim_cia402_event_t sim_cia402_feed(sim_cia402_t* d, const canopen_frame_t* f, double t_s);

/// Next drive frame, if any (returns 1 and fills *f, else 0). O(1).
int sim_cia402_drain(sim_cia402_t* d, canopen_frame_t* f);

/// Queues TPDO1 + TPDO2 of every drive in NMT operational (translation first). O(1).
void sim_cia402_emit_tpdos(sim_cia402_t* d, const sim_cia402_sample_t* s, double t_s);

/// Time-driven work at t_s: heartbeats due, RPDO watchdog. O(1).
void sim_cia402_poll(sim_cia402_t* d, double t_s);

/// Commands in force at t_s. O(1).
void sim_cia402_get_command(sim_cia402_t* d, double t_s, sim_cia402_command_t* out);

/// True when both drives are NMT operational and in OPERATION_ENABLED.
bool sim_cia402_ready(const sim_cia402_t* d);

/// True when both drives are NMT operational (whatever their CiA 402 state).
bool sim_cia402_operational(const sim_cia402_t* d);

/// Puts drive `node` into FAULT and queues its EMCY. Returns 0, or -1 for an unknown node.
int sim_cia402_inject_fault(sim_cia402_t* d, uint8_t node, double t_s);

/// The drives send nothing and ignore frames until t_s; 0 ends it.
void sim_cia402_set_silent_until(sim_cia402_t* d, double t_s);

/// Statusword and NMT state of drive `node` (for tests); returns -1 for an unknown node.
int sim_cia402_drive_state(const sim_cia402_t* d, uint8_t node, uint16_t* statusword,
                           uint8_t* nmt_state);

const sim_cia402_counters_t* sim_cia402_get_counters(const sim_cia402_t* d);

#ifdef __cplusplus
}
#endif

#endif  // B21R_SIM_CIA402_DEV_H
