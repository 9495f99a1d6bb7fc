// SPDX-License-Identifier: MIT
// Private state of the loop core, shared by loop.c (tick, schedule, learning) and base.c
// (rFLEX / CANopen adapters).
#ifndef FW_LOOP_INTERNAL_H
#define FW_LOOP_INTERNAL_H

#include "fw/loop.h"
#include "fw/safety.h"
#include "fw/timing.h"

#include <features/features.h>
#include <hedger/hedger.h>
#include <proto/canopen.h>
#include <proto/lms200.h>
#include <proto/rflex.h>
#include <tasks/tasks.h>

#include <pthread.h>
#include <stdatomic.h>

#define FW_MAX_STATE 8
#define FW_MAILBOX 8

typedef struct fw_drive {
  uint8_t node;
  cia402_master_t master;
  canopen_hb_consumer_t hb;
  uint16_t statusword;
  bool sw_seen;
  bool tpdo1_new;   // since the last tick
  bool tpdo2_new;
  int32_t position;
  int32_t velocity;
  uint16_t emcy_code;
  bool emcy_seen;   // an EMCY with a non-zero code arrived and no good statusword since
} fw_drive_t;

struct fw_loop {
  fw_config_t cfg;
  fw_io_t io;
  fw_loop_outputs_t out;
  int64_t period_us;
  double dt_s;

  // Task.
  tasks_corridor_spec_t corridor;
  features_corridor_config_t corridor_fc;
  tasks_obstacles_spec_t obstacles;
  features_obstacles_config_t obstacles_fc;
  uint32_t state_dim;
  double omega_max;
  double gamma;

  // Learner.
  void* hedger_storage;
  hedger_t* hedger;
  size_t hedger_save_max;

  // Laser.
  lms_scan_t scan_raw;
  features_scan_t scan;
  bool have_scan;
  bool scan_new;
  int64_t last_scan_us;
  int32_t laser_silent_ticks;
  int64_t laser_scans;
  bool laser_error_logged;

  // Base (both protocols integrate odometry with the rFLEX rule).
  rflex_odometry_t odo;
  bool odo_new[2];
  int32_t base_silent_ticks;
  int64_t last_base_us;
  int64_t base_packets;
  uint32_t bumper_mask;
  bool base_fault;
  char base_fault_detail[128];
  // rFLEX.
  rflex_b21r_params_t rflex;
  rflex_decoder_t rdec;
  uint8_t rbuf[1024];
  bool brake_expected_released;
  int8_t brake_reported;       // -1 unknown, 0 released, 1 engaged
  int32_t sys_status_countdown;
  double battery_v;
  // CANopen.
  fw_drive_t drive[2];
  int64_t can_start_us;

  // Mailboxes (filled by other threads).
  pthread_mutex_t mbox_mu;
  b21r_teleop_t teleop_box[FW_MAILBOX];
  int64_t teleop_arrival[FW_MAILBOX];
  uint32_t teleop_n;
  b21r_command_t cmd_box[FW_MAILBOX];
  uint32_t cmd_n;
  uint64_t mbox_overflow_teleop;
  uint64_t mbox_overflow_cmd;
  atomic_int signal_number;

  // Operator input state.
  bool teleop_have_seq;
  int64_t teleop_last_seq;
  bool teleop_deadman;
  double teleop_rot_radps;
  int64_t teleop_last_us;
  int64_t teleop_accepted;
  int64_t teleop_rejected;
  int64_t teleop_rejected_nan;
  int64_t teleop_rejected_range;
  int64_t teleop_rejected_seq;
  int64_t teleop_rejected_stale;
  bool cmd_have_seq;
  int64_t cmd_last_seq;
  int64_t commands_accepted;
  int64_t commands_rejected;
  bool paused;
  bool resume_now;
  bool confirm_pending;
  bool shutdown_requested;

  // Supervisors.
  fw_safety_t safety;
  fw_timing_t timing;
  fw_schedule_t sched;

  // Random streams.
  tasks_rng_t pose_rng;
  tasks_rng_t explore_rng;
  uint64_t driver_seed_base;
  tasks_driver_t driver;

  // Run state.
  int32_t mode;                // b21r_status_t MODE_*
  fw_run_plan_t plan;
  bool pose_requested;
  bool awaiting_confirm;
  int32_t settle_ticks;
  int32_t retry_countdown;
  bool stopped_pose_requested; // a start pose was requested while stopped (bumper case)
  features_pose_t start_pose;
  features_pose_t odom_at_start;
  int32_t run_id;
  int32_t actions_taken;       // actions executed in the current run
  bool have_prev;
  double prev_s[FW_MAX_STATE];
  double prev_a;
  double prev_v;
  int8_t prev_source;
  double s[FW_MAX_STATE];
  bool s_valid;
  features_corridor_t fcor;
  features_obstacles_t fobs;
  double run_return;

  // Command.
  double cmd_v;
  double cmd_w;

  // Output bookkeeping.
  int64_t tick_count;
  int64_t utime;               // of the current tick
  int64_t exp_seq;
  int64_t exp_dropped;
  int64_t steps;
  int64_t held_ticks;
  int64_t next_deadline_us;
  int64_t tick_deadline_us;
  bool started;
  bool done;
  int exit_status;
  bool status_now;
  int32_t status_countdown;
  int32_t runs_finished;
  int32_t runs_aborted;
  int32_t last_run_steps;
  bool last_run_goal;
  fw_eval_block_t last_block;
  int64_t checkpoints_submitted;
  int64_t checkpoints_skipped;
};

// base.c: protocol adapters.
int fw_base_start(fw_loop_t* L, char* err, size_t err_cap);
void fw_base_poll(fw_loop_t* L, int64_t now_us);
bool fw_base_all_reports(const fw_loop_t* L);
bool fw_base_any_report(const fw_loop_t* L);
void fw_base_clear_flags(fw_loop_t* L);
void fw_base_evaluate_faults(fw_loop_t* L, int64_t now_us);
void fw_base_command(fw_loop_t* L, double v_mps, double w_radps, bool stopping);
void fw_base_shutdown(fw_loop_t* L);
uint64_t fw_base_bytes_dropped(const fw_loop_t* L);
uint64_t fw_base_checksum_errors(const fw_loop_t* L);

// loop.c helpers shared with base.c.
void fw_loop_log(fw_loop_t* L, int stream, const char* format, ...) __attribute__((format(printf, 3, 4)));

#endif  // FW_LOOP_INTERNAL_H
