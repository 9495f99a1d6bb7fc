// SPDX-License-Identifier: MIT
/// train.h — Offline training of HEDGER from the controller's experience logs (b21r-train).
///
/// Q-learning is off-policy: every logged transition (s, a, r, s', terminal), whoever chose the
/// action (example policy, joystick, learned policy, exploration), is a valid training sample.
/// The trainer feeds the logs' B21R_EXPERIENCE messages, in file order, through exactly the calls
/// the controller makes online (hedger_update per experience, hedger_end_run after each run, so
/// the backward replay of hedger_replay too), with the HEDGER settings the controller derives from
/// the same configuration (fw_loop_learner_config), the run tags of pair_runs and, from a full log
/// (its B21R_RUN records), the ranking of its pairs. Training from the log of a session therefore
/// gives the learned state that session ended with, bit for bit (with pairs: from its full log);
/// training from several logs gives the state of one controller that had lived through them all
/// in order (run tags keep increasing where run ids start again). With include_eval an
/// evaluation run's points carry the tag, and so the pair weight, of the training run before it.
///
/// By default only the experiences the controller learned from are used (training runs; not
/// evaluation runs, where learning is off); train_options_t.include_eval adds those too.
///
/// Memory: one HEDGER instance of the configured capacity (hedger_storage_size), one decoded
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
  uint64_t used;              ///< experiences given to hedger_update successfully
  uint64_t skipped_eval;      ///< experiences of evaluation runs left out (include_eval off)
  uint64_t refused;           ///< experiences HEDGER refused (non-finite values): counted, skipped
  uint64_t undecodable;       ///< messages on the channel that did not decode as experience_t
  uint64_t seq_gaps;          ///< gaps in the experiences' seq (lost messages in the recording)
  uint64_t runs;              ///< runs ended (hedger_end_run calls)
  uint64_t replayed;          ///< updates done by backward replay at run ends
  /// the learner configured for pairs: pairs of training runs ranked from the log's B21R_RUN
  /// records (a full log, log_file; an experience log has none), as the controller ranked them
  uint64_t pairs_ranked;
  /// cfg runs pairs (fw_config_pair_runs_active): training experiences of logs without B21R_RUN
  /// records from phases that run pairs (phase two; phase one with pair_phase_one and the example
  /// policy); whether they came from pair runs cannot be told, so any pair among them is not
  /// ranked (weight 1, no shift)
  uint64_t paired_unranked;
  uint64_t pairs_unmatched;          ///< second runs of a pair whose first run's record is missing
  uint64_t run_records_undecodable;  ///< B21R_RUN records of another layout (an older controller)
  uint64_t run_records_invalid;      ///< pair-run records with a non-finite perturbation or shift: not ranked
  /// pair records whose shift in force differed from the trainer's (it then takes the log's):
  /// logs of different sessions, a second pass, an --init that already held the log's pairs
  uint64_t shift_taken_from_log;
  uint64_t shift_steps_halved;   ///< pair_shift_vet: ranked pairs whose step of the shift the vet cut (to a half, a quarter or an eighth)
  uint64_t shift_steps_refused;  ///< and whose step it refused (fw/shift_vet.h, as the controller)
  /// --init's obstacle shift moved but its file does not record the hold past the obstacle it was
  /// learned with (fw_progress_pass_hold_unknown): it goes on under the configuration's hold
  bool init_pass_hold_unrecorded;
  double seconds;             ///< wall time spent reading and training
  fw_pair_shift_t shift;      ///< the learned policy's shift after training; it goes into the checkpoint written
} train_stats_t;

typedef struct trainer trainer_t;

/// Builds a trainer for the controller configuration cfg (already validated): HEDGER with the
/// controller's settings (fw_loop_learner_config). Returns NULL with a message on failure.
trainer_t* trainer_create(const fw_config_t* cfg, const train_options_t* opt, char* err, size_t err_cap);

/// Starts from the learned state of an existing checkpoint (the controller's or a trainer's)
/// instead of an empty one. Returns 0, or -1 with a message (missing, corrupt, other settings).
int trainer_load_checkpoint(trainer_t* t, const char* path, char* err, size_t err_cap);

/// Trains on one LCM event log, streamed in file order. A run ends where the run id changes, the
/// controller restarted (seq back to 0), or the log ends. Where cfg configures the learner for
/// pairs (fw_config_pair_learner: the default for both tasks), every training run's points
/// carry its run tag as in the controller, and each pair of phase-two runs is ranked from the
/// B21R_RUN records of a full log (fw_pair_ranker_end) after the second run's replay. Call it once
/// per log (and again for further passes over the data). Returns 0, or -1 with a message naming
/// the file: unreadable, not an LCM log, or experiences of another task / state dimension than
/// cfg (the fix is named); the experiences before the error have been learned.
int trainer_add_log(trainer_t* t, const char* path, char* err, size_t err_cap);

/// Ends the run under way (if any) as the controller does between runs. Call it after the last
/// log. O(run length) updates when hedger_replay is on.
void trainer_finish(trainer_t* t);

/// Writes the learned state as a controller checkpoint at path, atomically (fw/checkpoint.h):
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
