// SPDX-License-Identifier: MIT
// The two-phase learning framework (learn/learn.h): who acts, the step's update after the
// command, and the between-run replay in slices.
//
// Why the update waits for the command: the tick that sees a new state must send its command
// first (a stop must never wait for learning); the transition into that state is queued and
// learned after the command went out. Its q' is the greedy value at the new state, which the
// learned policy's action choice computes anyway: the search runs once.
//
// Why decisions every decision_ticks control ticks: one tick's rotation changes the return by a
// fraction of a step, less than the error of the local values (docs/LEARNING.md): a decision
// held for N ticks moves the robot N times as far, and its transition is learned as one step of
// discount gamma^N with the window's discounted rewards, so the values rank what a decision does.
//
// Why slices between runs: the replay of a finished run costs replay_passes × its length updates,
// tens of milliseconds at 20k points on a PC and seconds on a small onboard computer, and the
// actor's learning a few hundred million instructions. The caller does one slice per control
// period while the robot stands, and the next run starts when the work is done. The work is
// counted in updates and work units, never in time, so a lockstep run stays a function of its
// inputs however loaded the machine is.
#include "learn/learn.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

// The transition into the newest state, learned after the command (learn_update).
typedef struct pending {
  bool active;
  bool learning;      // update the learner (training) or only predict Q for the record (evaluation)
  bool need_greedy;   // q' not known yet (no greedy search at s_next was needed for the action)
  double q_next;      // greedy value at s_next (when !need_greedy)
  learn_experience_t e;
} pending_t;

struct learn {
  learn_task_t task;
  learn_config_t cfg;
  uint32_t state_dim;  // the learner's
  learn_learner_t learner;
  actor_t* actor;      // policy = actor (in the storage after the learner's), else NULL
  learn_schedule_t sched;
  learn_plan_t plan;
  rng_t explore_rng;
  int32_t explore_steps_left;  // of the exploration (or dither) segment under way
  double explore_offset;       // its offset [action units]
  // The run.
  bool running;
  int32_t run_id;
  int32_t actions_taken;
  bool have_prev;
  double s[LEARN_MAX_STATE];
  double prev_s[LEARN_MAX_STATE];
  double prev_a;
  double prev_v;
  int8_t source;               // who chose the action of this step (learn_act)
  int8_t prev_source;          // ... of the executed one
  double run_return;
  int32_t steps_by_source[LEARN_N_SOURCES];
  // Learning.
  pending_t pending;
  bool replay_pending;         // a training run ended: its replay begins with the next slice
  bool replaying;
  bool actor_due;              // the actor's learning follows the replay
  bool policy_fault;           // the last learn_act's learned policy gave a non-finite action
  uint64_t guard_replaced;     // actor decisions replaced by the greedy action (actor_guard_se)
  uint64_t policy_faults;
  int64_t steps;
  // The decision under way (cfg.decision_ticks > 1): its action, held until the next decision,
  // and the discounted rewards of its ticks so far.
  double held_action;
  int8_t held_source;
  double window_reward;
  double window_discount;      // gamma^(ticks of the window so far)
  // policy = select: the pairs of phase-two training runs and the choice they rank.
  learn_selection_t selection;
  bool run_greedy;             // the greedy action acts in this run (else the actor)
  int8_t pair_role;            // this run in its pair: 0 none, 1 first, 2 second
  bool pair_first_greedy;      // the pair's first run was the greedy policy's
  bool pair_first_done;        // its first run ended (not aborted): a second run is due
  bool pair_first_resumed;     // ... as a run resumed from a journal (learn_resume_run)
  bool resuming;               // learn_resume_run is ending a recorded run
  int32_t pair_first_steps;    // its steps, a miss at the step limit
  rng_t pair_explore_rng;      // the exploration stream at the first run's start
};

_Static_assert(LEARN_SOURCE_ADVISOR + 1 == LEARN_N_SOURCES, "the sources are counted in steps_by_source");
_Static_assert(LEARN_MAX_STATE <= HEDGER_MAX_STATE_DIM, "the learner's state fits HEDGER's");

learn_config_t learn_config_default(void) {
  learn_config_t c;
  memset(&c, 0, sizeof c);
  c.mode = LEARN_MODE_LEARN;
  c.phase_one_driver = LEARN_DRIVER_EXAMPLE;
  c.schedule.eval_every = 5;
  c.schedule.eval_starts = 10;
  c.schedule.eval_at_start = false;
  c.schedule.phase_one_runs = 30;
  c.schedule.phase_two_runs = 35;
  c.schedule.switch_mode = LEARN_SWITCH_RUNS;
  c.schedule.auto_min_runs = 10;
  c.schedule.auto_ratio = 1.0;
  c.policy = LEARN_POLICY_GREEDY;
  c.actor = actor_config_default();
  c.actor_work_per_slice = 1500U;
  c.learner = LEARN_LEARNER_HEDGER;
  c.alpha = 0.2;
  c.gamma = 0.0;
  c.state_last_action = true;
  c.last_action_scale = 1.0;
  c.capacity = 20000U;
  c.k_min = 8U;
  c.k_max = 48U;
  c.bandwidth = 0.2;
  c.merge_radius = 0.02;
  c.greedy_actions = 9U;
  c.greedy_method = HEDGER_GREEDY_STATE_MODEL;
  c.greedy_pessimism = 4.0;
  c.greedy_reach = 0.0;
  c.replay = true;
  c.replay_passes = 3U;
  c.replay_lambda = 0.9;
  c.replay_alpha = 0.7741;
  c.tabular_bins = 10U;
  c.tabular_actions = 9U;
  c.explore_sigma = 0.3;
  c.explore_probability = 0.1;
  c.explore_hold_steps = 1U;
  c.decision_ticks = 1U;
  c.example_dither_sigma = 0.3;
  c.advisor = true;
  c.replay_updates_per_slice = 200U;
  c.explore_seed = 1U;
  c.learner_seed = 2U;
  return c;
}

uint32_t learn_state_dim(const learn_task_t* task, const learn_config_t* cfg) {
  return task->state_dim + (cfg->state_last_action ? 1U : 0U);
}

// The discount of one control tick.
static double discount(const learn_task_t* task, const learn_config_t* cfg) {
  return cfg->gamma > 0.0 ? cfg->gamma : task->gamma;
}

static uint32_t decision_ticks(const learn_config_t* cfg) {
  return cfg->decision_ticks > 1U ? cfg->decision_ticks : 1U;
}

// The discount of one decision (one learned transition): gamma^decision_ticks. Exactly gamma at 1.
static double decision_discount(const learn_task_t* task, const learn_config_t* cfg) {
  const double g = discount(task, cfg);
  const uint32_t n = decision_ticks(cfg);
  return n == 1U ? g : pow(g, (double)n);
}

void learn_learner_config(const learn_task_t* task, const learn_config_t* cfg, learn_learner_config_t* out) {
  memset(out, 0, sizeof *out);
  out->kind = cfg->learner;
  const uint32_t dim = learn_state_dim(task, cfg);
  hedger_config_t* hc = &out->hedger;
  *hc = hedger_config_default();
  hc->state_dim = dim;
  hc->action_min = task->action_min;
  hc->action_max = task->action_max;
  hc->capacity = cfg->capacity;
  hc->k_min = cfg->k_min;
  hc->k_max = cfg->k_max;
  hc->bandwidth = cfg->bandwidth;
  hc->alpha = cfg->alpha;
  hc->gamma = decision_discount(task, cfg);
  if (cfg->input_scale_n > 0U) {
    for (uint32_t i = 0; i < cfg->input_scale_n && i <= LEARN_MAX_STATE; ++i) {
      hc->input_scale[i] = cfg->input_scale[i];
    }
  } else {
    // The task's declared scales, then (state_last_action) the last action's, then the action's.
    for (uint32_t i = 0; i < task->state_dim; ++i) {
      hc->input_scale[i] = task->state_scale[i];
    }
    if (cfg->state_last_action) {
      hc->input_scale[task->state_dim] = cfg->last_action_scale;
    }
    hc->input_scale[dim] = task->action_scale;
  }
  hc->merge_radius = cfg->merge_radius;
  hc->greedy_coarse_actions = cfg->greedy_actions;
  const uint32_t run_cap = task->step_limit + 8U;
  hc->run_capacity = run_cap > HEDGER_MAX_RUN ? HEDGER_MAX_RUN : run_cap;
  hc->replay = cfg->replay ? 1U : 0U;
  hc->replay_passes = cfg->replay_passes;
  hc->replay_lambda = cfg->replay_lambda;
  hc->replay_alpha = cfg->replay_alpha;
  hc->greedy_method = (uint32_t)cfg->greedy_method;
  hc->greedy_pessimism = cfg->greedy_pessimism;
  hc->greedy_reach = cfg->greedy_reach > 0.0 ? cfg->greedy_reach : task->greedy_reach;
  hc->local_model = cfg->learner == LEARN_LEARNER_LWA ? HEDGER_LOCAL_LWA : HEDGER_LOCAL_LWR;
  hc->seed = cfg->learner_seed;

  tabq_config_t* tc = &out->tabular;
  *tc = tabq_config_default();
  tc->state_dim = dim;
  for (uint32_t i = 0; i < dim && i < TABQ_MAX_STATE_DIM; ++i) {
    tc->bins[i] = cfg->tabular_bins;
  }
  // The task's declared ranges (values outside fall into the edge bins), then the last action's.
  for (uint32_t i = 0; i < task->state_dim && i < TABQ_MAX_STATE_DIM; ++i) {
    tc->state_min[i] = task->state_min[i];
    tc->state_max[i] = task->state_max[i];
  }
  if (cfg->state_last_action && task->state_dim < TABQ_MAX_STATE_DIM) {
    tc->state_min[task->state_dim] = task->action_min;
    tc->state_max[task->state_dim] = task->action_max;
  }
  tc->action_min = task->action_min;
  tc->action_max = task->action_max;
  tc->n_actions = cfg->tabular_actions;
  tc->alpha = hc->alpha;
  tc->gamma = hc->gamma;
  tc->run_capacity = hc->run_capacity;
  tc->replay = hc->replay;
  tc->replay_passes = hc->replay_passes;
  tc->replay_lambda = hc->replay_lambda;
  tc->replay_alpha = hc->replay_alpha;
}

void learn_actor_config(const learn_task_t* task, const learn_config_t* cfg, actor_config_t* out) {
  *out = cfg->actor;
  learn_learner_config_t lc;
  learn_learner_config(task, cfg, &lc);
  const uint32_t dim = learn_state_dim(task, cfg);
  out->state_dim = dim;
  // The network's inputs by the declared ranges; the local models' neighbourhoods by the value
  // learner's input scales (the task's declared scales and the last action's), so that both
  // learners judge nearness alike.
  for (uint32_t i = 0; i < task->state_dim && i < ACTOR_MAX_STATE_DIM; ++i) {
    out->state_min[i] = task->state_min[i];
    out->state_max[i] = task->state_max[i];
  }
  if (cfg->state_last_action && task->state_dim < ACTOR_MAX_STATE_DIM) {
    out->state_min[task->state_dim] = task->action_min;
    out->state_max[task->state_dim] = task->action_max;
  }
  for (uint32_t i = 0; i < dim && i < ACTOR_MAX_STATE_DIM; ++i) {
    out->state_scale[i] = lc.hedger.input_scale[i];
  }
  out->action_min = task->action_min;
  out->action_max = task->action_max;
  out->action_scale = lc.hedger.input_scale[dim];
  out->gamma = decision_discount(task, cfg);
}

static size_t align_storage(size_t n) {
  return (n + LEARN_STORAGE_ALIGN - 1U) & ~(size_t)(LEARN_STORAGE_ALIGN - 1U);
}

static size_t agent_bytes(void) { return align_storage(sizeof(learn_t)); }

static bool has_actor(const learn_config_t* cfg) {
  return cfg->policy == LEARN_POLICY_ACTOR || cfg->policy == LEARN_POLICY_SELECT;
}

static bool policy_valid(int32_t policy) {
  return policy == LEARN_POLICY_ACTOR || policy == LEARN_POLICY_GREEDY || policy == LEARN_POLICY_SELECT;
}

// The actor's storage (0 with the greedy policy; SIZE_MAX when its configuration is invalid).
static size_t actor_bytes(const learn_task_t* task, const learn_config_t* cfg) {
  if (!has_actor(cfg)) {
    return 0;
  }
  actor_config_t ac;
  learn_actor_config(task, cfg, &ac);
  const size_t n = actor_storage_size(&ac);
  return n == 0 ? SIZE_MAX : align_storage(n);
}

static bool task_valid(const learn_task_t* t) {
  if (t->state_dim < 1U || t->state_dim > LEARN_MAX_TASK_STATE || !isfinite(t->action_min) ||
      !isfinite(t->action_max) || !(t->action_min < t->action_max) || !(t->action_scale > 0.0) ||
      !(t->gamma >= 0.0 && t->gamma < 1.0) || !(t->greedy_reach >= 1.0)) {
    return false;
  }
  for (uint32_t i = 0; i < t->state_dim; ++i) {
    if (!(t->state_scale[i] > 0.0) || !isfinite(t->state_scale[i]) || !(t->state_min[i] <= t->state_max[i])) {
      return false;
    }
  }
  return true;
}

size_t learn_storage_size(const learn_task_t* task, const learn_config_t* cfg) {
  if (!task_valid(task)) {
    return 0;
  }
  if (!policy_valid(cfg->policy)) {
    return 0;
  }
  learn_learner_config_t lc;
  learn_learner_config(task, cfg, &lc);
  const size_t learner = learn_learner_storage_size(&lc);
  const size_t actor = actor_bytes(task, cfg);
  return learner == 0 || actor == SIZE_MAX ? 0 : agent_bytes() + learner + actor;
}

learn_t* learn_init(void* storage, size_t storage_size, const learn_task_t* task, const learn_config_t* cfg,
                    char* err, size_t err_cap) {
  if (!task_valid(task)) {
    snprintf(err, err_cap, "the task's declaration is invalid (state dimension 1..%u, finite ordered action bounds, "
             "positive scales, discount in [0, 1), greedy reach >= 1)", LEARN_MAX_TASK_STATE);
    return NULL;
  }
  if (storage == NULL || ((uintptr_t)storage % LEARN_STORAGE_ALIGN) != 0U) {
    snprintf(err, err_cap, "the learner's storage is missing or not aligned to %u bytes", LEARN_STORAGE_ALIGN);
    return NULL;
  }
  if (!policy_valid(cfg->policy)) {
    snprintf(err, err_cap, "unknown policy %d (actor, greedy or select)", (int)cfg->policy);
    return NULL;
  }
  if (actor_bytes(task, cfg) == SIZE_MAX) {
    snprintf(err, err_cap, "the actor's settings are invalid (check the actor_* keys: hidden 1..%u, runs >= 1, "
             "queries 1..actor capacity, capacity 16..%u, positive learning rate)", ACTOR_MAX_HIDDEN,
             ACTOR_MAX_CAPACITY);
    return NULL;
  }
  const size_t need = learn_storage_size(task, cfg);
  if (need == 0 || storage_size < need) {
    learn_learner_config_t lc;
    learn_learner_config(task, cfg, &lc);
    if (learn_learner_storage_size(&lc) == 0) {
      // The learner's own message names the setting.
      learn_learner_t probe;
      (void)learn_learner_init(&probe, NULL, 0, &lc, err, err_cap);
    } else {
      snprintf(err, err_cap, "the learner needs %zu bytes of storage, %zu given", need, storage_size);
    }
    return NULL;
  }
  learn_t* a = (learn_t*)storage;
  memset(a, 0, sizeof *a);
  a->task = *task;
  a->cfg = *cfg;
  if (a->cfg.explore_hold_steps < 1U) {
    a->cfg.explore_hold_steps = 1U;
  }
  a->state_dim = learn_state_dim(task, cfg);
  learn_learner_config_t lc;
  learn_learner_config(task, cfg, &lc);
  const size_t learner_bytes = learn_learner_storage_size(&lc);
  if (learn_learner_init(&a->learner, (uint8_t*)storage + agent_bytes(), learner_bytes, &lc, err, err_cap) != 0) {
    return NULL;
  }
  if (has_actor(cfg)) {
    actor_config_t ac;
    learn_actor_config(task, cfg, &ac);
    const size_t at = agent_bytes() + learner_bytes;
    const actor_status_t st = actor_init(&a->actor, (uint8_t*)storage + at, storage_size - at, &ac);
    if (st != ACTOR_OK) {
      snprintf(err, err_cap, "cannot set up the actor (%s)", actor_status_str(st));
      return NULL;
    }
  }
  learn_schedule_config_t sc = cfg->schedule;
  sc.evaluate_only = cfg->mode != LEARN_MODE_LEARN;
  learn_schedule_init(&a->sched, &sc, NULL);
  a->plan = learn_schedule_next(&a->sched);
  rng_seed(&a->explore_rng, cfg->explore_seed);
  a->run_greedy = cfg->policy != LEARN_POLICY_ACTOR;
  a->run_id = -1;
  return a;
}

learn_plan_t learn_plan(const learn_t* a) { return learn_schedule_next(&a->sched); }

// policy = select: which learned policy acts in the run now beginning. Phase two's training runs
// come in pairs: the pair's second run starts where its first did (learn_run_repeats_start), with
// the same exploration stream, and the other policy acts; the first run's policy alternates from
// pair to pair. Every other run (the evaluations, phase one's, a second run whose first was cut
// short) has the policy the ranked pairs favour: the greedy one while it has saved at least as
// many steps as the actor.
static bool pair_run(const learn_t* a) {
  return a->cfg.policy == LEARN_POLICY_SELECT && a->plan.kind == LEARN_RUN_TRAINING && a->plan.phase == 2 &&
         a->cfg.mode == LEARN_MODE_LEARN;
}

// The planned run (a->plan: the run under way, or the next one between runs) is a pair's second.
static bool pair_second(const learn_t* a) {
  // A first run resumed from a journal pairs only with a resumed second: its start pose is not
  // the caller's to repeat after a restart.
  return pair_run(a) && a->sched.p.phase_two_runs % 2 == 1 && a->pair_first_done &&
         (!a->pair_first_resumed || a->resuming);
}

static void begin_pair(learn_t* a) {
  a->pair_role = 0;
  if (a->cfg.policy != LEARN_POLICY_SELECT) {
    a->run_greedy = a->cfg.policy == LEARN_POLICY_GREEDY;
    return;
  }
  a->run_greedy = a->selection.greedy_saved_steps >= 0.0;
  if (!pair_run(a)) {
    return;
  }
  // The run's place in phase two: an aborted run does not count, so its replacement has the same.
  const int32_t j = a->sched.p.phase_two_runs;
  if (j % 2 == 0) {
    a->pair_role = 1;
    a->pair_first_greedy = (j / 2) % 2 == 0;
    a->pair_first_done = false;
    a->pair_explore_rng = a->explore_rng;
    a->run_greedy = a->pair_first_greedy;
  } else if (pair_second(a)) {
    a->pair_role = 2;
    a->explore_rng = a->pair_explore_rng;
    a->run_greedy = !a->pair_first_greedy;
  }
}

// The end of a pair's run with its steps as the schedule counts them (a miss at the step limit):
// the first's are kept; the second's rank the pair. An aborted second run is repeated, so the
// pair stays open.
static void end_pair(learn_t* a, int32_t steps, bool aborted) {
  if (a->pair_role == 0 || aborted) {
    return;
  }
  if (a->pair_role == 1) {
    a->pair_first_done = true;
    a->pair_first_resumed = a->resuming;
    a->pair_first_steps = steps;
    return;
  }
  const int32_t greedy_steps = a->pair_first_greedy ? a->pair_first_steps : steps;
  const int32_t actor_steps = a->pair_first_greedy ? steps : a->pair_first_steps;
  a->selection.greedy_saved_steps += (double)actor_steps - (double)greedy_steps;
  a->selection.pairs++;
  a->pair_first_done = false;
}

bool learn_run_repeats_start(const learn_t* a) { return pair_second(a); }

bool learn_run_greedy(const learn_t* a) { return a->run_greedy; }

learn_selection_t learn_selection_get(const learn_t* a) { return a->selection; }

bool learn_resume_selection(learn_t* a, const learn_selection_t* s) {
  if (a->cfg.policy != LEARN_POLICY_SELECT || !isfinite(s->greedy_saved_steps) || s->pairs < 0) {
    return false;
  }
  a->selection = *s;
  a->pair_first_done = false;  // a pair cut by the restart is not ranked
  return true;
}

void learn_begin_run(learn_t* a) {
  a->plan = learn_schedule_next(&a->sched);
  a->run_id++;
  a->running = true;
  a->explore_steps_left = 0;
  a->actions_taken = 0;
  a->have_prev = false;
  a->run_return = 0.0;
  memset(a->steps_by_source, 0, sizeof a->steps_by_source);
  begin_pair(a);
}

bool learn_running(const learn_t* a) { return a->running; }

bool learn_observe(learn_t* a, const double* features, double last_command) {
  for (uint32_t i = 0; i < a->task.state_dim; ++i) {
    a->s[i] = features[i];
  }
  if (a->cfg.state_last_action) {
    // The command in force (after the caller's limits): the action the base executes now, and the
    // one an acceleration limit measures the next change against. Known exactly, unlike a measured
    // rate, so a lockstep run stays a function of its inputs.
    a->s[a->task.state_dim] = last_command;
  }
  for (uint32_t i = 0; i < a->state_dim; ++i) {
    if (!isfinite(a->s[i])) {
      return false;
    }
  }
  return true;
}

const double* learn_state(const learn_t* a) { return a->s; }

uint32_t learn_agent_state_dim(const learn_t* a) { return a->state_dim; }

bool learn_has_transition(const learn_t* a) { return a->running && a->have_prev; }

int32_t learn_run_actions(const learn_t* a) { return a->actions_taken; }

static bool evaluating(const learn_t* a) { return a->plan.kind == LEARN_RUN_EVAL; }

static bool learning(const learn_t* a) { return !evaluating(a) && a->cfg.mode == LEARN_MODE_LEARN; }

bool learn_policy_acts(const learn_t* a) {
  return (evaluating(a) && a->cfg.mode != LEARN_MODE_EVALUATE_ADVICE) || (!evaluating(a) && a->plan.phase == 2);
}

bool learn_joystick_drives(const learn_t* a) {
  return a->running && a->cfg.mode == LEARN_MODE_LEARN && a->cfg.phase_one_driver == LEARN_DRIVER_JOYSTICK &&
         a->plan.kind == LEARN_RUN_TRAINING && a->plan.phase == 1;
}

// The run under way ends: the schedule counts it (an aborted one is repeated); a training run of
// the learn mode has its replay between runs (also when aborted: its transitions were learned).
static void end_run(learn_t* a, bool goal, bool aborted, learn_run_end_t* end) {
  memset(end, 0, sizeof *end);
  end->run_id = a->run_id;
  end->plan = a->plan;
  end->goal = goal;
  end->aborted = aborted;
  end->steps = a->actions_taken;
  end->total_reward = a->run_return;
  memcpy(end->steps_by_source, a->steps_by_source, sizeof end->steps_by_source);
  end->eval_block = evaluating(a) ? a->sched.p.eval_blocks : -1;  // blocks finished so far = this block's number
  end->learning = a->plan.kind == LEARN_RUN_TRAINING && a->cfg.mode == LEARN_MODE_LEARN;
  end->policy = (int8_t)(a->run_greedy ? LEARN_POLICY_GREEDY : LEARN_POLICY_ACTOR);
  // A run that missed the goal counts at the step limit.
  const int32_t steps = goal ? a->actions_taken : (int32_t)a->task.step_limit;
  end_pair(a, steps, aborted);
  end->block_done = learn_schedule_finish_run(&a->sched, steps, goal, aborted, &end->block);
  if (end->learning) {
    a->replay_pending = true;
  }
  a->running = false;
  a->plan = learn_schedule_next(&a->sched);
}

// A tick where the policy decides: the run's first, then every cfg.decision_ticks-th.
static bool deciding(const learn_t* a) { return a->actions_taken % (int32_t)decision_ticks(&a->cfg) == 0; }

bool learn_transition(learn_t* a, const learn_outcome_t* o, learn_run_end_t* end) {
  pending_t* p = &a->pending;
  a->window_reward += a->window_discount * o->reward;
  a->window_discount *= discount(&a->task, &a->cfg);
  if (!deciding(a) && !o->terminal && !o->end_run) {
    // Inside a decision's window: its transition is learned when the window closes.
    a->steps++;
    a->run_return += o->reward;
    return false;
  }
  p->active = true;
  p->learning = learning(a);
  p->need_greedy = true;
  p->q_next = 0.0;
  learn_experience_t* e = &p->e;
  e->run_id = a->run_id;
  e->step_id = a->actions_taken - 1;
  e->phase = a->plan.phase;
  e->evaluating = evaluating(a);
  e->source = a->prev_source;
  e->reason = o->reason;
  e->state_dim = a->state_dim;
  memcpy(e->s, a->prev_s, sizeof e->s);
  memcpy(e->s_next, a->s, sizeof e->s_next);
  e->a = a->prev_a;
  e->v = a->prev_v;
  e->reward = a->window_reward;  // o->reward at one tick per decision (the same bits)
  e->terminal = o->terminal;
  a->steps++;
  a->run_return += o->reward;
  if (!o->end_run) {
    return false;
  }
  end_run(a, o->goal, false, end);
  return true;
}

bool learn_abort_run(learn_t* a, learn_run_end_t* end) {
  if (!a->running) {
    return false;
  }
  end_run(a, false, true, end);
  return true;
}

static double clamp_action(const learn_t* a, double x) {
  if (!isfinite(x)) {
    return 0.0;
  }
  return x < a->task.action_min ? a->task.action_min : (x > a->task.action_max ? a->task.action_max : x);
}

// Exploration (or phase one's dither) of a training step: with explore_probability per step a
// segment starts that adds one offset ~ N(0, sigma) to the actions for explore_hold_steps steps.
// Returns true (with the offset) while a segment is running.
static bool explore_offset(learn_t* a, double sigma, double* offset) {
  if (a->explore_steps_left == 0) {
    if (sigma <= 0.0 || !(rng_uniform(&a->explore_rng) < a->cfg.explore_probability)) {
      return false;
    }
    a->explore_steps_left = (int32_t)a->cfg.explore_hold_steps;
    a->explore_offset = sigma * rng_normal(&a->explore_rng);
  }
  a->explore_steps_left--;
  *offset = a->explore_offset;
  return true;
}

// The actor's action at s into *act; false where it knows none (nothing learned yet). A
// non-finite output is a fault: the action is 0 and the caller is told (learn_policy_fault).
static bool actor_action(learn_t* a, double* act) {
  const actor_status_t st = actor_act(a->actor, a->s, act);
  if (st == ACTOR_ERR_NON_FINITE) {
    a->policy_fault = true;
    a->policy_faults++;
    *act = 0.0;
    return true;
  }
  if (st != ACTOR_OK) {
    return false;
  }
  *act = clamp_action(a, *act);
  return true;
}

// The values' guard of the actor's action act at s (actor_guard_se, actor_guard_range). The
// search's greedy value is the q' of the transition into s, as on the greedy policy's path.
static void guard_actor(learn_t* a, double* act) {
  hedger_judgement_t j;
  const bool known = learn_learner_judge(&a->learner, a->s, *act, &j);
  if (a->pending.active) {
    a->pending.need_greedy = false;
    a->pending.q_next = j.greedy_value;  // the default value when no action is known
  }
  if (!known || !j.judged) {
    return;
  }
  if (a->cfg.actor_guard_se > 0.0 && j.gap > a->cfg.actor_guard_se * j.gap_se) {
    *act = clamp_action(a, j.greedy_action);
    a->guard_replaced++;
  } else if (a->cfg.actor_guard_range) {
    // Beyond the data's actions the values judged the nearest one they hold: that one acts.
    *act = clamp_action(a, j.kept_action);
  }
}

void learn_act(learn_t* a, double advice, double joystick, double* action, int8_t* source) {
  if (!deciding(a)) {
    // Inside a decision's window: its action holds, whoever chose it (the driver's too, so that
    // every learned transition is one held action).
    a->source = a->held_source;
    *action = a->held_action;
    *source = a->held_source;
    return;
  }
  const bool eval = evaluating(a);
  const bool policy = learn_policy_acts(a);
  a->policy_fault = false;
  // The greedy search at s chooses the greedy policy's action; its value is also the q' of the
  // transition into s (learned after the command), so it runs once. The actor's action needs no
  // search: the update finds q' itself.
  bool greedy_known = false;
  double greedy_action = 0.0;
  if (policy && a->actor != NULL && !a->run_greedy) {
    greedy_known = actor_action(a, &greedy_action);
    if (greedy_known && !a->policy_fault && (a->cfg.actor_guard_se > 0.0 || a->cfg.actor_guard_range)) {
      guard_actor(a, &greedy_action);
    }
  } else if (policy) {
    double value = 0.0;
    greedy_known = learn_learner_greedy(&a->learner, a->s, &greedy_action, &value);
    if (greedy_known) {
      greedy_action = clamp_action(a, greedy_action);
    }
    if (a->pending.active) {
      a->pending.need_greedy = false;
      a->pending.q_next = value;  // the default value when no action is known
    }
  }
  double act = 0.0;
  double offset = 0.0;
  int8_t src = LEARN_SOURCE_EXAMPLE;
  if (!policy) {
    if (learn_joystick_drives(a)) {
      act = joystick;
      src = LEARN_SOURCE_JOYSTICK;
    } else {
      act = advice;
      if (!eval && a->cfg.example_dither_sigma > 0.0 && explore_offset(a, a->cfg.example_dither_sigma, &offset)) {
        act += offset;  // phase-one dither: the learner sees actions around the example's
      }
    }
  } else if (greedy_known) {
    act = greedy_action;
    src = LEARN_SOURCE_GREEDY;
    if (!eval && !a->policy_fault && explore_offset(a, a->cfg.explore_sigma, &offset)) {
      act += offset;
      src = LEARN_SOURCE_EXPLORATION;
    }
  } else if (!eval && a->cfg.advisor) {
    act = advice;  // the learner knows no action here: the example policy advises
    src = LEARN_SOURCE_ADVISOR;
  } else {
    act = 0.0;  // nothing known: hold course (evaluations measure the learned policy alone)
    src = LEARN_SOURCE_GREEDY;
  }
  a->source = src;
  *action = act;
  *source = src;
  a->held_action = clamp_action(a, act);  // within the action bounds, as a learned action must be
  a->held_source = src;
}

void learn_executed(learn_t* a, double action, double translation) {
  if (!a->running) {
    return;
  }
  if (deciding(a)) {
    // A decision's first tick: its transition starts here. With one tick per decision the action
    // is the executed one (the caller's limits applied); over several, the decision (the ticks'
    // executed actions differ while an acceleration limit ramps them).
    memcpy(a->prev_s, a->s, sizeof a->prev_s);
    a->prev_a = decision_ticks(&a->cfg) == 1U ? action : a->held_action;
    a->prev_v = translation;
    a->prev_source = a->source;
    a->window_reward = 0.0;
    a->window_discount = 1.0;
  }
  a->have_prev = true;
  a->actions_taken++;
  if (a->prev_source >= 0 && a->prev_source < LEARN_N_SOURCES) {
    a->steps_by_source[a->prev_source]++;
  }
}

// The queued transition: its update (training) or the prediction of its Q (evaluation).
// Bounded: at most one greedy search and one update.
static bool update_pending(learn_t* a, learn_experience_t* exp) {
  pending_t* p = &a->pending;
  if (!p->active) {
    return false;
  }
  double q = 0.0;
  hedger_kind_t kind = HEDGER_KIND_UNKNOWN;
  learn_experience_t* e = &p->e;
  if (p->learning) {
    double q_next = 0.0;
    if (!e->terminal) {
      if (p->need_greedy) {
        (void)learn_learner_greedy(&a->learner, e->s_next, NULL, &q_next);
      } else {
        q_next = p->q_next;
      }
    }
    if (!learn_learner_learn(&a->learner, e->s, e->a, e->reward, e->s_next, e->terminal, q_next, &q, &kind)) {
      q = 0.0;
      kind = HEDGER_KIND_UNKNOWN;
    }
    if (a->actor != NULL) {
      (void)actor_record(a->actor, e->s, e->a, e->reward, e->s_next, e->terminal ? 1 : 0);
    }
  } else if (!learn_learner_predict(&a->learner, e->s, e->a, &q, &kind)) {
    q = 0.0;
    kind = HEDGER_KIND_UNKNOWN;
  }
  e->q = isfinite(q) ? q : 0.0;
  e->q_kind = kind;
  *exp = *e;
  p->active = false;
  return true;
}

bool learn_update(learn_t* a, learn_experience_t* exp) { return update_pending(a, exp); }

// A training run ended: its replay begins, and the actor's learning is due after it.
static void begin_between_runs(learn_t* a) {
  a->replay_pending = false;
  learn_learner_end_run_begin(&a->learner);
  a->replaying = true;
  a->actor_due = a->actor != NULL;
}

// One slice of the actor's learning (it begins with the first); true while work is left.
static bool actor_slice(learn_t* a, uint32_t max_work) {
  if (a->actor == NULL) {
    return false;
  }
  if (a->actor_due) {
    a->actor_due = false;
    (void)actor_end_run_begin(a->actor, NULL);  // nothing is due when the run recorded nothing
  }
  int remaining = 0;
  (void)actor_end_run_step(a->actor, max_work, &remaining);
  return remaining != 0;
}

uint32_t learn_between_runs_slice(learn_t* a, uint32_t max_updates) {
  if (a->replay_pending) {
    begin_between_runs(a);
  }
  if (a->replaying) {
    const uint32_t left = learn_learner_end_run_step(&a->learner, max_updates);
    a->replaying = left > 0;
    return left + (a->actor_due ? 1U : 0U);
  }
  return actor_slice(a, a->cfg.actor_work_per_slice) ? 1U : 0U;
}

bool learn_after_command(learn_t* a, learn_experience_t* exp) {
  const bool had = update_pending(a, exp);
  if (!had || learn_between_runs_busy(a)) {
    (void)learn_between_runs_slice(a, a->cfg.replay_updates_per_slice);
  }
  return had;
}

bool learn_idle(const learn_t* a) { return !a->pending.active && !learn_between_runs_busy(a); }

bool learn_between_runs_due(const learn_t* a) { return a->replay_pending; }

bool learn_between_runs_busy(const learn_t* a) {
  return a->replay_pending || a->replaying || a->actor_due || (a->actor != NULL && actor_working(a->actor));
}

// The whole between-run work at once: the replay, then the actor's learning.
static void between_runs_now(learn_t* a) {
  if (a->replay_pending) {
    begin_between_runs(a);
  }
  (void)learn_learner_end_run_step(&a->learner, UINT32_MAX);
  a->replaying = false;
  while (actor_slice(a, UINT32_MAX)) {
  }
}

bool learn_finish_now(learn_t* a, learn_experience_t* exp) {
  const bool had = update_pending(a, exp);
  between_runs_now(a);
  return had;
}

bool learn_offline_transition(learn_t* a, const double* s, double action, double reward, const double* s_next,
                              bool terminal, learn_experience_t* exp) {
  double q_next = 0.0;
  if (!terminal) {
    (void)learn_learner_greedy(&a->learner, s_next, NULL, &q_next);
  }
  double q = 0.0;
  hedger_kind_t kind = HEDGER_KIND_UNKNOWN;
  if (!learn_learner_learn(&a->learner, s, action, reward, s_next, terminal, q_next, &q, &kind)) {
    return false;
  }
  if (a->actor != NULL) {
    (void)actor_record(a->actor, s, action, reward, s_next, terminal ? 1 : 0);
  }
  a->steps++;
  if (exp != NULL) {
    memset(exp, 0, sizeof *exp);
    memcpy(exp->s, s, a->state_dim * sizeof(double));
    memcpy(exp->s_next, s_next, a->state_dim * sizeof(double));
    exp->a = action;
    exp->reward = reward;
    exp->terminal = terminal;
    exp->q = isfinite(q) ? q : 0.0;
    exp->q_kind = kind;
  }
  return true;
}

uint64_t learn_offline_end_run(learn_t* a) {
  const uint64_t before = learn_learner_stats(&a->learner).replayed_updates;
  a->replay_pending = true;
  between_runs_now(a);
  return learn_learner_stats(&a->learner).replayed_updates - before;
}

void learn_request_phase_two(learn_t* a) { learn_schedule_request_phase_two(&a->sched); }

const learn_schedule_t* learn_schedule(const learn_t* a) { return &a->sched; }

int32_t learn_run_id(const learn_t* a) { return a->run_id; }

void learn_resume(learn_t* a, const learn_schedule_progress_t* progress, int32_t run_id) {
  const learn_schedule_config_t sc = a->sched.cfg;  // a copy: init clears the schedule first
  learn_schedule_init(&a->sched, &sc, progress);
  a->run_id = run_id;
  a->plan = learn_schedule_next(&a->sched);
}

bool learn_resume_run(learn_t* a, const learn_plan_t* plan, int32_t steps, bool goal, bool aborted,
                      learn_run_end_t* end) {
  const learn_plan_t next = learn_schedule_next(&a->sched);
  if (a->running || plan->kind != next.kind || plan->phase != next.phase ||
      (next.kind == LEARN_RUN_EVAL && plan->eval_index != next.eval_index) ||
      (next.kind == LEARN_RUN_TRAINING && plan->training_index != next.training_index)) {
    return false;
  }
  a->resuming = true;
  learn_begin_run(a);
  a->actions_taken = steps;
  learn_run_end_t e;
  end_run(a, goal, aborted, &e);
  a->resuming = false;
  a->replay_pending = false;  // the caller has done the run's learning
  if (end != NULL) {
    *end = e;
  }
  return true;
}

learn_learner_t* learn_get_learner(learn_t* a) { return &a->learner; }

actor_t* learn_get_actor(learn_t* a) { return a->actor; }

const actor_t* learn_get_actor_const(const learn_t* a) { return a->actor; }

bool learn_policy_fault(const learn_t* a) { return a->policy_fault; }

uint64_t learn_policy_faults(const learn_t* a) { return a->policy_faults; }

uint64_t learn_guard_replaced(const learn_t* a) { return a->guard_replaced; }

// The stored points of HEDGER as cloning samples (state, action).
static int stored_point(void* user, uint32_t index, double* state, double* action) {
  const learn_t* a = (const learn_t*)user;
  hedger_point_t pt;
  if (hedger_get_point(a->learner.hedger, index, &pt) != HEDGER_OK) {
    return 1;
  }
  memcpy(state, pt.state, a->state_dim * sizeof(double));
  *action = pt.action;
  return 0;
}

uint32_t learn_actor_from_values(learn_t* a) {
  if (a->actor == NULL || a->learner.hedger == NULL) {
    return 0;
  }
  const uint32_t n = hedger_size(a->learner.hedger);
  if (n == 0 || actor_clone(a->actor, n, stored_point, a) != ACTOR_OK) {
    return 0;
  }
  return n;
}

const learn_learner_t* learn_get_learner_const(const learn_t* a) { return &a->learner; }

int64_t learn_steps(const learn_t* a) { return a->steps; }
