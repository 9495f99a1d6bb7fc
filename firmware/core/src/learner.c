// SPDX-License-Identifier: MIT
// The value-function learner behind the loop: HEDGER (the paper's), HEDGER with locally weighted
// averaging only, or tabular Q-learning on a discretised state (config key `learner`). The loop
// asks the same five things of each: the greedy action and its value, the prediction of Q(s, a),
// the update of one transition with a given q', the sliced backward replay between runs, and
// gauges for the status message. Checkpoints exist for HEDGER only (the configuration refuses a
// tabular learner with checkpoint_file).
#include "loop_internal.h"

#include <stdio.h>
#include <stdlib.h>

#define PI 3.14159265358979323846

// The task's state ranges for the tabular learner's bins (values outside fall into the edge bins).
static void tabular_ranges(const fw_loop_t* L, tabq_config_t* tc) {
  if (fw_run_is_corridor(L)) {
    tc->state_min[0] = 0.0;  // end distance [m]
    tc->state_max[0] = L->cfg.corridor_length_m;
    tc->state_min[1] = 0.0;  // lateral position, fraction of the width from the left wall
    tc->state_max[1] = 1.0;
    tc->state_min[2] = -0.5 * PI;  // target angle [rad]: beyond +-90 deg the robot faces a wall
    tc->state_max[2] = 0.5 * PI;
  } else {
    tc->state_min[0] = -PI;  // goal bearing [rad]
    tc->state_max[0] = PI;
    tc->state_min[1] = 0.0;        // goal distance [m]
    tc->state_max[1] = 8.0;
    tc->state_min[2] = -PI;  // obstacle bearing [rad]
    tc->state_max[2] = PI;
    tc->state_min[3] = 0.0;        // obstacle distance [m], 8 = the edge of sensing
    tc->state_max[3] = 8.0;
  }
  if (L->cfg.state_rotation) {
    tc->state_min[L->ep.state_dim] = -L->omega_max;  // executed rotation [rad/s]
    tc->state_max[L->ep.state_dim] = L->omega_max;
  }
}

int fw_learner_init(fw_loop_t* L, uint64_t seed, char* err, size_t err_cap) {
  fw_learner_t* lr = &L->learner;
  lr->kind = L->cfg.learner;
  hedger_config_t hc;
  fw_learning_config(L, &hc);
  hc.seed = seed;
  if (lr->kind == FW_LEARNER_TABULAR) {
    tabq_config_t tc = tabq_config_default();
    tc.state_dim = L->state_dim;
    for (uint32_t i = 0; i < L->state_dim; ++i) {
      tc.bins[i] = (uint32_t)L->cfg.tabular_bins;
    }
    tabular_ranges(L, &tc);
    tc.action_min = -L->omega_max;
    tc.action_max = L->omega_max;
    tc.n_actions = (uint32_t)L->cfg.tabular_actions;
    tc.alpha = hc.alpha;
    tc.gamma = hc.gamma;
    tc.run_capacity = hc.run_capacity;
    tc.replay = hc.replay;
    tc.replay_passes = hc.replay_passes;
    tc.replay_lambda = hc.replay_lambda;
    const size_t bytes = tabq_storage_size(&tc);
    if (bytes == 0) {
      snprintf(err, err_cap, "loop: the tabular learner's table is too large (tabular_bins %d ^ %u dimensions x %d "
               "actions); lower tabular_bins", (int)L->cfg.tabular_bins, L->state_dim, (int)L->cfg.tabular_actions);
      return -1;
    }
    lr->storage_bytes = (bytes + TABQ_STORAGE_ALIGN - 1) & ~(size_t)(TABQ_STORAGE_ALIGN - 1);
    lr->storage = aligned_alloc(TABQ_STORAGE_ALIGN, lr->storage_bytes);
    if (lr->storage == NULL || tabq_init(&lr->tabq, lr->storage, bytes, &tc) != TABQ_OK) {
      snprintf(err, err_cap, "loop: cannot set up the tabular learner (%zu bytes)", bytes);
      free(lr->storage);
      lr->storage = NULL;
      return -1;
    }
    return 0;
  }
  if (hedger_config_validate(&hc) != HEDGER_OK) {
    snprintf(err, err_cap, "loop: the learner's configuration is invalid (check the hedger_* keys)");
    return -1;
  }
  const size_t bytes = hedger_storage_size(&hc);
  lr->storage_bytes = (bytes + HEDGER_STORAGE_ALIGN - 1) & ~(size_t)(HEDGER_STORAGE_ALIGN - 1);
  lr->storage = aligned_alloc(HEDGER_STORAGE_ALIGN, lr->storage_bytes);
  if (lr->storage == NULL || hedger_init(&lr->hedger, lr->storage, bytes, &hc) != HEDGER_OK) {
    snprintf(err, err_cap, "loop: cannot set up the learner (%zu bytes for %d samples)", bytes,
             (int)L->cfg.hedger_capacity);
    free(lr->storage);
    lr->storage = NULL;
    return -1;
  }
  lr->save_max = hedger_serialized_max_size(&hc);
  return 0;
}

void fw_learner_free(fw_learner_t* lr) {
  free(lr->storage);
  lr->storage = NULL;
  lr->storage_bytes = 0;
  lr->hedger = NULL;
  lr->tabq = NULL;
}

bool fw_learner_greedy(fw_learner_t* lr, const double* s, double* action, double* value) {
  if (lr->tabq != NULL) {
    return tabq_greedy(lr->tabq, s, action, value) == TABQ_OK;
  }
  return hedger_greedy(lr->hedger, s, action, value, NULL) == HEDGER_OK;
}

// A tabular value is a visited cell or unknown: reported as kind LWA (an average of the updates
// the cell received) or UNKNOWN, so that the experience message keeps one meaning of "unknown".
static hedger_kind_t tabular_kind(int known) { return known ? HEDGER_KIND_LWA : HEDGER_KIND_UNKNOWN; }

bool fw_learner_learn(fw_learner_t* lr, const double* s, double a, double r, const double* s_next, bool terminal,
                      double q_next, double* q_old, hedger_kind_t* kind) {
  if (lr->tabq != NULL) {
    int known = 0;
    if (tabq_learn(lr->tabq, s, a, r, s_next, terminal ? 1 : 0, q_next, q_old, &known) != TABQ_OK) {
      return false;
    }
    *kind = tabular_kind(known);
    return true;
  }
  hedger_update_info_t info;
  if (hedger_learn(lr->hedger, s, a, r, s_next, terminal ? 1 : 0, q_next, &info) != HEDGER_OK) {
    return false;
  }
  *q_old = info.q_old;
  *kind = info.kind;
  return true;
}

bool fw_learner_predict(fw_learner_t* lr, const double* s, double a, double* q, hedger_kind_t* kind) {
  if (lr->tabq != NULL) {
    int known = 0;
    if (tabq_predict(lr->tabq, s, a, q, &known) != TABQ_OK) {
      return false;
    }
    *kind = tabular_kind(known);
    return true;
  }
  hedger_prediction_t pr;
  if (hedger_predict(lr->hedger, s, a, &pr) != HEDGER_OK) {
    return false;
  }
  *q = pr.value;
  *kind = pr.kind;
  return true;
}

void fw_learner_end_run_begin(fw_learner_t* lr) {
  if (lr->tabq != NULL) {
    (void)tabq_end_run_begin(lr->tabq, NULL);
  } else {
    (void)hedger_end_run_begin(lr->hedger, NULL);
  }
}

uint32_t fw_learner_end_run_step(fw_learner_t* lr, uint32_t max_updates) {
  uint32_t remaining = 0;
  if (lr->tabq != NULL) {
    (void)tabq_end_run_step(lr->tabq, max_updates, &remaining);
  } else {
    (void)hedger_end_run_step(lr->hedger, max_updates, &remaining);
  }
  return remaining;
}

fw_learner_stats_t fw_learner_stats(const fw_learner_t* lr) {
  fw_learner_stats_t st = {0};
  if (lr->tabq != NULL) {
    const tabq_counters_t* c = tabq_counters(lr->tabq);
    st.fill = c->cells_visited;
    st.capacity = tabq_cells(lr->tabq);
    st.predictions_lwa = c->predictions_known;
    st.predictions_unknown = c->predictions_unknown;
    return st;
  }
  const hedger_counters_t* c = hedger_counters(lr->hedger);
  st.fill = c->store_fill;
  st.capacity = hedger_get_config(lr->hedger)->capacity;
  st.predictions_lwr = c->predictions_lwr;
  st.predictions_lwa = c->predictions_lwa;
  st.predictions_unknown = c->predictions_unknown;
  st.evictions = c->evictions;
  st.rebuilds = c->rebuilds;
  return st;
}
