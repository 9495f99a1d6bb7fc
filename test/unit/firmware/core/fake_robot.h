// SPDX-License-Identifier: MIT
/// fake_robot.h — A deterministic in-process B21r for loop-core tests and the firmware
/// benchmark: the analytic corridor world and kinematic synchro drive of b21r_test/synthetic_world.h
/// behind the loop's I/O vtable, speaking the real byte protocols (LMS200 0xB0 telegrams decoded
/// with lib/proto, rFLEX packets stuffed as the base sends them, CiA 402 frames and the CiA 401
/// bump-panel node's TPDO1).
///
/// Lockstep like the emulator's contract: time advances one control period when the rotation
/// SET_DIR (rFLEX) or SYNC (CANopen) arrives; then the scan and the odometry of the new period
/// are queued. Streaming (and time) starts with rFLEX's odometry request, on CANopen at the SYNC
/// that finds both drives enabled; the start's SYNCs before it are answered at the current time.
/// The clock is simulated: `wait` jumps it to the deadline when nothing is pending.
/// Fault injection mirrors the emulator's control socket (laser drop, base silence, drive fault,
/// bumper, bump-panel node silence, corrupt bytes). No allocation after fake_robot_init. Not thread-safe.
#ifndef B21R_TEST_FAKE_ROBOT_H
#define B21R_TEST_FAKE_ROBOT_H

#include "fw/io.h"

#include <b21r_test/synthetic_world.h>
#include <proto/canopen.h>
#include <proto/lms200.h>
#include <proto/rflex.h>

#include <stdbool.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define FAKE_BYTES 16384
#define FAKE_FRAMES 64

typedef struct fake_robot {
  // World and body.
  synth_world_t world;
  synth_lidar_config_t lidar;
  synth_rng_t rng;
  synth_robot_t robot;
  synth_drive_limits_t limits;
  double dt_s;
  double k_d;   // counts per metre
  double k_a;   // counts per radian
  double trans_pos_m;   // wheel odometry accumulators
  double rot_pos_rad;
  bool collided;
  int64_t clock_us;
  int64_t ticks;        // periods simulated
  bool streaming;
  /// false (default): lockstep, a period advances with each velocity command, as b21r-sim
  /// --lockstep; true: real time, a period advances whenever the clock (moved by the loop's
  /// waits) passes its end, as b21r-sim without --lockstep (rFLEX base).
  bool paced;
  int64_t next_period_us;  ///< paced: end of the period under way
  bool canopen;
  // Commands.
  double v_cmd;
  double w_cmd;
  bool brake;
  // Laser link: the host side decodes real telegrams.
  uint8_t laser_bytes[FAKE_BYTES];
  uint32_t laser_fill;
  uint16_t last_raw[SYNTH_MAX_BEAMS];  // the last scan's raw values (repeated while stuck)
  int last_n;
  lms_decoder_t lms_dec;
  // Base link.
  uint8_t base_bytes[FAKE_BYTES];   // device -> host
  uint32_t base_fill;
  rflex_decoder_t host_dec;         // host -> device packets
  uint8_t dev_id;
  canopen_frame_t frames[FAKE_FRAMES];
  int64_t frame_ready_us[FAKE_FRAMES];  ///< clock time from which each queued frame can be read
  uint32_t n_frames;
  /// CAN frames become readable this long after they are sent [µs] (0 = at once), while the
  /// laser's bytes are readable at once: the bus reaches the host later than the laser's line,
  /// as separate channels may on a loaded machine.
  int64_t can_lag_us;
  /// In period can_stall_period (counted like ticks), the frames after the bump-panel node's
  /// heartbeat become readable can_stall_us later (0 = never): the emulator stalled between two
  /// frames of one period, as a loaded machine's scheduler may stop it.
  int64_t can_stall_us;
  int64_t can_stall_period;
  int64_t stall_extra_us;  ///< added to the frames pushed now (the stall under way)
  cia402_drive_t drive[2];
  int32_t drive_target[2];
  // CANopen bump-panel node (node 16): TPDO1 on NMT start, on change and once per period.
  uint8_t bump_panels[CIA401_BUMP_PANELS];
  bool bump_operational;
  bool bump_absent;          ///< no such node on the bus (start-up must fail naming it)
  int32_t bump_silent_ticks; ///< periods the node sends nothing
  int32_t bump_hb_silent_ticks; ///< periods the node sends no heartbeat while its PDOs go on (a hung application)
  int64_t bump_pdos;
  // Faults.
  int32_t laser_drop_ticks;
  int32_t laser_stuck_ticks;  ///< periods whose scan repeats the last distances (a frozen sensor)
  int32_t base_silent_ticks;
  int32_t bumper_ticks;
  double corrupt_fraction;
  bool nan_odometry;
  /// A signal handler's wake-up: the first wait whose deadline passes wake_at_us returns at that
  /// time after calling wake(wake_user) once (which, like the controller's handler, calls
  /// fw_loop_signal). NULL: none.
  void (*wake)(void* user);
  void* wake_user;
  int64_t wake_at_us;
  // Counters.
  int64_t start_pose_requests;
  uint64_t start_pose_run;        ///< the run id given with the last start-pose request
  int64_t commands;
  int64_t laser_telegrams;
  int64_t busy_ns;      ///< CPU time of the calling thread spent simulating (advance), to subtract in benchmarks
} fake_robot_t;

/// Builds the paper's 10 m × 2 m corridor with the LMS200 180°/1° laser (noise 1 cm, seeded),
/// the robot at rest at (1, 0, 0). canopen selects the bus (else rFLEX). dt_s: control period.
void fake_robot_init(fake_robot_t* f, bool canopen, double dt_s, uint64_t seed);

/// The binding for the loop: vtable + this fake as user.
fw_io_t fake_robot_io(fake_robot_t* f);

#ifdef __cplusplus
}
#endif

#endif  // B21R_TEST_FAKE_ROBOT_H
