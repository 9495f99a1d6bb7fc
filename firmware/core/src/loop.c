// SPDX-License-Identifier: MIT
// The control loop: tick, run lifecycle, learning, safety reactions, publishing, checkpoints.
#define _POSIX_C_SOURCE 200809L
#include "loop_internal.h"
#include "fw/progress.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define FW_PI 3.14159265358979323846

// ---- small helpers ----------------------------------------------------------------------

static void fmt(char* err, size_t cap, const char* format, ...) __attribute__((format(printf, 3, 4)));
static void fmt(char* err, size_t cap, const char* format, ...) {
  if (err == NULL || cap == 0) {
    return;
  }
  va_list ap;
  va_start(ap, format);
  (void)vsnprintf(err, cap, format, ap);
  va_end(ap);
}

static double clampd(double x, double lo, double hi) { return x < lo ? lo : (x > hi ? hi : x); }

static int64_t io_now(const fw_loop_t* L) { return L->io.vt->now_us(L->io.user); }

static void notify(fw_loop_t* L) {
  if (L->out.notify != NULL) {
    L->out.notify(L->out.notify_user);
  }
}

void fw_loop_log(fw_loop_t* L, int stream, const char* format, ...) {
  char line[FW_TEXT_MAX];
  va_list ap;
  va_start(ap, format);
  (void)vsnprintf(line, sizeof line, format, ap);
  va_end(ap);
  fw_msg_t* m = L->out.queue != NULL ? fw_pubq_reserve(L->out.queue, FW_MSG_TEXT) : NULL;
  if (m == NULL) {
    if (L->out.queue == NULL && stream == 2) {
      // No publisher (start-up, tools): write directly; not on the tick path.
      fprintf(stderr, "%s\n", line);
    }
    return;
  }
  m->u.text.stream = stream;
  memcpy(m->u.text.line, line, sizeof line);
  fw_pubq_commit(L->out.queue);
  notify(L);
}





static bool all_finite(const double* v, uint32_t n) {
  for (uint32_t i = 0; i < n; ++i) {
    if (!isfinite(v[i])) {
      return false;
    }
  }
  return true;
}

// ---- task glue ----------------------------------------------------------------------------

static bool is_corridor(const fw_loop_t* L) { return L->cfg.task == FW_TASK_CORRIDOR; }

static uint32_t step_limit(const fw_loop_t* L) {
  if (L->cfg.max_steps_per_run > 0) {
    return (uint32_t)L->cfg.max_steps_per_run;
  }
  return is_corridor(L) ? L->corridor.step_limit : L->obstacles.step_limit;
}

static features_pose_t eval_pose(const fw_loop_t* L, int32_t index) {
  return is_corridor(L) ? tasks_corridor_eval_start(&L->corridor, (uint32_t)index)
                        : tasks_obstacles_eval_start(&L->obstacles, (uint32_t)index);
}

static features_pose_t odom_pose(const fw_loop_t* L) {
  const features_pose_t p = {L->odo.x_m, L->odo.y_m, L->odo.theta_rad};
  return p;
}

// Features of the newest scan at the robot's odometry pose in the task frame. Returns false when
// the state is not usable (invalid features or a non-finite value).
static bool compute_state(fw_loop_t* L) {
  const features_pose_t pose = features_odom_to_task(L->start_pose, L->odom_at_start, odom_pose(L));
  if (is_corridor(L)) {
    if (features_corridor_compute(&L->corridor_fc, &L->scan, &pose, &L->fcor) != FEATURES_OK || !L->fcor.valid) {
      return false;
    }
    features_corridor_state(&L->fcor, L->s);
  } else {
    if (features_obstacles_compute(&L->obstacles_fc, &L->scan, &pose, L->obstacles.goal_x_m, L->obstacles.goal_y_m,
                                   &L->fobs) != FEATURES_OK ||
        !L->fobs.valid) {
      return false;
    }
    (void)features_obstacles_state(&L->fobs, 1, L->s, FW_MAX_STATE);
  }
  return true;
}

static tasks_outcome_t outcome(const fw_loop_t* L, uint8_t contact, uint32_t steps_taken) {
  if (is_corridor(L)) {
    tasks_corridor_spec_t spec = L->corridor;
    spec.step_limit = step_limit(L);
    return tasks_corridor_outcome(&spec, &L->fcor, contact, steps_taken);
  }
  tasks_obstacles_spec_t spec = L->obstacles;
  spec.step_limit = step_limit(L);
  return tasks_obstacles_outcome(&spec, &L->fobs, contact, steps_taken);
}

static double speed(const fw_loop_t* L) {
  return is_corridor(L) ? tasks_corridor_speed_mps(&L->corridor, &L->fcor) : tasks_obstacles_speed_mps(&L->obstacles);
}

static double driver_action(fw_loop_t* L) {
  return is_corridor(L) ? tasks_driver_corridor(&L->driver, &L->fcor) : tasks_driver_obstacles(&L->driver, &L->fobs);
}

// ---- publishing ---------------------------------------------------------------------------

static void publish_experience(fw_loop_t* L, double reward, bool terminal, double q, hedger_kind_t kind) {
  if (L->out.queue == NULL) {
    L->exp_seq++;
    return;
  }
  fw_msg_t* m = fw_pubq_reserve(L->out.queue, FW_MSG_EXPERIENCE);
  const int64_t seq = L->exp_seq++;  // a dropped experience leaves a gap in seq: detectable
  if (m == NULL) {
    L->exp_dropped++;
    return;
  }
  b21r_experience_t* e = &m->u.experience;
  memset(e, 0, sizeof *e);
  e->utime = L->utime;
  e->seq = seq;
  e->run_id = L->run_id;
  e->step_id = L->actions_taken - 1;
  e->task = (int8_t)L->cfg.task;
  e->phase = (int8_t)L->plan.phase;
  e->source = L->prev_source;
  e->evaluating = L->plan.kind == FW_RUN_EVAL ? 1 : 0;
  e->state_dim = (int8_t)L->state_dim;
  for (uint32_t i = 0; i < L->state_dim; ++i) {
    e->s[i] = L->prev_s[i];
    e->s_next[i] = L->s[i];
  }
  e->action_radps = L->prev_a;
  e->translation_mps = L->prev_v;
  e->reward = reward;
  e->terminal = terminal ? 1 : 0;
  e->q_value = isfinite(q) ? q : 0.0;
  e->q_kind = (int8_t)(kind == HEDGER_KIND_LWR ? 0 : (kind == HEDGER_KIND_LWA ? 1 : 2));
  fw_pubq_commit(L->out.queue);
}

static void publish_pose(fw_loop_t* L) {
  if (L->out.queue == NULL) {
    return;
  }
  fw_msg_t* m = fw_pubq_reserve(L->out.queue, FW_MSG_POSE);
  if (m == NULL) {
    return;
  }
  b21r_pose_t* p = &m->u.pose;
  p->utime = L->utime;
  p->run_id = L->run_id;
  p->step_id = L->actions_taken;
  p->x_m = L->odo.x_m;
  p->y_m = L->odo.y_m;
  p->theta_rad = L->odo.theta_rad;
  p->translation_mps = L->odo.v_mps;
  p->rotation_radps = L->odo.omega_radps;
  fw_pubq_commit(L->out.queue);
}

static void publish_scan(fw_loop_t* L) {
  if (L->out.queue == NULL || !L->cfg.publish_scan) {
    return;
  }
  fw_msg_t* m = fw_pubq_reserve(L->out.queue, FW_MSG_SCAN);
  if (m == NULL) {
    return;
  }
  b21r_scan_t* s = &m->u.scan;
  s->utime = L->utime;
  s->run_id = L->run_id;
  s->step_id = L->actions_taken;
  s->angle_min_rad = (float)L->scan.angle_min_rad;
  s->angle_increment_rad = (float)L->scan.angle_increment_rad;
  s->n_beams = (int16_t)L->scan.n_beams;
  for (uint16_t i = 0; i < L->scan.n_beams; ++i) {
    s->no_return_reason[i] = (int8_t)L->scan.no_return[i];
    s->ranges_m[i] = L->scan.no_return[i] != 0 ? 0.0F : L->scan.ranges_m[i];
  }
  fw_pubq_commit(L->out.queue);
}

static void publish_eval(fw_loop_t* L, const fw_eval_block_t* b) {
  if (L->out.queue == NULL) {
    return;
  }
  fw_msg_t* m = fw_pubq_reserve(L->out.queue, FW_MSG_EVAL);
  if (m == NULL) {
    return;
  }
  b21r_eval_t* e = &m->u.eval;
  memset(e, 0, sizeof *e);
  e->utime = L->utime;
  e->block = b->block;
  e->training_runs = b->training_runs;
  e->phase = (int8_t)b->phase;
  e->task = (int8_t)L->cfg.task;
  e->n_starts = b->n_starts;
  for (int32_t i = 0; i < b->n_starts && i < 16; ++i) {
    e->steps[i] = b->steps[i];
    e->success[i] = b->success[i] ? 1 : 0;
  }
  e->successes = b->successes;
  e->mean_steps = b->mean_steps;
  e->ci95_halfwidth = b->ci95_halfwidth;
  fw_pubq_commit(L->out.queue);
}

static int8_t status_mode(const fw_loop_t* L) {
  if (L->mode == B21R_STATUS_T_MODE_STOPPED && L->safety.reason == FW_STOP_OPERATOR) {
    return B21R_STATUS_T_MODE_PAUSED;
  }
  return (int8_t)L->mode;
}

static void publish_status(fw_loop_t* L) {
  if (L->out.queue == NULL) {
    return;
  }
  fw_msg_t* m = fw_pubq_reserve(L->out.queue, FW_MSG_STATUS);
  if (m == NULL) {
    return;
  }
  b21r_status_t* s = &m->u.status.msg;
  memset(s, 0, sizeof *s);
  s->utime = L->utime;
  s->phase = (int8_t)L->sched.p.phase;
  s->mode = status_mode(L);
  s->stop_reason = (int8_t)L->safety.reason;
  memcpy(m->u.status.detail, L->safety.detail, sizeof m->u.status.detail);
  s->run_id = L->run_id;
  s->step_id = L->actions_taken;
  s->training_runs = L->sched.p.training_runs;
  s->eval_blocks = L->sched.p.eval_blocks;
  const fw_timing_summary_t t = fw_timing_summary(&L->timing);
  s->tick_p50_us = t.p50_us;
  s->tick_p99_us = t.p99_us;
  s->tick_max_us = t.max_us;
  s->tick_overruns = t.overruns;
  s->ticks = t.ticks;
  const hedger_counters_t* hc = hedger_counters(L->hedger);
  s->store_fill = (int32_t)hc->store_fill;
  s->store_capacity = L->cfg.hedger_capacity;
  s->hedger_lwr = (int64_t)hc->predictions_lwr;
  s->hedger_lwa = (int64_t)hc->predictions_lwa;
  s->hedger_unknown = (int64_t)hc->predictions_unknown;
  s->hedger_evictions = (int64_t)hc->evictions;
  s->hedger_rebuilds = (int64_t)hc->rebuilds;
  s->laser_scans = L->laser_scans;
  fw_laser_stats_t ls;
  memset(&ls, 0, sizeof ls);
  if (L->io.vt->laser_stats != NULL) {
    L->io.vt->laser_stats(L->io.user, &ls);
  }
  s->laser_bytes_dropped = (int64_t)ls.bytes_dropped;
  s->laser_crc_errors = (int64_t)ls.crc_errors;
  s->base_packets = L->base_packets;
  s->base_bytes_dropped = (int64_t)fw_base_bytes_dropped(L);
  s->base_checksum_errors = (int64_t)fw_base_checksum_errors(L);
  s->teleop_accepted = L->teleop_accepted;
  s->teleop_rejected = L->teleop_rejected;
  s->lcm_queue_drops = (int64_t)fw_pubq_drops(L->out.queue, -1);
  // One snapshot of the writer's counters (each read takes the writer's lock).
  fw_ckpt_counters_t ckpt;
  memset(&ckpt, 0, sizeof ckpt);
  if (L->out.checkpoints != NULL) {
    ckpt = fw_ckpt_writer_counters(L->out.checkpoints);
  }
  s->checkpoints_written = (int64_t)ckpt.written;
  s->safety_stops = L->safety.stops;
  s->held_ticks = L->held_ticks;
  s->teleop_rejected_nan = L->teleop_rejected_nan;
  s->teleop_rejected_range = L->teleop_rejected_range;
  s->teleop_rejected_seq = L->teleop_rejected_seq;
  s->teleop_rejected_stale = L->teleop_rejected_stale;
  s->commands_accepted = L->commands_accepted;
  s->commands_rejected = L->commands_rejected;
  s->checkpoint_failures = (int64_t)ckpt.failed;
  s->laser_restarts = (int64_t)ls.restarts;
  s->odometry_rejected = (int64_t)(L->odo.rejected_trans + L->odo.rejected_rot);
  s->experiences = L->exp_seq;
  s->experiences_dropped = L->exp_dropped;
  s->tick_max_ever_us = t.max_ever_us;
  s->battery_v = L->battery_v;
  fw_pubq_commit(L->out.queue);
}

// ---- checkpoints --------------------------------------------------------------------------

static size_t encode_meta(const fw_loop_t* L, uint8_t* p) {
  const fw_progress_t g = {
      .task = L->cfg.task, .state_dim = L->state_dim, .schedule = L->sched.p, .run_id = L->run_id};
  return fw_progress_encode(&g, p);
}

static void checkpoint(fw_loop_t* L) {
  if (L->out.checkpoints == NULL) {
    return;
  }
  void* meta = NULL;
  void* payload = NULL;
  size_t meta_cap = 0;
  size_t payload_cap = 0;
  const int h = fw_ckpt_writer_acquire(L->out.checkpoints, &meta, &meta_cap, &payload, &payload_cap);
  if (h < 0) {
    L->checkpoints_skipped++;
    return;
  }
  size_t written = 0;
  const size_t meta_size = encode_meta(L, (uint8_t*)meta);
  if (hedger_save(L->hedger, payload, payload_cap, &written) != HEDGER_OK) {
    fw_ckpt_writer_submit(L->out.checkpoints, h, 0, 0);  // never happens: sized by serialized_max
    L->checkpoints_skipped++;
    return;
  }
  fw_ckpt_writer_submit(L->out.checkpoints, h, meta_size, written);
  L->checkpoints_submitted++;
}

// ---- create / destroy --------------------------------------------------------------------

static void hedger_config_for(const fw_loop_t* L, hedger_config_t* hc) {
  *hc = hedger_config_default();
  hc->state_dim = L->state_dim;
  hc->action_min = -L->omega_max;
  hc->action_max = L->omega_max;
  hc->capacity = (uint32_t)L->cfg.hedger_capacity;
  hc->k_min = (uint32_t)L->cfg.hedger_k_min;
  hc->k_max = (uint32_t)L->cfg.hedger_k_max;
  hc->bandwidth = L->cfg.hedger_bandwidth;
  hc->alpha = L->cfg.alpha;
  hc->gamma = L->gamma;
  // Input scales: one scaled unit is about the distance over which the value changes markedly,
  // so one bandwidth means the same in every direction. The action's scale is small on purpose:
  // actions far from those tried stay "unknown" and never win the greedy search.
  if (L->cfg.hedger_input_scale_n > 0) {
    for (int32_t i = 0; i < L->cfg.hedger_input_scale_n; ++i) {
      hc->input_scale[i] = L->cfg.hedger_input_scale[i];
    }
  } else if (is_corridor(L)) {
    // Measured on the corridor: a long scale along the corridor spreads the sparse reward's value
    // back from the end wall; short lateral, angle and action scales keep the value of an action
    // local (actions far from those tried stay unknown and never win the greedy search).
    hc->input_scale[0] = 10.0;  // end distance [m]
    hc->input_scale[1] = 0.5;   // lateral fraction of the width
    hc->input_scale[2] = 0.5;   // target angle [rad]
    hc->input_scale[3] = 0.25;  // rotation [rad/s]
  } else {
    hc->input_scale[0] = 1.0;   // goal bearing [rad]
    hc->input_scale[1] = 1.0;   // goal distance [m]
    hc->input_scale[2] = 1.0;   // obstacle bearing [rad]
    hc->input_scale[3] = 1.0;   // obstacle distance [m]
    hc->input_scale[4] = 0.5;   // rotation [rad/s]
  }
  hc->merge_radius = L->cfg.hedger_merge_radius;
  hc->greedy_coarse_actions = (uint32_t)L->cfg.hedger_greedy_actions;
  uint32_t run_cap = step_limit(L) + 8U;
  hc->run_capacity = run_cap > HEDGER_MAX_RUN ? HEDGER_MAX_RUN : run_cap;
  hc->replay = L->cfg.hedger_replay ? 1U : 0U;
}

void fw_loop_learner_config(const fw_config_t* cfg, hedger_config_t* out) {
  // A throw-away loop state carries the task specs the config depends on.
  fw_loop_t* L = (fw_loop_t*)calloc(1, sizeof *L);
  if (L == NULL) {
    *out = hedger_config_default();
    return;
  }
  L->cfg = *cfg;
  L->omega_max = cfg->max_rotation_radps;
  tasks_corridor_spec_default(&L->corridor);
  tasks_obstacles_spec_default(&L->obstacles);
  L->state_dim = is_corridor(L) ? FEATURES_CORRIDOR_STATE_DIM : FEATURES_OBSTACLES_STATE_DIM;
  L->gamma = cfg->gamma > 0.0 ? cfg->gamma : (is_corridor(L) ? L->corridor.gamma : L->obstacles.gamma);
  hedger_config_for(L, out);
  uint64_t st = cfg->seed;
  (void)tasks_rng_splitmix64(&st);
  (void)tasks_rng_splitmix64(&st);
  out->seed = tasks_rng_splitmix64(&st);
  free(L);
}

fw_loop_t* fw_loop_create(const fw_config_t* cfg, const fw_io_t* io, const fw_loop_outputs_t* out, char* err,
                          size_t err_cap) {
  if (fw_config_validate(cfg, err, err_cap) != 0) {
    return NULL;
  }
  if (io == NULL || io->vt == NULL || io->vt->now_us == NULL || io->vt->wait == NULL || io->vt->laser_poll == NULL) {
    fmt(err, err_cap, "loop: incomplete I/O binding");
    return NULL;
  }
  fw_loop_t* L = (fw_loop_t*)calloc(1, sizeof *L);
  if (L == NULL) {
    fmt(err, err_cap, "loop: out of memory");
    return NULL;
  }
  L->cfg = *cfg;
  L->io = *io;
  if (out != NULL) {
    L->out = *out;
  }
  L->period_us = fw_config_period_us(cfg);
  L->dt_s = (double)L->period_us * 1e-6;
  L->omega_max = cfg->max_rotation_radps;

  tasks_corridor_spec_default(&L->corridor);
  L->corridor.omega_max_radps = L->omega_max;
  L->corridor.dt_s = L->dt_s;
  tasks_corridor_features_config(&L->corridor, &L->corridor_fc);
  tasks_obstacles_spec_default(&L->obstacles);
  L->obstacles.omega_max_radps = L->omega_max;
  L->obstacles.dt_s = L->dt_s;
  tasks_obstacles_features_config(&L->obstacles, &L->obstacles_fc);
  L->state_dim = is_corridor(L) ? FEATURES_CORRIDOR_STATE_DIM : FEATURES_OBSTACLES_STATE_DIM;
  L->gamma = cfg->gamma > 0.0 ? cfg->gamma : (is_corridor(L) ? L->corridor.gamma : L->obstacles.gamma);

  // Seeds: every stream derived from the one root seed.
  uint64_t st = cfg->seed;
  tasks_rng_seed(&L->pose_rng, tasks_rng_splitmix64(&st));
  tasks_rng_seed(&L->explore_rng, tasks_rng_splitmix64(&st));
  const uint64_t hedger_seed = tasks_rng_splitmix64(&st);
  L->driver_seed_base = tasks_rng_splitmix64(&st);

  hedger_config_t hc;
  hedger_config_for(L, &hc);
  hc.seed = hedger_seed;  // as fw_loop_learner_config derives it
  if (hedger_config_validate(&hc) != HEDGER_OK) {
    fmt(err, err_cap, "loop: the learner's configuration is invalid (check hedger_* keys)");
    free(L);
    return NULL;
  }
  const size_t bytes = hedger_storage_size(&hc);
  L->hedger_storage = aligned_alloc(HEDGER_STORAGE_ALIGN, (bytes + HEDGER_STORAGE_ALIGN - 1) & ~(size_t)(HEDGER_STORAGE_ALIGN - 1));
  if (L->hedger_storage == NULL || hedger_init(&L->hedger, L->hedger_storage, bytes, &hc) != HEDGER_OK) {
    fmt(err, err_cap, "loop: cannot set up the learner (%zu bytes for %d samples)", bytes, (int)cfg->hedger_capacity);
    free(L->hedger_storage);
    free(L);
    return NULL;
  }
  L->hedger_save_max = hedger_serialized_max_size(&hc);

  rflex_b21r_params_default(&L->rflex);
  L->rflex.trans_counts_per_m = cfg->distance_counts_per_m;
  L->rflex.rot_counts_per_rad = cfg->angle_counts_per_rad;
  L->rflex.trans_acc_mps2 = cfg->max_translation_accel_mps2;
  (void)rflex_odom_init(&L->odo, &L->rflex);
  rflex_decoder_init(&L->rdec);
  L->brake_reported = -1;
  L->drive[0].node = (uint8_t)cfg->can_node_translation;
  L->drive[1].node = (uint8_t)cfg->can_node_rotation;
  for (int i = 0; i < 2; ++i) {
    cia402_master_init(&L->drive[i].master);
    const double hb_s = cfg->can_heartbeat_timeout_s > 0.0 ? cfg->can_heartbeat_timeout_s : 1.0;
    (void)canopen_hb_init(&L->drive[i].hb, L->drive[i].node, (uint32_t)(hb_s * 1e6));
  }

  pthread_mutex_init(&L->mbox_mu, NULL);
  atomic_init(&L->signal_number, 0);

  const fw_safety_config_t sc = {.lockstep = cfg->lockstep,
                                 .laser_limit_ticks = fw_config_ticks(cfg, cfg->laser_timeout_s),
                                 .base_limit_ticks = fw_config_ticks(cfg, cfg->base_timeout_s),
                                 .laser_limit_us = (int64_t)(cfg->laser_timeout_s * 1e6),
                                 .base_limit_us = (int64_t)(cfg->base_timeout_s * 1e6),
                                 .clear_ticks = cfg->safety_clear_ticks,
                                 .auto_resume = cfg->safety_auto_resume};
  fw_safety_init(&L->safety, &sc);
  fw_timing_init(&L->timing);
  const fw_schedule_config_t schc = {.eval_every = cfg->eval_every_runs,
                                     .eval_starts = cfg->eval_starts,
                                     .eval_at_start = cfg->eval_at_start,
                                     .phase_one_runs = cfg->phase_one_runs,
                                     .phase_two_runs = cfg->phase_two_runs,
                                     .switch_mode = cfg->phase_switch,
                                     .auto_min_runs = cfg->auto_switch_min_runs,
                                     .auto_ratio = cfg->auto_switch_ratio,
                                     .evaluate_only = cfg->mode == FW_MODE_EVALUATE};
  fw_schedule_init(&L->sched, &schc, NULL);
  L->mode = B21R_STATUS_T_MODE_STARTING;
  L->run_id = -1;
  L->last_block.block = -1;
  L->status_countdown = 0;
  return L;
}

void fw_loop_destroy(fw_loop_t* L) {
  if (L == NULL) {
    return;
  }
  pthread_mutex_destroy(&L->mbox_mu);
  free(L->hedger_storage);
  free(L);
}

int64_t fw_loop_period_us(const fw_loop_t* L) { return L->period_us; }

void fw_loop_checkpoint_capacity(const fw_loop_t* L, size_t* meta_bytes, size_t* payload_bytes) {
  *meta_bytes = FW_PROGRESS_BYTES;
  *payload_bytes = L->hedger_save_max;
}

void fw_loop_attach_checkpoints(fw_loop_t* L, fw_ckpt_writer_t* writer) { L->out.checkpoints = writer; }

int fw_loop_load_checkpoint(fw_loop_t* L, char* err, size_t err_cap) {
  const char* path = L->cfg.checkpoint_file;
  if (path[0] == '\0') {
    return 0;
  }
  size_t meta_size = 0;
  size_t payload_size = 0;
  int r = fw_checkpoint_peek(path, &meta_size, &payload_size, err, err_cap);
  if (r <= 0) {
    return r;
  }
  uint8_t meta[FW_PROGRESS_BYTES];
  // At most the largest learned state this configuration can hold, whatever the header claims:
  // fw_checkpoint_read refuses a larger (or corrupt) size with a message instead.
  const size_t payload_cap = payload_size < L->hedger_save_max ? payload_size : L->hedger_save_max;
  void* payload = malloc(payload_cap + 1U);
  if (payload == NULL) {
    fmt(err, err_cap, "checkpoint %s: cannot allocate %zu bytes", path, payload_cap);
    return -1;
  }
  r = fw_checkpoint_read(path, meta, sizeof meta, &meta_size, payload, payload_cap, &payload_size, err, err_cap);
  if (r <= 0) {
    free(payload);
    return r;
  }
  // The controller section is validated before the learner is touched: a refusal changes nothing.
  fw_progress_t g;
  char why[FW_PROGRESS_WHY_MAX];
  if (fw_progress_decode(meta, meta_size, &g, why, sizeof why) != 0) {
    free(payload);
    fmt(err, err_cap, "checkpoint %s is corrupt (controller section: %s); " FW_CHECKPOINT_FRESH_HINT, path, why, path,
        path);
    return -1;
  }
  if (g.task != L->cfg.task || g.state_dim != L->state_dim) {
    free(payload);
    fmt(err, err_cap,
        "checkpoint %s was learned for another task (%s); to start fresh, move the file away (e.g. mv '%s' '%s.other')",
        path, g.task == FW_TASK_CORRIDOR ? "corridor" : "obstacles", path, path);
    return -1;
  }
  const hedger_status_t hs = hedger_load(L->hedger, payload, payload_size);
  free(payload);
  if (hs != HEDGER_OK) {
    fmt(err, err_cap,
        "checkpoint %s: the learned state was refused (%s; hedger_capacity, the task or the action limits may differ "
        "from when it was written); to start fresh, move the file away (e.g. mv '%s' '%s.bad')",
        path, hedger_status_str(hs), path, path);
    return -1;
  }
  const fw_schedule_config_t sc = L->sched.cfg;  // a copy: init clears the schedule first
  fw_schedule_init(&L->sched, &sc, &g.schedule);
  L->run_id = g.run_id;
  return 1;
}

// ---- inputs -------------------------------------------------------------------------------

static void take_scan(fw_loop_t* L) {
  const lms_scan_t* r = &L->scan_raw;
  features_scan_t* s = &L->scan;
  if (r->geometry_known) {
    s->angle_min_rad = (double)r->start_angle_rad;
    s->angle_increment_rad = (double)r->step_rad;
    s->n_beams = r->count;
  } else {
    (void)features_scan_set_lms200_geometry(s, L->cfg.laser_fov_deg, (double)L->cfg.laser_resolution_cdeg / 100.0);
  }
  const uint16_t n = r->count < s->n_beams ? r->count : s->n_beams;
  s->n_beams = n;
  for (uint16_t i = 0; i < n; ++i) {
    s->ranges_m[i] = r->range_m[i];
    s->no_return[i] = r->beam_status[i];
  }
  L->have_scan = true;
  L->scan_new = true;
  L->laser_scans++;
}

static void poll_inputs(fw_loop_t* L, int64_t now_us) {
  const int r = L->io.vt->laser_poll(L->io.user, now_us, &L->scan_raw);
  if (r == 1) {
    take_scan(L);
  } else if (r < 0 && !L->laser_error_logged) {
    L->laser_error_logged = true;
    fw_loop_log(L, 2, "b21r-controller: laser device error (%d) on %s", r, L->cfg.laser_device);
  }
  fw_base_poll(L, now_us);
}

// ---- operator input -----------------------------------------------------------------------

static void take_teleop(fw_loop_t* L, const b21r_teleop_t* m, int64_t arrival_us, int64_t now_us) {
  if (!isfinite(m->rotation_radps) || !isfinite(m->translation_mps)) {
    L->teleop_rejected_nan++;
  } else if (fabs(m->rotation_radps) > L->cfg.max_rotation_radps ||
             fabs(m->translation_mps) > L->cfg.max_translation_mps) {
    L->teleop_rejected_range++;
  } else if (L->teleop_have_seq && m->seq <= L->teleop_last_seq) {
    L->teleop_rejected_seq++;
  } else if (now_us - arrival_us > (int64_t)(L->cfg.teleop_timeout_s * 1e6)) {
    L->teleop_rejected_stale++;
  } else {
    L->teleop_accepted++;
    L->teleop_have_seq = true;
    L->teleop_last_seq = m->seq;
    L->teleop_deadman = m->deadman != 0;
    L->teleop_rot_radps = m->rotation_radps;
    L->teleop_last_us = arrival_us;
    return;
  }
  L->teleop_rejected++;
}

static void take_command(fw_loop_t* L, const b21r_command_t* m) {
  if (m->command < B21R_COMMAND_T_START_PHASE_TWO || m->command > B21R_COMMAND_T_SHUTDOWN ||
      (L->cmd_have_seq && m->seq <= L->cmd_last_seq)) {
    L->commands_rejected++;
    return;
  }
  L->commands_accepted++;
  L->cmd_have_seq = true;
  L->cmd_last_seq = m->seq;
  switch (m->command) {
    case B21R_COMMAND_T_START_PHASE_TWO:
      fw_schedule_request_phase_two(&L->sched);
      fw_loop_log(L, 2, "b21r-controller: operator: phase two starts when the current training run ends");
      break;
    case B21R_COMMAND_T_CONFIRM_START_POSE:
      L->confirm_pending = true;
      break;
    case B21R_COMMAND_T_PAUSE:
      L->paused = true;
      break;
    case B21R_COMMAND_T_RESUME:
      L->paused = false;
      L->resume_now = true;
      break;
    default:
      L->shutdown_requested = true;
      break;
  }
}

static void drain_mailboxes(fw_loop_t* L, int64_t now_us) {
  b21r_teleop_t tel[FW_MAILBOX];
  int64_t arr[FW_MAILBOX];
  b21r_command_t cmd[FW_MAILBOX];
  pthread_mutex_lock(&L->mbox_mu);
  const uint32_t nt = L->teleop_n;
  const uint32_t nc = L->cmd_n;
  memcpy(tel, L->teleop_box, nt * sizeof tel[0]);
  memcpy(arr, L->teleop_arrival, nt * sizeof arr[0]);
  memcpy(cmd, L->cmd_box, nc * sizeof cmd[0]);
  L->teleop_n = 0;
  L->cmd_n = 0;
  const uint64_t over_t = L->mbox_overflow_teleop;
  const uint64_t over_c = L->mbox_overflow_cmd;
  L->mbox_overflow_teleop = 0;
  L->mbox_overflow_cmd = 0;
  pthread_mutex_unlock(&L->mbox_mu);
  L->teleop_rejected += (int64_t)over_t;
  L->commands_rejected += (int64_t)over_c;
  for (uint32_t i = 0; i < nt; ++i) {
    take_teleop(L, &tel[i], arr[i], now_us);
  }
  for (uint32_t i = 0; i < nc; ++i) {
    take_command(L, &cmd[i]);
  }
}

void fw_loop_post_teleop(fw_loop_t* L, const b21r_teleop_t* msg, int64_t arrival_us) {
  pthread_mutex_lock(&L->mbox_mu);
  if (L->teleop_n == FW_MAILBOX) {
    // Keep the newest: drop the oldest.
    memmove(&L->teleop_box[0], &L->teleop_box[1], (FW_MAILBOX - 1) * sizeof L->teleop_box[0]);
    memmove(&L->teleop_arrival[0], &L->teleop_arrival[1], (FW_MAILBOX - 1) * sizeof L->teleop_arrival[0]);
    L->teleop_n--;
    L->mbox_overflow_teleop++;
  }
  L->teleop_box[L->teleop_n] = *msg;
  L->teleop_arrival[L->teleop_n] = arrival_us;
  L->teleop_n++;
  pthread_mutex_unlock(&L->mbox_mu);
}

void fw_loop_post_command(fw_loop_t* L, const b21r_command_t* msg, int64_t arrival_us) {
  (void)arrival_us;
  pthread_mutex_lock(&L->mbox_mu);
  if (L->cmd_n == FW_MAILBOX) {
    L->mbox_overflow_cmd++;
  } else {
    L->cmd_box[L->cmd_n++] = *msg;
  }
  pthread_mutex_unlock(&L->mbox_mu);
}

void fw_loop_signal(fw_loop_t* L, int signal_number) { atomic_store(&L->signal_number, signal_number); }

// ---- runs ---------------------------------------------------------------------------------

static bool joystick_drives(const fw_loop_t* L) {
  return L->cfg.mode == FW_MODE_LEARN && L->cfg.phase_driver == FW_DRIVER_JOYSTICK &&
         L->plan.kind == FW_RUN_TRAINING && L->plan.phase == 1 &&
         (L->mode == B21R_STATUS_T_MODE_RUNNING || L->mode == B21R_STATUS_T_MODE_EVALUATING);
}

static const char* run_kind_name(const fw_loop_t* L) {
  if (L->plan.kind == FW_RUN_EVAL) {
    if (L->cfg.mode == FW_MODE_EVALUATE) {
      return L->cfg.evaluate_policy == FW_EVAL_OPTIMAL ? "eval(optimal)"
                                                         : (L->cfg.evaluate_policy == FW_EVAL_EXAMPLE ? "eval(example)"
                                                                                                      : "eval(learned)");
    }
    return "eval";
  }
  return "train";
}

static void begin_run(fw_loop_t* L) {
  L->run_id++;
  L->actions_taken = 0;
  L->have_prev = false;
  L->run_return = 0.0;
  L->odom_at_start = odom_pose(L);
  // The driver of this run: the example policy in phase one, the advisor in phase two, or the
  // evaluated reference. Its stream is seeded per run, so a run does not depend on earlier ones.
  uint64_t st = L->driver_seed_base ^ ((uint64_t)(uint32_t)L->run_id * 0x9E3779B97F4A7C15ULL);
  const uint64_t run_seed = tasks_rng_splitmix64(&st);
  tasks_driver_kind_t kind = TASKS_DRIVER_PROPORTIONAL;
  if (L->cfg.mode == FW_MODE_EVALUATE && L->cfg.evaluate_policy == FW_EVAL_OPTIMAL) {
    kind = TASKS_DRIVER_OPTIMAL;
  } else if (L->cfg.phase_driver == FW_DRIVER_HUMAN && L->plan.kind == FW_RUN_TRAINING && L->plan.phase == 1) {
    kind = TASKS_DRIVER_HUMAN;
  }
  tasks_driver_begin_run(&L->driver, kind, is_corridor(L) ? TASKS_TASK_CORRIDOR : TASKS_TASK_OBSTACLES, L->omega_max,
                         run_seed);
  if (L->cfg.mode == FW_MODE_EVALUATE && L->cfg.evaluate_policy == FW_EVAL_EXAMPLE) {
    // The example policy at its nominal gain: the middle of the range the runs are drawn from.
    L->driver.gain = is_corridor(L)
                         ? 0.5 * (TASKS_PROPORTIONAL_CORRIDOR_GAIN_MIN + TASKS_PROPORTIONAL_CORRIDOR_GAIN_MAX)
                         : 0.5 * (TASKS_PROPORTIONAL_OBSTACLES_GAIN_MIN + TASKS_PROPORTIONAL_OBSTACLES_GAIN_MAX);
  }
  L->mode = L->plan.kind == FW_RUN_EVAL ? B21R_STATUS_T_MODE_EVALUATING : B21R_STATUS_T_MODE_RUNNING;
  L->status_now = true;
}

static void begin_repositioning(fw_loop_t* L) {
  L->mode = B21R_STATUS_T_MODE_REPOSITIONING;
  L->pose_requested = L->stopped_pose_requested;
  L->stopped_pose_requested = false;
  L->awaiting_confirm = false;
  L->confirm_pending = false;
  L->settle_ticks = L->pose_requested ? (L->cfg.lockstep ? 0 : 3) : 0;
  L->retry_countdown = 0;
  L->plan = fw_schedule_next(&L->sched);
  L->status_now = true;
  if (L->plan.kind == FW_RUN_NONE) {
    L->mode = B21R_STATUS_T_MODE_DONE;
    L->done = true;
    L->exit_status = 0;
    fw_loop_log(L, 1, "schedule complete: %d training runs, %d evaluation blocks", L->sched.p.training_runs,
                L->sched.p.eval_blocks);
    return;
  }
  if (!L->pose_requested) {
    L->start_pose = L->plan.kind == FW_RUN_EVAL
                        ? eval_pose(L, L->plan.eval_index)
                        : (is_corridor(L) ? tasks_corridor_training_start(&L->corridor, &L->pose_rng)
                                          : tasks_obstacles_training_start(&L->obstacles, &L->pose_rng));
  }
}

static void finish_run(fw_loop_t* L, bool reached_goal, bool aborted, const char* why) {
  const bool training = L->plan.kind == FW_RUN_TRAINING && L->cfg.mode == FW_MODE_LEARN;
  if (training) {
    uint32_t replayed = 0;
    (void)hedger_end_run(L->hedger, &replayed);  // backward replay (cfg.hedger_replay), between runs
  }
  const int32_t steps = reached_goal ? L->actions_taken : (int32_t)step_limit(L);
  fw_eval_block_t block;
  const bool block_done = fw_schedule_finish_run(&L->sched, reached_goal ? L->actions_taken : steps, reached_goal,
                                                 aborted, &block);
  if (aborted) {
    L->runs_aborted++;
  } else {
    L->runs_finished++;
    L->last_run_steps = L->actions_taken;
    L->last_run_goal = reached_goal;
  }
  if (L->cfg.progress) {
    fw_loop_log(L, 1, "run %4d  phase %d  %-13s %-9s %4d steps  (%s)  store %u/%d", L->run_id, L->plan.phase,
                run_kind_name(L), aborted ? "ABORTED" : (reached_goal ? "goal" : "no goal"), L->actions_taken, why,
                hedger_counters(L->hedger)->store_fill, L->cfg.hedger_capacity);
  }
  if (block_done) {
    L->last_block = block;
    publish_eval(L, &block);
    if (L->cfg.progress) {
      fw_loop_log(L, 1, "EVAL block %2d after %3d training runs (phase %d): %2d/%d reached the goal, mean %.1f +- %.1f steps",
                  block.block, block.training_runs, block.phase, block.successes, block.n_starts, block.mean_steps,
                  block.ci95_halfwidth);
      if (L->sched.p.phase == 2 && block.phase == 1) {
        fw_loop_log(L, 1, "PHASE TWO: the learned policy drives from now on");
      }
    }
  }
  if (training) {
    checkpoint(L);
  }
  begin_repositioning(L);
}

// Phase-two training with the advisor on: the example policy's action is taken unless HEDGER's
// greedy value comes from a local regression (LWR, inside the data's hull) and beats the
// advisor's action by more than advisor_margin of its value: the learned policy acts where it
// knows better. Measured on the corridor (fake robot, 30 + 35 runs, 3 seeds): without this rule
// the greedy search follows approximation noise (Q differences between actions are about one
// step's discount, 1 %), crashes, and the evaluations fall from 10/10 to 1-3/10; with it they
// stay at 10/10. Evaluations never consult the advisor: they measure the learned policy alone.
static bool advisor_wins(fw_loop_t* L, bool evaluating, double greedy_action, double advice) {
  if (evaluating || !L->cfg.advisor || L->cfg.mode != FW_MODE_LEARN) {
    return false;
  }
  hedger_prediction_t pg;
  hedger_prediction_t pa;
  if (hedger_predict(L->hedger, L->s, advice, &pa) != HEDGER_OK ||
      hedger_predict(L->hedger, L->s, greedy_action, &pg) != HEDGER_OK) {
    return false;
  }
  if (pa.kind == HEDGER_KIND_UNKNOWN || pg.kind != HEDGER_KIND_LWR) {
    // Nothing to compare with, or the greedy value is an average (LWA) rather than a local model:
    // HEDGER does not know better than the advisor here.
    return true;
  }
  return pg.value <= pa.value + L->cfg.advisor_margin * fabs(pa.value);
}

// One learning step of a running run (a new scan arrived and no stop is in force).
// contact: the bumper was hit this tick (the run ends as a collision).
static void run_step(fw_loop_t* L, bool state_ok, uint8_t contact, double* v_cmd, double* w_cmd) {
  const bool evaluating = L->plan.kind == FW_RUN_EVAL;
  const bool learning = !evaluating && L->cfg.mode == FW_MODE_LEARN;
  const bool learned_policy =
      (evaluating && !(L->cfg.mode == FW_MODE_EVALUATE && L->cfg.evaluate_policy != FW_EVAL_LEARNED)) ||
      (!evaluating && L->plan.phase == 2);
  bool greedy_known = false;
  double greedy_action = 0.0;
  if (L->have_prev) {
    const tasks_outcome_t o = outcome(L, contact, (uint32_t)L->actions_taken);
    const bool terminal = o.terminal != 0;
    double q = 0.0;
    hedger_kind_t kind = HEDGER_KIND_UNKNOWN;
    if (learning) {
      hedger_update_info_t info;
      if (hedger_update(L->hedger, L->prev_s, L->prev_a, o.reward, L->s, terminal ? 1 : 0, &info) == HEDGER_OK) {
        q = info.q_old;
        kind = info.kind;
        greedy_known = info.next_status == HEDGER_OK;
        greedy_action = info.next_action;
      }
    } else {
      hedger_prediction_t pr;
      if (hedger_predict(L->hedger, L->prev_s, L->prev_a, &pr) == HEDGER_OK) {
        q = pr.value;
        kind = pr.kind;
      }
      if (learned_policy && !o.end_run) {
        greedy_known = hedger_greedy(L->hedger, L->s, &greedy_action, NULL, NULL) == HEDGER_OK;
      }
    }
    publish_experience(L, o.reward, terminal, q, kind);
    L->steps++;
    L->run_return += o.reward;
    if (o.end_run) {
      *v_cmd = 0.0;
      *w_cmd = 0.0;
      const bool goal = o.reason == TASKS_END_GOAL;
      finish_run(L, goal, false,
                 goal ? "goal" : (o.reason == TASKS_END_COLLISION ? "collision" : "step limit"));
      return;
    }
  } else if (learned_policy) {
    greedy_known = hedger_greedy(L->hedger, L->s, &greedy_action, NULL, NULL) == HEDGER_OK;
  }
  (void)state_ok;
  // The driver runs every step (even when it only advises) so its state follows the run.
  const double advice = driver_action(L);
  double a = 0.0;
  int8_t source = B21R_EXPERIENCE_T_SOURCE_EXAMPLE;
  if (!learned_policy) {
    if (joystick_drives(L)) {
      a = L->teleop_rot_radps;
      source = B21R_EXPERIENCE_T_SOURCE_JOYSTICK;
    } else {
      a = advice;
    }
  } else if (greedy_known && !advisor_wins(L, evaluating, greedy_action, advice)) {
    a = greedy_action;
    source = B21R_EXPERIENCE_T_SOURCE_GREEDY;
    if (!evaluating && tasks_rng_uniform(&L->explore_rng) < L->cfg.explore_probability) {
      a += L->cfg.explore_sigma_radps * tasks_rng_normal(&L->explore_rng);
      source = B21R_EXPERIENCE_T_SOURCE_EXPLORATION;
    }
  } else if (!evaluating && L->cfg.advisor) {
    a = advice;
    source = B21R_EXPERIENCE_T_SOURCE_ADVISOR;
  } else {
    a = 0.0;  // nothing known: hold course (evaluations measure the learned policy alone)
    source = B21R_EXPERIENCE_T_SOURCE_GREEDY;
  }
  *w_cmd = a;
  *v_cmd = speed(L);
  L->prev_source = source;
}

// ---- the tick -----------------------------------------------------------------------------

static void clamp_command(fw_loop_t* L, double* v, double* w) {
  const double dv = L->cfg.max_translation_accel_mps2 * L->dt_s;
  const double dw = L->cfg.max_rotation_accel_radps2 * L->dt_s;
  *v = clampd(*v, -L->cfg.max_translation_mps, L->cfg.max_translation_mps);
  *w = clampd(*w, -L->cfg.max_rotation_radps, L->cfg.max_rotation_radps);
  *v = clampd(*v, L->cmd_v - dv, L->cmd_v + dv);
  *w = clampd(*w, L->cmd_w - dw, L->cmd_w + dw);
}

static void abort_run(fw_loop_t* L, const char* why) {
  if (L->mode == B21R_STATUS_T_MODE_RUNNING || L->mode == B21R_STATUS_T_MODE_EVALUATING) {
    finish_run(L, false, true, why);
  }
}

bool fw_loop_tick(fw_loop_t* L, int64_t now_us) {
  L->tick_count++;
  // In lockstep, time is the emulator's: tick × period, so identical runs log identical times.
  L->utime = L->cfg.lockstep ? L->tick_count * L->period_us : now_us;
  poll_inputs(L, now_us);

  if (L->scan_new) {
    L->laser_silent_ticks = 0;
    L->last_scan_us = now_us;
  } else {
    L->laser_silent_ticks++;
  }
  if (fw_base_any_report(L)) {
    L->base_silent_ticks = 0;
    L->last_base_us = now_us;
    (void)rflex_odom_update(&L->odo);
  } else {
    L->base_silent_ticks++;
  }
  fw_base_evaluate_faults(L, now_us);
  drain_mailboxes(L, now_us);

  const bool running = L->mode == B21R_STATUS_T_MODE_RUNNING || L->mode == B21R_STATUS_T_MODE_EVALUATING;
  const bool run_starting =
      L->mode == B21R_STATUS_T_MODE_REPOSITIONING && L->pose_requested && L->settle_ticks == 0 && L->scan_new &&
      (!L->awaiting_confirm || L->confirm_pending);
  if (run_starting) {
    L->odom_at_start = odom_pose(L);
  }
  // Features whenever a new scan arrives during (or at the start of) a run.
  bool state_ok = false;
  if (L->scan_new && (running || run_starting)) {
    state_ok = compute_state(L) && all_finite(L->s, L->state_dim);
  }
  const double odo_vals[3] = {L->odo.x_m, L->odo.y_m, L->odo.theta_rad};
  const bool odo_finite = all_finite(odo_vals, 3);

  fw_safety_inputs_t in;
  memset(&in, 0, sizeof in);
  in.laser_silent_ticks = L->laser_silent_ticks;
  in.base_silent_ticks = L->base_silent_ticks;
  in.laser_age_us = now_us - L->last_scan_us;
  in.base_age_us = now_us - L->last_base_us;
  in.base_fault = L->base_fault;
  in.base_fault_detail = L->base_fault_detail;
  in.bumper_mask = L->bumper_mask;
  in.non_finite = !odo_finite || (L->scan_new && (running || run_starting) && !all_finite(L->s, L->state_dim));
  in.non_finite_where = !odo_finite ? "odometry" : "task state";
  // The joystick must hold the deadman while it drives, and already in the tick its run starts.
  in.deadman_required = joystick_drives(L) ||
                        (run_starting && L->cfg.mode == FW_MODE_LEARN && L->cfg.phase_driver == FW_DRIVER_JOYSTICK &&
                         L->plan.kind == FW_RUN_TRAINING && L->plan.phase == 1);
  in.deadman_fresh = L->teleop_deadman && now_us - L->teleop_last_us <= (int64_t)(L->cfg.teleop_timeout_s * 1e6);
  in.signal_number = atomic_load(&L->signal_number);
  in.operator_pause = L->paused;
  in.operator_resume = L->resume_now;
  L->resume_now = false;
  const fw_safety_event_t ev = fw_safety_update(&L->safety, &in);

  double v = 0.0;
  double w = 0.0;
  bool stopping = true;
  if (ev == FW_SAFETY_STOP_BEGAN) {
    fw_loop_log(L, 2, "b21r-controller: SAFETY STOP (%s): %s", fw_stop_reason_name(L->safety.reason), L->safety.detail);
    if (running) {
      if (L->safety.reason == FW_STOP_BUMPER && L->scan_new && state_ok && L->have_prev) {
        // A bump ends the run as a collision: learn that last transition, then stop.
        run_step(L, state_ok, 1, &v, &w);
      } else {
        abort_run(L, fw_stop_reason_name(L->safety.reason));
      }
    }
    L->mode = B21R_STATUS_T_MODE_STOPPED;
    L->status_now = true;
    v = 0.0;
    w = 0.0;
    if (L->safety.reason == FW_STOP_SIGNAL) {
      L->done = true;
      L->exit_status = 128 + in.signal_number;
    }
  } else if (ev == FW_SAFETY_STOPPED) {
    L->mode = B21R_STATUS_T_MODE_STOPPED;
    // A bumped robot cannot clear its bumper by itself: with the emulator, reset it to the next
    // start pose while stopped (on the robot the operator frees it).
    if (L->safety.reason == FW_STOP_BUMPER && !L->stopped_pose_requested && L->io.vt->request_start_pose != NULL &&
        L->cfg.reposition == FW_REPOSITION_EMULATOR) {
      const fw_run_plan_t plan = fw_schedule_next(&L->sched);
      if (plan.kind != FW_RUN_NONE) {
        L->start_pose = plan.kind == FW_RUN_EVAL
                            ? eval_pose(L, plan.eval_index)
                            : (is_corridor(L) ? tasks_corridor_training_start(&L->corridor, &L->pose_rng)
                                              : tasks_obstacles_training_start(&L->obstacles, &L->pose_rng));
        L->stopped_pose_requested =
            L->io.vt->request_start_pose(L->io.user, L->start_pose.x_m, L->start_pose.y_m, L->start_pose.theta_rad) == 1;
      }
    }
  } else if (ev == FW_SAFETY_RESUMED) {
    fw_loop_log(L, 2, "b21r-controller: safety stop cleared; repositioning for the next run");
    begin_repositioning(L);
  }

  if (L->shutdown_requested && !L->done) {
    fw_loop_log(L, 2, "b21r-controller: operator SHUTDOWN");
    abort_run(L, "shutdown");
    L->mode = B21R_STATUS_T_MODE_DONE;
    L->done = true;
    L->exit_status = 0;
  }

  if (!L->safety.stopped && !L->done && (ev == FW_SAFETY_OK || ev == FW_SAFETY_RESUMED)) {
    if (L->mode == B21R_STATUS_T_MODE_STARTING) {
      begin_repositioning(L);
    }
    if (L->mode == B21R_STATUS_T_MODE_REPOSITIONING) {
      if (!L->pose_requested) {
        if (L->retry_countdown > 0) {
          L->retry_countdown--;
        } else {
          const int r = L->io.vt->request_start_pose == NULL
                            ? 0
                            : L->io.vt->request_start_pose(L->io.user, L->start_pose.x_m, L->start_pose.y_m,
                                                           L->start_pose.theta_rad);
          if (r == 1) {
            L->pose_requested = true;
            // Lockstep: the data of the next period is already taken at the new pose. Real
            // time: let a few scans pass that may predate the reset.
            L->settle_ticks = L->cfg.lockstep ? 0 : 3;
          } else if (r == 0) {
            L->pose_requested = true;
            L->awaiting_confirm = true;
            fw_loop_log(L, 2,
                        "b21r-controller: place the robot at x %.2f m, y %.2f m, heading %.2f rad (task frame) and send "
                        "B21R_COMMAND CONFIRM_START_POSE",
                        L->start_pose.x_m, L->start_pose.y_m, L->start_pose.theta_rad);
          } else {
            L->retry_countdown = 10;
            fw_loop_log(L, 2, "b21r-controller: start pose request failed (%d); retrying", r);
          }
        }
      } else if (L->settle_ticks > 0) {
        L->settle_ticks--;
      } else if (L->scan_new && (!L->awaiting_confirm || L->confirm_pending) && state_ok) {
        begin_run(L);
        run_step(L, state_ok, 0, &v, &w);
        stopping = false;
      }
    } else if (L->mode == B21R_STATUS_T_MODE_RUNNING || L->mode == B21R_STATUS_T_MODE_EVALUATING) {
      if (L->scan_new && state_ok) {
        run_step(L, state_ok, 0, &v, &w);
        stopping = L->mode != B21R_STATUS_T_MODE_RUNNING && L->mode != B21R_STATUS_T_MODE_EVALUATING;
      } else {
        // No new scan (or features unusable) this tick: hold the command, learn nothing.
        L->held_ticks++;
        v = L->cmd_v;
        w = L->cmd_w;
        stopping = false;
      }
    }
  }

  // Clamp and send. A stop commands zero at once (the base decelerates at its own limit).
  if (stopping) {
    v = 0.0;
    w = 0.0;
  } else {
    clamp_command(L, &v, &w);
    if (!isfinite(v) || !isfinite(w)) {
      v = 0.0;  // the supervisor reports it next tick; never send a non-finite number
      w = 0.0;
    }
    if (L->mode == B21R_STATUS_T_MODE_RUNNING || L->mode == B21R_STATUS_T_MODE_EVALUATING) {
      // The learner records what was executed: the clamped action.
      for (uint32_t i = 0; i < L->state_dim; ++i) {
        L->prev_s[i] = L->s[i];
      }
      L->prev_a = w;
      L->prev_v = v;
      L->have_prev = true;
      L->actions_taken++;
    }
  }
  fw_base_command(L, v, w, stopping);
  L->cmd_v = v;
  L->cmd_w = w;

  publish_pose(L);
  if (L->scan_new) {
    publish_scan(L);
  }
  if (--L->status_countdown <= 0 || L->status_now) {
    publish_status(L);
    L->status_countdown = L->cfg.status_period_ticks;
    L->status_now = false;
  }
  notify(L);

  L->scan_new = false;
  fw_base_clear_flags(L);
  L->confirm_pending = false;

  const int64_t end_us = io_now(L);
  const bool overrun =
      L->cfg.lockstep ? (end_us - now_us > L->period_us) : (L->tick_deadline_us > 0 && end_us > L->tick_deadline_us + L->period_us);
  fw_timing_record(&L->timing, end_us - now_us, overrun);
  return !L->done;
}

// ---- pacing -------------------------------------------------------------------------------

int64_t fw_loop_wait(fw_loop_t* L) {
  int64_t now = io_now(L);
  if (L->cfg.lockstep) {
    const int64_t start = now;
    int64_t deadline = start + (int64_t)(L->cfg.lockstep_timeout_s * 1e6);
    bool grace_set = false;
    for (;;) {
      poll_inputs(L, now);
      if (L->scan_new && fw_base_all_reports(L)) {
        break;
      }
      if (!grace_set && (L->scan_new || fw_base_any_report(L))) {
        grace_set = true;
        const int64_t g = now + (int64_t)(L->cfg.lockstep_grace_s * 1e6);
        deadline = g < deadline ? g : deadline;
      }
      if (now >= deadline) {
        break;
      }
      (void)L->io.vt->wait(L->io.user, deadline);
      now = io_now(L);
    }
    L->tick_deadline_us = now;
    return now;
  }
  if (L->next_deadline_us == 0) {
    L->next_deadline_us = now;
  }
  while (now < L->next_deadline_us) {
    (void)L->io.vt->wait(L->io.user, L->next_deadline_us);
    now = io_now(L);
    poll_inputs(L, now);
  }
  const int64_t tick = L->next_deadline_us;
  L->tick_deadline_us = tick;
  // Absolute deadlines; deadlines missed by a long tick are skipped (counted as overruns).
  L->next_deadline_us += L->period_us;
  if (now >= L->next_deadline_us) {
    const int64_t missed = (now - L->next_deadline_us) / L->period_us + 1;
    L->next_deadline_us += missed * L->period_us;
    L->timing.overruns += missed;
  }
  return now;
}

int fw_loop_run(fw_loop_t* L) {
  for (;;) {
    const int64_t t = fw_loop_wait(L);
    if (!fw_loop_tick(L, t)) {
      break;
    }
  }
  return L->exit_status;
}

// ---- start-up and shutdown ----------------------------------------------------------------

int fw_loop_start(fw_loop_t* L, char* err, size_t err_cap) {
  if (fw_base_start(L, err, err_cap) != 0) {
    return -1;
  }
  // The first scan (the laser driver may first have to find the LMS200's baud rate) and the
  // first odometry. Zero commands keep the base's watchdog fed meanwhile (and, in lockstep,
  // make the emulator's time advance).
  const int64_t start = io_now(L);
  const int64_t limit_us = 20000000;
  int64_t next_cmd = start;
  for (;;) {
    const int64_t now = io_now(L);
    poll_inputs(L, now);
    if (fw_base_any_report(L)) {
      (void)rflex_odom_update(&L->odo);
    }
    // The arrival flags are kept: the first tick then runs at once on this data (in lockstep
    // the emulator waits for our first command before it sends more).
    if (L->have_scan && L->odo.baseline) {
      break;
    }
    if (now - start > limit_us) {
      fmt(err, err_cap, "%s: no %s within %d s (device %s); check the cable, the power and the *_device keys",
          !L->have_scan ? "laser" : "base", !L->have_scan ? "scan" : "odometry", (int)(limit_us / 1000000),
          !L->have_scan ? L->cfg.laser_device
                        : (L->cfg.base_protocol == FW_BASE_RFLEX ? L->cfg.base_device : "CAN bus"));
      return -1;
    }
    if (now >= next_cmd) {
      fw_base_command(L, 0.0, 0.0, true);  // keeps the base's watchdog fed
      next_cmd = now + L->period_us;
    }
    (void)L->io.vt->wait(L->io.user, now + 20000);
  }
  L->last_scan_us = io_now(L);
  L->last_base_us = L->last_scan_us;
  L->started = true;
  return 0;
}

int fw_loop_shutdown(fw_loop_t* L) {
  fw_loop_log(L, 2, "b21r-controller: shutting down: zero command, brake set, devices off, final checkpoint");
  abort_run(L, "shutdown");
  fw_base_shutdown(L);
  if (L->io.vt->laser_stop != NULL) {
    L->io.vt->laser_stop(L->io.user);
  }
  // The learned state as it is now: nothing learned is lost, even mid-run.
  checkpoint(L);
  L->mode = B21R_STATUS_T_MODE_DONE;
  L->status_now = true;
  publish_status(L);
  notify(L);
  if (L->out.checkpoints != NULL) {
    fw_ckpt_writer_flush(L->out.checkpoints);
    if (fw_ckpt_writer_counters(L->out.checkpoints).failed > 0) {
      return -1;
    }
  }
  return 0;
}

void fw_loop_get_stats(const fw_loop_t* L, fw_loop_stats_t* out) {
  memset(out, 0, sizeof *out);
  out->ticks = L->tick_count;
  out->steps = L->steps;
  out->experiences_dropped = L->exp_dropped;
  out->run_id = L->run_id;
  out->runs_finished = L->runs_finished;
  out->runs_aborted = L->runs_aborted;
  out->training_runs = L->sched.p.training_runs;
  out->eval_blocks = L->sched.p.eval_blocks;
  out->phase = L->sched.p.phase;
  out->mode = status_mode(L);
  out->stop_reason = L->safety.reason;
  out->safety_stops = L->safety.stops;
  for (int i = 0; i < 9; ++i) {
    out->stops_by_reason[i] = L->safety.stops_by_reason[i];
  }
  out->held_ticks = L->held_ticks;
  out->teleop_accepted = L->teleop_accepted;
  out->teleop_rejected = L->teleop_rejected;
  out->commands_accepted = L->commands_accepted;
  out->commands_rejected = L->commands_rejected;
  out->store_fill = hedger_counters(L->hedger)->store_fill;
  out->done = L->done;
  out->last_block = L->last_block;
  out->best_example_steps = L->sched.p.best_example_steps;
  out->mean_example_steps =
      L->sched.p.example_runs > 0 ? L->sched.p.example_steps_sum / (double)L->sched.p.example_runs : 0.0;
  out->last_run_steps = L->last_run_steps;
  out->last_run_goal = L->last_run_goal;
}
