// SPDX-License-Identifier: MIT
/// learn/schedule.h — The paper's run schedule: training runs in two phases, an evaluation block
/// (learning off, fixed start poses) every eval_every training runs, and the phase switch.
///
/// The loop asks learn_schedule_next() what the next run is, drives it, and reports its outcome with
/// learn_schedule_finish_run(). Rules:
/// - Every eval_every-th completed training run is followed by an evaluation block of
///   eval_starts runs (start pose i = evaluation pose i); optionally one block before training.
///   The last training run of the schedule is always followed by a block.
/// - An aborted run (safety stop) does not count: a training run is replaced by a new one, an
///   evaluation run is repeated from the same start pose.
/// - Phase switch: LEARN_SWITCH_RUNS after phase_one_runs training runs; LEARN_SWITCH_OPERATOR when
///   learn_schedule_request_phase_two() was called; LEARN_SWITCH_AUTO after an evaluation block that
///   reached the goal from every start with mean steps ≤ auto_ratio × the mean length of the
///   successful phase-one runs, not before auto_min_runs phase-one runs, and at the latest after
///   phase_one_runs. Every switch takes effect at a run boundary; when the switching run is
///   followed by an evaluation block, the block still counts as phase one (as in the paper).
///   An operator request always switches at the next run boundary, whatever the mode.
/// - The schedule is done after phase_two_runs phase-two training runs and the block after them.
/// - Evaluate-only schedules (one block, then done) serve `mode = evaluate`.
///
/// Transparent struct, no allocation, O(1) per call except the O(eval_starts) block summary.
#ifndef LEARN_SCHEDULE_H
#define LEARN_SCHEDULE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define LEARN_SCHEDULE_MAX_STARTS 16

/// When phase two starts (learn_schedule_config_t::switch_mode).
typedef enum learn_switch {
  LEARN_SWITCH_RUNS = 0,      ///< after phase_one_runs training runs (the paper: 30)
  LEARN_SWITCH_OPERATOR = 1,  ///< only on learn_schedule_request_phase_two()
  LEARN_SWITCH_AUTO = 2,      ///< when an evaluation block shows the learned policy is ready
} learn_switch_t;

typedef struct learn_schedule_config {
  int32_t eval_every;       ///< ≥ 1
  int32_t eval_starts;      ///< [1, LEARN_SCHEDULE_MAX_STARTS]
  bool eval_at_start;
  int32_t phase_one_runs;
  int32_t phase_two_runs;
  int32_t switch_mode;      ///< learn_switch_t
  int32_t auto_min_runs;
  double auto_ratio;
  bool evaluate_only;       ///< one evaluation block, then done
} learn_schedule_config_t;

typedef enum learn_run_kind { LEARN_RUN_TRAINING = 0, LEARN_RUN_EVAL = 1, LEARN_RUN_NONE = 2 } learn_run_kind_t;

/// The next run to drive.
typedef struct learn_plan_s {
  int32_t kind;         ///< learn_run_kind_t; LEARN_RUN_NONE when the schedule is done
  int32_t phase;        ///< 1 or 2
  int32_t eval_index;   ///< evaluation start pose index (LEARN_RUN_EVAL only)
  int32_t training_index; ///< 0-based index of this training run (LEARN_RUN_TRAINING only)
} learn_plan_t;

/// One finished evaluation block (the fields of b21r_eval_t).
typedef struct learn_eval_block {
  int32_t block;            ///< 0, 1, 2, ...
  int32_t training_runs;    ///< training runs completed before the block
  int32_t phase;            ///< phase in force while it ran
  int32_t n_starts;
  int32_t steps[LEARN_SCHEDULE_MAX_STARTS];
  bool success[LEARN_SCHEDULE_MAX_STARTS];
  int32_t successes;
  double mean_steps;        ///< over successful runs, 0 when none
  double ci95_halfwidth;    ///< Student-t 95 % half-width, 0 with fewer than 2 successes
} learn_eval_block_t;

/// Persistent part of the schedule (goes into the checkpoint so a restart resumes).
typedef struct learn_schedule_progress {
  int32_t phase;
  int32_t training_runs;     ///< completed, both phases
  int32_t phase_one_runs;    ///< completed in phase one
  int32_t phase_two_runs;    ///< completed in phase two
  int32_t eval_blocks;       ///< completed
  int32_t example_runs;      ///< successful phase-one runs (auto switch reference)
  double example_steps_sum;  ///< their summed lengths
  int32_t best_example_steps; ///< shortest successful phase-one run (0 = none yet)
} learn_schedule_progress_t;

typedef struct learn_schedule_s {
  learn_schedule_config_t cfg;
  learn_schedule_progress_t p;
  bool in_eval;
  int32_t eval_index;
  bool switch_pending;       ///< switch to phase two after the current block
  bool operator_request;
  bool final_block;          ///< the block under way ends the schedule
  bool done;
  learn_eval_block_t current;   ///< block being filled
} learn_schedule_t;

/// Starts a schedule (fresh, or from saved progress when `resume` is not NULL).
void learn_schedule_init(learn_schedule_t* s, const learn_schedule_config_t* cfg, const learn_schedule_progress_t* resume);

learn_plan_t learn_schedule_next(const learn_schedule_t* s);

/// Reports the outcome of the run learn_schedule_next() planned. steps = steps taken (the step
/// limit when the goal was not reached). Returns true when this run completed an evaluation
/// block, which is then copied into *block (if not NULL).
bool learn_schedule_finish_run(learn_schedule_t* s, int32_t steps, bool reached_goal, bool aborted,
                            learn_eval_block_t* block);

/// Operator START_PHASE_TWO: phase two starts at the next run boundary (or after the block
/// under way). No effect in phase two.
void learn_schedule_request_phase_two(learn_schedule_t* s);

bool learn_schedule_done(const learn_schedule_t* s);

/// Student-t 0.975 quantile for df degrees of freedom (exact table to 30, then 1.96 + 2.4/df).
double learn_student_t975(int32_t df);

/// Mean and 95 % half-width of n values (half-width 0 when n < 2). O(n).
void learn_mean_ci95(const double* values, int32_t n, double* mean, double* half_width);

#ifdef __cplusplus
}
#endif

#endif  // LEARN_SCHEDULE_H
