// SPDX-License-Identifier: MIT
/// learn/learner.h — The value-function learner behind one interface: HEDGER (the paper's),
/// HEDGER with locally weighted averaging only, or tabular Q-learning on a discretised state
/// (lib/tabq). The learning framework (learn/learn.h) asks the same things of each: the greedy
/// action and its value, the prediction of Q(s, a), the update of one transition with a given
/// q', the sliced backward replay between runs, and gauges for status messages.
///
/// Memory: the learner lives in storage the caller provides (learn_learner_storage_size, aligned
/// to LEARN_LEARNER_ALIGN); nothing is allocated after learn_learner_init. Not thread-safe.
/// Costs: those of hedger.h / tabq.h for the corresponding calls (a HEDGER update or greedy search
/// is one neighbourhood query, O(log n + k), and one local fit; a tabular call O(state_dim)).
#ifndef LEARN_LEARNER_H
#define LEARN_LEARNER_H

#include <hedger/hedger.h>
#include <tabq/tabq.h>

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Which learner (the learner ablation compares them on the same data).
typedef enum learn_learner_kind {
  LEARN_LEARNER_HEDGER = 0,   ///< HEDGER: LWR guarded by the hull and plausibility tests, LWA fallback
  LEARN_LEARNER_LWA = 1,      ///< HEDGER with every prediction by locally weighted averaging
  LEARN_LEARNER_TABULAR = 2,  ///< tabular Q-learning on a discretised state and action (lib/tabq)
} learn_learner_kind_t;

/// Alignment of the learner's storage.
#define LEARN_LEARNER_ALIGN 64U

/// The learner's settings, fully derived (learn_learner_config() in learn/learn.h derives them
/// from a task and the framework's settings).
typedef struct learn_learner_config_s {
  int32_t kind;            ///< learn_learner_kind_t
  hedger_config_t hedger;  ///< HEDGER and LWA (local_model LWA for the latter)
  tabq_config_t tabular;   ///< the tabular learner
} learn_learner_config_t;

/// A learner: exactly one of hedger and tabq is set after a successful init.
typedef struct learn_learner {
  int32_t kind;      ///< learn_learner_kind_t
  hedger_t* hedger;  ///< in the caller's storage
  tabq_t* tabq;      ///< in the caller's storage
} learn_learner_t;

/// Gauges and counters of the learner for status messages and progress lines.
typedef struct learn_learner_stats_s {
  uint32_t fill;                 ///< HEDGER: stored points; tabular: visited cells
  uint32_t capacity;             ///< HEDGER: store capacity; tabular: cells
  uint64_t predictions_lwr;
  uint64_t predictions_lwa;      ///< tabular: predictions of a visited cell
  uint64_t predictions_unknown;
  uint64_t evictions;
  uint64_t rebuilds;
  uint64_t updates;              ///< training updates, including replayed ones
  uint64_t replayed_updates;     ///< updates done by backward replay
} learn_learner_stats_t;

/// Bytes of storage the learner of cfg needs (a multiple of LEARN_LEARNER_ALIGN); 0 when cfg is
/// invalid or the tabular learner's table is too large. O(1).
size_t learn_learner_storage_size(const learn_learner_config_t* cfg);

/// Sets up the learner of cfg in storage (aligned to LEARN_LEARNER_ALIGN, at least
/// learn_learner_storage_size bytes). Returns 0, or -1 with a message (err, capacity err_cap)
/// naming the setting to change. O(storage).
int learn_learner_init(learn_learner_t* lr, void* storage, size_t storage_size, const learn_learner_config_t* cfg,
                       char* err, size_t err_cap);

/// Greedy action and its value at s; false when no action is known there (value = the default).
bool learn_learner_greedy(learn_learner_t* lr, const double* s, double* action, double* value);

/// The greedy action and value at s (as learn_learner_greedy) and HEDGER's judgement of action
/// there (hedger_judge()) into *j; false when no action is known at s. Tabular Q: the greedy
/// action, j->judged = 0.
bool learn_learner_judge(learn_learner_t* lr, const double* s, double action, hedger_judgement_t* j);

/// One update of (s, a, r, s', terminal) with q' given; *q_old / *kind: Q(s, a) before it.
bool learn_learner_learn(learn_learner_t* lr, const double* s, double a, double r, const double* s_next, bool terminal,
                         double q_next, double* q_old, hedger_kind_t* kind);

/// Q(s, a) and how it was obtained (tabular: LWA = a visited cell, UNKNOWN = never visited).
bool learn_learner_predict(learn_learner_t* lr, const double* s, double a, double* q, hedger_kind_t* kind);

/// The finished run's backward replay: begin, then steps of at most max_updates; each step
/// returns the updates left (0: done).
void learn_learner_end_run_begin(learn_learner_t* lr);
uint32_t learn_learner_end_run_step(learn_learner_t* lr, uint32_t max_updates);

/// Gauges and counters. O(1).
learn_learner_stats_t learn_learner_stats(const learn_learner_t* lr);

#ifdef __cplusplus
}
#endif

#endif  // LEARN_LEARNER_H
