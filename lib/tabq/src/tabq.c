// SPDX-License-Identifier: MIT
// Tabular Q-learning in one caller block: header, the values, the visit counts, the run buffer.
#include "tabq/tabq.h"

#include <math.h>
#include <stdbool.h>
#include <string.h>

struct tabq {
  tabq_config_t cfg;
  tabq_counters_t counters;
  double* q;                 // cells values, index = state_bin · n_actions + action
  uint32_t* visits;          // updates per cell (saturating); 0 = unknown
  double* run;               // run_capacity records: s, a, r, s', terminal
  uint32_t run_stride;       // doubles per record
  uint32_t run_head;         // next record to write
  uint32_t run_count;
  uint32_t n_cells;
  bool replay_pending;
  uint32_t replay_pass;
  uint32_t replay_k;         // record of the pass, counted back from the newest
  double replay_next_return; // target of the record after this one (λ-return)
};

static size_t align_up(size_t n) { return (n + TABQ_STORAGE_ALIGN - 1U) & ~(size_t)(TABQ_STORAGE_ALIGN - 1U); }

tabq_config_t tabq_config_default(void) {
  tabq_config_t c;
  memset(&c, 0, sizeof c);
  c.state_dim = 1;
  for (uint32_t i = 0; i < TABQ_MAX_STATE_DIM; ++i) {
    c.state_min[i] = 0.0;
    c.state_max[i] = 1.0;
    c.bins[i] = 10;
  }
  c.action_min = -1.0;
  c.action_max = 1.0;
  c.n_actions = 9;
  c.alpha = 0.2;
  c.gamma = 0.99;
  c.run_capacity = 0;
  c.replay = 0;
  c.replay_passes = 1;
  c.replay_lambda = 0.0;
  c.replay_alpha = 0.0;
  return c;
}

// Cells of cfg, or 0 when the table would exceed TABQ_MAX_CELLS.
static uint32_t cell_count(const tabq_config_t* c) {
  uint64_t n = c->n_actions;
  for (uint32_t i = 0; i < c->state_dim; ++i) {
    n *= c->bins[i];
    if (n > TABQ_MAX_CELLS) {
      return 0;
    }
  }
  return (uint32_t)n;
}

tabq_status_t tabq_config_validate(const tabq_config_t* c) {
  if (c == NULL || c->state_dim < 1 || c->state_dim > TABQ_MAX_STATE_DIM) {
    return TABQ_ERR_INVALID_ARG;
  }
  for (uint32_t i = 0; i < c->state_dim; ++i) {
    if (!isfinite(c->state_min[i]) || !isfinite(c->state_max[i]) || !(c->state_max[i] > c->state_min[i]) ||
        c->bins[i] < 1 || c->bins[i] > TABQ_MAX_BINS) {
      return TABQ_ERR_INVALID_ARG;
    }
  }
  if (!isfinite(c->action_min) || !isfinite(c->action_max) || !(c->action_max > c->action_min) ||
      c->n_actions < 2 || c->n_actions > TABQ_MAX_ACTIONS) {
    return TABQ_ERR_INVALID_ARG;
  }
  if (!(c->alpha > 0.0 && c->alpha <= 1.0) || !(c->gamma >= 0.0 && c->gamma < 1.0)) {
    return TABQ_ERR_INVALID_ARG;
  }
  if (c->run_capacity > TABQ_MAX_RUN || c->replay > 1 || (c->replay == 1 && c->run_capacity == 0) ||
      c->replay_passes < 1 || c->replay_passes > TABQ_MAX_REPLAY_PASSES ||
      !(c->replay_lambda >= 0.0 && c->replay_lambda <= 1.0) ||
      !(c->replay_alpha >= 0.0 && c->replay_alpha <= 1.0)) {
    return TABQ_ERR_INVALID_ARG;
  }
  return cell_count(c) == 0 ? TABQ_ERR_INVALID_ARG : TABQ_OK;
}

size_t tabq_storage_size(const tabq_config_t* c) {
  if (tabq_config_validate(c) != TABQ_OK) {
    return 0;
  }
  const size_t cells = cell_count(c);
  const size_t stride = 2U * c->state_dim + 3U;
  return align_up(sizeof(struct tabq)) + align_up(cells * sizeof(double)) + align_up(cells * sizeof(uint32_t)) +
         align_up((size_t)c->run_capacity * stride * sizeof(double));
}

tabq_status_t tabq_init(tabq_t** out, void* storage, size_t storage_size, const tabq_config_t* c) {
  if (out == NULL || storage == NULL || tabq_config_validate(c) != TABQ_OK) {
    return TABQ_ERR_INVALID_ARG;
  }
  if (((uintptr_t)storage % TABQ_STORAGE_ALIGN) != 0) {
    return TABQ_ERR_ALIGNMENT;
  }
  if (storage_size < tabq_storage_size(c)) {
    return TABQ_ERR_CAPACITY;
  }
  uint8_t* p = (uint8_t*)storage;
  tabq_t* t = (tabq_t*)(void*)p;
  memset(t, 0, sizeof *t);
  t->cfg = *c;
  t->n_cells = cell_count(c);
  t->run_stride = 2U * c->state_dim + 3U;
  p += align_up(sizeof *t);
  t->q = (double*)(void*)p;
  p += align_up((size_t)t->n_cells * sizeof(double));
  t->visits = (uint32_t*)(void*)p;
  p += align_up((size_t)t->n_cells * sizeof(uint32_t));
  t->run = (double*)(void*)p;
  for (uint32_t i = 0; i < t->n_cells; ++i) {
    t->q[i] = 0.0;
    t->visits[i] = 0;
  }
  *out = t;
  return TABQ_OK;
}

const tabq_config_t* tabq_get_config(const tabq_t* self) { return self == NULL ? NULL : &self->cfg; }
uint32_t tabq_cells(const tabq_t* self) { return self == NULL ? 0U : self->n_cells; }

double tabq_action(const tabq_t* self, uint32_t j) {
  const tabq_config_t* c = &self->cfg;
  if (j + 1U >= c->n_actions) {
    return c->action_max;  // the upper end exactly, not through rounding
  }
  return c->action_min + (c->action_max - c->action_min) * (double)j / (double)(c->n_actions - 1U);
}

static bool all_finite(const double* v, uint32_t n) {
  for (uint32_t i = 0; i < n; ++i) {
    if (!isfinite(v[i])) {
      return false;
    }
  }
  return true;
}

// First cell of the state's bin (its actions follow).
static uint32_t state_base(const tabq_t* t, const double* s) {
  const tabq_config_t* c = &t->cfg;
  uint32_t idx = 0;
  for (uint32_t i = 0; i < c->state_dim; ++i) {
    const double u = (s[i] - c->state_min[i]) / (c->state_max[i] - c->state_min[i]) * (double)c->bins[i];
    uint32_t b = 0;
    if (u >= (double)c->bins[i]) {
      b = c->bins[i] - 1U;
    } else if (u > 0.0) {
      b = (uint32_t)u;
    }
    idx = idx * c->bins[i] + b;
  }
  return idx * c->n_actions;
}

static uint32_t action_index(const tabq_t* t, double a) {
  const tabq_config_t* c = &t->cfg;
  const double u = (a - c->action_min) / (c->action_max - c->action_min) * (double)(c->n_actions - 1U);
  if (!(u > 0.0)) {
    return 0;
  }
  const double r = ceil(u - 0.5);  // nearest; a tie goes to the lower action
  return r >= (double)(c->n_actions - 1U) ? c->n_actions - 1U : (uint32_t)r;
}

typedef struct greedy_result {
  bool known;
  uint32_t j;
  double value;
} greedy_result_t;

static greedy_result_t greedy_at(tabq_t* t, const double* s) {
  const uint32_t base = state_base(t, s);
  greedy_result_t g = {false, 0, 0.0};
  double best_abs = HUGE_VAL;
  t->counters.greedy_calls++;
  for (uint32_t j = 0; j < t->cfg.n_actions; ++j) {
    const double a = fabs(tabq_action(t, j));
    if (t->visits[base + j] == 0) {
      if (!g.known && a < best_abs) {  // the fallback action: the grid action nearest 0
        best_abs = a;
        g.j = j;
      }
      continue;
    }
    const double v = t->q[base + j];
    if (!g.known || v > g.value || (!(v < g.value) && a < best_abs)) {  // equal: the smaller |a|
      g.known = true;
      g.j = j;
      g.value = v;
      best_abs = a;
    }
  }
  if (!g.known) {
    t->counters.greedy_all_unknown++;
    g.value = 0.0;
  }
  return g;
}

tabq_status_t tabq_predict(tabq_t* self, const double* state, double action, double* value, int* known) {
  if (self == NULL || state == NULL) {
    return TABQ_ERR_INVALID_ARG;
  }
  if (!all_finite(state, self->cfg.state_dim) || !isfinite(action)) {
    self->counters.rejected_non_finite++;
    return TABQ_ERR_NON_FINITE;
  }
  const uint32_t cell = state_base(self, state) + action_index(self, action);
  const bool k = self->visits[cell] > 0;
  if (k) {
    self->counters.predictions_known++;
  } else {
    self->counters.predictions_unknown++;
  }
  if (value != NULL) {
    *value = k ? self->q[cell] : 0.0;
  }
  if (known != NULL) {
    *known = k ? 1 : 0;
  }
  return TABQ_OK;
}

tabq_status_t tabq_greedy(tabq_t* self, const double* state, double* action, double* value) {
  if (self == NULL || state == NULL) {
    return TABQ_ERR_INVALID_ARG;
  }
  if (!all_finite(state, self->cfg.state_dim)) {
    self->counters.rejected_non_finite++;
    return TABQ_ERR_NON_FINITE;
  }
  const greedy_result_t g = greedy_at(self, state);
  if (action != NULL) {
    *action = tabq_action(self, g.j);
  }
  if (value != NULL) {
    *value = g.value;
  }
  return g.known ? TABQ_OK : TABQ_NO_KNOWN_ACTION;
}

// The update of one cell toward target with step alpha; returns the value before.
static double update_cell(tabq_t* t, const double* s, double a, double target, double alpha, int* known_old) {
  const uint32_t cell = state_base(t, s) + action_index(t, a);
  const bool known = t->visits[cell] > 0;
  const double q = known ? t->q[cell] : 0.0;
  if (known) {
    t->counters.predictions_known++;
  } else {
    t->counters.predictions_unknown++;
    t->counters.cells_visited++;
  }
  t->q[cell] = q + alpha * (target - q);
  if (t->visits[cell] < UINT32_MAX) {
    t->visits[cell]++;
  }
  t->counters.updates++;
  if (known_old != NULL) {
    *known_old = known ? 1 : 0;
  }
  return q;
}

static void replay_step(tabq_t* t, uint32_t max_updates) {
  const uint32_t sd = t->cfg.state_dim;
  const uint32_t cap = t->cfg.run_capacity;
  const double lambda = t->cfg.replay_lambda;
  const double alpha = t->cfg.replay_alpha > 0.0 ? t->cfg.replay_alpha : t->cfg.alpha;
  uint32_t done = 0;
  while (t->replay_pending && done < max_updates) {
    const uint32_t idx = (t->run_head + cap - 1U - t->replay_k % cap) % cap;
    const double* rec = t->run + (size_t)idx * t->run_stride;
    const double a = rec[sd];
    const double r = rec[sd + 1U];
    const double* sn = rec + sd + 2U;
    const bool terminal = rec[2U * sd + 2U] > 0.5;
    const double boot = terminal ? 0.0 : greedy_at(t, sn).value;
    double target = t->replay_k == 0 ? r + t->cfg.gamma * boot
                                     : r + t->cfg.gamma * ((1.0 - lambda) * boot + lambda * t->replay_next_return);
    if (terminal) {
      target = r;
    }
    (void)update_cell(t, rec, a, target, alpha, NULL);
    t->counters.replayed_updates++;
    t->replay_next_return = target;
    ++done;
    if (++t->replay_k == t->run_count) {
      t->replay_k = 0;
      if (++t->replay_pass == t->cfg.replay_passes) {
        t->replay_pending = false;
        t->run_head = 0;
        t->run_count = 0;
        t->counters.run_fill = 0;
      }
    }
  }
}

tabq_status_t tabq_learn(tabq_t* self, const double* state, double action, double reward, const double* state_next,
                         int terminal, double q_next, double* q_old, int* known_old) {
  if (self == NULL || state == NULL || (!terminal && state_next == NULL)) {
    return TABQ_ERR_INVALID_ARG;
  }
  const uint32_t sd = self->cfg.state_dim;
  if (!all_finite(state, sd) || !isfinite(action) || !isfinite(reward) ||
      (!terminal && (!all_finite(state_next, sd) || !isfinite(q_next)))) {
    self->counters.rejected_non_finite++;
    return TABQ_ERR_NON_FINITE;
  }
  if (self->replay_pending) {
    replay_step(self, UINT32_MAX);
  }
  const double target = terminal ? reward : reward + self->cfg.gamma * q_next;
  const double q = update_cell(self, state, action, target, self->cfg.alpha, known_old);
  if (q_old != NULL) {
    *q_old = q;
  }
  const uint32_t cap = self->cfg.run_capacity;
  if (cap > 0) {
    double* rec = self->run + (size_t)self->run_head * self->run_stride;
    memcpy(rec, state, sd * sizeof(double));
    rec[sd] = action;
    rec[sd + 1U] = reward;
    if (terminal) {
      memcpy(rec + sd + 2U, state, sd * sizeof(double));  // unused: no bootstrap from a terminal state
    } else {
      memcpy(rec + sd + 2U, state_next, sd * sizeof(double));
    }
    rec[2U * sd + 2U] = terminal ? 1.0 : 0.0;
    self->run_head = (self->run_head + 1U) % cap;
    if (self->run_count < cap) {
      self->run_count++;
    } else {
      self->counters.run_overflows++;
    }
    self->counters.run_fill = self->run_count;
  }
  return TABQ_OK;
}

tabq_status_t tabq_end_run_begin(tabq_t* self, uint32_t* pending) {
  if (self == NULL) {
    return TABQ_ERR_INVALID_ARG;
  }
  if (self->replay_pending) {
    replay_step(self, UINT32_MAX);
  }
  uint32_t n = 0;
  if (!self->cfg.replay || self->run_count == 0) {
    self->run_head = 0;
    self->run_count = 0;
    self->counters.run_fill = 0;
  } else {
    self->replay_pending = true;
    self->replay_pass = 0;
    self->replay_k = 0;
    self->replay_next_return = 0.0;
    n = self->run_count * self->cfg.replay_passes;
  }
  if (pending != NULL) {
    *pending = n;
  }
  return TABQ_OK;
}

tabq_status_t tabq_end_run_step(tabq_t* self, uint32_t max_updates, uint32_t* remaining) {
  if (self == NULL) {
    return TABQ_ERR_INVALID_ARG;
  }
  if (self->replay_pending && max_updates > 0) {
    replay_step(self, max_updates);
  }
  if (remaining != NULL) {
    *remaining = self->replay_pending
                     ? (self->cfg.replay_passes - self->replay_pass) * self->run_count - self->replay_k
                     : 0U;
  }
  return TABQ_OK;
}

const tabq_counters_t* tabq_counters(const tabq_t* self) { return self == NULL ? NULL : &self->counters; }

const char* tabq_status_str(tabq_status_t status) {
  switch (status) {
    case TABQ_OK:
      return "ok";
    case TABQ_NO_KNOWN_ACTION:
      return "no known action";
    case TABQ_ERR_INVALID_ARG:
      return "invalid argument";
    case TABQ_ERR_NON_FINITE:
      return "non-finite input";
    case TABQ_ERR_CAPACITY:
      return "storage too small";
    case TABQ_ERR_ALIGNMENT:
      return "storage misaligned";
  }
  return "unknown status";
}
