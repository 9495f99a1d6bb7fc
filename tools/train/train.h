// SPDX-License-Identifier: MIT
/// train.h — Offline training from the controller's experience logs (b21r-train), through the
/// learning framework (lib/learn) set up exactly as the controller sets it up from the same
/// configuration (fw/config_task.h), never through the controller's loop.
///
/// Q-learning is off-policy, and the actor learns from the returns of whatever was recorded: every
/// logged transition (s, a, r, s', terminal), whoever chose the action (example policy, joystick,
/// learned policy, exploration), is a valid training sample. The trainer feeds the logs'
/// B21R_EXPERIENCE messages, in file order, through the framework's offline calls, which are the
/// online ones (learn_offline_transition per experience: the update with q' the greedy value at s'
/// and the actor's record; learn_offline_end_run after each run: the backward replay of
/// hedger_replay, then the actor's learning). Training from the log of a session therefore gives
/// the learned state that session ended with (HEDGER's values and, with policy = actor, the actor
/// with its recorded transitions), bit for bit; training from several logs gives the state of one
/// controller that had lived through them all in order.
///
/// By default only the experiences the controller learned from are used (training runs; not
/// evaluation runs, where learning is off); train_options_t.include_eval adds those too.
///
/// Memory: one agent of the configured capacity (learn_storage_size), one decoded
/// event at a time (the logs are streamed, never loaded whole). Not thread-safe.
#ifndef B21R_TOOLS_TRAIN_H
#define B21R_TOOLS_TRAIN_H

#include <fw/config.h>
#include <fw/progress.h>
#include <hedger/hedger.h>

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Capacity of the trainer's error messages, including the NUL.
#define TRAIN_ERR_MAX 1024U

typedef struct train_options {
  bool include_eval;        ///< also learn from evaluation runs (learning was off in them online)
  const char* channel;      ///< experience channel; NULL = "B21R_EXPERIENCE"
  FILE* progress;           ///< progress lines (about one per progress_period_s); NULL = none
  double progress_period_s; ///< > 0
} train_options_t;

/// Counters of a training (all monotonic over the trainer's life).
typedef struct train_stats {
  uint64_t events;            ///< log events read (all channels)
  uint64_t experiences;       ///< B21R_EXPERIENCE messages decoded
  uint64_t used;              ///< experiences learned (learn_offline_transition succeeded)
  uint64_t skipped_eval;      ///< experiences of evaluation runs left out (include_eval off)
  uint64_t refused;           ///< experiences HEDGER refused (non-finite values): counted, skipped
  uint64_t undecodable;       ///< messages on the channel that did not decode as experience_t
  uint64_t seq_gaps;          ///< gaps in the experiences' seq (lost messages in the recording)
  uint64_t runs;              ///< runs ended (learn_offline_end_run calls)
  uint64_t replayed;          ///< updates done by backward replay at run ends
  /// --init's file was written by an older controller whose policy added a shift learned from
  /// ranked pairs of runs (fw_progress_t.legacy_shift): its values are trained on, the shift is gone
  bool init_legacy_shift;
  /// --init's file holds no actor (policy = greedy or an older controller): the actor was cloned
  /// from this many of its stored points (0: none, or the file had an actor)
  uint32_t init_actor_cloned;
  /// --init's file holds an actor that policy = greedy does not use: the output holds none
  bool init_actor_dropped;
  double seconds;             ///< wall time spent reading and training
} train_stats_t;

typedef struct trainer trainer_t;

/// Builds a trainer for the controller configuration cfg (already validated): the learning
/// framework with the controller's settings, in phase two from the start (what the written
/// checkpoint says). Returns NULL with a message on failure.
trainer_t* trainer_create(const fw_config_t* cfg, const train_options_t* opt, char* err, size_t err_cap);

/// Starts from the learned state of an existing checkpoint (the controller's or a trainer's)
/// instead of an empty one. Returns 0, or -1 with a message (missing, corrupt, other settings).
int trainer_load_checkpoint(trainer_t* t, const char* path, char* err, size_t err_cap);

/// Trains on one LCM event log, streamed in file order. A run ends where the run id changes, the
/// controller restarted (seq back to 0), or the log ends. Call it once
/// per log (and again for further passes over the data). Returns 0, or -1 with a message naming
/// the file: unreadable, not an LCM log, or experiences of another task / state dimension than
/// cfg (the fix is named); the experiences before the error have been learned.
int trainer_add_log(trainer_t* t, const char* path, char* err, size_t err_cap);

/// Ends the run under way (if any) as the controller does between runs. Call it after the last
/// log. O(run length) updates when hedger_replay is on.
void trainer_finish(trainer_t* t);

/// Writes the learned state as a controller checkpoint at path, atomically (fw/checkpoint.h;
/// HEDGER's values and, with policy = actor, the actor: fw/progress.h):
/// the controller started with this file (and the same configuration) resumes in phase two, the
/// learned policy driving. Refuses to replace an existing file unless overwrite. Returns 0 or -1.
int trainer_write_checkpoint(trainer_t* t, const char* path, bool overwrite, char* err, size_t err_cap);

/// The HEDGER instance (for tools and tests: predictions, counters). Owned by the trainer.
hedger_t* trainer_hedger(trainer_t* t);

/// Counters so far.
train_stats_t trainer_stats(const trainer_t* t);

/// Frees everything. NULL is ignored.
void trainer_destroy(trainer_t* t);

#ifdef __cplusplus
}
#endif

#endif  // B21R_TOOLS_TRAIN_H
