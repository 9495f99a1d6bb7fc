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
  hedger_config_t hc;
  hedger_t* hedger;
  train_stats_t stats;
  // The run under way: the controller ends a run (hedger_end_run) before the next one starts.
  bool in_run;
  bool run_learned;      // at least one experience of it went through hedger_update
  int32_t run_id;
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

train_stats_t trainer_stats(const trainer_t* t) { return t->stats; }

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
    } else if ((hs = hedger_load(t->hedger, payload, payload_size)) == HEDGER_OK) {
      t->stats.init_legacy_shift = g.legacy_shift;
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
  if (!t->in_run || restart || e->run_id != t->run_id) {
    end_run(t);
    t->in_run = true;
    t->run_id = e->run_id;
  }
  if (e->evaluating && !t->opt.include_eval) {
    t->stats.skipped_eval++;
    return 0;
  }
  const hedger_status_t hs =
      hedger_update(t->hedger, e->s, e->action_radps, e->reward, e->s_next, e->terminal ? 1 : 0, NULL);
  if (hs == HEDGER_OK) {
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
