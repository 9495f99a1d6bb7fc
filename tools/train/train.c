// SPDX-License-Identifier: MIT
// Offline HEDGER training from experience logs (see train.h).
#define _POSIX_C_SOURCE 200809L
#include "train.h"

#include <fw/checkpoint.h>
#include <fw/config_task.h>
#include <fw/errfmt.h>
#include <fw/progress.h>
#include <learn/learn.h>

#include <b21r/b21r_experience_t.h>
#include <lcm/eventlog.h>

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

struct trainer {
  fw_config_t cfg;
  train_options_t opt;
  void* storage;         // the agent's (learn_storage_size), allocated once
  learn_t* agent;
  hedger_t* hedger;      // the agent's learner
  uint32_t state_dim;    // the learner's state dimension
  train_stats_t stats;
  // The run under way: the controller ends a run (hedger_end_run) before the next one starts.
  bool in_run;
  bool run_learned;      // at least one experience of it went through hedger_update
  int32_t run_id;
  int64_t next_seq;      // expected seq of the next experience (-1: none yet in this log)
  // The decisions' spacing (decision_ticks): a run's experiences are that many steps apart, but
  // its last (the run ended inside a window). A spacing off that is followed by another
  // experience of the run means the log was recorded with another decision_ticks.
  int32_t prev_step_id;
  int32_t off_spacing;   // the spacing of the previous pair when it was off, else 0
  double progress_next_s;
  double started_s;
};

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

trainer_t* trainer_create(const fw_config_t* cfg, const train_options_t* opt, char* err, size_t err_cap) {
  if (cfg->learner == FW_LEARNER_TABULAR) {
    fw_errfmt(err, err_cap, "learner = tabular: the offline trainer trains HEDGER only (learner = hedger or lwa)");
    return NULL;
  }
  // The learning framework exactly as the controller sets it up from cfg (fw/config_task.h), but
  // in phase two from the start: its progress is what the trained checkpoint says, so that the
  // controller resumes from it with the learned policy.
  tasks_episode_t ep;
  if (fw_config_task(cfg, &ep, NULL, err, err_cap) != 0) {
    return NULL;
  }
  learn_task_t task;
  fw_config_learn_task(cfg, &ep, &task);
  learn_config_t lc;
  fw_config_learn_settings(cfg, &lc);
  lc.mode = LEARN_MODE_LEARN;
  lc.schedule.evaluate_only = false;
  lc.schedule.switch_mode = LEARN_SWITCH_RUNS;
  lc.schedule.phase_one_runs = 0;
  if (lc.schedule.phase_two_runs < 1) {
    lc.schedule.phase_two_runs = 1;
  }
  const size_t bytes = learn_storage_size(&task, &lc);
  if (bytes == 0) {
    fw_errfmt(err, err_cap, "the learner cannot be set up with these settings (check the hedger_* keys)");
    return NULL;
  }
  trainer_t* t = (trainer_t*)calloc(1, sizeof *t);
  void* storage = aligned_alloc(LEARN_STORAGE_ALIGN, (bytes + LEARN_STORAGE_ALIGN - 1U) / LEARN_STORAGE_ALIGN *
                                                         LEARN_STORAGE_ALIGN);
  if (t == NULL || storage == NULL) {
    fw_errfmt(err, err_cap, "out of memory (%zu bytes for the learner)", bytes);
    free(t);
    free(storage);
    return NULL;
  }
  char why[LEARN_ERR_MAX];
  learn_t* agent = learn_init(storage, bytes, &task, &lc, why, sizeof why);
  if (agent == NULL || learn_get_learner(agent)->hedger == NULL) {
    fw_errfmt(err, err_cap, "cannot set up the learner with the controller's settings: %s", why);
    free(t);
    free(storage);
    return NULL;
  }
  t->cfg = *cfg;
  t->opt = *opt;
  if (t->opt.channel == NULL) {
    t->opt.channel = "B21R_EXPERIENCE";
  }
  if (!(t->opt.progress_period_s > 0.0)) {
    t->opt.progress_period_s = 1.0;
  }
  t->storage = storage;
  t->agent = agent;
  t->hedger = learn_get_learner(agent)->hedger;
  t->state_dim = learn_agent_state_dim(agent);
  t->next_seq = -1;
  t->started_s = now_s();
  t->progress_next_s = t->started_s + t->opt.progress_period_s;
  return t;
}

void trainer_destroy(trainer_t* t) {
  if (t == NULL) {
    return;
  }
  free(t->storage);
  free(t);
}

hedger_t* trainer_hedger(trainer_t* t) { return t->hedger; }

train_stats_t trainer_stats(const trainer_t* t) { return t->stats; }

// The actor's section of an --init checkpoint (after HEDGER's values loaded): loaded; or, where
// the file has none, the actor cloned from the values' stored points (as the controller does);
// or, with policy = greedy, left unused. Returns 0 or -1 with a message.
static int load_actor(trainer_t* t, const char* path, const fw_progress_t* g, const uint8_t* bytes, char* err,
                      size_t err_cap) {
  actor_t* actor = learn_get_actor(t->agent);
  if (actor == NULL) {
    t->stats.init_actor_dropped = g->actor_bytes > 0U;
    return 0;
  }
  if (g->actor_bytes == 0U) {
    t->stats.init_actor_cloned = learn_actor_from_values(t->agent);
    return 0;
  }
  const actor_status_t as = actor_load(actor, bytes, (size_t)g->actor_bytes);
  if (as != ACTOR_OK) {
    fw_errfmt(err, err_cap,
        "%s: the actor's learned state does not fit these settings (%s): train with the configuration it was "
        "learned with (task, actor_hidden, actor_capacity, max_rotation_radps, gamma, hedger_input_scale)",
        path, actor_status_str(as));
    return -1;
  }
  return 0;
}

int trainer_load_checkpoint(trainer_t* t, const char* path, char* err, size_t err_cap) {
  size_t meta_size = 0;
  size_t payload_size = 0;
  int r = fw_checkpoint_peek(path, &meta_size, &payload_size, err, err_cap);
  if (r == 0) {
    fw_errfmt(err, err_cap, "%s: no such checkpoint", path);
  }
  if (r <= 0) {
    return -1;
  }
  void* meta = malloc(meta_size + 1U);
  void* payload = malloc(payload_size + 1U);
  int rc = -1;
  if (meta == NULL || payload == NULL) {
    fw_errfmt(err, err_cap, "%s: cannot allocate %zu bytes", path, meta_size + payload_size);
  } else if (fw_checkpoint_read(path, meta, meta_size + 1U, &meta_size, payload, payload_size + 1U, &payload_size,
                                err, err_cap) == 1) {
    // The controller's section is validated before the learner is touched.
    fw_progress_t g;
    char why[FW_PROGRESS_WHY_MAX];
    hedger_status_t hs = HEDGER_OK;
    if (fw_progress_decode((const uint8_t*)meta, meta_size, &g, why, sizeof why) != 0) {
      fw_errfmt(err, err_cap, "%s is corrupt (controller section: %s); give a checkpoint the controller or "
          "b21r-train wrote", path, why);
    } else if (g.task != t->cfg.task) {
      const char* task = fw_task_name(g.task);
      fw_errfmt(err, err_cap, "%s was learned for another task (%s): train with task = %s", path, task, task);
    } else if (g.actor_bytes > payload_size) {
      fw_errfmt(err, err_cap, "%s is corrupt (an actor section of %llu bytes in a payload of %zu)", path,
                (unsigned long long)g.actor_bytes, payload_size);
    } else if ((hs = hedger_load(t->hedger, payload, payload_size - (size_t)g.actor_bytes)) == HEDGER_OK) {
      rc = load_actor(t, path, &g, (const uint8_t*)payload + (payload_size - (size_t)g.actor_bytes), err, err_cap);
      t->stats.init_legacy_shift = g.legacy_shift;
      if (g.policy == LEARN_POLICY_SELECT) {
        // The ranked pairs go on into the written checkpoint (a log's runs are not paired: none is added).
        (void)learn_resume_selection(t->agent, &g.selection);
      }
    } else {
      fw_errfmt(err, err_cap,
          "%s: the learned state does not fit these settings (%s): train with the configuration it was "
          "learned with (task, hedger_capacity, max_rotation_radps, gamma, hedger_input_scale)",
          path, hedger_status_str(hs));
    }
  }
  free(meta);
  free(payload);
  return rc;
}

// The controller's between-runs step: the backward replay, if configured.
static void end_run(trainer_t* t) {
  if (t->in_run && t->run_learned) {
    t->stats.replayed += learn_offline_end_run(t->agent);
    t->stats.runs++;
  }
  t->in_run = false;
  t->run_learned = false;
}

static void report_progress(trainer_t* t, const char* path, bool final) {
  if (t->opt.progress == NULL) {
    return;
  }
  const double now = now_s();
  if (!final && now < t->progress_next_s) {
    return;
  }
  t->progress_next_s = now + t->opt.progress_period_s;
  const double dt = now - t->started_s;
  const hedger_counters_t* c = hedger_counters(t->hedger);
  fprintf(t->opt.progress, "b21r-train: %s: %llu experiences learned (%.0f/s), %llu runs, store %u/%u\n", path,
          (unsigned long long)t->stats.used, dt > 0.0 ? (double)t->stats.used / dt : 0.0,
          (unsigned long long)t->stats.runs, c->store_fill, hedger_get_config(t->hedger)->capacity);
  fflush(t->opt.progress);
}

// One decoded experience. Returns 0, or -1 with a message when the log does not fit cfg.
static int learn(trainer_t* t, const b21r_experience_t* e, const char* path, char* err, size_t err_cap) {
  if (e->task != (int8_t)t->cfg.task || e->state_dim != (int8_t)t->state_dim) {
    fw_errfmt(err, err_cap,
        "%s: experience seq %lld is of task %s with %d state dimensions, but the configuration says task = %s (%u): "
        "give the configuration the controller ran with (--config, or --set task = ... and state_rotation = ...)",
        path, (long long)e->seq, fw_task_name(e->task), (int)e->state_dim, fw_task_name(t->cfg.task), t->state_dim);
    return -1;
  }
  const bool restart = t->next_seq > 0 && e->seq == 0;
  const bool consecutive = t->next_seq >= 0 && e->seq == t->next_seq;
  if (t->next_seq >= 0 && !restart && e->seq != t->next_seq) {
    t->stats.seq_gaps++;
  }
  t->next_seq = e->seq + 1;
  const bool same_run = t->in_run && !restart && e->run_id == t->run_id;
  if (!same_run) {
    end_run(t);
    t->in_run = true;
    t->run_id = e->run_id;
  }
  const int32_t ticks = t->cfg.decision_ticks > 1 ? t->cfg.decision_ticks : 1;
  if (same_run && consecutive) {
    if (t->off_spacing != 0) {
      fw_errfmt(err, err_cap,
          "%s: experience seq %lld: the log's steps are %d control tick(s) apart, this configuration's "
          "decision_ticks = %d: give the setting the controller ran with (--set decision_ticks=%d)",
          path, (long long)e->seq - 1, (int)t->off_spacing, (int)ticks, (int)t->off_spacing);
      return -1;
    }
    const int32_t spacing = e->step_id - t->prev_step_id;
    t->off_spacing = spacing != ticks && e->terminal == 0 && spacing > 0 ? spacing : 0;
  } else {
    t->off_spacing = 0;
  }
  t->prev_step_id = e->step_id;
  if (e->evaluating && !t->opt.include_eval) {
    t->stats.skipped_eval++;
    return 0;
  }
  if (learn_offline_transition(t->agent, e->s, e->action_radps, e->reward, e->s_next, e->terminal != 0, NULL)) {
    t->stats.used++;
    t->run_learned = true;
  } else {
    t->stats.refused++;
  }
  return 0;
}

int trainer_add_log(trainer_t* t, const char* path, char* err, size_t err_cap) {
  lcm_eventlog_t* log = lcm_eventlog_create(path, "r");
  if (log == NULL) {
    fw_errfmt(err, err_cap, "%s: cannot open: %s", path, strerror(errno));
    return -1;
  }
  end_run(t);  // a log starts with a run of its own
  t->next_seq = -1;
  const double t0 = now_s();
  uint64_t events_here = 0;
  int rc = 0;
  for (;;) {
    lcm_eventlog_event_t* ev = lcm_eventlog_read_next_event(log);
    if (ev == NULL) {
      break;
    }
    events_here++;
    t->stats.events++;
    if (strcmp(ev->channel, t->opt.channel) == 0) {
      b21r_experience_t e;
      if (b21r_experience_t_decode(ev->data, 0, ev->datalen, &e) < 0) {
        t->stats.undecodable++;
      } else {
        t->stats.experiences++;
        rc = learn(t, &e, path, err, err_cap);
        b21r_experience_t_decode_cleanup(&e);
      }
    }
    lcm_eventlog_free_event(ev);
    if (rc != 0) {
      break;
    }
    report_progress(t, path, false);
  }
  lcm_eventlog_destroy(log);
  t->stats.seconds += now_s() - t0;
  if (rc == 0 && events_here == 0) {
    FILE* f = fopen(path, "rb");
    const bool empty = f != NULL && fgetc(f) == EOF;
    if (f != NULL) {
      fclose(f);
    }
    if (!empty) {
      fw_errfmt(err, err_cap, "%s: not an LCM event log (no event could be read)", path);
      return -1;
    }
  }
  report_progress(t, path, true);
  return rc;
}

void trainer_finish(trainer_t* t) {
  const double t0 = now_s();
  end_run(t);
  t->stats.seconds += now_s() - t0;
}

// ---- the checkpoint ------------------------------------------------------------------------
//
// The controller's section says: this task and state dimension, phase two from the start (the
// agent's schedule, set up so), no run started. The controller resumes from it with the learned
// policy.

int trainer_write_checkpoint(trainer_t* t, const char* path, bool overwrite, char* err, size_t err_cap) {
  if (!overwrite && access(path, F_OK) == 0) {
    fw_errfmt(err, err_cap, "%s exists; give --force to replace it (or another output file)", path);
    return -1;
  }
  const actor_t* actor = learn_get_actor_const(t->agent);
  const size_t actor_cap = actor != NULL ? actor_serialized_size(actor) : 0U;
  const fw_progress_t g = {.task = t->cfg.task,
                           .state_dim = t->state_dim,
                           .schedule = learn_schedule(t->agent)->p,
                           .run_id = -1,
                           .policy = t->cfg.policy,
                           .actor_bytes = actor_cap,
                           .selection = learn_selection_get(t->agent)};
  uint8_t meta[FW_PROGRESS_BYTES];
  const size_t meta_size = fw_progress_encode(&g, meta);
  const size_t hedger_cap = hedger_serialized_size(t->hedger);
  const size_t cap = hedger_cap + actor_cap;
  uint8_t* payload = malloc(cap);
  size_t written = 0;
  size_t actor_written = 0;
  int rc = -1;
  if (payload == NULL) {
    fw_errfmt(err, err_cap, "out of memory (%zu bytes)", cap);
  } else if (hedger_save(t->hedger, payload, hedger_cap, &written) != HEDGER_OK ||
             (actor != NULL && actor_save(actor, payload + written, actor_cap, &actor_written) != ACTOR_OK)) {
    fw_errfmt(err, err_cap, "%s: the learned state could not be serialised", path);
  } else {
    rc = fw_checkpoint_write(path, meta, meta_size, payload, written + actor_written, err, err_cap);
  }
  free(payload);
  return rc;
}
