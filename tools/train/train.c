// SPDX-License-Identifier: MIT
// Offline HEDGER training from experience logs (see train.h).
#define _POSIX_C_SOURCE 200809L
#include "train.h"

#include <fw/checkpoint.h>
#include <fw/progress.h>
#include <fw/errfmt.h>
#include <fw/io.h>
#include <fw/loop.h>
#include <fw/pubq.h>
#include <fw/shift_vet.h>

#include <b21r/b21r_experience_t.h>
#include <b21r/b21r_run_t.h>
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
  hedger_config_t hc;
  hedger_t* hedger;
  train_stats_t stats;
  // The run under way: the controller ends a run (hedger_end_run) before the next one starts.
  bool in_run;
  bool run_learned;      // at least one experience of it went through hedger_update
  int32_t run_id;
  // The learner configured for pairs (fw_config_pair_learner): the run tag of the training run
  // under way (fw_pair_run_tag, the controller's rule), and the pair's first run until it is
  // ranked (fw_pair_ranker_end, the controller's ranking).
  bool pairs;
  bool pairs_ran;            // cfg runs pairs in phase two (fw_config_pair_runs_active)
  bool pairs_in_phase_one;   // and in phase one (fw_config_pair_phase_one_active)
  uint32_t run_tag;
  fw_pair_ranker_t ranker;
  // pair_shift_vet: the controller's vet of each step of the shift, from the same starts (the first
  // state of each training run's first experience; emptied where a controller session begins: a
  // log, or seq starting again at 0).
  fw_shift_vet_env_t vet_env;
  fw_shift_vet_starts_t vet_starts;
  bool log_has_run_records;  // the log being read has B21R_RUN (a full log)
  uint64_t log_paired;       // training experiences of phases that run pairs, learned from the log being read
  int64_t next_seq;      // expected seq of the next experience (-1: none yet in this log)
  double progress_next_s;
  double started_s;
};

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

trainer_t* trainer_create(const fw_config_t* cfg, const train_options_t* opt, char* err, size_t err_cap) {
  trainer_t* t = (trainer_t*)calloc(1, sizeof *t);
  if (t == NULL) {
    fw_errfmt(err, err_cap, "out of memory");
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
  if (cfg->learner == FW_LEARNER_TABULAR) {
    fw_errfmt(err, err_cap, "learner = tabular: the offline trainer trains HEDGER only (learner = hedger or lwa)");
    free(t);
    return NULL;
  }
  fw_loop_learner_config(cfg, &t->hc);
  const hedger_status_t hs = hedger_create(&t->hedger, &t->hc);
  if (hs != HEDGER_OK) {
    fw_errfmt(err, err_cap, "cannot set up HEDGER with the controller's settings (%s; check the hedger_* keys)",
        hedger_status_str(hs));
    free(t);
    return NULL;
  }
  t->pairs = fw_config_pair_learner(cfg);
  t->pairs_ran = fw_config_pair_runs_active(cfg);
  t->pairs_in_phase_one = fw_config_pair_phase_one_active(cfg);
  fw_shift_vet_env_init(&t->vet_env, cfg);
  t->next_seq = -1;
  t->started_s = now_s();
  t->progress_next_s = t->started_s + t->opt.progress_period_s;
  return t;
}

void trainer_destroy(trainer_t* t) {
  if (t == NULL) {
    return;
  }
  hedger_destroy(t->hedger);
  free(t);
}

hedger_t* trainer_hedger(trainer_t* t) { return t->hedger; }

train_stats_t trainer_stats(const trainer_t* t) {
  train_stats_t s = t->stats;
  s.shift = t->ranker.shift;
  return s;
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
    // The controller's section carries the learned policy's shift (pair_runs): validated before
    // the learner is touched; training then continues from that shift as the controller would.
    fw_progress_t g;
    char why[FW_PROGRESS_WHY_MAX];
    hedger_status_t hs = HEDGER_OK;
    double learned_clearance_m = 0.0;
    int32_t learned_hold_steps = 0;
    if (fw_progress_decode((const uint8_t*)meta, meta_size, &g, why, sizeof why) != 0) {
      fw_errfmt(err, err_cap, "%s is corrupt (controller section: %s); give a checkpoint the controller or "
          "b21r-train wrote", path, why);
    } else if (g.task != t->cfg.task) {
      const char* task = fw_task_name(g.task);
      fw_errfmt(err, err_cap, "%s was learned for another task (%s): train with task = %s", path, task, task);
    } else if (!fw_progress_clearance_fits(&g, t->cfg.pair_obstacle_clearance_m, &learned_clearance_m)) {
      fw_errfmt(err, err_cap, "%s: its learned policy's shift bends around the obstacle at pair_obstacle_clearance_m = "
          "%.15g, not %.15g: train with pair_obstacle_clearance_m = %.15g", path, learned_clearance_m,
          t->cfg.pair_obstacle_clearance_m, learned_clearance_m);
    } else if (!fw_progress_pass_hold_fits(&g, t->cfg.obstacle_pass_hold_steps, &learned_hold_steps)) {
      fw_errfmt(err, err_cap, "%s: its learned policy's shift was learned holding course past the obstacle for "
          "obstacle_pass_hold_steps = %d, not %d: train with obstacle_pass_hold_steps = %d", path,
          (int)learned_hold_steps, (int)t->cfg.obstacle_pass_hold_steps, (int)learned_hold_steps);
    } else if ((hs = hedger_load(t->hedger, payload, payload_size)) == HEDGER_OK) {
      t->ranker.shift = g.shift;
      t->stats.init_pass_hold_unrecorded = fw_progress_pass_hold_unknown(&g);
      rc = 0;
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

// The controller's between-runs step (loop.c finish_run): the backward replay, if configured.
static void end_run(trainer_t* t) {
  if (t->in_run && t->run_learned) {
    uint32_t replayed = 0;
    (void)hedger_end_run(t->hedger, &replayed);
    t->stats.runs++;
    t->stats.replayed += replayed;
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
          (unsigned long long)t->stats.runs, c->store_fill, t->hc.capacity);
  fflush(t->opt.progress);
}

// One decoded experience. Returns 0, or -1 with a message when the log does not fit cfg.
static int learn(trainer_t* t, const b21r_experience_t* e, const char* path, char* err, size_t err_cap) {
  if (e->task != (int8_t)t->cfg.task || e->state_dim != (int8_t)t->hc.state_dim) {
    fw_errfmt(err, err_cap,
        "%s: experience seq %lld is of task %s with %d state dimensions, but the configuration says task = %s (%u): "
        "give the configuration the controller ran with (--config, or --set task = ... and state_rotation = ...)",
        path, (long long)e->seq, fw_task_name(e->task), (int)e->state_dim, fw_task_name(t->cfg.task), t->hc.state_dim);
    return -1;
  }
  const bool restart = t->next_seq > 0 && e->seq == 0;
  if (t->next_seq >= 0 && !restart && e->seq != t->next_seq) {
    t->stats.seq_gaps++;
  }
  t->next_seq = e->seq + 1;
  if (restart) {
    // A controller that started again (seq from 0 in one log): its vet starts with no starts.
    memset(&t->vet_starts, 0, sizeof t->vet_starts);
  }
  if (!t->in_run || restart || e->run_id != t->run_id) {
    end_run(t);
    t->in_run = true;
    t->run_id = e->run_id;
    if (t->pairs && !e->evaluating) {
      t->run_tag = fw_pair_run_tag(e->run_id, hedger_run_tag(t->hedger));
      (void)hedger_set_run_tag(t->hedger, t->run_tag);
    }
  }
  if (e->evaluating && !t->opt.include_eval) {
    t->stats.skipped_eval++;
    return 0;
  }
  if (!e->evaluating && e->step_id == 0) {
    fw_shift_vet_starts_add(&t->vet_starts, &t->vet_env, e->s);
  }
  const hedger_status_t hs =
      hedger_update(t->hedger, e->s, e->action_radps, e->reward, e->s_next, e->terminal ? 1 : 0, NULL);
  if (hs == HEDGER_OK) {
    t->stats.used++;
    t->run_learned = true;
    t->log_paired += e->phase == 2 || (e->phase == 1 && t->pairs_in_phase_one) ? 1U : 0U;
  } else {
    t->stats.refused++;
  }
  return 0;
}

// Exact comparison of two finite doubles (the log's copies are bit-exact).
static bool differs(double a, double b) { return a < b || a > b; }

// pair_runs: a B21R_RUN record of a pair run (it follows the run's last experience). As in the
// controller, the run's replay comes first, then its weights: a first run weighs 0 until its pair
// is ranked, an aborted run 0 (its pair starts again), and the second run ranks the pair and
// proposes a step of the learned policy's shift (fw_pair_ranker_end, the controller's rule; the
// record's phase 1 marks a pair of example runs, which keeps weight 1), which the vet then takes,
// cuts (to 1/2, 1/4 or 1/8) or refuses (pair_shift_vet, fw/shift_vet.h) on the store the replay and weights left.
static void rank_pair_run(trainer_t* t, const b21r_run_t* r) {
  if (!t->pairs || r->kind != B21R_RUN_T_KIND_TRAINING || r->pair_member < 0 || !t->in_run ||
      r->run_id != t->run_id) {
    return;
  }
  end_run(t);
  // The pair's perturbation and the shift in force come from the log: a record with values the
  // controller cannot have written (non-finite, or a shift beyond its bound) ranks nothing.
  if (!isfinite(r->pair_gain) || !isfinite(r->pair_centring) || !isfinite(r->pair_imitation) ||
      !fw_pair_shift_valid(r->shift_gain, r->shift_centring, r->shift_imitation)) {
    t->stats.run_records_invalid++;
    return;
  }
  // The shift the controller drove with is the log's, exactly: the trainer takes it (another
  // session's log, a second pass over the same log or an --init that already holds these pairs
  // would otherwise move it again) and counts where its own differed.
  fw_pair_shift_t* shift = &t->ranker.shift;
  if (differs(r->shift_gain, shift->gain) || differs(r->shift_centring, shift->centring) ||
      differs(r->shift_imitation, shift->imitation) || r->shift_pairs < 0 || (uint32_t)r->shift_pairs != shift->pairs) {
    t->stats.shift_taken_from_log++;
    shift->gain = r->shift_gain;
    shift->centring = r->shift_centring;
    shift->imitation = r->shift_imitation;
    shift->pairs = r->shift_pairs > 0 ? (uint32_t)r->shift_pairs : 0U;
  }
  const bool aborted = r->end_reason == B21R_RUN_T_END_SAFETY_STOP || r->end_reason == B21R_RUN_T_END_SHUTDOWN;
  const bool goal = r->end_reason == B21R_RUN_T_END_GOAL && !r->pair_vetoed;
  uint32_t tags[2];
  double weights[2];
  const fw_pair_shift_t in_force = *shift;
  const int32_t n = fw_pair_ranker_end(&t->ranker, &t->cfg, r->phase == 1, r->pair_member, aborted, goal, r->steps,
                                       t->run_tag, r->pair_gain, r->pair_centring, r->pair_imitation, tags, weights);
  for (int32_t i = 0; i < n; ++i) {
    (void)hedger_weight_run(t->hedger, tags[i], weights[i], NULL);
  }
  if (n == 2 && t->cfg.pair_shift_vet) {
    // The controller's vet of the step, after the replay and the weights as there (at once here).
    fw_shift_vet_t vet;
    fw_shift_vet_begin(&vet, &in_force, shift);
    (void)fw_shift_vet_step(&vet, fw_shift_vet_hedger_greedy, t->hedger, &t->vet_env, &t->vet_starts, UINT32_MAX);
    *shift = vet.result;
    t->stats.shift_steps_halved += vet.verdict == FW_SHIFT_STEP_HALVED ? 1U : 0U;
    t->stats.shift_steps_refused += vet.verdict == FW_SHIFT_STEP_REFUSED ? 1U : 0U;
  }
  if (n == 2) {
    t->stats.pairs_ranked++;
  } else if (n == 0) {
    // The first run's record is missing (a recording that lost it): the pair cannot be ranked,
    // and this run stays unweighted rather than be ranked against another pair's first run.
    t->stats.pairs_unmatched++;
  }
}

int trainer_add_log(trainer_t* t, const char* path, char* err, size_t err_cap) {
  lcm_eventlog_t* log = lcm_eventlog_create(path, "r");
  if (log == NULL) {
    fw_errfmt(err, err_cap, "%s: cannot open: %s", path, strerror(errno));
    return -1;
  }
  end_run(t);  // a log starts with a run of its own
  t->next_seq = -1;
  // A log is one controller session, whose vet began with no starts (they are not checkpointed).
  memset(&t->vet_starts, 0, sizeof t->vet_starts);
  t->log_has_run_records = false;
  t->log_paired = 0;
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
    } else if (strcmp(ev->channel, "B21R_RUN") == 0) {
      t->log_has_run_records = true;
      b21r_run_t r;
      if (b21r_run_t_decode(ev->data, 0, ev->datalen, &r) >= 0) {
        rank_pair_run(t, &r);
        b21r_run_t_decode_cleanup(&r);
      } else {
        t->stats.run_records_undecodable++;  // another layout: an older controller's (pair_member, the imitation's weight)
      }
    }
    lcm_eventlog_free_event(ev);
    if (rc != 0) {
      break;
    }
    report_progress(t, path, false);
  }
  lcm_eventlog_destroy(log);
  if (t->pairs_ran && !t->log_has_run_records) {
    t->stats.paired_unranked += t->log_paired;
  }
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
// The checkpoint's meta section is the controller's own encoding of its schedule's progress
// (fw/checkpoint.h: "fw_loop's own encoding"). The trainer does not write it itself: it asks
// the controller's loop for it, through the public fw/loop.h API only. A loop made with the
// given configuration, but with no phase-one runs left, starts in phase two; its orderly
// shutdown writes a checkpoint whose meta section says so. That section, with the trained
// HEDGER as the payload, is the trainer's checkpoint. The loop is never started: it sees an I/O
// binding that has no devices.

static int64_t null_now(void* user) {
  (void)user;
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}
static int null_wait(void* user, int64_t deadline_us) {
  (void)user;
  (void)deadline_us;
  return 0;
}
static int null_laser_poll(void* user, int64_t now_us, lms_scan_t* out) {
  (void)user;
  (void)now_us;
  (void)out;
  return 0;
}
static ssize_t null_base_read(void* user, uint8_t* buf, size_t cap) {
  (void)user;
  (void)buf;
  (void)cap;
  return 0;
}
static int null_base_write(void* user, const uint8_t* buf, size_t n) {
  (void)user;
  (void)buf;
  (void)n;
  return 0;
}
static int null_can_read(void* user, canopen_frame_t* frame) {
  (void)user;
  (void)frame;
  return 0;
}
static int null_can_write(void* user, const canopen_frame_t* frame) {
  (void)user;
  (void)frame;
  return 0;
}

static const fw_io_vtable_t k_no_devices = {
    .now_us = null_now,
    .wait = null_wait,
    .laser_poll = null_laser_poll,
    .base_read = null_base_read,
    .base_write = null_base_write,
    .can_read = null_can_read,
    .can_write = null_can_write,
};

// The controller's meta section for "phase two from the start" under cfg, into a malloc'ed
// buffer. Returns its size, or 0 with a message.
static size_t phase_two_meta(const fw_config_t* cfg, const char* dir, uint8_t** meta, char* err, size_t err_cap) {
  fw_config_t c = *cfg;
  c.mode = FW_MODE_LEARN;
  c.phase_switch = FW_SWITCH_RUNS;
  c.phase_one_runs = 0;
  if (c.phase_two_runs < 1) {
    c.phase_two_runs = 1;
  }
  c.reposition = FW_REPOSITION_OPERATOR;
  c.checkpoint_file[0] = '\0';
  c.log_file[0] = '\0';
  c.experience_log_file[0] = '\0';
  *meta = NULL;
  char tmp[FW_CONFIG_STR_MAX + 64];
  snprintf(tmp, sizeof tmp, "%s/.b21r-train-meta-%ld.ckpt", dir, (long)getpid());
  const fw_io_t io = {.vt = &k_no_devices, .user = NULL};
  // The loop's messages (its shutdown notice) go to a queue nobody drains: not to the terminal.
  fw_pubq_t* q = fw_pubq_create(16U);
  const fw_loop_outputs_t out = {.queue = q};
  fw_loop_t* loop = q != NULL ? fw_loop_create(&c, &io, &out, err, err_cap) : NULL;
  fw_ckpt_writer_t* w = NULL;
  size_t meta_size = 0;
  size_t payload_size = 0;
  size_t meta_cap = 0;
  size_t payload_cap = 0;
  if (loop != NULL) {
    fw_loop_checkpoint_capacity(loop, &meta_cap, &payload_cap);
    w = fw_ckpt_writer_create(tmp, meta_cap, payload_cap, err, err_cap);
  }
  if (w != NULL) {
    fw_loop_attach_checkpoints(loop, w);
    if (fw_loop_shutdown(loop) == 0) {
      *meta = (uint8_t*)malloc(meta_cap + 1U);
      void* payload = malloc(payload_cap + 1U);
      if (*meta == NULL || payload == NULL ||
          fw_checkpoint_read(tmp, *meta, meta_cap + 1U, &meta_size, payload, payload_cap + 1U, &payload_size, err,
                             err_cap) != 1) {
        meta_size = 0;
      }
      free(payload);
    } else {
      fw_errfmt(err, err_cap, "cannot write a temporary checkpoint in %s", dir);
    }
  } else if (q == NULL) {
    fw_errfmt(err, err_cap, "out of memory");
  }
  fw_ckpt_writer_destroy(w);
  fw_loop_destroy(loop);
  fw_pubq_destroy(q);
  (void)unlink(tmp);
  if (meta_size == 0) {
    free(*meta);
    *meta = NULL;
  }
  return meta_size;
}

int trainer_write_checkpoint(trainer_t* t, const char* path, bool overwrite, char* err, size_t err_cap) {
  if (!overwrite && access(path, F_OK) == 0) {
    fw_errfmt(err, err_cap, "%s exists; give --force to replace it (or another output file)", path);
    return -1;
  }
  char dir[FW_CONFIG_STR_MAX];
  const char* slash = strrchr(path, '/');
  if (slash == NULL) {
    snprintf(dir, sizeof dir, ".");
  } else if ((size_t)(slash - path) < sizeof dir) {
    memcpy(dir, path, (size_t)(slash - path));
    dir[slash - path] = '\0';
    if (dir[0] == '\0') {
      snprintf(dir, sizeof dir, "/");
    }
  } else {
    fw_errfmt(err, err_cap, "%s: path too long", path);
    return -1;
  }
  uint8_t* meta = NULL;
  char why[FW_LOOP_ERR_MAX];
  size_t meta_size = phase_two_meta(&t->cfg, dir, &meta, why, sizeof why);
  if (meta_size == 0) {
    fw_errfmt(err, err_cap, "%s: cannot build the controller's section of the checkpoint: %s", path, why);
    return -1;
  }
  // The controller's section with the shift the pairs learned (fw/progress.h).
  fw_progress_t g;
  if (fw_progress_decode(meta, meta_size, &g, why, sizeof why) != 0) {
    free(meta);
    fw_errfmt(err, err_cap, "%s: the controller's section of the checkpoint is invalid: %s", path, why);
    return -1;
  }
  g.shift = t->ranker.shift;
  fw_progress_record_clearance(&g, t->cfg.pair_obstacle_clearance_m);
  fw_progress_record_pass_hold(&g, t->cfg.obstacle_pass_hold_steps);
  meta_size = fw_progress_encode(&g, meta);  // the section grows where it records the hold
  const size_t cap = hedger_serialized_size(t->hedger);
  void* payload = malloc(cap);
  size_t written = 0;
  int rc = -1;
  if (payload == NULL) {
    fw_errfmt(err, err_cap, "out of memory (%zu bytes)", cap);
  } else if (hedger_save(t->hedger, payload, cap, &written) != HEDGER_OK) {
    fw_errfmt(err, err_cap, "%s: the learned state could not be serialised", path);
  } else {
    rc = fw_checkpoint_write(path, meta, meta_size, payload, written, err, err_cap);
  }
  free(payload);
  free(meta);
  return rc;
}
