// SPDX-License-Identifier: MIT
// Kind `learn`: the controller's loop core and the ODE emulator in one process. The loop runs
// exactly as on the robot (same config, same schedule, same learner); the runner only reads
// what the loop publishes (experiences, evaluation blocks) and its counters between ticks.
#define _POSIX_C_SOURCE 200809L
#include "experiment.h"

#include <fw/config_task.h>
#include "fw/errfmt.h"
#include "fw/loop.h"
#include "fw/publisher.h"
#include "fw/pubq.h"
#include "inproc_sim.h"

#include <sim/task_worlds.h>
#include <tasks/tasks.h>

#include <stdlib.h>
#include <string.h>
#include <time.h>

// Sources of an executed action, indexed by b21r_experience_t SOURCE_* (0..4).
#define N_SOURCES 5
static const char* const k_source_names[N_SOURCES] = {"example", "joystick", "greedy", "exploration", "advisor"};

typedef enum outcome { OUT_GOAL = 0, OUT_COLLISION = 1, OUT_STEP_LIMIT = 2, OUT_ABORTED = 3 } outcome_t;
static const char* const k_outcome_names[] = {"goal", "collision", "step_limit", "aborted"};

typedef struct run_rec {
  int32_t run_id;
  bool eval;
  int32_t phase;
  int32_t block;           // evaluation runs: the block they belong to
  int32_t training_index;  // training runs: 0, 1, ... (completed runs only)
  int32_t steps;
  int32_t outcome;
  double ret;              // the run's rewards summed, undiscounted (its B21R_RUN record's once it came)
  bool recorded;           // the run's end record came: ret is the controller's total_reward
  bool last_terminal;
  int64_t sources[N_SOURCES];
  uint32_t store_fill;     // after the run (and its backward replay)
} run_rec_t;

typedef struct block_rec {
  learn_eval_block_t b;
  uint32_t store_fill;
  int64_t training_steps;  // training steps driven before the block
} block_rec_t;

// Everything one loop session produced.
typedef struct session {
  run_rec_t* runs;
  size_t n_runs;
  size_t cap_runs;
  block_rec_t* blocks;
  size_t n_blocks;
  size_t cap_blocks;
  bool have_current;
  int32_t training_done;
  int64_t training_steps;
  int64_t training_steps_by_phase_source[2][N_SOURCES];
  int64_t eval_steps;
  uint64_t phase_one_digest;  // FNV-1a over the phase-one training transitions (s, a, r, s', terminal)
  int64_t phase_one_transitions;
  fw_loop_stats_t final;
  int64_t ticks;
  double wall_s;
} session_t;

static void* grow(void* p, size_t* cap, size_t need, size_t elem) {
  if (need <= *cap) {
    return p;
  }
  const size_t n = *cap == 0 ? 64 : *cap * 2;
  void* q = realloc(p, n * elem);
  if (q == NULL) {
    fprintf(stderr, "b21r-experiment: out of memory\n");
    exit(1);
  }
  *cap = n;
  return q;
}

static void digest_bytes(uint64_t* h, const void* data, size_t n) {
  const unsigned char* p = (const unsigned char*)data;
  for (size_t i = 0; i < n; ++i) {
    *h = (*h ^ p[i]) * 1099511628211ULL;
  }
}

static void take_experience(session_t* S, const b21r_experience_t* e) {
  if (!S->have_current || S->runs[S->n_runs - 1].run_id != e->run_id) {
    S->runs = grow(S->runs, &S->cap_runs, S->n_runs + 1, sizeof *S->runs);
    run_rec_t* r = &S->runs[S->n_runs++];
    memset(r, 0, sizeof *r);
    r->run_id = e->run_id;
    r->eval = e->evaluating != 0;
    r->phase = e->phase;
    r->block = r->eval ? (int32_t)S->n_blocks : -1;
    r->training_index = -1;
    r->outcome = OUT_ABORTED;
    S->have_current = true;
  }
  run_rec_t* r = &S->runs[S->n_runs - 1];
  // Steps are control ticks, the same count as the reference learners' environment steps: an
  // experience covers the ticks since the run's previous one (one tick, or with decision_ticks = N
  // a decision's N ticks, fewer where the run ends inside a decision).
  const int64_t since = (int64_t)e->step_id + 1 - r->steps;
  const int64_t ticks = since > 0 ? since : 0;
  r->steps = e->step_id + 1;
  if (!r->recorded) {
    // Until the end record: with decisions over several ticks an experience's reward is its
    // ticks' rewards discounted within the decision, so this sum is exact only at one tick each.
    r->ret += e->reward;
  }
  r->last_terminal = e->terminal != 0;
  const int src = e->source >= 0 && e->source < N_SOURCES ? e->source : 0;
  r->sources[src] += ticks;
  if (r->eval) {
    S->eval_steps += ticks;
  } else {
    S->training_steps += ticks;
    S->training_steps_by_phase_source[e->phase == 2 ? 1 : 0][src] += ticks;
    if (e->phase == 1) {
      // The phase-one data: identical across learner variants for the same seed (the learner does
      // not act in phase one), which the report checks to call a comparison "same data".
      const int n = e->state_dim > 0 && e->state_dim <= 8 ? e->state_dim : 0;
      digest_bytes(&S->phase_one_digest, e->s, (size_t)n * sizeof(double));
      digest_bytes(&S->phase_one_digest, &e->action_radps, sizeof e->action_radps);
      digest_bytes(&S->phase_one_digest, &e->reward, sizeof e->reward);
      digest_bytes(&S->phase_one_digest, e->s_next, (size_t)n * sizeof(double));
      digest_bytes(&S->phase_one_digest, &e->terminal, sizeof e->terminal);
      S->phase_one_transitions++;
    }
  }
}

// A run's end record (B21R_RUN): its undiscounted return, whatever the decisions' spacing.
static void take_run_record(session_t* S, const b21r_run_t* m) {
  for (size_t i = S->n_runs; i-- > 0;) {
    if (S->runs[i].run_id == m->run_id) {
      S->runs[i].ret = m->total_reward;
      S->runs[i].recorded = true;
      return;
    }
  }
}

// After a tick: a run that ended gets its outcome from the loop's counters.
static void take_run_end(session_t* S, const fw_loop_stats_t* before, const fw_loop_stats_t* after) {
  if (!S->have_current) {
    return;
  }
  run_rec_t* r = &S->runs[S->n_runs - 1];
  if (after->runs_finished > before->runs_finished) {
    r->outcome = after->last_run_goal ? OUT_GOAL : (r->last_terminal ? OUT_COLLISION : OUT_STEP_LIMIT);
  } else if (after->runs_aborted > before->runs_aborted) {
    r->outcome = OUT_ABORTED;
  } else {
    return;
  }
  r->store_fill = after->store_fill;
  if (!r->eval && r->outcome != OUT_ABORTED) {
    r->training_index = S->training_done++;
  }
  S->have_current = false;
}

// Copies every experience into the publisher's queue (event log), waiting when it is full:
// the runner may wait, the loop's tick has already ended.
static void tee_experience(fw_pubq_t* q, fw_publisher_t* pub, const fw_msg_t* m) {
  fw_msg_t* slot;
  while ((slot = fw_pubq_reserve(q, FW_MSG_EXPERIENCE)) == NULL) {
    fw_publisher_notify(pub);
    fw_publisher_flush(pub);
  }
  slot->u.experience = m->u.experience;
  fw_pubq_commit(q);
  fw_publisher_notify(pub);
}

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static uint32_t step_limit_of(const fw_config_t* cfg) {
  static tasks_episode_t ep;
  char err[FW_CONFIG_ERR_MAX];
  return fw_config_task(cfg, &ep, NULL, err, sizeof err) == 0 ? tasks_episode_step_limit(&ep) : 1000U;
}

// Upper bound on the ticks of a schedule (every run at its step limit, generous repositioning):
// a loop that has not finished by then is reported as stuck instead of running forever.
static int64_t tick_budget(const fw_config_t* cfg) {
  const int64_t training = cfg->mode == FW_MODE_EVALUATE ? 0 : cfg->phase_one_runs + cfg->phase_two_runs;
  const int64_t blocks = cfg->mode == FW_MODE_EVALUATE ? 1 : training / cfg->eval_every_runs + 2;
  const int64_t runs = training + blocks * cfg->eval_starts;
  return (runs + 10) * ((int64_t)step_limit_of(cfg) + 100) * 2;
}

typedef struct session_io {
  const sim_world_t* world;
  uint64_t sim_seed;
  const char* experience_log;
  const char* trace_svg;
  bool verbose;
} session_io_t;

// Runs one loop session (a learning schedule or one reference evaluation) to its end.
static int run_session(const fw_config_t* cfg, const session_io_t* sio, session_t* S, char* err, size_t err_cap) {
  memset(S, 0, sizeof *S);
  S->phase_one_digest = 1469598103934665603ULL;
  static inproc_sim_t sim;  // large; one session at a time
  const inproc_sim_options_t opt = {.canopen = cfg->base_protocol == FW_BASE_CANOPEN,
                                    .seed = sio->sim_seed,
                                    .trace_capacity = sio->trace_svg != NULL ? (size_t)tick_budget(cfg) : 16,
                                    .alloc_probe = NULL};
  if (inproc_sim_open(&sim, sio->world, &opt, err, err_cap) != 0) {
    return -1;
  }
  fw_pubq_t* q = fw_pubq_create((uint32_t)cfg->queue_capacity);
  fw_pubq_t* log_q = NULL;
  fw_publisher_t* pub = NULL;
  if (sio->experience_log != NULL) {
    log_q = fw_pubq_create(4096);
    const fw_publisher_config_t pc = {.lcm = NULL, .log_file = NULL, .experience_log_file = sio->experience_log};
    pub = log_q != NULL ? fw_publisher_create(log_q, &pc, err, err_cap) : NULL;
    if (pub == NULL) {
      fw_pubq_destroy(log_q);
      fw_pubq_destroy(q);
      inproc_sim_close(&sim);
      return -1;
    }
  }
  const fw_io_t io = inproc_sim_io(&sim);
  const fw_loop_outputs_t out = {.queue = q, .notify = NULL, .notify_user = NULL, .checkpoints = NULL};
  fw_loop_t* loop = q != NULL ? fw_loop_create(cfg, &io, &out, err, err_cap) : NULL;
  int rc = -1;
  if (loop == NULL) {
    if (q == NULL) {
      fw_errfmt(err, err_cap, "out of memory");
    }
  } else if (fw_loop_start(loop, err, err_cap) == 0) {
    const double t0 = now_s();
    const int64_t budget = tick_budget(cfg);
    fw_loop_stats_t before;
    fw_loop_get_stats(loop, &before);
    bool more = true;
    while (more && S->ticks < budget) {
      const int64_t t = fw_loop_wait(loop);
      more = fw_loop_tick(loop, t);
      S->ticks++;
      const fw_msg_t* m;
      while ((m = fw_pubq_peek(q)) != NULL) {
        if (m->kind == FW_MSG_EXPERIENCE) {
          take_experience(S, &m->u.experience);
          if (pub != NULL) {
            tee_experience(log_q, pub, m);
          }
        } else if (m->kind == FW_MSG_EVAL) {
          fw_loop_stats_t now;
          fw_loop_get_stats(loop, &now);
          S->blocks = grow(S->blocks, &S->cap_blocks, S->n_blocks + 1, sizeof *S->blocks);
          block_rec_t* b = &S->blocks[S->n_blocks++];
          memset(b, 0, sizeof *b);
          const b21r_eval_t* e = &m->u.eval;
          b->b.block = e->block;
          b->b.training_runs = e->training_runs;
          b->b.phase = e->phase;
          b->b.n_starts = e->n_starts;
          for (int32_t i = 0; i < e->n_starts && i < LEARN_SCHEDULE_MAX_STARTS; ++i) {
            b->b.steps[i] = e->steps[i];
            b->b.success[i] = e->success[i] != 0;
          }
          b->b.successes = e->successes;
          b->store_fill = now.store_fill;
          b->training_steps = S->training_steps;
        } else if (m->kind == FW_MSG_RUN) {
          take_run_record(S, &m->u.run);
        } else if (m->kind == FW_MSG_TEXT && sio->verbose) {
          fprintf(stderr, "%s\n", m->u.text.line);
        }
        fw_pubq_pop(q);
      }
      fw_loop_stats_t after;
      fw_loop_get_stats(loop, &after);
      take_run_end(S, &before, &after);
      before = after;
    }
    S->wall_s = now_s() - t0;
    fw_loop_get_stats(loop, &S->final);
    if (more) {
      fw_errfmt(err, err_cap, "the schedule did not end within %lld ticks (%d runs finished, %d aborted, %lld safety stops)",
          (long long)budget, S->final.runs_finished, S->final.runs_aborted, (long long)S->final.safety_stops);
    } else if (S->final.experiences_dropped > 0 || fw_pubq_drops(q, -1) > 0) {
      fw_errfmt(err, err_cap, "the loop's queue dropped %llu messages: results would be incomplete",
          (unsigned long long)fw_pubq_drops(q, -1));
    } else {
      rc = 0;
    }
    if (rc == 0 && sio->trace_svg != NULL && sim_emu_write_svg(sim.emu, sio->trace_svg) != 0) {
      fw_errfmt(err, err_cap, "%s: cannot write the picture", sio->trace_svg);
      rc = -1;
    }
  }
  fw_loop_destroy(loop);
  if (pub != NULL) {
    fw_publisher_flush(pub);
    if (fw_publisher_counters(pub).log_errors > 0 && rc == 0) {
      fw_errfmt(err, err_cap, "%s: write errors in the experience log", sio->experience_log);
      rc = -1;
    }
    fw_publisher_destroy(pub);
  }
  fw_pubq_destroy(log_q);
  fw_pubq_destroy(q);
  inproc_sim_close(&sim);
  return rc;
}

static void session_free(session_t* S) {
  free(S->runs);
  free(S->blocks);
  memset(S, 0, sizeof *S);
}

static void write_int_array(json_writer_t* w, const char* key, const int32_t* v, int32_t n) {
  json_array(w, key);
  for (int32_t i = 0; i < n; ++i) {
    json_int(w, NULL, v[i]);
  }
  json_end_array(w);
}

static void write_block(json_writer_t* w, const learn_eval_block_t* b) {
  write_int_array(w, "steps", b->steps, b->n_starts);
  json_array(w, "success");
  for (int32_t i = 0; i < b->n_starts; ++i) {
    json_bool(w, NULL, b->success[i]);
  }
  json_end_array(w);
  json_int(w, "successes", b->successes);
}

static void write_sources(json_writer_t* w, const char* key, const int64_t* counts) {
  json_object(w, key);
  for (int i = 0; i < N_SOURCES; ++i) {
    json_int(w, k_source_names[i], counts[i]);
  }
  json_end_object(w);
}

static void write_learning(json_writer_t* w, const session_t* S, double dt_s) {
  json_object(w, "learning");
  json_num(w, "wall_time_s", S->wall_s);
  json_int(w, "ticks", S->ticks);
  json_array(w, "blocks");
  for (size_t i = 0; i < S->n_blocks; ++i) {
    const block_rec_t* b = &S->blocks[i];
    json_object(w, NULL);
    json_int(w, "block", b->b.block);
    json_int(w, "training_runs", b->b.training_runs);
    json_int(w, "phase", b->b.phase);
    write_block(w, &b->b);
    json_int(w, "store_fill", b->store_fill);
    json_int(w, "training_steps", b->training_steps);
    json_num(w, "training_time_s", (double)b->training_steps * dt_s);
    json_end_object(w);
  }
  json_end_array(w);
  json_array(w, "runs");
  int32_t switch_after = -1;
  for (size_t i = 0; i < S->n_runs; ++i) {
    const run_rec_t* r = &S->runs[i];
    if (!r->eval && r->phase == 2 && switch_after < 0 && r->training_index >= 0) {
      switch_after = r->training_index;
    }
    json_object(w, NULL);
    json_int(w, "run_id", r->run_id);
    json_str(w, "kind", r->eval ? "eval" : "train");
    json_int(w, "phase", r->phase);
    if (r->eval) {
      json_int(w, "block", r->block);
    } else {
      json_int(w, "training_index", r->training_index);
    }
    json_int(w, "steps", r->steps);
    json_str(w, "outcome", k_outcome_names[r->outcome]);
    json_num(w, "return", r->ret);
    write_sources(w, "sources", r->sources);
    json_int(w, "store_fill", r->store_fill);
    json_end_object(w);
  }
  json_end_array(w);
  if (switch_after >= 0) {
    json_int(w, "phase_switch_after_training_runs", switch_after);
  } else {
    json_null(w, "phase_switch_after_training_runs");  // no switch
  }
  json_object(w, "totals");
  json_int(w, "training_runs", S->final.training_runs);
  json_int(w, "training_steps", S->training_steps);
  json_num(w, "training_time_s", (double)S->training_steps * dt_s);
  json_int(w, "eval_steps", S->eval_steps);
  json_num(w, "eval_time_s", (double)S->eval_steps * dt_s);
  write_sources(w, "phase_one_steps_by_source", S->training_steps_by_phase_source[0]);
  write_sources(w, "phase_two_steps_by_source", S->training_steps_by_phase_source[1]);
  json_int(w, "store_fill", S->final.store_fill);
  json_int(w, "best_example_steps", S->final.best_example_steps);
  json_num(w, "mean_example_steps", S->final.mean_example_steps);
  json_int(w, "runs_aborted", S->final.runs_aborted);
  json_int(w, "safety_stops", S->final.safety_stops);
  json_int(w, "held_ticks", S->final.held_ticks);
  // policy = select: the ranked pairs, and so which policy acted in the last evaluations.
  json_int(w, "ranked_pairs", S->final.selection.pairs);
  json_num(w, "greedy_saved_steps", S->final.selection.greedy_saved_steps);
  json_end_object(w);
  char hex[24];
  snprintf(hex, sizeof hex, "%016llx", (unsigned long long)S->phase_one_digest);
  json_str(w, "phase_one_data_digest", hex);
  json_int(w, "phase_one_transitions", S->phase_one_transitions);
  json_end_object(w);
}

int exp_run_learn(const exp_settings_t* s, const fw_config_t* cfg_in, const exp_task_t* task, char* err,
                  size_t err_cap) {
  fw_config_t cfg = *cfg_in;
  // The in-process binding is an emulator in lockstep that places the robot itself.
  cfg.seed = task->seed;
  cfg.lockstep = true;
  cfg.reposition = FW_REPOSITION_EMULATOR;
  strcpy(cfg.emulator_control, "in-process");
  strcpy(cfg.lcm_url, "none");
  cfg.checkpoint_file[0] = '\0';
  cfg.log_file[0] = '\0';
  cfg.experience_log_file[0] = '\0';
  cfg.progress = task->verbose;
  if (fw_config_validate(&cfg, err, err_cap) != 0) {
    return -1;
  }

  static sim_world_t world;
  char path[EXP_STR_MAX * 2];
  if (s->world[0] != '\0') {
    if (exp_resolve_path(s, s->world, path, sizeof path) != 0 ||
        sim_world_load(path, &world, err, err_cap) != SIM_WORLD_OK) {
      return -1;
    }
  } else {
    // The configured task's own world (its declaration, with its parameters).
    static tasks_episode_t ep;
    if (fw_config_task(&cfg, &ep, NULL, err, err_cap) != 0) {
      return -1;
    }
    if (sim_world_from_task(ep.decl, tasks_episode_spec(&ep), &world) != SIM_WORLD_OK) {
      fw_errfmt(err, err_cap, "cannot build the %s task's world (check task_params)", ep.decl->name);
      return -1;
    }
  }

  const double dt_s = (double)fw_config_period_us(&cfg) * 1e-6;
  const session_io_t learn_io = {.world = &world, .sim_seed = task->seed, .experience_log = task->experience_log,
                                 .trace_svg = task->trace_svg, .verbose = task->verbose};
  session_t learn;
  if (run_session(&cfg, &learn_io, &learn, err, err_cap) != 0) {
    session_free(&learn);
    return -1;
  }
  // References: the controller's own evaluate mode, from the same poses, with the same emulator
  // seed, so every comparison with the learned policy is paired pose by pose.
  session_t refs[EXP_MAX_REFERENCES];
  memset(refs, 0, sizeof refs);
  int rc = 0;
  for (int32_t i = 0; i < s->n_references && rc == 0; ++i) {
    fw_config_t rc_cfg = cfg;
    char inner[EXP_ERR_MAX];
    // example@GAIN: the example policy at that gain; the plain name always the nominal gain (the
    // middle of its range), whatever evaluate_example_gain the experiment sets.
    double gain = 0.0;
    const bool at_gain = exp_reference_example_gain(s->references[i], &gain);
    const bool plain_example = strcmp(s->references[i], "example") == 0;
    char gain_text[32];
    snprintf(gain_text, sizeof gain_text, "%.17g", gain);
    if (fw_config_set(&rc_cfg, "mode", "evaluate", "reference", inner, sizeof inner) != 0 ||
        fw_config_set(&rc_cfg, "evaluate_policy", at_gain ? "example" : s->references[i], "reference", inner,
                      sizeof inner) != 0 ||
        ((at_gain || plain_example) &&
         fw_config_set(&rc_cfg, "evaluate_example_gain", gain_text, "reference", inner, sizeof inner) != 0)) {
      fw_errfmt(err, err_cap, "%s", inner);
      rc = -1;
      break;
    }
    // The optimal controller is the yardstick of every variant: its law decides every tick,
    // whatever decision_ticks the learner (and its teachers, the other references) run with.
    if (strcmp(s->references[i], "optimal") == 0) {
      rc_cfg.decision_ticks = 1;
    }
    const session_io_t ref_io = {.world = &world, .sim_seed = task->seed, .verbose = task->verbose};
    if (run_session(&rc_cfg, &ref_io, &refs[i], inner, sizeof inner) != 0 || refs[i].n_blocks != 1) {
      fw_errfmt(err, err_cap, "reference '%s': %s", s->references[i], refs[i].n_blocks != 1 ? "no evaluation block" : inner);
      rc = -1;
    }
  }

  char tmp[EXP_STR_MAX * 2];
  FILE* f = rc == 0 ? exp_open_result(task->out_path, tmp, sizeof tmp, err, err_cap) : NULL;
  if (f != NULL) {
    json_writer_t w;
    json_begin(&w, f);
    json_object(&w, NULL);
    exp_write_header(&w, s, &cfg, task);
    json_str(&w, "task", fw_task_name(cfg.task));
    json_str(&w, "world", world.name);
    json_int(&w, "sim_seed", (int64_t)task->seed);
    json_num(&w, "dt_s", dt_s);
    json_int(&w, "step_limit", step_limit_of(&cfg));
    json_int(&w, "eval_starts", cfg.eval_starts);
    write_learning(&w, &learn, dt_s);
    json_object(&w, "references");
    for (int32_t i = 0; i < s->n_references; ++i) {
      json_object(&w, s->references[i]);
      write_block(&w, &refs[i].blocks[0].b);
      json_num(&w, "wall_time_s", refs[i].wall_s);
      json_end_object(&w);
    }
    json_end_object(&w);
    json_end_object(&w);
    rc = exp_commit_result(f, tmp, task->out_path, err, err_cap);
  } else {
    rc = -1;
  }
  session_free(&learn);
  for (int32_t i = 0; i < EXP_MAX_REFERENCES; ++i) {
    session_free(&refs[i]);
  }
  return rc;
}
