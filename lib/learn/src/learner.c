// SPDX-License-Identifier: MIT
// The value-function learner behind one interface (learn/learner.h). Checkpoints exist for HEDGER
// only: the framework's callers refuse a tabular learner with a checkpoint.
#include "learn/learner.h"

#include <stdio.h>
#include <string.h>

static size_t round_up(size_t n) { return (n + LEARN_LEARNER_ALIGN - 1U) & ~(size_t)(LEARN_LEARNER_ALIGN - 1U); }

size_t learn_learner_storage_size(const learn_learner_config_t* cfg) {
  if (cfg->kind == LEARN_LEARNER_TABULAR) {
    return round_up(tabq_storage_size(&cfg->tabular));
  }
  if (hedger_config_validate(&cfg->hedger) != HEDGER_OK) {
    return 0;
  }
  return round_up(hedger_storage_size(&cfg->hedger));
}

int learn_learner_init(learn_learner_t* lr, void* storage, size_t storage_size, const learn_learner_config_t* cfg,
                       char* err, size_t err_cap) {
  memset(lr, 0, sizeof *lr);
  lr->kind = cfg->kind;
  if (cfg->kind == LEARN_LEARNER_TABULAR) {
    const size_t bytes = tabq_storage_size(&cfg->tabular);
    if (bytes == 0) {
      snprintf(err, err_cap, "the tabular learner's table is too large (tabular_bins %u ^ %u dimensions x %u "
               "actions); lower tabular_bins", cfg->tabular.bins[0], cfg->tabular.state_dim, cfg->tabular.n_actions);
      return -1;
    }
    if (storage_size < bytes || tabq_init(&lr->tabq, storage, bytes, &cfg->tabular) != TABQ_OK) {
      snprintf(err, err_cap, "cannot set up the tabular learner (%zu bytes)", bytes);
      return -1;
    }
    return 0;
  }
  if (hedger_config_validate(&cfg->hedger) != HEDGER_OK) {
    snprintf(err, err_cap, "the learner's configuration is invalid (check the hedger_* keys)");
    return -1;
  }
  const size_t bytes = hedger_storage_size(&cfg->hedger);
  if (storage_size < bytes || hedger_init(&lr->hedger, storage, bytes, &cfg->hedger) != HEDGER_OK) {
    snprintf(err, err_cap, "cannot set up the learner (%zu bytes for %u samples)", bytes, cfg->hedger.capacity);
    return -1;
  }
  return 0;
}

bool learn_learner_greedy(learn_learner_t* lr, const double* s, double* action, double* value) {
  if (lr->tabq != NULL) {
    return tabq_greedy(lr->tabq, s, action, value) == TABQ_OK;
  }
  return hedger_greedy(lr->hedger, s, action, value, NULL) == HEDGER_OK;
}

bool learn_learner_judge(learn_learner_t* lr, const double* s, double action, hedger_judgement_t* j) {
  // Where a call refuses its inputs it writes nothing: then judged 0 and the greedy value 0, the
  // value the greedy policy's path starts from.
  memset(j, 0, sizeof *j);
  j->kept_action = action;
  if (lr->tabq != NULL) {
    return tabq_greedy(lr->tabq, s, &j->greedy_action, &j->greedy_value) == TABQ_OK;
  }
  return hedger_judge(lr->hedger, s, action, j) == HEDGER_OK;
}

// A tabular value is a visited cell or unknown: reported as kind LWA (an average of the updates
// the cell received) or UNKNOWN, so that the experience message keeps one meaning of "unknown".
static hedger_kind_t tabular_kind(int known) { return known ? HEDGER_KIND_LWA : HEDGER_KIND_UNKNOWN; }

bool learn_learner_learn(learn_learner_t* lr, const double* s, double a, double r, const double* s_next, bool terminal,
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

bool learn_learner_predict(learn_learner_t* lr, const double* s, double a, double* q, hedger_kind_t* kind) {
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

void learn_learner_end_run_begin(learn_learner_t* lr) {
  if (lr->tabq != NULL) {
    (void)tabq_end_run_begin(lr->tabq, NULL);
  } else {
    (void)hedger_end_run_begin(lr->hedger, NULL);
  }
}

uint32_t learn_learner_end_run_step(learn_learner_t* lr, uint32_t max_updates) {
  uint32_t remaining = 0;
  if (lr->tabq != NULL) {
    (void)tabq_end_run_step(lr->tabq, max_updates, &remaining);
  } else {
    (void)hedger_end_run_step(lr->hedger, max_updates, &remaining);
  }
  return remaining;
}

learn_learner_stats_t learn_learner_stats(const learn_learner_t* lr) {
  learn_learner_stats_t st = {0};
  if (lr->tabq != NULL) {
    const tabq_counters_t* c = tabq_counters(lr->tabq);
    st.fill = c->cells_visited;
    st.capacity = tabq_cells(lr->tabq);
    st.predictions_lwa = c->predictions_known;
    st.predictions_unknown = c->predictions_unknown;
    st.updates = c->updates;
    st.replayed_updates = c->replayed_updates;
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
  st.updates = c->updates;
  st.replayed_updates = c->replayed_updates;
  return st;
}
