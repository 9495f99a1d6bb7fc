// SPDX-License-Identifier: MIT
// The vet of a step of the learned policy's shift (fw/shift_vet.h): the learned policy with the
// step, driven on the safety filter's kinematic model from the last training runs' starts.
#include "fw/shift_vet.h"

#include "loop_internal.h"

#include <math.h>
#include <string.h>

// Whether the obstacle task is its own mirror image about the line y = goal_y (the default:
// goal, disc and walls on and about the x axis): then a start's mirror image is a start too.
static bool obstacles_symmetric(const tasks_obstacles_spec_t* spec) {
  const double gy = spec->goal_y_m;
  if (fabs((spec->arena_max_y_m - gy) - (gy - spec->arena_min_y_m)) > 1e-9) {
    return false;
  }
  for (uint32_t i = 0U; i < spec->n_obstacles && i < TASKS_MAX_OBSTACLES; ++i) {
    const tasks_circle_t* a = &spec->obstacles[i];
    bool twin = false;
    for (uint32_t j = 0U; j < spec->n_obstacles && j < TASKS_MAX_OBSTACLES && !twin; ++j) {
      const tasks_circle_t* b = &spec->obstacles[j];
      twin = fabs(a->x_m - b->x_m) < 1e-9 && fabs((a->y_m - gy) + (b->y_m - gy)) < 1e-9 &&
             fabs(a->radius_m - b->radius_m) < 1e-9;
    }
    if (!twin) {
      return false;
    }
  }
  return true;
}

void fw_shift_vet_env_init(fw_shift_vet_env_t* env, const fw_config_t* cfg) {
  memset(env, 0, sizeof *env);
  fw_loop_task_specs(cfg, &env->spec, &env->obstacles, &env->lim);
  env->task = (fw_task_t)cfg->task;
  tasks_obstacles_features_config(&env->obstacles, &env->obstacles_features);
  const bool corridor = cfg->task == FW_TASK_CORRIDOR;
  env->dt_s = corridor ? env->spec.dt_s : env->obstacles.dt_s;
  env->omega_max_radps = corridor ? env->spec.omega_max_radps : env->obstacles.omega_max_radps;
  env->step_limit = corridor ? env->spec.step_limit : env->obstacles.step_limit;
  env->task_dim = corridor ? 3U : 4U;
  env->margin_m = corridor ? cfg->pair_safety_margin_m : FW_SHIFT_VET_OBSTACLES_MARGIN_M;
  env->obstacle_clearance_m = cfg->pair_obstacle_clearance_m;
  env->pass_hold_steps = cfg->obstacle_pass_hold_steps > 0 ? (uint32_t)cfg->obstacle_pass_hold_steps : 0U;
  env->mirror = corridor || obstacles_symmetric(&env->obstacles);
  env->state_rotation = cfg->state_rotation;
  const int32_t cap = cfg->pair_shift_vet_starts;
  env->capacity = cap < 1 ? 1U : (cap > FW_SHIFT_VET_STARTS_MAX ? FW_SHIFT_VET_STARTS_MAX : (uint32_t)cap);
}

void fw_shift_vet_starts_add(fw_shift_vet_starts_t* starts, const fw_shift_vet_env_t* env, const double* state) {
  const uint32_t dim = env->task_dim;
  const double omega = env->state_rotation ? state[dim] : 0.0;
  for (uint32_t i = 0U; i < dim; ++i) {
    if (!isfinite(state[i])) {
      return;
    }
  }
  if (!isfinite(omega)) {
    return;
  }
  const uint32_t cap = env->capacity;
  const uint32_t slot = starts->next < cap ? starts->next : 0U;
  memset(starts->state[slot], 0, sizeof starts->state[slot]);
  memcpy(starts->state[slot], state, dim * sizeof state[0]);
  starts->omega_radps[slot] = omega;
  starts->next = slot + 1U < cap ? slot + 1U : 0U;
  starts->n = starts->n < cap ? starts->n + 1U : cap;
}

static void decide(fw_shift_vet_t* vet, fw_shift_verdict_t verdict) {
  vet->verdict = verdict;
  vet->result = vet->shift[verdict == FW_SHIFT_STEP_TAKEN ? 0 : (verdict == FW_SHIFT_STEP_HALVED ? 2 : 1)];
  vet->result.pairs = vet->shift[0].pairs;
  vet->stage = -1;
}

void fw_shift_vet_begin(fw_shift_vet_t* vet, const fw_pair_shift_t* in_force, const fw_pair_shift_t* proposed) {
  memset(vet, 0, sizeof *vet);
  vet->shift[0] = *proposed;
  vet->shift[1] = *in_force;
  vet->shift[2] = *in_force;  // the fraction under test, set when one is tried (candidate_dropped)
  vet->stage = 0;
  if (!(proposed->gain < in_force->gain || proposed->gain > in_force->gain ||
        proposed->centring < in_force->centring || proposed->centring > in_force->centring ||
        proposed->imitation < in_force->imitation || proposed->imitation > in_force->imitation)) {
    decide(vet, FW_SHIFT_STEP_TAKEN);
  }
}

bool fw_shift_vet_done(const fw_shift_vet_t* vet) { return vet->stage < 0; }

// Rollouts per start: 2 where the task is mirror-symmetric (the start and its mirror image).
static uint32_t rollouts_per_start(const fw_shift_vet_env_t* env) { return env->mirror ? 2U : 1U; }

void fw_pass_hold_reset(fw_pass_hold_t* h) {
  h->steps_left = 0U;
  h->near_before = false;
}

bool fw_pass_hold_observe(fw_pass_hold_t* h, fw_task_t task, const double* s, uint32_t hold_steps) {
  if (task == FW_TASK_CORRIDOR || hold_steps == 0U) {
    fw_pass_hold_reset(h);
    return false;
  }
  // A visible obstacle's bearing lies within ±π/2 (the laser's 180°); an empty slot's is π.
  const double half_pi = 1.57079632679489661923;
  const bool in_view = fabs(s[2]) <= half_pi;
  const bool near = in_view && s[3] < FW_PAIR_OBSTACLE_RANGE_M;
  if (in_view) {
    h->steps_left = 0U;  // back in view (or another one): the state says where it is
  } else if (h->near_before) {
    h->steps_left = hold_steps;
  } else if (h->steps_left > 0U) {
    h->steps_left--;
  }
  h->near_before = near;
  return fw_pass_hold_active(h);
}

bool fw_pass_hold_active(const fw_pass_hold_t* h) { return h->steps_left > 0U; }

// Rollout k of a start set: start k / 2, mirrored when k is odd (with env->mirror; else start k).
// The mirror image: corridor lateral fraction 1 - l, target angle negated; obstacles both
// bearings negated (a visible obstacle's bearing is within +-pi/2; a hidden one's start has no
// pose either way); the rotation negated.
static void begin_rollout(fw_shift_vet_t* vet, const fw_shift_vet_env_t* env, const fw_shift_vet_starts_t* starts,
                          uint32_t k) {
  const uint32_t per = rollouts_per_start(env);
  const uint32_t i = k / per;
  const bool mirrored = per == 2U && (k & 1U) != 0U;
  double s[FW_SHIFT_VET_TASK_DIM_MAX];
  memcpy(s, starts->state[i], sizeof s);
  double omega = starts->omega_radps[i];
  if (mirrored) {
    omega = -omega;
    if (env->task == FW_TASK_CORRIDOR) {
      s[1] = 1.0 - s[1];
      s[2] = -s[2];
    } else {
      s[0] = -s[0];
      s[2] = -s[2];
    }
  }
  if (env->task == FW_TASK_CORRIDOR) {
    (void)tasks_corridor_rollout_begin(&vet->ro, &env->spec, s, omega);
  } else {
    (void)tasks_obstacles_rollout_begin(&vet->ro_obstacles, &env->obstacles, &env->obstacles_features, s, omega);
  }
  fw_pass_hold_reset(&vet->pass_hold);
  vet->rolling = true;
}

// The rollout under way: its status, and (running) the learner's state at its pose, the rotation
// in force appended.
static int32_t rollout_status(const fw_shift_vet_t* vet, const fw_shift_vet_env_t* env) {
  return env->task == FW_TASK_CORRIDOR ? vet->ro.status : vet->ro_obstacles.status;
}

static void rollout_state(const fw_shift_vet_t* vet, const fw_shift_vet_env_t* env, double* s) {
  if (env->task == FW_TASK_CORRIDOR) {
    features_corridor_state(&vet->ro.f, s);
    s[3] = vet->ro.omega_radps;
  } else {
    (void)features_obstacles_state(&vet->ro_obstacles.f, 1U, s, FW_SHIFT_VET_TASK_DIM_MAX);
    s[4] = vet->ro_obstacles.omega_radps;
  }
}

static void rollout_step(fw_shift_vet_t* vet, const fw_shift_vet_env_t* env, double omega) {
  if (env->task == FW_TASK_CORRIDOR) {
    (void)tasks_corridor_rollout_step(&vet->ro, &env->spec, &env->lim, env->dt_s, omega, env->margin_m,
                                      env->step_limit);
  } else {
    (void)tasks_obstacles_rollout_step(&vet->ro_obstacles, &env->obstacles, &env->obstacles_features, &env->lim,
                                       env->dt_s, omega, env->margin_m, env->step_limit);
  }
}

// The candidate under test is not taken: after the proposed shift half the step is tried, then a
// quarter, then an eighth (each from the first start again; the shift in force's verdicts per
// start are kept, it is the same shift); after the last the shift stays.
static void candidate_dropped(fw_shift_vet_t* vet) {
  if (vet->stage < FW_SHIFT_VET_HALVINGS) {
    vet->stage++;
    vet->start = 0;
    vet->lost = 0;
    memset(vet->candidate_failed, 0, sizeof vet->candidate_failed);
    const double fraction = ldexp(1.0, -vet->stage);
    const fw_pair_shift_t* in_force = &vet->shift[1];
    vet->shift[2].gain = in_force->gain + fraction * (vet->shift[0].gain - in_force->gain);
    vet->shift[2].centring = in_force->centring + fraction * (vet->shift[0].centring - in_force->centring);
    vet->shift[2].imitation = in_force->imitation + fraction * (vet->shift[0].imitation - in_force->imitation);
  } else {
    decide(vet, FW_SHIFT_STEP_REFUSED);
  }
}

// The shift in force's verdict from start k (driven once per vet: each start at most once).
static void record_in_force(fw_shift_vet_t* vet, uint32_t k, bool failed) {
  vet->failures[1] += failed ? 1 : 0;
  vet->in_force_failed[k] = failed ? 1 : -1;
}

// The first start the shift in force has not been driven from, at or after k (n when none is).
static uint32_t next_unknown_in_force(const fw_shift_vet_t* vet, uint32_t k, uint32_t n) {
  while (k < n && vet->in_force_failed[k] != 0) {
    k++;
  }
  return k;
}

// The candidate lost a start the shift in force reaches the goal from. It can still be taken
// only by rescuing more starts than it loses, which needs starts the shift in force fails from:
// with no more of those than it has lost, it is dropped at once (with a shift in force that
// fails nowhere, at its first lost start, as a rule of "no new failure" would).
static void candidate_lost_a_start(fw_shift_vet_t* vet) {
  vet->lost++;
  if (vet->lost >= vet->failures[1]) {
    candidate_dropped(vet);
    return;
  }
  vet->start++;
}

// The candidate was driven from every start: taken where it lost none, or where it rescued more
// starts (reaching the goal where the shift in force fails) than it lost; else dropped.
static void candidate_judged(fw_shift_vet_t* vet, uint32_t n) {
  int32_t rescued = 0;
  for (uint32_t k = 0U; k < n; ++k) {
    rescued += vet->candidate_failed[k] < 0 && vet->in_force_failed[k] > 0 ? 1 : 0;
  }
  if (vet->lost == 0 || vet->lost < rescued) {
    decide(vet, vet->stage == 0 ? FW_SHIFT_STEP_TAKEN : FW_SHIFT_STEP_HALVED);
  } else {
    candidate_dropped(vet);
  }
}

// A rollout ended (status failed or not): what the vet does next.
static void rollout_finished(fw_shift_vet_t* vet, bool failed, uint32_t n) {
  vet->rolling = false;
  const uint32_t k = vet->start;
  switch (vet->driving) {
    case FW_SHIFT_VET_DRIVING_ALL_IN_FORCE: {
      // The shift in force from every start it was not driven from, once per vet: the starts it
      // fails from are the most the candidate can rescue.
      record_in_force(vet, vet->in_force_next, failed);
      vet->in_force_next = next_unknown_in_force(vet, vet->in_force_next + 1U, n);
      if (vet->in_force_next >= n) {
        vet->driving = FW_SHIFT_VET_DRIVING_CANDIDATE;
        candidate_lost_a_start(vet);
      }
      return;
    }
    case FW_SHIFT_VET_DRIVING_IN_FORCE: {
      // The shift in force from the start the candidate failed from decides whether it lost it.
      vet->driving = FW_SHIFT_VET_DRIVING_CANDIDATE;
      record_in_force(vet, k, failed);
      if (failed) {
        vet->start++;
        return;
      }
      break;  // lost: below
    }
    case FW_SHIFT_VET_DRIVING_CANDIDATE:
    default: {
      const int32_t candidate = vet->stage == 0 ? 0 : 2;
      vet->failures[candidate] += failed ? 1 : 0;
      vet->candidate_failed[k] = failed ? 1 : -1;
      if (!failed || vet->in_force_failed[k] > 0) {
        vet->start++;
        return;
      }
      if (vet->in_force_failed[k] == 0) {
        vet->driving = FW_SHIFT_VET_DRIVING_IN_FORCE;
        return;
      }
      break;  // lost: below
    }
  }
  // The candidate lost start k. The first time in a vet, the shift in force is driven from every
  // start it has not been yet (its failures bound what the candidate can rescue).
  vet->in_force_next = next_unknown_in_force(vet, 0U, n);
  if (vet->in_force_next < n) {
    vet->driving = FW_SHIFT_VET_DRIVING_ALL_IN_FORCE;
    return;
  }
  candidate_lost_a_start(vet);
}

bool fw_shift_vet_hedger_greedy(void* hedger, const double* s, double* action) {
  return hedger != NULL && hedger_greedy((hedger_t*)hedger, s, action, NULL, NULL) == HEDGER_OK;
}

bool fw_shift_vet_step(fw_shift_vet_t* vet, fw_shift_vet_greedy_fn greedy, void* ctx, const fw_shift_vet_env_t* env,
                       const fw_shift_vet_starts_t* starts, uint32_t periods) {
  const double omega_max = env->omega_max_radps;
  const uint32_t n_rollouts = rollouts_per_start(env) * starts->n;
  uint32_t budget = periods;
  while (vet->stage >= 0) {
    if (!vet->rolling) {
      if (vet->driving == FW_SHIFT_VET_DRIVING_CANDIDATE && vet->start >= n_rollouts) {
        candidate_judged(vet, n_rollouts);
        continue;
      }
      begin_rollout(vet, env, starts,
                    vet->driving == FW_SHIFT_VET_DRIVING_ALL_IN_FORCE ? vet->in_force_next : vet->start);
    }
    if (budget == 0U) {
      return false;
    }
    if (rollout_status(vet, env) == TASKS_ROLLOUT_RUNNING) {
      double s[FW_SHIFT_VET_TASK_DIM_MAX + 1];
      rollout_state(vet, env, s);
      const bool held = fw_pass_hold_observe(&vet->pass_hold, env->task, s, env->pass_hold_steps);
      double a = 0.0;
      double omega = 0.0;
      if (greedy(ctx, s, &a)) {
        // The learned policy as run.c drives it: the greedy action weighted by 1 + the imitation's
        // weight plus the shift where an action is known (held past an obstacle: none), 0 (hold
        // course) where none is.
        const fw_pair_shift_t* sh =
            &vet->shift[vet->driving != FW_SHIFT_VET_DRIVING_CANDIDATE ? 1 : (vet->stage == 0 ? 0 : 2)];
        omega = tasks_clamp_omega(fw_pair_policy_action(sh, env->task, env->obstacle_clearance_m, s, a, held),
                                  omega_max);
      }
      budget--;
      vet->periods++;
      rollout_step(vet, env, omega);
    }
    const int32_t status = rollout_status(vet, env);
    if (status != TASKS_ROLLOUT_RUNNING) {
      rollout_finished(vet, status != TASKS_ROLLOUT_GOAL, n_rollouts);
    }
  }
  return true;
}
