// SPDX-License-Identifier: MIT
/// actor/actor.h — A deterministic policy learned from the rewards of recorded transitions: an
/// actor moved along the deterministic policy gradient through locally learned models (MB-DPG).
///
/// What it learns from. Transitions (s, a, r, s', terminal) of training runs, recorded as they
/// happen (actor_record), whoever chose the action (an example policy, a person, the actor
/// itself with exploration). It knows the task only through actor_config_t: the state's
/// dimension, declared range and scales, the action's bounds and scale, and the discount. No
/// task's name, features or reference controllers.
///
/// What it is. a = c_a + r_a · tanh(w2 · tanh(W1 x + b1) + b2), x = the state mapped to [-1, 1]
/// by its declared range (c_a, r_a: the centre and half-width of the action bounds): one hidden
/// layer of cfg.hidden tanh units. actor_act() evaluates it (per tick); nothing else happens in a
/// tick but actor_record()'s copy.
///
/// How it learns, between runs (actor_end_run_begin / actor_end_run_step), after run k:
///  1. Monte-Carlo returns G_t = r_t + γ G_{t+1} backwards over the run (0 after a terminal and
///     after its last step).
///  2. After the first run that recorded anything: behaviour cloning, cfg.clone_steps full-batch
///     Adam steps on (s, a) of every recorded transition. Nothing else that time.
///  3. Later runs: a query set Q of at most cfg.max_queries transitions drawn (seeded, without
///     replacement, in recording order) from the window: the last cfg.recent_runs runs, or with
///     cfg.rewarded_window as many runs back as it takes to hold cfg.recent_runs runs that
///     collected a non-zero reward (the whole ring if it holds fewer). Why: a run that collected
///     none (a failure scored 0, a run stopped at the step limit) says nothing about where the
///     reward is; after cfg.recent_runs such runs in a row the last runs' returns are all 0, V is
///     0 everywhere, no query has a slope and the actor can never move again.
///  4. For each q in Q, a local linear model of the state change s' − s on the scaled state and
///     action [s/scale, a/action_scale] over every recorded non-terminal transition (Gaussian
///     weights, bandwidth cfg.model_bandwidth, cfg.model_k nearest within the kernel's 1 % radius,
///     ridge cfg.ridge on the slopes, at least cfg.model_min_neighbours): at (s_q, a_q) it gives
///     the predicted change D_q and the action's effect B_q = ∂(s' − s)/∂a.
///  5. The state value V: a local linear regression of the returns G over the states of the window's
///     runs (cfg.value_bandwidth, cfg.value_k, at least
///     cfg.value_min_neighbours), at the state the actor's action is predicted to lead to,
///     s_q + D_q + B_q (π(s_q) − a_q): its value V_q and gradient ∇V_q.
///  6. The slope of the return in the action, γ ∇V_q · B_q, in ticks of discounting:
///     g_q = γ ∇V_q · B_q / (|V_q| ln(1/γ)) (|V_q| floored at 1e-6 of the largest |V| of Q;
///     0 where either model lacks neighbours or anything is not finite). With cfg.slope_min_t > 0
///     also 0 where |γ ∇V_q · B_q| is below cfg.slope_min_t times its standard error: the slope
///     is a contrast of the value model's coefficients, its error from the cluster sandwich with
///     one cluster per run (a run's returns share its noise, so the value model has about as many
///     observations as runs; B_q taken as exact). Why: the step rule saturates at a third of a
///     tick, the slope's noise is of that order, and a step on noise that keeps its sign from run
///     to run (while an example policy drives, the same runs are queried again) walks the actor
///     off the data (below).
///  7. Targets y_q = clip(π(s_q) + clip(cfg.step_gain g_q, ±cfg.step_max), action bounds), then
///     kept within cfg.trust_radius of the recorded action a_q (when cfg.trust_radius > 0), and
///     cfg.fit_steps full-batch Adam steps (learning rate cfg.learning_rate) on the mean of
///     (π(s_q) − y_q)². A fit that leaves a parameter non-finite is undone (counted).
///     Why the trust radius: both local models are linear, so the slope at a state does not
///     shrink as π moves away from the recorded actions, and the same recent runs are queried
///     again after the next run. Without a bound the steps add up run after run wherever the
///     slope keeps one sign, also where that sign is only the value model's noise: while an
///     example policy drives (its runs do not answer the actor's moves) the actor's action at
///     such states walks up to 0.1 per run to far outside what the runs ever did, where neither
///     model has data. The bound keeps every target where the models were fitted.
///
/// Work between runs, in slices. Every step is cut into atomic operations and a slice runs
/// operations while its work is below the caller's budget, in work units:
///   one training sample's forward and backward pass (steps 2 and 7)       1 unit
///   one Adam update of the parameters                                      1 unit
///   one query's two local regressions (steps 4-6)                          ACTOR_WORK_QUERY units
///   ACTOR_ITEMS_PER_UNIT items of a linear pass (returns, pools, copies,
///   and the kd-trees' build work units)                                    1 unit
/// A unit costs at most ACTOR_INSTRUCTIONS_PER_UNIT instructions (x86-64, callgrind; test
/// actor.slice_instructions: a ring of 20,000 corridor transitions, state dimension 4, a run of
/// 147 steps, 1,477 queries: a sample 1,850 instructions, a query 100,000 to 360,000 depending on
/// the neighbourhoods, a build unit 1,800), so a slice of budget B costs at most
/// (B + ACTOR_WORK_QUERY) × ACTOR_INSTRUCTIONS_PER_UNIT instructions (measured at B = 1,500: at
/// most 2.95 million, median 2.78 million; bound 3.4 million). The whole work after that run:
/// 0.94 billion instructions (about 0.3 s of CPU, 409 slices of 1,500 units), three fifths of it
/// the fit. The result does not depend on how the work is sliced: every sum runs in one fixed order.
/// Per tick: actor_act about 1,300 instructions (state dimension 4, 16 hidden units);
/// actor_record a copy of 2 state_dim + 3 values.
///
/// Memory. Everything lives in the caller's storage (actor_storage_size, exact): per transition
/// 8 (2 state_dim + 3) + 5 bytes of ring and 2 × (8 · 9 + 4) + 8 bytes of models (two kd-trees of
/// padded 9-D points, their ids, a row map) and 4 of the query pool; per query 8 · 4 + 5 bytes;
/// per parameter 8 · 7 bytes ((state_dim + 2) hidden + 1 parameters: weights, Adam's two moments,
/// a gradient, and the copies a diverged fit is undone from), plus the trees' nodes (about
/// capacity / 8 × 32 bytes each). The default configuration at state dimension 4: 5,484,992 bytes.
/// No allocation after actor_init().
///
/// Determinism. Results are a pure function of the configuration and the sequence of calls: the
/// draws come from one seeded generator (lib/rng), every neighbour set is ordered by (distance,
/// id) (lib/hedger's kd-tree), every sum runs in a fixed order. Same binary, same calls →
/// bit-identical actions, parameters and saved bytes, however the work was sliced, and across a
/// save and load (the saved state holds the ring, the parameters, the optimiser's moments and
/// the generator).
///
/// Errors. Functions return actor_status_t: 0 OK, 1 an outcome (ACTOR_UNTRAINED), >= 2 errors.
/// A failed call leaves the learned state unchanged. Not thread-safe: one instance per thread.
#ifndef ACTOR_ACTOR_H
#define ACTOR_ACTOR_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
#define ACTOR_NOEXCEPT noexcept
extern "C" {
#else
#define ACTOR_NOEXCEPT
#endif

/// Largest state dimension (the learner's: the task's features and the last action).
#define ACTOR_MAX_STATE_DIM 8U
/// Largest hidden layer.
#define ACTOR_MAX_HIDDEN 64U
/// Largest neighbourhood of either local model.
#define ACTOR_MAX_K 1024U
/// Largest transition ring.
#define ACTOR_MAX_CAPACITY (1U << 22)
/// Alignment of the storage given to actor_init().
#define ACTOR_STORAGE_ALIGN 64U
/// Work units of one query's two local regressions (the slice accounting above).
#define ACTOR_WORK_QUERY 200U
/// Items of a linear pass, or kd-tree build units, per work unit.
#define ACTOR_ITEMS_PER_UNIT 24U
/// Instructions per work unit, about (x86-64, callgrind; see the file comment).
#define ACTOR_INSTRUCTIONS_PER_UNIT 2000U
/// Version of the byte format of actor_save(); actor_load() reads this version only.
#define ACTOR_FORMAT_VERSION 1U

typedef enum actor_status {
  ACTOR_OK = 0,
  /// actor_act(): nothing learned yet (no run ended with a recorded transition, nothing cloned);
  /// the output is the middle of the action bounds. The caller decides (an advisor, or hold).
  ACTOR_UNTRAINED = 1,
  ACTOR_ERR_INVALID_ARG = 2,      ///< NULL pointer, or a configuration value outside its range
  ACTOR_ERR_NON_FINITE = 3,       ///< a non-finite input (nothing recorded), or actor_act's output
  ACTOR_ERR_CAPACITY = 4,         ///< storage or a caller buffer too small; nothing written
  ACTOR_ERR_ALIGNMENT = 5,        ///< storage not aligned to ACTOR_STORAGE_ALIGN
  ACTOR_ERR_BUSY = 6,             ///< between-run work under way: record, save and load wait for it
  ACTOR_ERR_FORMAT = 7,           ///< actor_load(): not an actor's bytes, or impossible contents
  ACTOR_ERR_VERSION = 8,          ///< actor_load(): another format version
  ACTOR_ERR_TRUNCATED = 9,        ///< actor_load(): shorter than the length it declares
  ACTOR_ERR_CHECKSUM = 10,        ///< actor_load(): CRC-32 mismatch
  ACTOR_ERR_CONFIG_MISMATCH = 11, ///< actor_load(): saved under another configuration (see actor_load)
  ACTOR_ERR_CHANGED = 12,         ///< actor_save_step(): the state changed since actor_save_begin()
} actor_status_t;

/// Settings. Units: the caller's raw state units, the action's units (e.g. rad/s).
typedef struct actor_config_s {
  uint32_t state_dim;                       ///< 1..ACTOR_MAX_STATE_DIM
  double state_min[ACTOR_MAX_STATE_DIM];    ///< declared range per entry: the network's input is
  double state_max[ACTOR_MAX_STATE_DIM];    ///< (s - centre) / half-width (1 where the range is empty)
  double state_scale[ACTOR_MAX_STATE_DIM];  ///< raw units per scaled unit of the models (> 0)
  double action_min;                        ///< action bounds, action_min < action_max
  double action_max;
  double action_scale;                      ///< raw action units per scaled unit of the models (> 0)
  double gamma;                             ///< discount, (0, 1)
  uint32_t capacity;                        ///< recorded transitions kept (a ring), 16..ACTOR_MAX_CAPACITY; 20000
  uint32_t hidden;                          ///< tanh units, 1..ACTOR_MAX_HIDDEN; 16
  uint32_t recent_runs;                     ///< runs whose returns fit V and whose states are queried, >= 1; 10
  uint32_t max_queries;                     ///< query set, 1..capacity; 4000
  uint32_t model_k;                         ///< neighbours of the dynamics model, 1..ACTOR_MAX_K; 64
  double model_bandwidth;                   ///< its kernel width in scaled units (> 0); 0.5
  uint32_t model_min_neighbours;            ///< fewer: no slope at that query, 1..model_k; 8
  uint32_t value_k;                         ///< neighbours of the value model, 1..ACTOR_MAX_K; 256
  double value_bandwidth;                   ///< its kernel width in scaled units (> 0); 0.5
  uint32_t value_min_neighbours;            ///< 1..value_k; 12
  double ridge;                             ///< on the local slopes, >= 0; 1e-3
  double step_gain;                         ///< target step per tick of discounting of slope, >= 0; 0.3
  double step_max;                          ///< largest target step per run [action units], >= 0; 0.1
  double trust_radius;                      ///< largest distance of a target from the action recorded
                                            ///< at its state [action units], >= 0 (0: no bound); 0
  double slope_min_t;                       ///< a query steps only where |slope| >= slope_min_t × its
                                            ///< standard error (step 7), >= 0 (0: every slope); 3
  uint32_t rewarded_window;                 ///< 1: the window reaches back to recent_runs runs with a
                                            ///< non-zero reward (steps 3, 5); 0: the last recent_runs; 1
  uint32_t clone_steps;                     ///< Adam steps of the behaviour cloning; 300
  uint32_t fit_steps;                       ///< Adam steps of each fit to the targets; 200
  double learning_rate;                     ///< Adam's (> 0); 3e-3
  uint64_t seed;                            ///< initial weights and the query draws
} actor_config_t;

/// Monotonic counters (never decrease; restored by actor_load only where they are learned state:
/// runs and fits), plus gauges.
typedef struct actor_counters_s {
  uint64_t recorded;            ///< transitions recorded
  uint64_t rejected_non_finite; ///< actor_record calls refused for a non-finite value
  uint64_t runs;                ///< runs ended with recorded transitions (saved: the ring's run ids)
  uint64_t clones;              ///< behaviour clonings done
  uint64_t fits;                ///< fits to slope targets done
  uint64_t fits_undone;         ///< fits undone because a parameter became non-finite
  uint64_t queries;             ///< queries of the local models
  uint64_t queries_with_slope;  ///< of them, with both models formed and a finite slope
  uint64_t queries_stepped;     ///< of them, with a slope that passed the significance test
  uint64_t slices;              ///< actor_end_run_step calls that did work
  uint64_t output_faults;       ///< actor_act outputs that were not finite
  uint32_t max_slice_work;      ///< gauge: largest work of one slice [units]
  uint32_t fill;                ///< gauge: transitions in the ring
  double last_mean_step;        ///< gauge: mean |target step| of the last fit [action units]
  double last_fit_loss;         ///< gauge: mean squared error after the last fit or cloning
} actor_counters_t;

typedef struct actor actor_t;

/// The defaults above; the task fields (state_dim, ranges, scales, bounds, gamma) are zero and
/// must be set. O(1).
actor_config_t actor_config_default(void) ACTOR_NOEXCEPT;

/// ACTOR_OK, or ACTOR_ERR_INVALID_ARG when a field is outside its documented range. O(state_dim).
actor_status_t actor_config_validate(const actor_config_t* cfg) ACTOR_NOEXCEPT;

/// Exact bytes of storage for cfg (a multiple of ACTOR_STORAGE_ALIGN), 0 when cfg is invalid. O(1).
size_t actor_storage_size(const actor_config_t* cfg) ACTOR_NOEXCEPT;

/// Sets up an actor in the caller's storage (aligned, at least actor_storage_size bytes; it must
/// outlive the actor): initial weights from cfg.seed, nothing recorded, untrained. O(storage).
actor_status_t actor_init(actor_t** out, void* storage, size_t storage_size, const actor_config_t* cfg) ACTOR_NOEXCEPT;

const actor_config_t* actor_get_config(const actor_t* self) ACTOR_NOEXCEPT;

/// The actor's action at state (cfg.state_dim values) into *action. ACTOR_OK; ACTOR_UNTRAINED
/// (*action = the middle of the bounds); ACTOR_ERR_NON_FINITE when state or the output is not
/// finite (*action = the middle of the bounds; an output fault is counted: the caller stops the
/// robot). O(state_dim × hidden), no allocation, never blocks. Allowed during between-run work.
actor_status_t actor_act(actor_t* self, const double* state, double* action) ACTOR_NOEXCEPT;

/// True once a behaviour cloning or a fit has set the weights.
int actor_trained(const actor_t* self) ACTOR_NOEXCEPT;

/// Records one transition of the run under way (s_next is ignored when terminal; may then be
/// NULL). The ring keeps the newest cfg.capacity. ACTOR_ERR_NON_FINITE (counted) or
/// ACTOR_ERR_BUSY (between-run work under way) leave everything unchanged. O(state_dim).
actor_status_t actor_record(actor_t* self, const double* state, double action, double reward, const double* state_next,
                            int terminal) ACTOR_NOEXCEPT;

/// Transitions recorded since the last run ended.
uint32_t actor_run_length(const actor_t* self) ACTOR_NOEXCEPT;

/// Ends the run under way: when it recorded a transition, the between-run work (steps 1-7 above)
/// is due and *pending (may be NULL) is 1, else nothing happens and it is 0. ACTOR_ERR_BUSY when
/// work is already under way. O(1).
actor_status_t actor_end_run_begin(actor_t* self, int* pending) ACTOR_NOEXCEPT;

/// Does the due between-run work for at most about max_work units (the first operation always
/// runs; the last one may pass the budget by at most ACTOR_WORK_QUERY units). *remaining (may be
/// NULL): 1 while work is left, 0 when done (or none was due). O(max_work) units.
actor_status_t actor_end_run_step(actor_t* self, uint32_t max_work, int* remaining) ACTOR_NOEXCEPT;

/// True while between-run work is due or under way.
int actor_working(const actor_t* self) ACTOR_NOEXCEPT;

/// One sample of a behaviour cloning from outside the ring (actor_clone): the state and the
/// action at it. Returns 0 to give the sample, nonzero to skip it.
typedef int (*actor_sample_fn)(void* user, uint32_t index, double* state, double* action);

/// Behaviour cloning on n samples got from get (cfg.clone_steps Adam steps; samples whose values
/// are not finite are skipped), e.g. to start an actor from another learner's stored experience.
/// Afterwards the actor is trained. ACTOR_ERR_BUSY during between-run work. Not for a tick:
/// O(clone_steps × n × state_dim × hidden), n calls of get per step.
actor_status_t actor_clone(actor_t* self, uint32_t n, actor_sample_fn get, void* user) ACTOR_NOEXCEPT;

/// Counters and gauges. O(1).
const actor_counters_t* actor_counters(const actor_t* self) ACTOR_NOEXCEPT;

/// Bytes actor_save() writes now (O(1)), and the most any instance of cfg writes (0 if invalid).
size_t actor_serialized_size(const actor_t* self) ACTOR_NOEXCEPT;
size_t actor_serialized_max_size(const actor_config_t* cfg) ACTOR_NOEXCEPT;

/// Position of a sliced save (caller-owned plain data).
typedef struct actor_save_cursor {
  uint8_t* buf;
  size_t size;           ///< bytes the complete save takes
  size_t offset;         ///< bytes written so far
  uint32_t next;         ///< next ring entry to write
  uint32_t crc;          ///< running CRC-32 register
  uint64_t generation;   ///< the state the save belongs to
  int done;
} actor_save_cursor_t;

/// The learned state as bytes (little-endian; the layout is in actor.cpp): the configuration it
/// needs, the generator, the run counter, the parameters with the optimiser's moments, the ring,
/// a CRC-32. actor_save_begin writes the header and parameters (O(parameters)); each
/// actor_save_step writes at most max_entries ring entries (O(max_entries × state_dim)) and, with
/// the last, the CRC; *written (may be NULL) is the byte count once done, else 0. The bytes equal
/// actor_save()'s. ACTOR_ERR_CHANGED when a record, a run's end or a load came in between;
/// ACTOR_ERR_BUSY when between-run work is due or under way.
actor_status_t actor_save_begin(const actor_t* self, void* buf, size_t size, actor_save_cursor_t* cursor) ACTOR_NOEXCEPT;
actor_status_t actor_save_step(const actor_t* self, actor_save_cursor_t* cursor, uint32_t max_entries,
                               size_t* written) ACTOR_NOEXCEPT;
actor_status_t actor_save(const actor_t* self, void* buf, size_t size, size_t* written) ACTOR_NOEXCEPT;

/// The saved length declared by bytes (at least 16 of them) from actor_save, or 0 when they are
/// not an actor's.
size_t actor_saved_length(const void* buf, size_t size) ACTOR_NOEXCEPT;

/// Replaces the learned state with buf's. Checks in order: magic (FORMAT), version (VERSION),
/// declared length (TRUNCATED), CRC-32 (CHECKSUM), configuration (CONFIG_MISMATCH: state_dim,
/// hidden, ranges, scales, action bounds and gamma equal bit for bit, the saved entries fit
/// cfg.capacity), contents (FORMAT: non-finite values, impossible counters). Any failure leaves
/// the actor unchanged. Bytes after the declared length are ignored. Not for a tick: O(saved).
actor_status_t actor_load(actor_t* self, const void* buf, size_t size) ACTOR_NOEXCEPT;

/// A constant English description of a status. Never NULL.
const char* actor_status_str(actor_status_t status) ACTOR_NOEXCEPT;

#ifdef __cplusplus
}
#endif

#endif  // ACTOR_ACTOR_H
