// SPDX-License-Identifier: MIT
/// tabq/tabq.h — tabular Q-learning on a discretised state and action, in fixed memory.
///
/// The baseline HEDGER is measured against (issue 12, learner ablation): Q(s, a) is a table with
/// one cell per (state bin, action); each update is Watkins' Q-learning on the cell of (s, a),
/// Q ← Q + α (r + γ q' − Q), with the same backward replay of a finished run (λ-return target)
/// as hedger_end_run(). No generalisation between cells: what is learned in one cell says nothing
/// about its neighbours.
///
/// Discretisation. State dimension i has bins[i] equal bins over [state_min[i], state_max[i]]
/// (caller units); a value outside the range falls into the nearest edge bin. Actions are
/// n_actions evenly spaced values over [action_min, action_max] (both ends included); an executed
/// action is learned in the cell of its nearest grid action (ties go to the lower one).
///
/// Unknown. A cell never updated holds no value: prediction answers "unknown" with value 0 (as
/// HEDGER's default value), the greedy search never prefers it to a visited one, and with every
/// action of the state bin unvisited the greedy search reports TABQ_NO_KNOWN_ACTION (action 0 if
/// the grid holds it, else the grid action nearest 0; value 0).
///
/// Memory. One caller-provided block (tabq_storage_size(), exact): 12 bytes per cell
/// (value 8, visit count 4), cells = Π bins[i] · n_actions, plus run_capacity · (2 state_dim + 3)
/// · 8 bytes of run buffer and a small header. E.g. corridor 10×10×10 bins × 9 actions: 108 kB.
/// After tabq_init() nothing allocates.
///
/// Cost. predict O(state_dim); greedy O(state_dim + n_actions); learn O(state_dim) (q' is given);
/// replay update O(state_dim + n_actions). Deterministic: the same calls give bit-identical results.
#ifndef TABQ_TABQ_H
#define TABQ_TABQ_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define TABQ_MAX_STATE_DIM 8
#define TABQ_MAX_ACTIONS 64
#define TABQ_MAX_BINS 1024
#define TABQ_MAX_CELLS (1U << 26)  ///< 768 MiB of table: anything larger is a configuration error
#define TABQ_MAX_RUN 100000
#define TABQ_MAX_REPLAY_PASSES 64
#define TABQ_STORAGE_ALIGN 16

typedef enum tabq_status {
  TABQ_OK = 0,
  TABQ_NO_KNOWN_ACTION = 1,    ///< tabq_greedy(): every action of the state's bin is unvisited
  TABQ_ERR_INVALID_ARG = 2,    ///< NULL pointer, invalid config
  TABQ_ERR_NON_FINITE = 3,     ///< an input was NaN or infinite: nothing changed
  TABQ_ERR_CAPACITY = 4,       ///< tabq_init(): storage smaller than tabq_storage_size()
  TABQ_ERR_ALIGNMENT = 5,      ///< tabq_init(): storage not aligned to TABQ_STORAGE_ALIGN
} tabq_status_t;

/// Configuration, fixed at init. Start from tabq_config_default().
typedef struct tabq_config {
  uint32_t state_dim;                    ///< 1..TABQ_MAX_STATE_DIM. Default 1.
  double state_min[TABQ_MAX_STATE_DIM];  ///< lower edge of dimension i (caller units), finite. Default 0.
  double state_max[TABQ_MAX_STATE_DIM];  ///< upper edge, finite, > state_min[i]. Default 1.
  uint32_t bins[TABQ_MAX_STATE_DIM];     ///< bins of dimension i, 1..TABQ_MAX_BINS. Default 10.
  double action_min;                     ///< action grid's lower end (e.g. rad/s), finite. Default -1.
  double action_max;                     ///< upper end, finite, > action_min. Default 1.
  uint32_t n_actions;                    ///< grid actions, 2..TABQ_MAX_ACTIONS. Default 9.
  double alpha;                          ///< learning rate, (0, 1]. Default 0.2.
  double gamma;                          ///< discount, [0, 1). Default 0.99.
  uint32_t run_capacity;                 ///< run buffer (experiences) for replay, 0..TABQ_MAX_RUN; the
                                         ///< oldest are dropped when a run is longer. Default 0.
  uint32_t replay;                       ///< 1: tabq_end_run_* replays the run backwards. Needs
                                         ///< run_capacity > 0. Default 0.
  uint32_t replay_passes;                ///< backward passes, 1..TABQ_MAX_REPLAY_PASSES. Default 1.
  double replay_lambda;                  ///< λ of the replay target, [0, 1] (as hedger_config_t). Default 0.
  double replay_alpha;                   ///< learning rate of the replay's updates, [0, 1]; 0 = alpha (as
                                         ///< hedger_config_t). Default 0.
} tabq_config_t;

/// Counters (monotonic) and gauges.
typedef struct tabq_counters_s {  // "_s": the function tabq_counters() keeps the plain name (C++ -Wshadow)
  uint64_t predictions_known;    ///< predictions (alone, or inside learn) of a visited cell
  uint64_t predictions_unknown;  ///< ... of an unvisited cell
  uint64_t greedy_calls;
  uint64_t greedy_all_unknown;   ///< greedy searches that found no visited action
  uint64_t updates;              ///< training updates, including replayed ones
  uint64_t replayed_updates;
  uint64_t run_overflows;        ///< experiences dropped from a full run buffer
  uint64_t rejected_non_finite;
  uint32_t cells_visited;        ///< gauge: cells updated at least once
  uint32_t run_fill;             ///< gauge: experiences in the run buffer
} tabq_counters_t;

typedef struct tabq tabq_t;

/// The default configuration (values documented per field). O(1).
tabq_config_t tabq_config_default(void);
/// TABQ_OK or TABQ_ERR_INVALID_ARG. O(state_dim).
tabq_status_t tabq_config_validate(const tabq_config_t* cfg);
/// Exact bytes tabq_init() needs for cfg, or 0 when cfg is invalid. O(state_dim).
size_t tabq_storage_size(const tabq_config_t* cfg);
/// Initialises an instance in caller storage (aligned to TABQ_STORAGE_ALIGN, outliving the
/// instance); every cell unvisited. O(cells). *out points into storage.
tabq_status_t tabq_init(tabq_t** out, void* storage, size_t storage_size, const tabq_config_t* cfg);
const tabq_config_t* tabq_get_config(const tabq_t* self);
/// Cells of the table (Π bins · n_actions). O(1).
uint32_t tabq_cells(const tabq_t* self);
/// Grid action j (0..n_actions-1). O(1).
double tabq_action(const tabq_t* self, uint32_t j);

/// Q(state, action): *value (0 when unknown) and *known (1 visited, 0 not); either may be NULL.
/// Errors: INVALID_ARG, NON_FINITE.
tabq_status_t tabq_predict(tabq_t* self, const double* state, double action, double* value, int* known);
/// Greedy grid action at state: the visited action of largest value; ties go to the smallest
/// |action|, then the lower action. TABQ_OK, or TABQ_NO_KNOWN_ACTION (see the file comment).
/// Outputs may be NULL. Errors: INVALID_ARG, NON_FINITE.
tabq_status_t tabq_greedy(tabq_t* self, const double* state, double* action, double* value);
/// One Q-learning update of the cell of (state, action) with target r (terminal) or r + γ q_next
/// (q_next: the caller's greedy value at state_next, 0 when unknown; ignored when terminal;
/// state_next ignored and may be NULL when terminal). Records the experience for the replay.
/// *q_old / *known_old (may be NULL): the cell before the update. A replay under way is finished
/// first. Errors: INVALID_ARG, NON_FINITE (nothing changed).
tabq_status_t tabq_learn(tabq_t* self, const double* state, double action, double reward, const double* state_next,
                         int terminal, double q_next, double* q_old, int* known_old);
/// Ends the run: with replay, *pending (may be NULL) receives the updates the replay takes
/// (replay_passes × recorded experiences, newest first, λ-return target T_t = r_t + γ ((1 − λ)
/// V(s_{t+1}) + λ T_{t+1}), V the greedy value); without, the run buffer is cleared. O(1).
tabq_status_t tabq_end_run_begin(tabq_t* self, uint32_t* pending);
/// At most max_updates replay updates; *remaining (may be NULL) receives those left.
tabq_status_t tabq_end_run_step(tabq_t* self, uint32_t max_updates, uint32_t* remaining);
const tabq_counters_t* tabq_counters(const tabq_t* self);
const char* tabq_status_str(tabq_status_t status);

#ifdef __cplusplus
}
#endif

#endif  // TABQ_TABQ_H
