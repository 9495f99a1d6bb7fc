// SPDX-License-Identifier: MIT
// Private state of the loop core (struct fw_loop), shared by the files of the loop, each of which
// declares its own functions in its own private header:
//   loop.c      the tick (sense → safety → decide → act → learn → publish), pacing, start-up,
//               shutdown;
//   run.c       the run lifecycle (repositioning, start poses, the task's driver, run ends) around
//               the learning framework (lib/learn), which decides who acts and learns;
//   learning.c  the framework's set-up from the configuration and the task, the step's update
//               after the command, the between-run work (the framework's replay, then the
//               checkpoint) in bounded slices, checkpoints;
//   outputs.c   the messages (experience, pose, scan, eval, status, text lines);
//   operator.c  B21R_TELEOP / B21R_COMMAND mailboxes and their validation;
//   base.c      the base adapters (rFLEX bytes, CANopen frames).
#ifndef FW_LOOP_STATE_H
#define FW_LOOP_STATE_H

#include "fw/journal.h"
#include "fw/loop.h"
#include "fw/safety.h"
#include "fw/timing.h"

#include <features/features.h>
#include <hedger/hedger.h>
#include <learn/learn.h>
#include <proto/canopen.h>
#include <proto/lms200.h>
#include <proto/rflex.h>
#include <tasks/episode.h>
#include <tasks/tasks.h>

#include <pthread.h>
#include <stdatomic.h>

#define FW_MAILBOX 8

typedef struct fw_drive {
  uint8_t node;
  cia402_master_t master;
  canopen_hb_consumer_t hb;
  uint16_t statusword;
  bool sw_seen;
  bool tpdo1_new;   // since the last tick
  bool tpdo2_new;
  uint32_t tpdo1_count; // since the NMT start (wraps): lockstep matches them with the SYNCs sent
  uint32_t tpdo2_count;
  int32_t position;
  int32_t velocity;
  uint16_t emcy_code;
  bool emcy_seen;   // an EMCY with a non-zero code arrived and no good statusword since
  // Plausibility of its answers: a drive that reports a velocity moves, so a position that stands
  // still answer after answer is a stale PDO (the node's application hangs, its CAN controller
  // keeps sending what it last wrote).
  bool have_position;
  int32_t stale_answers; // TPDO2s in a row with the same position while the TPDO1 velocity is not ~0
  uint32_t deficit;     // SYNCs without its answer when the last SYNC went out (already counted)
} fw_drive_t;

/// The CiA 401 bump-panel node (CANopen base): its TPDO1 carries the 14 panels' contact bits,
/// sent on change and every event timer, so a silent node is told from released panels.
typedef struct fw_bump_node {
  uint8_t node;
  bool seen;            // a valid TPDO1 arrived since the (re)start
  bool pdo_new;         // since the last tick
  int32_t silent_ticks; // lockstep: ticks without a valid TPDO1
  int64_t last_us;      // time of the last valid TPDO1 (bus clock, read in real time only)
  uint32_t mask;        // bit p = panel p pressed (as rflex_host_t.bumper_mask)
  uint64_t pdos;        // valid TPDO1 frames
  uint64_t bad_pdos;    // its TPDO1 COB-ID with a DLC below 7 (ignored)
  uint64_t bootups;     // boot-up messages: the node restarted (it is started again)
  uint64_t frames;      // every frame from its id (tells a mute node from a PDO-less one)
  canopen_hb_consumer_t hb; // its heartbeat (supervised with can_heartbeat_timeout_s > 0): a node
                            // whose application hangs may keep sending stale PDOs, not heartbeats
} fw_bump_node_t;

/// The learner's work after a step or between runs (learning.c).
typedef enum fw_learn_stage {
  FW_LEARN_IDLE = 0,     ///< nothing to do between runs
  FW_LEARN_REPLAY = 1,   ///< the framework's between-run work (backward replay, the actor's learning), in slices
  FW_LEARN_SAVE = 2,     ///< serialising the learned state into the checkpoint writer, in slices
} fw_learn_stage_t;

/// Reports that wait until their run is on disk (outputs.c): B21R_RUN, B21R_EVAL, progress lines.
#define FW_HELD_REPORTS 64

typedef struct fw_held_report {
  int32_t run_id;  // released once every run up to it is durable (fw_ckpt_writer_durable_run)
  int32_t kind;    // FW_MSG_RUN, FW_MSG_EVAL or FW_MSG_TEXT
  union {
    struct {
      b21r_run_t msg;
      learn_schedule_progress_t progress;  // the schedule after the run
    } run;
    learn_eval_block_t eval;
    char line[FW_TEXT_MAX];
  } u;
} fw_held_report_t;

struct fw_loop {
  fw_config_t cfg;
  fw_io_t io;
  fw_loop_outputs_t out;
  int64_t period_us;
  double dt_s;

  // Task: specs, feature extractors, the current run's frame and newest features.
  tasks_episode_t ep;
  tasks_command_limits_t limits;
  double omega_max;
  double features[LEARN_MAX_TASK_STATE];  // the task's state of the newest usable scan

  // The learning framework (lib/learn) in its own block, and the between-run work around it.
  learn_t* agent;
  void* agent_storage;         // owned; agent_bytes long (pre-faulted with rt_prefault)
  size_t agent_bytes;
  size_t save_max;             // the learner's largest checkpoint payload (0: no checkpoints)
  fw_learn_stage_t learn_stage;
  hedger_save_cursor_t save_cursor;
  actor_save_cursor_t save_actor_cursor;  // the actor's section, after HEDGER's
  bool save_actor_started;
  int save_handle;             // checkpoint writer buffer being filled (-1: none)
  void* save_payload;          // its payload section
  uint32_t save_points_done;   // points of the save (or of its writer-less stand-in) done
  size_t save_payload_cap;
  size_t save_meta_size;
  int64_t learn_ticks;         // ticks that did between-run work (replay or checkpoint slices)

  // The journal of finished runs (fw/journal.h): the record of the run under way (its learned
  // transitions) or of the run that ended this tick, submitted after the tick's last update.
  uint8_t* jrec;               // owned; jrec_cap bytes (pre-faulted with rt_prefault)
  size_t jrec_cap;
  uint32_t jn;                 // transitions in jrec
  bool jfull;                  // more transitions than fit: the run waits for its checkpoint
  bool jend_pending;           // a run ended: its record goes out after this tick's update
  fw_journal_run_t jrun;       // its fields
  bool reports_wait;           // checkpoints are written: reports wait until their run is on disk
  size_t journal_keep;         // bytes of the journal that load learned again (kept and appended to)

  // Laser.
  lms_scan_t scan_raw;
  features_scan_t scan;
  bool have_scan;
  bool scan_new;
  int64_t last_scan_us;
  int32_t laser_silent_ticks;
  int64_t laser_scans;
  bool laser_error_logged;
  uint64_t laser_bad_at_scan;  // laser bytes dropped + CRC errors when the last scan arrived
  // A frozen sensor repeats its distances bit for bit; a real one never does (every beam with a
  // return carries its own noise of several millimetres), so a repeat is no new scan.
  uint64_t scan_hash;          // FNV-1a of the last telegram's count and raw values (0 = none)
  int32_t scan_repeats;        // telegrams in a row that repeated it (0 after a fresh scan)
  int64_t laser_repeated_scans; // all such repeats (monotonic, B21R_STATUS)
  bool scan_repeat_new;        // a repeating telegram arrived since the last tick (lockstep: the
                               // period's laser data is in, though it is no new scan)
  bool lockstep_lost;          // lockstep: a device delivered nothing for lockstep_timeout_s
  char device_lost_detail[FW_SAFETY_DETAIL_MAX];
  uint32_t devices_lost;       // FW_IO_DEVICE_* gone now (the binding reopens them with back-off)
  char io_lost_detail[FW_IO_DETAIL_MAX];
  uint32_t output_overflows;   // base commands refused by the binding's full output queue this tick
  uint32_t output_overflows_waiting; // reported while the lockstep wait looked for lost devices
  int64_t output_overflows_total;

  // Base (both protocols integrate odometry with the rFLEX rule, in base.odometry).
  rflex_host_t base;           // rFLEX: decoder, odometry, report flags, bumpers, brake, battery
  // The odometry of the run: the same encoder counts integrated from (0, 0, 0) at the run's start
  // (base.odometry keeps the start-up frame for B21R_POSE). The run's poses then come from its
  // own encoder steps only, not from the rounding of a pose that grew over earlier runs.
  rflex_odometry_t run_odometry;
  int32_t base_silent_ticks;
  int64_t last_base_us;
  int64_t base_packets;
  uint32_t bumper_mask;
  bool base_fault;
  char base_fault_detail[128];
  rflex_b21r_params_t rflex;
  uint8_t rbuf[1024];
  bool brake_expected_released;
  int32_t sys_status_countdown;
  fw_drive_t drive[2];
  fw_bump_node_t bump;
  int32_t bump_limit_ticks;    // lockstep: can_bumper_timeout_s in whole ticks
  int64_t can_start_us;        // NMT start, on the bus clock (base.c: lockstep, the ticks' time)
  uint32_t can_syncs_sent;     // since the NMT start (wraps); every one is answered by a TPDO1 and
                               // a TPDO2 of each operational drive
  int64_t can_unanswered_syncs; // SYNCs still unanswered when the next went out (monotonic)
  int64_t can_foreign_frames;  // frames of no configured node (monotonic)
  int64_t can_stale_pdos;      // TPDO2s whose position stood still against the velocity (monotonic)
  uint32_t can_foreign_tick;   // foreign frames since the last tick: a flood is a babbling node
  uint32_t can_foreign_id;     // COB-ID of the last of them

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
  bool teleop_range_newest;    // the newest TELEOP (deadman held) was refused for exceeding the limits
  bool teleop_range_logged;    // the current burst of such refusals has been reported on stderr
  char teleop_range_detail[FW_SAFETY_DETAIL_MAX];
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

  // Random streams.
  rng_t pose_rng;
  uint64_t driver_seed_base;
  tasks_driver_t driver;
  tasks_start_cycle_t start_cycle;
  // Run state.
  int32_t mode;                // b21r_status_t MODE_*
  bool pose_requested;
  bool awaiting_confirm;
  int32_t settle_ticks;
  int32_t retry_countdown;
  bool stopped_pose_requested; // a start pose was requested while stopped (bumper case)
  bool stopped_pose_pending;   // that request is under way (the binding answered 2)
  bool start_pose_chosen;      // start_pose is the next run's (drawn once per run: the pose sequence
                               // of a seed does not depend on stops between runs)
  features_pose_t start_pose;
  features_pose_t training_start;  // the last training run's start pose (a ranked pair's second run repeats it)
  int64_t run_first_seq;       // exp_seq when the run began
  b21r_run_t run_end;          // the end record of the run that ended, published after its last experience
  bool run_end_ready;

  // Command.
  double cmd_v;
  double cmd_w;

  // Output bookkeeping.
  int64_t tick_count;
  int64_t utime;               // of the current tick
  int64_t data_utime;          // lockstep: utime of the tick whose period's data are being read
                               // (the coming tick's while they are awaited and at the start, then
                               // its own)
  int64_t exp_seq;
  int64_t exp_dropped;
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
  learn_eval_block_t last_block;
  int64_t checkpoints_submitted;
  int64_t checkpoints_skipped;
  bool policy_fault;           // this tick's learned policy gave a non-finite action (stop, report)
  // A run's reports wait until the run is on disk (its journal record, or a checkpoint): a run
  // reported done survives a kill. Lines logged meanwhile keep their place behind them.
  fw_held_report_t held[FW_HELD_REPORTS];
  uint32_t held_head;
  uint32_t held_n;
  int32_t held_run;            // the newest run whose reports are held (-1: none)
  int64_t reports_early;       // reports released before their run was durable (queue full)
  learn_schedule_progress_t reported_progress;  // the schedule as the released reports tell it
  char* config_text;           // the effective configuration (fw_config_print), for B21R_CONFIG
  int64_t pace_origin_us;      // lockstep_realtime_factor: monotonic time of pacing tick 0
  int64_t pace_ticks;
};

// The signal fw_loop_signal() recorded (0: none). Any thread; async-signal-safe.
static inline int fw_loop_signalled(fw_loop_t* L) { return atomic_load(&L->signal_number); }

#endif  // FW_LOOP_STATE_H
