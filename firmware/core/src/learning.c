// SPDX-License-Identifier: MIT
// The learner inside the loop: HEDGER's configuration, the update of each step (after the
// tick's command went out), the between-run work (backward replay, checkpoint) in bounded slices,
// and the checkpoint's controller section.
//
// Why slices: the replay of a finished run costs replay_passes × run length updates, and the
// serialisation of a full store O(n); done at once they take tens of milliseconds at 20k points
// on this machine and seconds on a small onboard computer, and a stop command must never wait
// for them. So the tick that ends a run only sends its command and learns its last transition;
// the following ticks (the robot stands, repositioning) each do at most learn_updates_per_tick
// replay updates, then checkpoint_points_per_tick points of the save, and the next run starts
// when the work is done. The work is counted in updates and points, never in time, so a lockstep
// run stays a function of its inputs however loaded the machine is.
#include "loop_internal.h"
#include "fw/progress.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

// state_rotation: the executed rotation's scale [rad/s per scaled unit]. Wide (the whole range
// is about two units): it must tell a robot still ramping up its turn from one turning steadily,
// and must not split the few samples near a start pose into separate neighbourhoods. Chosen on
// seeds 11-20 (docs/LEARNING.md, "The executed rotation in the state"): against the state without
// it, 0.25 (the action's scale) cost the human-driven corridor 31 steps in the final block, 1.0
// cost 9, within the seeds' spread (on seeds 1-10 1.0 gained 15).
static const double kExecutedRotationScale = 1.0;

void fw_learning_config(const fw_loop_t* L, hedger_config_t* hc) {
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
  if (L->cfg.hedger_input_scale_n > 0) {
    for (int32_t i = 0; i < L->cfg.hedger_input_scale_n; ++i) {
      hc->input_scale[i] = L->cfg.hedger_input_scale[i];
    }
  } else {
    // The inputs are the task's features, then (state_rotation) the executed rotation, then the
    // action: the feature scales per task, the other two by position.
    const uint32_t features = L->ep.state_dim;
    double action_scale;
    if (fw_run_is_corridor(L)) {
      // One scaled unit is about the distance over which the value of an action changes
      // markedly. Along the corridor the value falls by 1 % per 6 cm of progress: a 1 m scale
      // keeps a neighbourhood within a few tenths of a metre, where the value is nearly linear in
      // the distance; the lateral position at half its useful range; the action's scale sets how
      // far apart two actions must be to count as different. The target angle is finer (0.125
      // rad, about a tenth of its range): a run that starts heading far off the axis is then
      // judged by runs that started at a similar heading, not by the on-axis majority (hedger.h,
      // "Greedy method"; the measurements: docs/LEARNING.md, "A finer target-angle scale, and
      // k_max 64").
      hc->input_scale[0] = 1.0;    // end distance [m]
      hc->input_scale[1] = 0.5;    // lateral fraction of the width
      hc->input_scale[2] = 0.125;  // target angle [rad]
      action_scale = 0.25;         // rotation [rad/s]
    } else {
      hc->input_scale[0] = 1.0;  // goal bearing [rad]
      hc->input_scale[1] = 1.0;  // goal distance [m]
      hc->input_scale[2] = 1.0;  // obstacle bearing [rad]
      hc->input_scale[3] = 1.0;  // obstacle distance [m]
      action_scale = 0.5;        // rotation [rad/s]
    }
    if (L->cfg.state_rotation) {
      hc->input_scale[features] = kExecutedRotationScale;  // executed rotation [rad/s]
    }
    hc->input_scale[L->state_dim] = action_scale;
  }
  hc->merge_radius = L->cfg.hedger_merge_radius;
  hc->greedy_coarse_actions = (uint32_t)L->cfg.hedger_greedy_actions;
  const uint32_t run_cap = fw_run_step_limit(L) + 8U;
  hc->run_capacity = run_cap > HEDGER_MAX_RUN ? HEDGER_MAX_RUN : run_cap;
  hc->replay = L->cfg.hedger_replay ? 1U : 0U;
  hc->replay_passes = (uint32_t)L->cfg.hedger_replay_passes;
  hc->replay_lambda = L->cfg.hedger_replay_lambda;
  hc->greedy_method = (uint32_t)L->cfg.hedger_greedy_method;
  hc->greedy_pessimism = L->cfg.hedger_greedy_pessimism;
  // The corridor's fine target-angle scale leaves a state's neighbourhood empty while phase one
  // has covered few headings; a wide second attempt answers there from runs at other headings
  // instead of holding course (Fig. 4, seeds 11-20: 227 steps after 5 runs against 512 at 3, the
  // same final block; hedger.h, "Greedy method"; docs/LEARNING.md, "greedy_reach 8 for the
  // corridor, 3 for the obstacles"). The obstacle task did not gain from it.
  const double task_reach = fw_run_is_corridor(L) ? 8.0 : 3.0;
  hc->greedy_reach = L->cfg.hedger_greedy_reach > 0.0 ? L->cfg.hedger_greedy_reach : task_reach;
  hc->local_model = L->cfg.learner == FW_LEARNER_LWA ? HEDGER_LOCAL_LWA : HEDGER_LOCAL_LWR;
}

// ---- checkpoints --------------------------------------------------------------------------

static size_t encode_meta(const fw_loop_t* L, uint8_t* p) {
  const fw_progress_t g = {
      .task = L->cfg.task, .state_dim = L->state_dim, .schedule = L->sched.p, .run_id = L->run_id};
  return fw_progress_encode(&g, p);
}

// Acquires a writer buffer and fills its meta section; false when none is free (counted).
static bool checkpoint_acquire(fw_loop_t* L, void** payload, size_t* payload_cap) {
  void* meta = NULL;
  size_t meta_cap = 0;
  L->save_handle = fw_ckpt_writer_acquire(L->out.checkpoints, &meta, &meta_cap, payload, payload_cap);
  if (L->save_handle < 0) {
    L->checkpoints_skipped++;
    fw_out_release_lines(L, true);  // this checkpoint will not be written: nothing to wait for
    return false;
  }
  L->save_meta_size = encode_meta(L, (uint8_t*)meta);
  return true;
}

static void checkpoint_submit(fw_loop_t* L, size_t payload_size) {
  fw_ckpt_writer_submit(L->out.checkpoints, L->save_handle, L->save_meta_size, payload_size);
  L->save_handle = -1;
  L->checkpoints_submitted++;
  if (L->lines_holding && L->lines_release_at == 0) {
    // Every submission ends written, failed or superseded: when the writer has settled as many
    // as were submitted, this one is on disk (or reported).
    L->lines_release_at = (uint64_t)L->checkpoints_submitted;
  }
}

void fw_learning_checkpoint_now(fw_loop_t* L) {
  if (L->out.checkpoints == NULL || L->learner.hedger == NULL) {
    return;
  }
  void* payload = NULL;
  size_t payload_cap = 0;
  if (!checkpoint_acquire(L, &payload, &payload_cap)) {
    return;
  }
  size_t written = 0;
  if (hedger_save(L->learner.hedger, payload, payload_cap, &written) != HEDGER_OK) {
    written = 0;  // never happens: the buffer is sized by hedger_serialized_max_size
  }
  checkpoint_submit(L, written);
}

void fw_loop_checkpoint_capacity(const fw_loop_t* L, size_t* meta_bytes, size_t* payload_bytes) {
  *meta_bytes = FW_PROGRESS_BYTES;
  *payload_bytes = L->learner.save_max;
}

void fw_loop_attach_checkpoints(fw_loop_t* L, fw_ckpt_writer_t* writer) { L->out.checkpoints = writer; }

int fw_loop_load_checkpoint(fw_loop_t* L, char* err, size_t err_cap) {
  const char* path = L->cfg.checkpoint_file;
  if (path[0] == '\0') {
    return 0;
  }
  if (L->learner.hedger == NULL) {
    snprintf(err, err_cap, "checkpoint %s: learner = tabular keeps no checkpoints; set checkpoint_file = \"\"", path);
    return -1;
  }
  size_t meta_size = 0;
  size_t payload_size = 0;
  int r = fw_checkpoint_peek(path, &meta_size, &payload_size, err, err_cap);
  if (r <= 0) {
    return r;
  }
  uint8_t meta[FW_PROGRESS_READ_MAX];
  // At most the largest learned state this configuration can hold, whatever the header claims:
  // fw_checkpoint_read refuses a larger (or corrupt) size with a message instead.
  const size_t payload_cap = payload_size < L->learner.save_max ? payload_size : L->learner.save_max;
  void* payload = malloc(payload_cap + 1U);
  if (payload == NULL) {
    snprintf(err, err_cap, "checkpoint %s: cannot allocate %zu bytes", path, payload_cap);
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
    snprintf(err, err_cap, "checkpoint %s is corrupt (controller section: %s); " FW_CHECKPOINT_FRESH_HINT, path, why,
             path, path);
    return -1;
  }
  const uint32_t dim_other_rotation = L->ep.state_dim + (L->cfg.state_rotation ? 0U : 1U);  // the other setting's
  if (g.task == L->cfg.task && g.state_dim == dim_other_rotation) {
    free(payload);
    snprintf(err, err_cap,
             "checkpoint %s was learned %s the executed rotation in the state; set state_rotation = %s to go on "
             "with it, or move the file away to start fresh (e.g. mv '%s' '%s.other')",
             path, L->cfg.state_rotation ? "without" : "with", L->cfg.state_rotation ? "false" : "true", path, path);
    return -1;
  }
  if (g.task != L->cfg.task || g.state_dim != L->state_dim) {
    free(payload);
    snprintf(err, err_cap,
             "checkpoint %s was learned for another task (%s); to start fresh, move the file away (e.g. mv '%s' "
             "'%s.other')",
             path, fw_task_name(g.task), path, path);
    return -1;
  }
  const hedger_status_t hs = hedger_load(L->learner.hedger, payload, payload_size);
  free(payload);
  if (hs != HEDGER_OK) {
    snprintf(err, err_cap,
             "checkpoint %s: the learned state was refused (%s; hedger_capacity, the task or the action limits may "
             "differ from when it was written); to start fresh, move the file away (e.g. mv '%s' '%s.bad')",
             path, hedger_status_str(hs), path, path);
    return -1;
  }
  const fw_schedule_config_t sc = L->sched.cfg;  // a copy: init clears the schedule first
  fw_schedule_init(&L->sched, &sc, &g.schedule);
  L->run_id = g.run_id;
  err[0] = '\0';
  if (g.legacy_shift) {
    snprintf(err, err_cap,
             "note: checkpoint %s was written by an older controller whose learned policy added a shift learned "
             "from ranked pairs of runs; this controller drives with the learned values alone, and its next "
             "checkpoint no longer holds the shift",
             path);
  }
  return 1;
}

// ---- the step's update and the between-run work -------------------------------------------

void fw_learning_run_ended(fw_loop_t* L) {
  L->end_run_pending = true;
  if (L->out.checkpoints != NULL && L->cfg.progress) {
    L->lines_holding = true;  // the run's line waits for its checkpoint
  }
}

bool fw_learning_idle(const fw_loop_t* L) {
  return !L->pending.active && !L->end_run_pending && L->learn_stage == FW_LEARN_IDLE;
}

// The pending transition: its update (training) or the prediction of its Q (for the message),
// then the experience message. Bounded: at most one greedy search and one update.
static void learn_pending(fw_loop_t* L) {
  fw_pending_step_t* p = &L->pending;
  double q = 0.0;
  hedger_kind_t kind = HEDGER_KIND_UNKNOWN;
  if (p->learning) {
    double q_next = 0.0;
    if (!p->terminal) {
      if (p->need_greedy) {
        (void)fw_learner_greedy(&L->learner, p->s_next, NULL, &q_next);
      } else {
        q_next = p->q_next;
      }
    }
    if (!fw_learner_learn(&L->learner, p->s, p->a, p->reward, p->s_next, p->terminal, q_next, &q, &kind)) {
      q = 0.0;
      kind = HEDGER_KIND_UNKNOWN;
    }
  } else if (!fw_learner_predict(&L->learner, p->s, p->a, &q, &kind)) {
    q = 0.0;
    kind = HEDGER_KIND_UNKNOWN;
  }
  fw_out_experience(L, p, q, kind);
  p->active = false;
}

// The save of a checkpoint in slices. Without a writer (or with both of its buffers busy) the
// same slices pass without writing, so that a lockstep run spends the same ticks between runs
// with and without checkpoints (its experience stream does not depend on them).
static void save_slice(fw_loop_t* L) {
  const uint32_t fill = fw_learner_stats(&L->learner).fill;
  const uint32_t per_tick = (uint32_t)L->cfg.checkpoint_points_per_tick;
  if (L->save_handle < 0 && L->save_points_done == 0 && L->out.checkpoints != NULL && L->learner.hedger != NULL) {
    if (checkpoint_acquire(L, &L->save_payload, &L->save_payload_cap) &&
        hedger_save_begin(L->learner.hedger, L->save_payload, L->save_payload_cap, &L->save_cursor) != HEDGER_OK) {
      L->save_handle = -1;  // never happens: the buffer is sized by hedger_serialized_max_size
    }
  }
  if (L->save_handle >= 0) {
    size_t written = 0;
    if (hedger_save_step(L->learner.hedger, &L->save_cursor, per_tick, &written) != HEDGER_OK) {
      // Nothing changes the learner between runs; should it happen, the save starts over.
      (void)hedger_save_begin(L->learner.hedger, L->save_payload, L->save_payload_cap, &L->save_cursor);
      L->save_points_done = 0;
      return;
    }
    if (L->save_cursor.done) {
      checkpoint_submit(L, written);
    }
  }
  L->save_points_done = fill - L->save_points_done > per_tick ? L->save_points_done + per_tick : fill;
  if (L->save_points_done >= fill) {
    L->save_points_done = 0;
    L->learn_stage = FW_LEARN_IDLE;
  }
}

// One slice of the between-run work: at most learn_updates_per_tick replay updates, then at most
// checkpoint_points_per_tick points of the save.
static void between_runs_slice(fw_loop_t* L) {
  if (L->end_run_pending) {
    L->end_run_pending = false;
    fw_learner_end_run_begin(&L->learner);
    L->learn_stage = FW_LEARN_REPLAY;
    L->save_points_done = 0;
    L->save_handle = -1;
  }
  if (L->learn_stage == FW_LEARN_IDLE) {
    return;
  }
  L->learn_ticks++;
  if (L->learn_stage == FW_LEARN_REPLAY) {
    if (fw_learner_end_run_step(&L->learner, (uint32_t)L->cfg.learn_updates_per_tick) > 0) {
      return;
    }
    L->learn_stage = FW_LEARN_SAVE;
  }
  save_slice(L);
}

void fw_learning_after_command(fw_loop_t* L) {
  if (L->pending.active) {
    learn_pending(L);
    if (!L->end_run_pending) {
      return;
    }
  }
  between_runs_slice(L);
}

void fw_learning_finish_now(fw_loop_t* L) {
  if (L->pending.active) {
    learn_pending(L);
  }
  if (L->end_run_pending) {
    L->end_run_pending = false;
    fw_learner_end_run_begin(&L->learner);
  }
  (void)fw_learner_end_run_step(&L->learner, UINT32_MAX);
  if (L->learn_stage == FW_LEARN_SAVE && L->save_handle >= 0) {
    // A slice-wise save was under way: finish it at once.
    size_t written = 0;
    if (hedger_save_step(L->learner.hedger, &L->save_cursor, UINT32_MAX, &written) == HEDGER_OK && L->save_cursor.done) {
      checkpoint_submit(L, written);
    }
  }
  L->save_points_done = 0;
  L->learn_stage = FW_LEARN_IDLE;
}
