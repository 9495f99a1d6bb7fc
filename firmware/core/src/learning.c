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
#define _POSIX_C_SOURCE 200809L  // O_CLOEXEC
#include "learning.h"
#include "outputs.h"
#include "fw/config_task.h"
#include "fw/journal.h"
#include "fw/progress.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

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
  // The journal record of one run: at most as many transitions as the learner's run buffer keeps
  // for the replay (a longer run waits for its checkpoint).
  learn_learner_config_t llc;
  learn_learner_config(&task, &lc, &llc);
  const uint32_t run_cap = llc.kind == LEARN_LEARNER_TABULAR ? llc.tabular.run_capacity : llc.hedger.run_capacity;
  L->jrec_cap = fw_journal_record_bytes(learn_agent_state_dim(L->agent), run_cap);
  L->jrec = (uint8_t*)malloc(L->jrec_cap);
  if (L->jrec == NULL) {
    snprintf(err, err_cap, "loop: cannot allocate %zu bytes for the journal record", L->jrec_cap);
    fw_learning_free(L);
    return -1;
  }
  return 0;
}

void fw_learning_free(fw_loop_t* L) {
  free(L->jrec);
  L->jrec = NULL;
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

// A learned state refused for its config (hedger_load's CONFIG_MISMATCH): when the setting that
// differs is one the user can give back, says which and its value, so that the file is kept and
// the session goes on with it. Returns true with err filled; false when no such setting explains
// it (the caller's general message then; a store larger than hedger_capacity never gets here:
// fw_checkpoint_read refuses it first). The discount per learned transition is gamma^N for
// decisions of N ticks, so a state learned with another decision_ticks is found by trying each.
// The input scales (hedger_input_scale, or the task's and the executed rotation's when it is
// empty) are given back as a list that reads back to the same bits: the stored points are in
// scaled units, so only the very scales they were written with find the same neighbours.
static bool explain_mismatch(const fw_loop_t* L, const char* path, const void* payload, size_t n, char* err,
                             size_t err_cap) {
  hedger_saved_t saved;
  if (hedger_saved_config(payload, n, &saved) != HEDGER_OK) {
    return false;
  }
  const hedger_config_t* now = hedger_get_config(hedger_of(L));
  if (saved.state_dim != now->state_dim || memcmp(&saved.action_min, &now->action_min, sizeof(double)) != 0 ||
      memcmp(&saved.action_max, &now->action_max, sizeof(double)) != 0) {
    return false;
  }
  if (memcmp(&saved.gamma, &now->gamma, sizeof(double)) == 0) {
    const uint32_t d = now->state_dim + 1U;
    if (memcmp(saved.input_scale, now->input_scale, sizeof(double) * d) == 0) {
      return false;
    }
    char then_s[HEDGER_MAX_INPUT_DIM * 26U], now_s[HEDGER_MAX_INPUT_DIM * 26U];
    if (fw_config_format_doubles(saved.input_scale, d, then_s, sizeof then_s) != 0 ||
        fw_config_format_doubles(now->input_scale, d, now_s, sizeof now_s) != 0) {
      return false;
    }
    snprintf(err, err_cap,
             "checkpoint %s was learned with the input scales %s (this configuration: %s); set hedger_input_scale "
             "= %s to go on with it, or move the file away to start fresh (e.g. mv '%s' '%s.other')",
             path, then_s, now_s, then_s, path, path);
    return true;
  }
  learn_task_t task;
  fw_config_learn_task(&L->cfg, &L->ep, &task);
  learn_config_t lc;
  fw_config_learn_settings(&L->cfg, &lc);
  for (int32_t ticks = 1; ticks <= FW_DECISION_TICKS_MAX; ++ticks) {
    lc.decision_ticks = (uint32_t)ticks;
    learn_learner_config_t other;
    learn_learner_config(&task, &lc, &other);
    if (memcmp(&other.hedger.gamma, &saved.gamma, sizeof(double)) == 0) {
      snprintf(err, err_cap,
               "checkpoint %s was learned with decision_ticks = %d (this configuration: %d); set decision_ticks = "
               "%d to go on with it, or move the file away to start fresh (e.g. mv '%s' '%s.other')",
               path, (int)ticks, (int)L->cfg.decision_ticks, (int)ticks, path, path);
      return true;
    }
  }
  snprintf(err, err_cap,
           "checkpoint %s was learned with a discount of %.17g per learned step (this configuration: %.17g); "
           "set gamma and decision_ticks as when it was written to go on with it, or move the file away to "
           "start fresh (e.g. mv '%s' '%s.other')",
           path, saved.gamma, now->gamma, path, path);
  return true;
}

// The actor (NULL with the greedy policy).
static actor_t* actor_of(const fw_loop_t* L) { return learn_get_actor(L->agent); }

static size_t encode_meta(const fw_loop_t* L, uint8_t* p) {
  const actor_t* actor = actor_of(L);
  const fw_progress_t g = {.task = L->cfg.task,
                           .state_dim = learn_agent_state_dim(L->agent),
                           .schedule = learn_schedule(L->agent)->p,
                           .run_id = learn_run_id(L->agent),
                           .policy = L->cfg.policy,
                           .actor_bytes = actor != NULL ? actor_serialized_size(actor) : 0U,
                           .selection = learn_selection_get(L->agent)};
  return fw_progress_encode(&g, p);
}

// Acquires a writer buffer and fills its meta section; false when none is free (counted).
static bool checkpoint_acquire(fw_loop_t* L, void** payload, size_t* payload_cap) {
  void* meta = NULL;
  size_t meta_cap = 0;
  L->save_handle = fw_ckpt_writer_acquire(L->out.checkpoints, &meta, &meta_cap, payload, payload_cap);
  if (L->save_handle < 0) {
    L->checkpoints_skipped++;  // the runs wait for their journal records or the next checkpoint
    return false;
  }
  L->save_meta_size = encode_meta(L, (uint8_t*)meta);
  return true;
}

// Saves happen between runs: the state and progress after the last run that started and ended.
static void checkpoint_submit(fw_loop_t* L, size_t payload_size) {
  fw_ckpt_writer_submit_run(L->out.checkpoints, L->save_handle, L->save_meta_size, payload_size,
                            learn_run_id(L->agent));
  L->save_handle = -1;
  L->checkpoints_submitted++;
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

void fw_loop_attach_checkpoints(fw_loop_t* L, fw_ckpt_writer_t* writer) {
  L->out.checkpoints = writer;
  L->reported_progress = learn_schedule(L->agent)->p;
  L->reports_wait = writer != NULL && hedger_of(L) != NULL;
  if (!L->reports_wait) {
    return;
  }
  // The runs so far are on disk: in the checkpoint, or in the part of the journal that load
  // learned again (kept; new records follow it).
  char err[FW_CHECKPOINT_ERR_MAX];
  if (fw_ckpt_writer_journal_init(writer, L->jrec_cap, 4U, learn_run_id(L->agent), L->journal_keep, err,
                                  sizeof err) != 0) {
    fw_loop_log(L, 2, "b21r-controller: %s; finished runs are reported once their checkpoint is written", err);
  }
}

static int load_checkpoint_file(fw_loop_t* L, char* err, size_t err_cap);

// Reads the journal beside the checkpoint (startup only; allocates its contents for the call).
// Returns the bytes read into *data (0: none or unreadable; *data NULL).
static size_t journal_read(const char* path, uint8_t** data) {
  *data = NULL;
  char jpath[FW_CONFIG_STR_MAX + 16];
  snprintf(jpath, sizeof jpath, "%s.journal", path);
  const int fd = open(jpath, O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    return 0;
  }
  struct stat st;
  size_t got = 0;
  if (fstat(fd, &st) == 0 && st.st_size > 0) {
    *data = (uint8_t*)malloc((size_t)st.st_size);
    while (*data != NULL && got < (size_t)st.st_size) {
      const ssize_t r = read(fd, *data + got, (size_t)st.st_size - got);
      if (r < 0 && errno == EINTR) {
        continue;
      }
      if (r <= 0) {
        break;
      }
      got += (size_t)r;
    }
  }
  close(fd);
  if (got == 0) {
    free(*data);
    *data = NULL;
  }
  return got;
}

// The journal's runs that follow the loaded progress (fw/journal.h), each learned and counted
// again as it was online: its transitions through the framework's offline update, its replay,
// then the schedule's count. Stops at the first record that does not follow (a torn write, a gap,
// another plan). Sets L->journal_keep to the bytes that hold the records up to the last one used.
// Returns the runs resumed. Startup only: O(records × (transitions + replay)).
static int journal_resume(fw_loop_t* L) {
  uint8_t* data = NULL;
  const size_t len = journal_read(L->cfg.checkpoint_file, &data);
  const uint32_t dim = learn_agent_state_dim(L->agent);
  size_t off = 0;
  int resumed = 0;
  L->journal_keep = 0;
  while (off < len) {
    fw_journal_run_t run;
    const uint8_t* tr = NULL;
    size_t size = 0;
    if (fw_journal_next(data + off, len - off, &run, &tr, &size) != 1) {
      break;
    }
    if (run.run_id <= learn_run_id(L->agent)) {
      off += size;  // in the checkpoint already (the process died before the journal was emptied)
      L->journal_keep = off;
      continue;
    }
    const learn_plan_t next = learn_plan(L->agent);
    const bool follows = run.run_id == learn_run_id(L->agent) + 1 && run.state_dim == dim && run.kind == next.kind &&
                         run.phase == next.phase &&
                         (next.kind != LEARN_RUN_EVAL || run.eval_index == next.eval_index) &&
                         (next.kind != LEARN_RUN_TRAINING || run.training_index == next.training_index);
    if (!follows || (run.learned && next.kind != LEARN_RUN_TRAINING)) {
      break;
    }
    if (run.learned) {
      for (uint32_t i = 0; i < run.n; ++i) {
        fw_journal_transition_t t;
        fw_journal_get_transition(tr, dim, i, &t);
        // A refused transition (a value not finite) was refused online too.
        (void)learn_offline_transition(L->agent, t.s, t.a, t.r, t.s_next, t.terminal, NULL);
      }
      (void)learn_offline_end_run(L->agent);
    }
    const learn_plan_t plan = {.kind = run.kind, .phase = run.phase, .eval_index = run.eval_index,
                               .training_index = run.training_index};
    if (!learn_resume_run(L->agent, &plan, run.steps, run.goal, run.aborted, NULL)) {
      break;  // never happens: the plan was checked above
    }
    off += size;
    L->journal_keep = off;
    resumed++;
  }
  free(data);
  return resumed;
}

int fw_loop_load_checkpoint(fw_loop_t* L, char* err, size_t err_cap) {
  const char* path = L->cfg.checkpoint_file;
  if (path[0] == '\0') {
    return 0;
  }
  const int r = load_checkpoint_file(L, err, err_cap);
  if (r < 0 || hedger_of(L) == NULL) {
    return r;
  }
  if (r == 0) {
    err[0] = '\0';
  }
  const int runs = journal_resume(L);
  if (runs > 0) {
    const size_t used = strlen(err);
    snprintf(err + used, err_cap - used,
             "%snote: %d finished run%s after the checkpoint learned again from %s.journal (up to run %d)",
             used > 0 ? "; " : "", runs, runs == 1 ? "" : "s", path, (int)learn_run_id(L->agent));
  }
  return r == 1 || runs > 0 ? 1 : 0;
}

// The checkpoint file itself: 1 loaded, 0 none, -1 refused (err says why).
static int load_checkpoint_file(fw_loop_t* L, char* err, size_t err_cap) {
  const char* path = L->cfg.checkpoint_file;
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
  if (hs == HEDGER_ERR_CONFIG_MISMATCH && explain_mismatch(L, path, payload, hedger_bytes, err, err_cap)) {
    free(payload);
    return -1;
  }
  if (hs != HEDGER_OK) {
    free(payload);
    snprintf(err, err_cap,
             "checkpoint %s: the learned state was refused (%s; hedger_capacity, gamma, decision_ticks, the task or "
             "the action limits may differ from when it was written); to start fresh, move the file away (e.g. mv '%s' '%s.bad')",
             path, hedger_status_str(hs), path, path);
    return -1;
  }
  actor_t* actor = actor_of(L);
  char note[FW_CHECKPOINT_ERR_MAX] = "";
  if (actor != NULL && g.actor_bytes > 0U) {
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
  } else if (g.actor_bytes > 0U) {
    snprintf(note, sizeof note,
             "note: checkpoint %s also holds an actor (policy = %s); with policy = greedy the values' greedy "
             "action drives and the next checkpoint no longer holds the actor (keep a copy of the file to go back)",
             path, g.policy == LEARN_POLICY_SELECT ? "select" : "actor");
  }
  free(payload);
  learn_resume(L->agent, &g.schedule, g.run_id);
  if (g.policy == LEARN_POLICY_SELECT) {
    (void)learn_resume_selection(L->agent, &g.selection);  // false (ignored) unless policy = select now
  }
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

void fw_learning_run_ended(fw_loop_t* L, const learn_run_end_t* e) {
  if (!L->reports_wait) {
    return;
  }
  // The run's reports (B21R_RUN, its progress line, the evaluation block it completes) wait until
  // its journal record, submitted after this tick's update (journal_end), or a checkpoint is on disk.
  L->held_run = e->run_id;
  L->jrun = (fw_journal_run_t){.run_id = e->run_id,
                               .kind = e->plan.kind,
                               .phase = e->plan.phase,
                               .training_index = e->plan.training_index,
                               .eval_index = e->plan.eval_index,
                               .steps = e->steps,
                               .goal = e->goal,
                               .aborted = e->aborted,
                               .learned = e->learning,
                               .state_dim = learn_agent_state_dim(L->agent)};
  L->jend_pending = true;
}

// A learned transition of the run under way, into its journal record. O(state_dim).
static void journal_transition(fw_loop_t* L, const learn_experience_t* e) {
  if (!L->reports_wait || e->evaluating || L->jfull) {
    return;
  }
  fw_journal_transition_t t;
  memset(&t, 0, sizeof t);
  memcpy(t.s, e->s, e->state_dim * sizeof(double));
  memcpy(t.s_next, e->s_next, e->state_dim * sizeof(double));
  t.a = e->a;
  t.r = e->reward;
  t.terminal = e->terminal;
  if (fw_journal_put_transition(L->jrec, L->jrec_cap, e->state_dim, L->jn, &t)) {
    L->jn++;
  } else {
    L->jfull = true;  // never expected: the record holds as many as the learner's run buffer
  }
}

// The run that ended this tick, its last update done: its record goes to the writer, which appends
// and syncs it before the run counts as durable. Bounded: a CRC and a copy of the record.
static void journal_end(fw_loop_t* L) {
  if (!L->jend_pending) {
    return;
  }
  L->jend_pending = false;
  L->jrun.n = L->jrun.learned ? L->jn : 0U;
  const size_t n = L->jfull ? 0U : fw_journal_finish(L->jrec, L->jrec_cap, &L->jrun);
  // A record that cannot be written (n == 0) is handed over as too large: the writer counts it
  // skipped, and the run becomes durable with the checkpoint that covers it.
  (void)fw_ckpt_writer_journal_submit(L->out.checkpoints, L->jrec, n > 0U ? n : SIZE_MAX, L->jrun.run_id);
  L->jn = 0;
  L->jfull = false;
}

bool fw_learning_idle(const fw_loop_t* L) { return learn_idle(L->agent) && L->learn_stage == FW_LEARN_IDLE; }

// The queued transition's update (training) or the prediction of its Q (for the message), then
// the experience message. Bounded: at most one greedy search and one update.
static bool learn_pending(fw_loop_t* L) {
  learn_experience_t e;
  if (!learn_update(L->agent, &e)) {
    return false;
  }
  journal_transition(L, &e);
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
  const bool updated = learn_pending(L);
  journal_end(L);
  if (updated && !learn_between_runs_due(L->agent)) {
    return;
  }
  between_runs_slice(L);
}

void fw_learning_finish_now(fw_loop_t* L) {
  learn_experience_t e;
  if (learn_update(L->agent, &e)) {
    journal_transition(L, &e);
    fw_out_experience(L, &e);
  }
  journal_end(L);
  (void)learn_finish_now(L->agent, &e);  // the replay (the queued update is done)
  if (L->learn_stage == FW_LEARN_SAVE && L->save_handle >= 0) {
    // A slice-wise save was under way: finish it at once.
    (void)save_step(L, UINT32_MAX);
  }
  L->save_points_done = 0;
  L->learn_stage = FW_LEARN_IDLE;
}
