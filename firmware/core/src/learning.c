// SPDX-License-Identifier: MIT
// The learning framework (lib/learn) inside the loop: its set-up from the configuration and the
// task, the update of each step (after the tick's command went out), the between-run work (the
// framework's backward replay, then the checkpoint) in bounded slices, and the checkpoint's
// controller section.
//
// Why slices: the replay of a finished run costs replay_passes × run length updates, and the
// serialisation of a full store O(n); done at once they take tens of milliseconds at 20k points
// on this machine and seconds on a small onboard computer, and a stop command must never wait
// for them. So the tick that ends a run only sends its command and learns its last transition;
// the following ticks (the robot stands, repositioning) each do at most learn_updates_per_tick
// replay updates, then checkpoint_points_per_tick points of the save, and the next run starts
// when the work is done. The work is counted in updates and points, never in time, so a lockstep
// run stays a function of its inputs however loaded the machine is.
#include "learning.h"
#include "outputs.h"
#include "fw/config_task.h"
#include "fw/progress.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int fw_learning_init(fw_loop_t* L, char* err, size_t err_cap) {
  learn_task_t task;
  fw_config_learn_task(&L->cfg, &L->ep, &task);
  learn_config_t lc;
  fw_config_learn_settings(&L->cfg, &lc);
  const size_t bytes = learn_storage_size(&task, &lc);
  if (bytes == 0) {
    char why[LEARN_ERR_MAX];
    (void)learn_init(NULL, 0, &task, &lc, why, sizeof why);
    snprintf(err, err_cap, "loop: %s", why);
    return -1;
  }
  L->agent_storage = aligned_alloc(LEARN_STORAGE_ALIGN, bytes);
  if (L->agent_storage == NULL) {
    snprintf(err, err_cap, "loop: cannot allocate %zu bytes for the learner (%d samples)", bytes,
             (int)L->cfg.hedger_capacity);
    return -1;
  }
  L->agent_bytes = bytes;
  char why[LEARN_ERR_MAX];
  L->agent = learn_init(L->agent_storage, bytes, &task, &lc, why, sizeof why);
  if (L->agent == NULL) {
    snprintf(err, err_cap, "loop: %s", why);
    fw_learning_free(L);
    return -1;
  }
  const hedger_t* h = learn_get_learner(L->agent)->hedger;
  const actor_t* actor = learn_get_actor_const(L->agent);
  L->save_max = h != NULL ? hedger_serialized_max_size(hedger_get_config(h)) : 0U;
  if (h != NULL && actor != NULL) {
    L->save_max += actor_serialized_max_size(actor_get_config(actor));
  }
  return 0;
}

void fw_learning_free(fw_loop_t* L) {
  free(L->agent_storage);
  L->agent_storage = NULL;
  L->agent = NULL;
  L->agent_bytes = 0;
}

// ---- checkpoints --------------------------------------------------------------------------
//
// The payload is HEDGER's save followed, with the actor policy, by the actor's (fw/progress.h).

// HEDGER's instance (NULL for the tabular learner, which keeps no checkpoints).
static hedger_t* hedger_of(const fw_loop_t* L) { return learn_get_learner(L->agent)->hedger; }

// The actor (NULL with the greedy policy).
static actor_t* actor_of(const fw_loop_t* L) { return learn_get_actor(L->agent); }

static size_t encode_meta(const fw_loop_t* L, uint8_t* p) {
  const actor_t* actor = actor_of(L);
  const fw_progress_t g = {.task = L->cfg.task,
                           .state_dim = learn_agent_state_dim(L->agent),
                           .schedule = learn_schedule(L->agent)->p,
                           .run_id = learn_run_id(L->agent),
                           .policy = actor != NULL ? LEARN_POLICY_ACTOR : LEARN_POLICY_GREEDY,
                           .actor_bytes = actor != NULL ? actor_serialized_size(actor) : 0U};
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
  if (L->out.checkpoints == NULL || hedger_of(L) == NULL) {
    return;
  }
  if (learn_between_runs_busy(L->agent)) {
    // The actor cannot be saved half-learned (fw_learning_finish_now completes it first).
    L->checkpoints_skipped++;
    return;
  }
  void* payload = NULL;
  size_t payload_cap = 0;
  if (!checkpoint_acquire(L, &payload, &payload_cap)) {
    return;
  }
  // Never fails: the buffer is sized by the largest saves, and nothing is under way.
  size_t written = 0;
  if (hedger_save(hedger_of(L), payload, payload_cap, &written) != HEDGER_OK) {
    written = 0;
  }
  size_t actor_written = 0;
  if (actor_of(L) != NULL &&
      actor_save(actor_of(L), (uint8_t*)payload + written, payload_cap - written, &actor_written) != ACTOR_OK) {
    actor_written = 0;
  }
  checkpoint_submit(L, written + actor_written);
}

void fw_loop_checkpoint_capacity(const fw_loop_t* L, size_t* meta_bytes, size_t* payload_bytes) {
  *meta_bytes = FW_PROGRESS_BYTES;
  *payload_bytes = L->save_max;
}

void fw_loop_attach_checkpoints(fw_loop_t* L, fw_ckpt_writer_t* writer) { L->out.checkpoints = writer; }

int fw_loop_load_checkpoint(fw_loop_t* L, char* err, size_t err_cap) {
  const char* path = L->cfg.checkpoint_file;
  if (path[0] == '\0') {
    return 0;
  }
  if (hedger_of(L) == NULL) {
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
  const size_t payload_cap = payload_size < L->save_max ? payload_size : L->save_max;
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
  if (g.task != L->cfg.task || g.state_dim != learn_agent_state_dim(L->agent)) {
    free(payload);
    snprintf(err, err_cap,
             "checkpoint %s was learned for another task (%s); to start fresh, move the file away (e.g. mv '%s' "
             "'%s.other')",
             path, fw_task_name(g.task), path, path);
    return -1;
  }
  if (g.actor_bytes > payload_size) {
    free(payload);
    snprintf(err, err_cap, "checkpoint %s is corrupt (an actor section of %llu bytes in a payload of %zu); "
             FW_CHECKPOINT_FRESH_HINT, path, (unsigned long long)g.actor_bytes, payload_size, path, path);
    return -1;
  }
  // On a refusal from here on the learner is not used: the caller stops (the controller exits).
  const size_t hedger_bytes = payload_size - (size_t)g.actor_bytes;
  const hedger_status_t hs = hedger_load(hedger_of(L), payload, hedger_bytes);
  if (hs != HEDGER_OK) {
    free(payload);
    snprintf(err, err_cap,
             "checkpoint %s: the learned state was refused (%s; hedger_capacity, the task or the action limits may "
             "differ from when it was written); to start fresh, move the file away (e.g. mv '%s' '%s.bad')",
             path, hedger_status_str(hs), path, path);
    return -1;
  }
  actor_t* actor = actor_of(L);
  char note[FW_CHECKPOINT_ERR_MAX] = "";
  if (actor != NULL && g.policy == LEARN_POLICY_ACTOR) {
    const actor_status_t as = actor_load(actor, (const uint8_t*)payload + hedger_bytes, (size_t)g.actor_bytes);
    if (as != ACTOR_OK) {
      free(payload);
      snprintf(err, err_cap,
               "checkpoint %s: the actor's learned state was refused (%s; actor_hidden, actor_capacity, the task, "
               "hedger_input_scale or the action limits may differ from when it was written); set them as they "
               "were, or move the file away to start fresh (e.g. mv '%s' '%s.bad')",
               path, actor_status_str(as), path, path);
      return -1;
    }
  } else if (actor != NULL) {
    const uint32_t cloned = learn_actor_from_values(L->agent);
    snprintf(note, sizeof note,
             "note: checkpoint %s holds no actor (written with policy = greedy or by an older controller): its "
             "values are kept and the actor starts as the policy of their %u stored points (behaviour cloning); "
             "it learns from the rewards from the next run on",
             path, cloned);
  } else if (g.policy == LEARN_POLICY_ACTOR) {
    snprintf(note, sizeof note,
             "note: checkpoint %s also holds an actor (policy = actor); with policy = greedy the values' greedy "
             "action drives and the next checkpoint no longer holds the actor (keep a copy of the file to go back)",
             path);
  }
  free(payload);
  learn_resume(L->agent, &g.schedule, g.run_id);
  err[0] = '\0';
  if (g.legacy_shift) {
    snprintf(err, err_cap,
             "note: checkpoint %s was written by an older controller whose learned policy added a shift learned "
             "from ranked pairs of runs; this controller drives with the learned values alone, and its next "
             "checkpoint no longer holds the shift%s%s",
             path, note[0] != '\0' ? "; " : "", note[0] != '\0' ? note + 6 : "");
  } else if (note[0] != '\0') {
    snprintf(err, err_cap, "%s", note);
  }
  return 1;
}

// ---- the step's update and the between-run work -------------------------------------------

void fw_learning_run_ended(fw_loop_t* L) {
  if (L->out.checkpoints != NULL && L->cfg.progress) {
    L->lines_holding = true;  // the run's line waits for its checkpoint
  }
}

bool fw_learning_idle(const fw_loop_t* L) { return learn_idle(L->agent) && L->learn_stage == FW_LEARN_IDLE; }

// The queued transition's update (training) or the prediction of its Q (for the message), then
// the experience message. Bounded: at most one greedy search and one update.
static bool learn_pending(fw_loop_t* L) {
  learn_experience_t e;
  if (!learn_update(L->agent, &e)) {
    return false;
  }
  fw_out_experience(L, &e);
  return true;
}

// Starts (or restarts) the sliced save into the acquired buffer: HEDGER's first.
static void save_begin(fw_loop_t* L) {
  L->save_actor_started = false;
  if (hedger_save_begin(hedger_of(L), L->save_payload, L->save_payload_cap, &L->save_cursor) != HEDGER_OK) {
    L->save_handle = -1;  // never happens: the buffer is sized by the largest saves
  }
}

// One slice of the save: at most `items` of HEDGER's points, then of the actor's entries.
// Returns false when the learned state changed since the save began (it then starts over).
static bool save_step(fw_loop_t* L, uint32_t items) {
  if (!L->save_cursor.done) {
    const uint32_t before = L->save_cursor.next_point;
    if (hedger_save_step(hedger_of(L), &L->save_cursor, items, NULL) != HEDGER_OK) {
      return false;
    }
    items -= L->save_cursor.next_point - before;
    if (!L->save_cursor.done) {
      return true;
    }
  }
  actor_t* actor = actor_of(L);
  if (actor == NULL) {
    checkpoint_submit(L, L->save_cursor.size);
    return true;
  }
  if (!L->save_actor_started) {
    if (actor_save_begin(actor, (uint8_t*)L->save_payload + L->save_cursor.size,
                         L->save_payload_cap - L->save_cursor.size, &L->save_actor_cursor) != ACTOR_OK) {
      return false;
    }
    L->save_actor_started = true;
  }
  if (actor_save_step(actor, &L->save_actor_cursor, items, NULL) != ACTOR_OK) {
    return false;
  }
  if (L->save_actor_cursor.done) {
    checkpoint_submit(L, L->save_cursor.size + L->save_actor_cursor.size);
  }
  return true;
}

// Items of the save: HEDGER's stored points, then the actor's recorded transitions.
static uint32_t save_items(const fw_loop_t* L) {
  const actor_t* actor = learn_get_actor_const(L->agent);
  return learn_learner_stats(learn_get_learner(L->agent)).fill +
         (actor != NULL ? actor_counters(actor)->fill : 0U);
}

// The save of a checkpoint in slices of checkpoint_points_per_tick items. Without a writer (or with
// both of its buffers busy) the same slices pass without writing, so that a lockstep run spends
// the same ticks between runs with and without checkpoints (its experience stream does not depend
// on them).
static void save_slice(fw_loop_t* L) {
  const uint32_t items = save_items(L);
  const uint32_t per_tick = (uint32_t)L->cfg.checkpoint_points_per_tick;
  if (L->save_handle < 0 && L->save_points_done == 0 && L->out.checkpoints != NULL && hedger_of(L) != NULL) {
    if (checkpoint_acquire(L, &L->save_payload, &L->save_payload_cap)) {
      save_begin(L);
    }
  }
  if (L->save_handle >= 0 && !save_step(L, per_tick)) {
    // Nothing changes the learner between runs; should it happen, the save starts over.
    save_begin(L);
    L->save_points_done = 0;
    return;
  }
  L->save_points_done = items - L->save_points_done > per_tick ? L->save_points_done + per_tick : items;
  if (L->save_points_done >= items) {
    L->save_points_done = 0;
    L->learn_stage = FW_LEARN_IDLE;
  }
}

// One slice of the between-run work: at most learn_updates_per_tick replay updates (the
// framework's), then at most checkpoint_points_per_tick points of the save.
static void between_runs_slice(fw_loop_t* L) {
  if (learn_between_runs_due(L->agent)) {
    L->learn_stage = FW_LEARN_REPLAY;
    L->save_points_done = 0;
    L->save_handle = -1;
  }
  if (L->learn_stage == FW_LEARN_IDLE) {
    return;
  }
  L->learn_ticks++;
  if (L->learn_stage == FW_LEARN_REPLAY) {
    if (learn_between_runs_slice(L->agent, (uint32_t)L->cfg.learn_updates_per_tick) > 0) {
      return;
    }
    L->learn_stage = FW_LEARN_SAVE;
  }
  save_slice(L);
}

void fw_learning_after_command(fw_loop_t* L) {
  if (learn_pending(L) && !learn_between_runs_due(L->agent)) {
    return;
  }
  between_runs_slice(L);
}

void fw_learning_finish_now(fw_loop_t* L) {
  learn_experience_t e;
  if (learn_finish_now(L->agent, &e)) {
    fw_out_experience(L, &e);
  }
  if (L->learn_stage == FW_LEARN_SAVE && L->save_handle >= 0) {
    // A slice-wise save was under way: finish it at once.
    (void)save_step(L, UINT32_MAX);
  }
  L->save_points_done = 0;
  L->learn_stage = FW_LEARN_IDLE;
}
