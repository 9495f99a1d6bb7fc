// SPDX-License-Identifier: MIT
/// fw/loop.h — The deterministic learning control loop of the B21r controller.
///
/// One tick (ARCHITECTURE.md, "One control tick"):
///   read every pending laser scan and base byte/frame → latest scan and odometry → features →
///   safety supervisor → reward/terminal → HEDGER update for the previous step (unless
///   evaluating) → action (phase one: example policy or joystick; phase two: HEDGER greedy with
///   seeded exploration, the example policy advising where HEDGER knows nothing) → clamp
///   (velocity and acceleration limits) → command to the base → experience, pose, status into
///   the publisher queue.
/// Around the ticks the loop runs the paper's schedule (fw/schedule.h): training runs,
/// evaluation blocks, the phase switch, repositioning between runs, and checkpoints of the
/// learned state at the end of every training run (written by a background thread).
///
/// Timing: fw_loop_run() paces ticks on absolute deadlines of the monotonic clock, or, in
/// lockstep, ticks as soon as the emulator's data for the next period (one scan and the
/// odometry of both axes) has arrived. A run is a function of (config, seed, input bytes):
/// in lockstep, timestamps are tick × period, so two identical runs produce bit-identical
/// experience streams.
///
/// Memory: everything (HEDGER storage, decoders, buffers) is allocated in fw_loop_create();
/// fw_loop_load_checkpoint() allocates a temporary read buffer. fw_loop_tick() performs no heap
/// allocation (tests count it over thousands of ticks, with the fake robot and with the emulator
/// linked in-process).
///
/// Work per tick is bounded: one HEDGER update with its greedy search (plus one or two
/// predictions), features linear in the beams. Between training runs (the robot standing still)
/// the backward replay and the checkpoint run in slices, one slice per tick after the command:
/// learn_updates_per_tick HEDGER updates (each one neighbourhood query and one local fit:
/// O(log n + k) with the store's n points and k ≤ hedger_k_max neighbours) or
/// checkpoint_points_per_tick serialised points. Worst tick ≈ learn_updates_per_tick × one
/// update. Measured (firmware.bench, Release, CPU time of the tick thread, 2-core x86-64, default
/// settings): p50 34-110 µs; max in runs 0.46-0.60 ms; max at run ends 0.25 / 0.33 / 1.32 /
/// 1.41 ms at 1k / 10k / 20k / 100k stored points.
///
/// Threads: one tick thread calls everything except fw_loop_post_teleop(),
/// fw_loop_post_command() (any thread, e.g. the LCM receive thread; a short mutex) and
/// fw_loop_signal() (async-signal-safe).
#ifndef FW_LOOP_H
#define FW_LOOP_H

#include "fw/checkpoint.h"
#include "fw/config.h"
#include "fw/io.h"
#include "fw/opauth.h"
#include "fw/publisher.h"
#include "fw/pubq.h"
#include "fw/safety.h"
#include "learn/learn.h"

#include <hedger/hedger.h>

#include <b21r/b21r_command_t.h>
#include <b21r/b21r_teleop_t.h>

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct fw_loop fw_loop_t;

/// Where the loop's output goes. All borrowed; each may be NULL.
typedef struct fw_loop_outputs {
  fw_pubq_t* queue;                ///< messages for the publisher thread
  void (*notify)(void* user);      ///< called after messages were committed (never blocks)
  void* notify_user;
  fw_ckpt_writer_t* checkpoints;   ///< background checkpoint writer (cfg.checkpoint_file)
  const fw_publisher_t* publisher; ///< its counters go on STATUS (lock-free reads)
  /// the receive thread's check of operator messages (fw/opauth.h): its refusals go on STATUS
  /// (lock-free reads); messages reach the loop (fw_loop_post_*) only once taken by it
  const fw_opauth_t* operator_auth;
} fw_loop_outputs_t;

/// Exit status of fw_loop_run() when, in lockstep, a device sent nothing for lockstep_timeout_s
/// (the emulator died or hung): the loop cannot go on without the period's data.
#define FW_EXIT_LOCKSTEP_TIMEOUT 5

/// Exit status of fw_loop_run() when a device was lost (end of file, EIO, ENODEV, hang-up) and
/// device_lost_action = exit: the base was stopped first, the learned state is saved on shutdown.
#define FW_EXIT_DEVICE_LOST 6

/// Capacity of the loop's error messages, including the NUL.
#define FW_LOOP_ERR_MAX 512U

/// Monotonic counters and the state of the loop, for tests and tools (STATUS carries them too).
typedef struct fw_loop_stats {
  int64_t ticks;
  int64_t steps;                 ///< learning steps taken (experiences produced)
  int64_t experiences_dropped;   ///< experiences the full queue refused
  int32_t run_id;                ///< current or last run
  int32_t runs_finished;         ///< runs ended (goal, collision, step limit), all kinds
  int32_t runs_aborted;          ///< runs cut short by a safety stop
  int32_t training_runs;
  int32_t eval_blocks;
  int32_t phase;
  int32_t mode;                  ///< b21r_status_t MODE_*
  int32_t stop_reason;           ///< fw_stop_reason_t in force
  int64_t safety_stops;
  int64_t stops_by_reason[FW_STOP_REASON_COUNT];
  int64_t held_ticks;            ///< running ticks without a new scan (command held)
  int64_t teleop_accepted;
  int64_t teleop_rejected;
  int64_t commands_accepted;
  int64_t commands_rejected;
  uint32_t store_fill;
  bool done;                     ///< the schedule has ended (or SHUTDOWN/signal)
  learn_eval_block_t last_block;    ///< newest finished evaluation block (block < 0: none yet)
  int32_t best_example_steps;
  double mean_example_steps;
  learn_selection_t selection;   ///< policy = select: the ranked pairs so far (zero otherwise)
  int32_t last_run_steps;
  bool last_run_goal;
  int64_t learn_ticks;           ///< ticks that did between-run learning work (replay, checkpoint)
  int64_t checkpoints_submitted; ///< checkpoints handed to the writer (between runs and at shutdown)
  // Deadline accounting (fw/timing.h; real time only, except the compute time).
  int32_t tick_max_ever_us;      ///< longest tick compute time since start [µs]
  int64_t tick_overruns;         ///< ticks that ended after the next scheduled start
  int32_t late_max_ever_us;      ///< largest wake-up lateness (actual − scheduled start) [µs]
  int64_t late_starts;           ///< ticks started later than late_start_threshold_s
  int64_t missed_periods;        ///< scheduled starts that passed without a tick of their own
  int32_t gap_max_ever_us;       ///< longest interval between consecutive tick starts [µs]
  int exit_status;               ///< what fw_loop_run returns once done (128 + N also after a
                                 ///< start that signal N ended: FW_LOOP_START_SIGNALLED)
} fw_loop_stats_t;

/// Builds a loop: validates cfg, sizes and allocates HEDGER and every buffer, seeds the
/// generators from cfg->seed. Touches no device. Returns NULL with a message on failure.
fw_loop_t* fw_loop_create(const fw_config_t* cfg, const fw_io_t* io, const fw_loop_outputs_t* out, char* err,
                          size_t err_cap);

/// Capacities a checkpoint writer needs for this loop (meta section, learner's payload at a full
/// store), to size fw_ckpt_writer_create(). O(1).
void fw_loop_checkpoint_capacity(const fw_loop_t* loop, size_t* meta_bytes, size_t* payload_bytes);

/// Sets (or replaces) the background checkpoint writer (borrowed; NULL = no checkpoints).
void fw_loop_attach_checkpoints(fw_loop_t* loop, fw_ckpt_writer_t* writer);

/// Loads the checkpoint at cfg->checkpoint_file (if set and present): the learned state and
/// the schedule's progress. Returns 1 (resumed; err holds a note for the operator, or is empty),
/// 0 (nothing to load: fresh start), -1 (corrupt or incompatible: err says what and how to start
/// fresh; the loop is unchanged).
int fw_loop_load_checkpoint(fw_loop_t* loop, char* err, size_t err_cap);

/// Device start-up: base (rFLEX: odometry and DIO reports on, defaults, brake release, status
/// request; CANopen: NMT start, CiA 402 enable sequence over SYNC cycles) and the first laser
/// scan. Blocks up to a few seconds (never inside the tick loop; in lockstep as long as a stalled
/// emulator keeps it, up to lockstep_timeout_s per wait). Returns 0; -1 with a message naming the
/// device that did not answer; FW_LOOP_START_SIGNALLED when fw_loop_signal() came meanwhile (it
/// is read at every wake-up of the I/O binding's wait: a signal handler should also wake that
/// wait), err saying so: the caller shuts down as usual and exits with the stats' exit_status
/// (128 + the signal's number).
int fw_loop_start(fw_loop_t* loop, char* err, size_t err_cap);

/// fw_loop_start()'s result when SIGINT/SIGTERM (fw_loop_signal) ended the start.
#define FW_LOOP_START_SIGNALLED (-2)

/// Waits for the next tick: lockstep, until the emulator's data for the next period arrived
/// (or the lockstep timeouts, or fw_loop_signal() came: that tick then runs without the period's
/// data and ends the loop); real time, until the next absolute deadline (reading input as it
/// comes). Returns the tick time [µs].
int64_t fw_loop_wait(fw_loop_t* loop);

/// One control tick at time now_us (see the file comment). No allocation, bounded work.
/// Returns true while the loop should go on, false when it is done (schedule ended, SHUTDOWN
/// command, or a signal: the base has then been commanded to zero in this tick).
bool fw_loop_tick(fw_loop_t* loop, int64_t now_us);

/// fw_loop_wait + fw_loop_tick until done. Returns the process exit status (0 = schedule done
/// or operator shutdown; 128 + signal number after a signal).
int fw_loop_run(fw_loop_t* loop);

/// Orderly stop: zero command, brake set, device reports off (rFLEX) / drives disabled and NMT
/// stop (CANopen), laser stream stopped, final checkpoint written and flushed. Safe to call once
/// after fw_loop_run. Returns 0, or -1 when the final checkpoint could not be written.
int fw_loop_shutdown(fw_loop_t* loop);

/// Maps every page of the loop's memory now (config rt_prefault, fw/prefault.h): the loop
/// itself, the learner's whole store, the publisher queue and the checkpoint writer's buffers of
/// the outputs, and 256 KiB of the calling thread's stack (call it from the tick thread, after
/// fw_loop_attach_checkpoints). Then no page fault happens in a tick while the store fills.
/// O(memory / 4 KiB); start-up only.
void fw_loop_prefault(fw_loop_t* loop);

/// Frees everything. NULL is ignored.
void fw_loop_destroy(fw_loop_t* loop);

/// Records SIGINT/SIGTERM: the next tick stops the base and ends the loop (in lockstep it does not
/// wait for a stalled emulator's data first), or fw_loop_start() returns FW_LOOP_START_SIGNALLED.
/// Async-signal-safe.
void fw_loop_signal(fw_loop_t* loop, int signal_number);

/// Hands a received B21R_TELEOP to the loop (validated in the tick: NaN, range, repeated or
/// old seq, staleness). arrival_us: monotonic receive time. Thread-safe, bounded, no allocation;
/// when the mailbox is full the oldest message is replaced (and counted as rejected).
void fw_loop_post_teleop(fw_loop_t* loop, const b21r_teleop_t* msg, int64_t arrival_us);

/// Hands a received B21R_COMMAND to the loop (validated in the tick: a known command; a command
/// older than the newest one taken is dropped, except a stop: PAUSE and SHUTDOWN are always
/// obeyed). Thread-safe.
void fw_loop_post_command(fw_loop_t* loop, const b21r_command_t* msg, int64_t arrival_us);

/// Snapshot of the counters and state (tick thread only).
void fw_loop_get_stats(const fw_loop_t* loop, fw_loop_stats_t* out);

/// The experience log's utime base etc. are deterministic in lockstep; this returns the tick
/// period in µs the loop runs at.
int64_t fw_loop_period_us(const fw_loop_t* loop);

#ifdef __cplusplus
}
#endif

#endif  // FW_LOOP_H
