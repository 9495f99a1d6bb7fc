// SPDX-License-Identifier: MIT
// The loop's messages: experience, pose, scan, evaluation block, status, and text lines, all
// handed to the publisher queue (reserve / fill in place / commit: never blocks, a full queue
// drops and counts).
#include "outputs.h"
#include "base.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

void fw_out_notify(fw_loop_t* L) {
  if (L->out.notify != NULL) {
    L->out.notify(L->out.notify_user);
  }
}

static void emit_line(fw_loop_t* L, int stream, const char* line) {
  fw_msg_t* m = L->out.queue != NULL ? fw_pubq_reserve(L->out.queue, FW_MSG_TEXT) : NULL;
  if (m == NULL) {
    if (L->out.queue == NULL && stream == 2) {
      // No publisher (start-up, tools): write directly; not on the tick path.
      fprintf(stderr, "%s\n", line);
    }
    return;
  }
  m->u.text.stream = stream;
  (void)snprintf(m->u.text.line, sizeof m->u.text.line, "%s", line);
  fw_pubq_commit(L->out.queue);
  fw_out_notify(L);
}

static void release_one(fw_loop_t* L);

// Every run up to this id is on disk (no checkpoints: every run, there is nothing to wait for).
static int32_t durable_run(fw_loop_t* L) {
  return L->reports_wait ? fw_ckpt_writer_durable_run(L->out.checkpoints) : INT32_MAX;
}

// Reports wait while a run that ended is not on disk yet, and behind any report that waits.
static bool holding(fw_loop_t* L) { return L->held_n > 0U || L->held_run > durable_run(L); }

// A report into the queue (when it is full the oldest goes out early, counted).
static fw_held_report_t* hold(fw_loop_t* L, int32_t kind) {
  if (L->held_n == FW_HELD_REPORTS) {
    L->reports_early++;
    release_one(L);
  }
  fw_held_report_t* h = &L->held[(L->held_head + L->held_n) % FW_HELD_REPORTS];
  L->held_n++;
  h->run_id = L->held_run;
  h->kind = kind;
  return h;
}

void fw_loop_log(fw_loop_t* L, int stream, const char* format, ...) {
  char line[FW_TEXT_MAX];
  va_list ap;
  va_start(ap, format);
  (void)vsnprintf(line, sizeof line, format, ap);
  va_end(ap);
  if (stream == 1 && holding(L)) {
    // Progress lines keep their order behind the reports of a run that is not on disk yet.
    memcpy(hold(L, FW_MSG_TEXT)->u.line, line, sizeof line);
    return;
  }
  emit_line(L, stream, line);
}

void fw_out_experience(fw_loop_t* L, const learn_experience_t* step) {
  const int64_t seq = L->exp_seq++;  // a dropped experience leaves a gap in seq: detectable
  if (L->out.queue == NULL) {
    return;
  }
  fw_msg_t* m = fw_pubq_reserve(L->out.queue, FW_MSG_EXPERIENCE);
  if (m == NULL) {
    L->exp_dropped++;
    return;
  }
  b21r_experience_t* e = &m->u.experience;
  memset(e, 0, sizeof *e);
  e->utime = L->utime;
  e->seq = seq;
  e->run_id = step->run_id;
  e->step_id = step->step_id;
  e->task = (int8_t)L->cfg.task;
  e->phase = (int8_t)step->phase;
  e->source = step->source;
  e->evaluating = step->evaluating ? 1 : 0;
  e->state_dim = (int8_t)step->state_dim;
  for (uint32_t i = 0; i < step->state_dim; ++i) {
    e->s[i] = step->s[i];
    e->s_next[i] = step->s_next[i];
  }
  e->action_radps = step->a;
  e->translation_mps = step->v;
  e->reward = step->reward;
  e->terminal = step->terminal ? 1 : 0;
  e->q_value = isfinite(step->q) ? step->q : 0.0;
  e->q_kind = (int8_t)(step->q_kind == HEDGER_KIND_LWR ? 0 : (step->q_kind == HEDGER_KIND_LWA ? 1 : 2));
  fw_pubq_commit(L->out.queue);
}

void fw_out_pose(fw_loop_t* L) {
  if (L->out.queue == NULL) {
    return;
  }
  fw_msg_t* m = fw_pubq_reserve(L->out.queue, FW_MSG_POSE);
  if (m == NULL) {
    return;
  }
  b21r_pose_t* p = &m->u.pose;
  p->utime = L->utime;
  p->run_id = learn_run_id(L->agent);
  p->step_id = learn_run_actions(L->agent);
  p->x_m = L->base.odometry.x_m;
  p->y_m = L->base.odometry.y_m;
  p->theta_rad = L->base.odometry.theta_rad;
  p->translation_mps = L->base.odometry.v_mps;
  p->rotation_radps = L->base.odometry.omega_radps;
  fw_pubq_commit(L->out.queue);
}

void fw_out_scan(fw_loop_t* L) {
  if (L->out.queue == NULL || !L->cfg.publish_scan) {
    return;
  }
  fw_msg_t* m = fw_pubq_reserve(L->out.queue, FW_MSG_SCAN);
  if (m == NULL) {
    return;
  }
  b21r_scan_t* s = &m->u.scan;
  s->utime = L->utime;
  s->run_id = learn_run_id(L->agent);
  s->step_id = learn_run_actions(L->agent);
  s->angle_min_rad = (float)L->scan.angle_min_rad;
  s->angle_increment_rad = (float)L->scan.angle_increment_rad;
  s->n_beams = (int16_t)L->scan.n_beams;
  for (uint16_t i = 0; i < L->scan.n_beams; ++i) {
    s->no_return_reason[i] = (int8_t)L->scan.no_return[i];
    s->ranges_m[i] = L->scan.no_return[i] != 0 ? 0.0F : L->scan.ranges_m[i];
  }
  fw_pubq_commit(L->out.queue);
}

static void emit_eval(fw_loop_t* L, const learn_eval_block_t* b) {
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

void fw_out_eval(fw_loop_t* L, const learn_eval_block_t* b) {
  if (holding(L)) {
    hold(L, FW_MSG_EVAL)->u.eval = *b;
    return;
  }
  emit_eval(L, b);
}

int8_t fw_out_status_mode(const fw_loop_t* L) {
  if (L->mode == B21R_STATUS_T_MODE_STOPPED && L->safety.reason == FW_STOP_OPERATOR) {
    return B21R_STATUS_T_MODE_PAUSED;
  }
  return (int8_t)L->mode;
}

void fw_out_status(fw_loop_t* L) {
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
  s->phase = (int8_t)learn_schedule(L->agent)->p.phase;
  s->mode = fw_out_status_mode(L);
  s->stop_reason = (int8_t)L->safety.reason;
  memcpy(m->u.status.detail, L->safety.detail, sizeof m->u.status.detail);
  s->run_id = learn_run_id(L->agent);
  s->step_id = learn_run_actions(L->agent);
  // The runs reported so far (those on disk): a run counted here survives a kill.
  s->training_runs = L->reported_progress.training_runs;
  s->eval_blocks = L->reported_progress.eval_blocks;
  const fw_timing_summary_t t = fw_timing_summary(&L->timing);
  s->tick_p50_us = t.p50_us;
  s->tick_p99_us = t.p99_us;
  s->tick_max_us = t.max_us;
  s->tick_overruns = t.overruns;
  s->ticks = t.ticks;
  const learn_learner_stats_t learner = learn_learner_stats(learn_get_learner(L->agent));
  s->store_fill = (int32_t)learner.fill;
  s->store_capacity = (int32_t)learner.capacity;
  s->hedger_lwr = (int64_t)learner.predictions_lwr;
  s->hedger_lwa = (int64_t)learner.predictions_lwa;
  s->hedger_unknown = (int64_t)learner.predictions_unknown;
  s->hedger_evictions = (int64_t)learner.evictions;
  s->hedger_rebuilds = (int64_t)learner.rebuilds;
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
  // Refusals of the receive thread's authentication count as refused operator input too.
  const fw_opauth_counters_t auth = fw_opauth_counters(L->out.operator_auth);
  s->teleop_accepted = L->teleop_accepted;
  s->teleop_rejected = L->teleop_rejected + (int64_t)auth.refused[FW_OPAUTH_TELEOP];
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
  s->commands_rejected = L->commands_rejected + (int64_t)auth.refused[FW_OPAUTH_COMMAND];
  s->checkpoint_failures = (int64_t)ckpt.failed;
  s->laser_restarts = (int64_t)ls.restarts;
  s->odometry_rejected = (int64_t)(L->base.odometry.rejected_trans + L->base.odometry.rejected_rot);
  s->laser_repeated_scans = L->laser_repeated_scans;
  fw_can_stats_t cs;
  memset(&cs, 0, sizeof cs);
  if (L->io.vt->can_stats != NULL) {
    L->io.vt->can_stats(L->io.user, &cs);
  }
  s->can_error_frames = (int64_t)cs.error_frames;
  s->can_unanswered_syncs = L->can_unanswered_syncs;
  s->can_foreign_frames = L->can_foreign_frames;
  s->can_stale_pdos = L->can_stale_pdos;
  s->experiences = L->exp_seq;
  s->experiences_dropped = L->exp_dropped;
  s->tick_max_ever_us = t.max_ever_us;
  s->battery_v = L->base.battery_v;
  const fw_publisher_counters_t pc = fw_publisher_counters(L->out.publisher);
  s->messages_published = (int64_t)pc.published;
  s->lcm_publish_errors = (int64_t)pc.lcm_errors;
  s->log_write_errors = (int64_t)pc.log_errors;
  s->operator_inputs_logged = (int64_t)pc.recorded;
  s->late_p99_us = t.late_p99_us;
  s->late_max_us = t.late_max_us;
  s->late_max_ever_us = t.late_max_ever_us;
  s->late_starts = t.late_starts;
  s->missed_periods = t.missed_periods;
  s->gap_max_ever_us = t.gap_max_ever_us;
  s->operator_refused_malformed = (int64_t)auth.by_verdict[FW_OPAUTH_MALFORMED];
  s->operator_refused_unauthenticated = (int64_t)auth.by_verdict[FW_OPAUTH_UNAUTHENTICATED];
  s->operator_refused_key = (int64_t)auth.by_verdict[FW_OPAUTH_KEY];
  s->operator_refused_mac = (int64_t)auth.by_verdict[FW_OPAUTH_MAC];
  s->operator_refused_session = (int64_t)auth.by_verdict[FW_OPAUTH_SESSION];
  s->operator_refused_replay = (int64_t)auth.by_verdict[FW_OPAUTH_REPLAY];
  s->operator_refused_old = (int64_t)auth.by_verdict[FW_OPAUTH_OLD];
  fw_pubq_commit(L->out.queue);
}

void fw_out_config(fw_loop_t* L) {
  if (L->out.queue == NULL) {
    return;
  }
  fw_msg_t* m = fw_pubq_reserve(L->out.queue, FW_MSG_CONFIG);
  if (m == NULL) {
    return;
  }
  b21r_config_t* c = &m->u.config;
  memset(c, 0, sizeof *c);
  c->utime = L->utime;
  c->text = L->config_text != NULL ? L->config_text : (char*)(uintptr_t)"";
  c->max_translation_mps = L->limits.max_translation_mps;
  c->max_rotation_radps = L->limits.max_rotation_radps;
  c->max_translation_accel_mps2 = L->limits.max_translation_accel_mps2;
  c->max_rotation_accel_radps2 = L->limits.max_rotation_accel_radps2;
  c->teleop_timeout_s = L->cfg.teleop_timeout_s;
  c->tick_rate_hz = L->cfg.tick_rate_hz;
  c->step_limit = (int32_t)tasks_episode_step_limit(&L->ep);
  c->task = (int8_t)L->cfg.task;
  c->lockstep = L->cfg.lockstep ? 1 : 0;
  fw_pubq_commit(L->out.queue);
  fw_out_notify(L);
}

static void emit_run(fw_loop_t* L, const b21r_run_t* run, const learn_schedule_progress_t* progress) {
  L->reported_progress = *progress;
  if (L->out.queue == NULL) {
    return;
  }
  fw_msg_t* m = fw_pubq_reserve(L->out.queue, FW_MSG_RUN);
  if (m != NULL) {
    m->u.run = *run;
    fw_pubq_commit(L->out.queue);
  }
}

void fw_out_run_end(fw_loop_t* L) {
  if (!L->run_end_ready) {
    return;
  }
  L->run_end_ready = false;
  // Every experience of the run has been produced by now (the last one right after the command).
  L->run_end.experiences = (int32_t)(L->exp_seq - L->run_end.first_seq);
  const learn_schedule_progress_t* progress = &learn_schedule(L->agent)->p;
  if (holding(L)) {
    fw_held_report_t* h = hold(L, FW_MSG_RUN);
    h->u.run.msg = L->run_end;
    h->u.run.progress = *progress;
    return;
  }
  emit_run(L, &L->run_end, progress);
}

static void release_one(fw_loop_t* L) {
  const fw_held_report_t* h = &L->held[L->held_head];
  L->held_head = (L->held_head + 1U) % FW_HELD_REPORTS;
  L->held_n--;
  if (h->kind == FW_MSG_RUN) {
    emit_run(L, &h->u.run.msg, &h->u.run.progress);
  } else if (h->kind == FW_MSG_EVAL) {
    emit_eval(L, &h->u.eval);
  } else {
    emit_line(L, 1, h->u.line);
  }
}

void fw_out_release_reports(fw_loop_t* L, bool force) {
  const int32_t durable = durable_run(L);
  while (L->held_n > 0U && (force || L->held[L->held_head].run_id <= durable)) {
    release_one(L);
  }
}
