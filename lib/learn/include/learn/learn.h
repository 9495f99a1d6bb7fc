// SPDX-License-Identifier: MIT
/// learn/learn.h — The two-phase learning framework of Smart & Kaelbling (ICRA 2002) as a pure
/// library: the schedule (phase one's driver, the switch, phase two, evaluation blocks), the
/// learner's update of every step, the learned policy (the value function's greedy action by
/// default, the actor of lib/actor, or either as ranked pairs of runs favour), the between-run
/// work (backward replay, the actor's learning) in bounded slices, exploration, and the advisor.
///
/// The policy (cfg.policy). LEARN_POLICY_ACTOR: the actor (actor/actor.h) acts wherever the
/// learned policy acts; it learns between runs from the transitions of every training run (phase
/// one's examples and its own runs alike) and their rewards. The value function (HEDGER) still
/// learns every step: the experience records carry its Q(s, a), and a checkpoint keeps its values
/// for LEARN_POLICY_GREEDY; the actor does not use it. LEARN_POLICY_GREEDY: the value function's
/// greedy action, as in the paper (measured: it imitates its teachers; docs/LEARNING.md).
/// LEARN_POLICY_SELECT: both, chosen by ranked pairs of runs. Phase two's training runs come in
/// pairs from one start pose (learn_run_repeats_start) with one exploration stream; one run of
/// each pair is the greedy policy's, the other the actor's (the order alternates), and the pair's
/// steps (a miss at the step limit) add to learn_selection_t. Every other run (the evaluations
/// included) is the greedy policy's while it has saved at least as many steps as the actor over
/// the pairs, else the actor's. Nothing here knows the task: the ranking is the runs' measured
/// length, the schedule's own measure.
///
/// It sees a task only through learn_task_t: the state's dimension, declared scales and ranges,
/// the action's bounds, the discount and the step limit. It never sees a task's name, its
/// features, its drivers or its reference controllers: the caller observes the world, computes the
/// task's reward and termination, asks the task's example policy for its action (the "advice"),
/// and hands all of it in. One agent serves the controller's loop (firmware/core), the offline
/// trainer (b21r-train) and the Python package alike.
///
/// A run, as the caller drives it (each call bounded; see the cost on each):
/// @code
///   const learn_plan_t plan = learn_plan(agent);        // training or evaluation, phase, pose index
///   learn_begin_run(agent);                              // (the caller places the robot first)
///   for each control period with a new observation:
///     learn_observe(agent, features, last_command);      // the learner's state
///     if (learn_has_transition(agent)) {                 // the last action's outcome
///       outcome = task's reward and termination (contact, learn_run_actions(agent));
///       if (learn_transition(agent, &outcome, &end)) { the run ended: end says how; break; }
///     }
///     learn_act(agent, advice, joystick, &a, &source);   // phase one's driver or the learned policy
///     send the command (clamped to the base's limits), then
///     learn_executed(agent, a_sent, v_sent);
///     learn_after_command(agent, &experience);           // the step's update, or a slice of replay
/// @endcode
/// Between runs, learn_after_command() does a slice of the between-run work per call (the backward
/// replay, then the actor's learning) until learn_idle(); the next run may start once it is idle.
///
/// Determinism: results are a pure function of the configuration, the task, the seeds and the
/// sequence of calls (the exploration draws from one seeded rng_t; the learner is deterministic).
/// Memory: everything lives in the storage the caller gives learn_init() (learn_storage_size());
/// no allocation after init. Not thread-safe: one agent per thread.
#ifndef LEARN_LEARN_H
#define LEARN_LEARN_H

#include "learn/learner.h"
#include "learn/schedule.h"

#include <actor/actor.h>
#include <rng/rng.h>

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Largest task state dimension (features; the learner's state may add the last action).
#define LEARN_MAX_TASK_STATE 7U
/// Largest learner state dimension (the task's features and, optionally, the last action).
#define LEARN_MAX_STATE (LEARN_MAX_TASK_STATE + 1U)
/// Alignment of the storage given to learn_init().
#define LEARN_STORAGE_ALIGN 64U
/// Capacity of learn_init()'s error message, including the NUL.
#define LEARN_ERR_MAX 256U

/// Who chose an action (the values of b21r.experience_t SOURCE_*).
typedef enum learn_source {
  LEARN_SOURCE_EXAMPLE = 0,      ///< phase one: the task's example policy (code, or a simulated person)
  LEARN_SOURCE_JOYSTICK = 1,     ///< phase one: the operator's joystick
  LEARN_SOURCE_GREEDY = 2,       ///< the learned policy's action (the actor's, or the greedy action)
  LEARN_SOURCE_EXPLORATION = 3,  ///< the learned policy's action plus exploration noise
  LEARN_SOURCE_ADVISOR = 4,      ///< the example policy where the learned policy knows no action
} learn_source_t;
#define LEARN_N_SOURCES 5

/// Who acts where the learned policy acts (learn_config_t::policy).
typedef enum learn_policy {
  LEARN_POLICY_ACTOR = 0,   ///< the actor of lib/actor, learned between runs from the rewards
  LEARN_POLICY_GREEDY = 1,  ///< the value function's greedy action (the paper's; the default)
  LEARN_POLICY_SELECT = 2,  ///< the greedy action or the actor, as ranked pairs of runs favour
} learn_policy_t;

/// What the ranked pairs of LEARN_POLICY_SELECT have measured (kept in a checkpoint).
typedef struct learn_selection {
  double greedy_saved_steps;  ///< Σ over ranked pairs: the actor's run's steps − the greedy's (whole numbers)
  int32_t pairs;              ///< ranked pairs, >= 0
} learn_selection_t;

/// Who drives phase one's training runs.
typedef enum learn_phase_one_driver {
  LEARN_DRIVER_EXAMPLE = 0,   ///< the task's example policy (its advice), with dither
  LEARN_DRIVER_JOYSTICK = 1,  ///< the operator (the joystick value handed to learn_act)
} learn_phase_one_driver_t;

/// What the framework does.
typedef enum learn_mode {
  LEARN_MODE_LEARN = 0,          ///< the two-phase schedule, learning in training runs
  LEARN_MODE_EVALUATE = 1,       ///< one evaluation block of the learned policy, learning off
  LEARN_MODE_EVALUATE_ADVICE = 2 ///< one evaluation block of the advice (a reference or example policy)
} learn_mode_t;

/// A task as the learner may know it: what its users declare, nothing of its solution.
typedef struct learn_task {
  uint32_t state_dim;                        ///< features, 1..LEARN_MAX_TASK_STATE
  double state_scale[LEARN_MAX_TASK_STATE];  ///< per feature: raw units per scaled unit (> 0)
  double state_min[LEARN_MAX_TASK_STATE];    ///< per feature: the declared range (tabular bins)
  double state_max[LEARN_MAX_TASK_STATE];
  double action_min;                         ///< action bounds (e.g. rad/s), action_min < action_max
  double action_max;
  double action_scale;                       ///< raw action units per scaled unit (> 0)
  double gamma;                              ///< the task's discount, [0, 1)
  uint32_t step_limit;                       ///< a run ends after this many actions (0 = none)
  /// The learner's wider second search where a state has few neighbours (hedger.h
  /// greedy_reach), as declared with the task (>= 1); learn_config_t can override it.
  double greedy_reach;
} learn_task_t;

/// The framework's settings (units in names; defaults: learn_config_default()).
typedef struct learn_config {
  int32_t mode;                 ///< learn_mode_t
  int32_t phase_one_driver;     ///< learn_phase_one_driver_t
  learn_schedule_config_t schedule;  ///< evaluate_only is set from mode by learn_init
  // The policy.
  int32_t policy;               ///< learn_policy_t (default LEARN_POLICY_GREEDY)
  /// The actor's settings (policy = actor). Its task fields (state dimension, ranges, scales,
  /// action bounds, discount) are derived from the task by learn_actor_config(); the rest are the
  /// method's (actor_config_default()) unless set.
  actor_config_t actor;
  uint32_t actor_work_per_slice; ///< the actor's between-run work per slice [actor work units, actor/actor.h]
  /// The values guard the actor (HEDGER only; hedger_judge()): where a state model answers at
  /// the state, the actor's action is replaced by the greedy action where the values put it more
  /// than actor_guard_se standard errors below it (0 = never, the library's default; the
  /// controller's is 1), and otherwise kept within the actions the data hold at the state
  /// (actor_guard_range; the library's default false, the controller's true). Costs one greedy
  /// search per decision, as policy = greedy does.
  double actor_guard_se;
  bool actor_guard_range;
  // The value-function learner.
  int32_t learner;              ///< learn_learner_kind_t
  double alpha;                 ///< learning rate (0, 1]
  double gamma;                 ///< discount; 0 = the task's
  bool state_last_action;       ///< the learner's state ends with the last command sent (the executed action)
  double last_action_scale;     ///< its scale [action units per scaled unit]
  uint32_t capacity;            ///< HEDGER's store
  uint32_t k_min;
  uint32_t k_max;
  double bandwidth;
  double merge_radius;
  uint32_t greedy_actions;
  int32_t greedy_method;        ///< hedger_greedy_method_t
  double greedy_pessimism;
  double greedy_reach;          ///< 0 = the task's
  bool replay;                  ///< backward replay of each finished training run
  uint32_t replay_passes;
  double replay_lambda;
  double replay_alpha;          ///< the replay's step (HEDGER's and tabular Q's), [0, 1]; 0 = alpha
  uint32_t input_scale_n;       ///< 0 = the task's scales, else state dimension + 1 values
  double input_scale[LEARN_MAX_STATE + 1U];
  uint32_t tabular_bins;        ///< per state dimension (learner = tabular)
  uint32_t tabular_actions;
  // Acting.
  double explore_sigma;         ///< phase two: standard deviation of an exploration offset [action units]
  double explore_probability;   ///< per training decision: the chance an exploration (or dither) segment starts
  uint32_t explore_hold_steps;  ///< a segment's length in decisions (>= 1)
  /// The policy (and phase one's driver) decides every this many control ticks and the action
  /// holds in between; each decision is learned as one transition with the discount gamma^N and
  /// the window's rewards discounted per tick. 1 (0 counts as 1) = every tick, the paper's.
  uint32_t decision_ticks;
  double example_dither_sigma;  ///< phase one, example driver: a dither segment's offset [action units]
  bool advisor;                 ///< phase two: the advice acts where the learned policy knows no action
                                ///< (greedy: no known action at the state; actor: nothing learned yet)
  // Between runs.
  uint32_t replay_updates_per_slice;  ///< backward-replay updates per learn_after_command() between runs
  // Seeds.
  uint64_t explore_seed;        ///< the exploration and dither stream
  uint64_t learner_seed;        ///< HEDGER's eviction generator
} learn_config_t;

/// The framework's defaults: the paper's schedule (30 + 35 runs, a block of 10 every 5) and
/// the controller's learner settings. O(1).
learn_config_t learn_config_default(void);

/// The learner settings derived from task and cfg (state dimension, input scales, action bounds,
/// discount, the run buffer for the replay, ...). Pure, O(1).
void learn_learner_config(const learn_task_t* task, const learn_config_t* cfg, learn_learner_config_t* out);

/// The learner's state dimension under task and cfg: the features, plus one for the last action.
uint32_t learn_state_dim(const learn_task_t* task, const learn_config_t* cfg);

/// The actor's configuration under task and cfg: cfg->actor with the learner's state (dimension;
/// the task's declared ranges, then the action bounds for the last action; the value learner's
/// input scales), the action bounds and scale and the discount. Pure, O(state dimension).
void learn_actor_config(const learn_task_t* task, const learn_config_t* cfg, actor_config_t* out);

typedef struct learn learn_t;

/// Bytes and alignment (LEARN_STORAGE_ALIGN) of the storage for task and cfg; 0 when invalid. O(1).
size_t learn_storage_size(const learn_task_t* task, const learn_config_t* cfg);

/// Sets up an agent in storage. Returns NULL with a message naming the setting to change when the
/// task or the settings are invalid or the storage too small. O(storage) (the learner's init).
learn_t* learn_init(void* storage, size_t storage_size, const learn_task_t* task, const learn_config_t* cfg,
                    char* err, size_t err_cap);

/// The run fw / callers drive next (kind LEARN_RUN_NONE once the schedule is done). O(1).
learn_plan_t learn_plan(const learn_t* a);

/// Starts the planned run: a new run id (the previous + 1), no transition yet. O(1).
void learn_begin_run(learn_t* a);

/// True when the planned run (learn_plan; between runs, the next one) or the run under way is the
/// second of a ranked pair (policy = select): the caller starts it where the previous training
/// run started (the pair's first). O(1).
bool learn_run_repeats_start(const learn_t* a);

/// True when the greedy action acts in the run under way or the next one (else the actor). O(1).
bool learn_run_greedy(const learn_t* a);

/// The ranked pairs' measurements (all zero unless policy = select). O(1).
learn_selection_t learn_selection_get(const learn_t* a);

/// Restores them from a checkpoint (policy = select; a pair cut by the restart is not ranked).
/// False (nothing changed) for another policy or a non-finite sum or negative count. O(1).
bool learn_resume_selection(learn_t* a, const learn_selection_t* s);

/// True while a run is under way (between learn_begin_run and its end).
bool learn_running(const learn_t* a);

/// The learner's state from the task's features and the last command sent (the executed action,
/// appended where cfg.state_last_action). Returns false when a value is not finite (do not step).
/// O(state_dim).
bool learn_observe(learn_t* a, const double* features, double last_command);

/// The learner's state dimension of this agent (learn_state_dim of its task and settings).
uint32_t learn_agent_state_dim(const learn_t* a);

/// The learner's current state (learn_agent_state_dim values).
const double* learn_state(const learn_t* a);

/// True when an action has been executed in this run whose outcome is due (learn_transition).
bool learn_has_transition(const learn_t* a);

/// Actions executed in the run so far.
int32_t learn_run_actions(const learn_t* a);

/// The outcome of the last executed action, as the task computes it.
typedef struct learn_outcome {
  double reward;
  bool terminal;  ///< the new state is absorbing (goal, collision): no bootstrap
  bool end_run;   ///< the run ends after this step (terminal, or the step limit)
  bool goal;      ///< the run ended by reaching the goal
  int8_t reason;  ///< the task's end reason (kept in the experience)
} learn_outcome_t;

/// How a run ended (learn_transition, learn_abort_run).
typedef struct learn_run_end {
  int32_t run_id;
  learn_plan_t plan;            ///< the run's plan
  bool goal;
  bool aborted;
  int32_t steps;                ///< actions executed
  double total_reward;
  int32_t steps_by_source[LEARN_N_SOURCES];
  int32_t eval_block;           ///< an evaluation run's block number (-1 for a training run)
  bool block_done;              ///< the run completed an evaluation block ...
  learn_eval_block_t block;     ///< ... this one
  bool learning;                ///< a training run of the learn mode: its replay follows between runs
  int8_t policy;                ///< who acted where the learned policy acted: LEARN_POLICY_GREEDY or _ACTOR
} learn_run_end_t;

/// The outcome of the last executed action: queues its transition (learned after the command,
/// learn_after_command; with cfg.decision_ticks > 1 the decision's, when its last tick's outcome
/// is in or the run ends inside it), and when the outcome ends the run, ends it (the schedule counts it; a
/// training run's replay waits for learn_after_command). Returns true when the run ended (*end
/// filled). O(1) (plus O(eval_starts) when a block completes).
bool learn_transition(learn_t* a, const learn_outcome_t* outcome, learn_run_end_t* end);

/// Ends the run under way without a terminal state (a safety stop, a shutdown): it does not count
/// and is repeated. *end filled; false when no run was under way. O(1).
bool learn_abort_run(learn_t* a, learn_run_end_t* end);

/// The action of this step: inside a decision's window (cfg.decision_ticks > 1) the decision's,
/// held (no search); else phase one's driver (the advice with dither, or the joystick), or the
/// learned policy (the actor's action or the greedy action, with exploration in training; the
/// advice where the learned policy knows nothing and cfg.advisor; 0 in evaluations). *source says
/// which. Cost: where the learned policy acts, the actor's network (O(state_dim × hidden)) or one
/// greedy search (whose value is then the q' of the queued transition). When the actor's output is
/// not finite the action is 0 and learn_policy_fault() is true: the caller must stop the robot.
void learn_act(learn_t* a, double advice, double joystick, double* action, int8_t* source);

/// True when the last learn_act()'s learned policy gave a non-finite action (a fault; the action
/// was 0); learn_policy_faults() counts them since init.
bool learn_policy_fault(const learn_t* a);
uint64_t learn_policy_faults(const learn_t* a);

/// Actor decisions the values' guard replaced by the greedy action (actor_guard_se), since init.
uint64_t learn_guard_replaced(const learn_t* a);

/// Whether the operator's joystick drives the run under way (phase one, joystick driver).
bool learn_joystick_drives(const learn_t* a);

/// Whether the learned policy acts in the run under way (phase two, or an evaluation of it).
bool learn_policy_acts(const learn_t* a);

/// The command sent after learn_act (clamped by the caller to the base's limits): the executed
/// action, which the next transition records. O(state_dim).
void learn_executed(learn_t* a, double action, double translation);

/// A learned (or, in evaluations, predicted) step, for the caller's experience record.
typedef struct learn_experience {
  int32_t run_id;
  int32_t step_id;
  int32_t phase;
  bool evaluating;       ///< learning was off
  int8_t source;         ///< learn_source_t of the action
  int8_t reason;         ///< the task's end reason of the transition
  uint32_t state_dim;
  double s[LEARN_MAX_STATE];
  double a;
  double v;              ///< the translation sent with it
  double reward;
  double s_next[LEARN_MAX_STATE];
  bool terminal;
  double q;              ///< Q(s, a) before the update (0 when unknown or non-finite)
  hedger_kind_t q_kind;  ///< how q was obtained
} learn_experience_t;

/// After the command: the queued transition's update (a training run: the value learner's update
/// and the actor's record) or prediction (an evaluation), written into *exp (returns true), then,
/// between runs (no transition was queued, or a training run just ended), one slice of the
/// between-run work (learn_between_runs_slice with cfg.replay_updates_per_slice). Bounded: one
/// update with its greedy search, plus the slice.
bool learn_after_command(learn_t* a, learn_experience_t* exp);

/// The two halves of learn_after_command, for callers that interleave their own between-run work
/// (the controller's checkpoint slices): the queued transition's update (false: none queued), and
/// one slice of the between-run work due after a training run (it begins with the first slice):
/// first the backward replay, at most max_updates updates per slice, then the actor's learning,
/// at most cfg.actor_work_per_slice actor work units per slice (plus one query's; actor/actor.h).
/// A slice does one or the other, never both. Returns nonzero while work is left (0: done, or
/// none was due).
bool learn_update(learn_t* a, learn_experience_t* exp);
uint32_t learn_between_runs_slice(learn_t* a, uint32_t max_updates);

/// True when no between-run work is left (a run may start).
bool learn_idle(const learn_t* a);

/// True when a training run ended and its between-run work has not begun yet.
bool learn_between_runs_due(const learn_t* a);

/// True while between-run work is due or under way.
bool learn_between_runs_busy(const learn_t* a);

/// Finishes the queued update and the whole between-run work at once (shutdown; not for a tick):
/// the replay's replay_passes × the run's length updates and all of the actor's learning.
/// *exp and the return as learn_after_command.
bool learn_finish_now(learn_t* a, learn_experience_t* exp);

/// Offline learning from logged transitions (b21r-train), through exactly the calls a run makes
/// online: the update of (s, a, r, s', terminal) with q' the learner's greedy value at s' (0 when
/// terminal), recorded for the run's backward replay and by the actor. The schedule and the run
/// bookkeeping are not touched; s and s_next have learn_agent_state_dim values. *exp (may be NULL) receives the
/// update's record. Returns false when the learner refused the transition (a value not finite;
/// nothing changed). Cost: one greedy search and one update.
bool learn_offline_transition(learn_t* a, const double* s, double action, double reward, const double* s_next,
                              bool terminal, learn_experience_t* exp);
/// The end of a logged run: its whole between-run work at once (not for a tick), as a training run
/// ends online: the backward replay, then the actor's learning. Returns the replayed updates.
/// O(replay_passes × the run's length) updates plus the actor's work (actor/actor.h).
uint64_t learn_offline_end_run(learn_t* a);

/// The operator's START_PHASE_TWO: phase two starts at the next run boundary. O(1).
void learn_request_phase_two(learn_t* a);

/// The schedule and its progress (read-only).
const learn_schedule_t* learn_schedule(const learn_t* a);

/// The last run started (-1: none).
int32_t learn_run_id(const learn_t* a);

/// Resumes from saved progress (a checkpoint): the schedule's and the last run id. O(1).
void learn_resume(learn_t* a, const learn_schedule_progress_t* progress, int32_t run_id);

/// Resumes one finished (or aborted) run that a journal recorded after the last saved progress:
/// the run the schedule plans next (learn_plan) gets the next run id and ends as it ended, so
/// that the schedule counts it exactly as learn_transition / learn_abort_run did (an evaluation
/// run inside a block included). The run's learning is the caller's: its transitions through
/// learn_offline_transition and its between-run work through learn_offline_end_run, before this
/// call; nothing is left due. plan: the run's plan as recorded; steps: the actions it executed.
/// Returns false (nothing changed) when a run is under way or the plan is not the one the
/// schedule plans next (the journal does not follow the saved progress). *end (may be NULL) as
/// learn_transition fills it. O(1) (plus O(eval_starts) when a block completes).
bool learn_resume_run(learn_t* a, const learn_plan_t* plan, int32_t steps, bool goal, bool aborted,
                      learn_run_end_t* end);

/// The learner (for checkpoints, predictions and counters). Owned by the agent.
learn_learner_t* learn_get_learner(learn_t* a);
const learn_learner_t* learn_get_learner_const(const learn_t* a);

/// The actor (policy = actor; NULL with the greedy policy), for checkpoints and counters. Owned
/// by the agent.
actor_t* learn_get_actor(learn_t* a);
const actor_t* learn_get_actor_const(const learn_t* a);

/// Starts the actor from the value learner's stored experience where no actor was saved (a
/// checkpoint written with the greedy policy or by an older controller): behaviour cloning on the
/// states and actions of HEDGER's stored points (actor_clone). The values are untouched. Returns
/// the points cloned (0: no actor, no HEDGER, or nothing stored). Not for a tick: O(clone_steps ×
/// stored points) network passes.
uint32_t learn_actor_from_values(learn_t* a);

/// Experiences produced (transitions queued) since init.
int64_t learn_steps(const learn_t* a);

#ifdef __cplusplus
}
#endif

#endif  // LEARN_LEARN_H
