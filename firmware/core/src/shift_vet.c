// SPDX-License-Identifier: MIT
// The vet of a step of the learned policy's shift (fw/shift_vet.h): the learned policy with the
// step, driven on the safety filter's kinematic model from the last training runs' starts.
#include "fw/shift_vet.h"

#include "loop_internal.h"

#include <math.h>
#include <string.h>

void fw_shift_vet_env_init(fw_shift_vet_env_t* env, const fw_config_t* cfg) {
  memset(env, 0, sizeof *env);
  tasks_obstacles_spec_t obstacles;
  fw_loop_task_specs(cfg, &env->spec, &obstacles, &env->lim);
  env->dt_s = env->spec.dt_s;
  env->margin_m = cfg->pair_safety_margin_m;
  env->state_rotation = cfg->state_rotation;
  const int32_t cap = cfg->pair_shift_vet_starts;
  env->capacity = cap < 1 ? 1U : (cap > FW_SHIFT_VET_STARTS_MAX ? FW_SHIFT_VET_STARTS_MAX : (uint32_t)cap);
}

void fw_shift_vet_starts_add(fw_shift_vet_starts_t* starts, const fw_shift_vet_env_t* env, const double* state) {
  const double omega = env->state_rotation ? state[3] : 0.0;
  if (!isfinite(state[0]) || !isfinite(state[1]) || !isfinite(state[2]) || !isfinite(omega)) {
    return;
  }
  const uint32_t cap = env->capacity;
  const uint32_t slot = starts->next < cap ? starts->next : 0U;
  memcpy(starts->state[slot], state, sizeof starts->state[slot]);
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
  vet->shift[2] = *in_force;
  vet->shift[2].gain = in_force->gain + 0.5 * (proposed->gain - in_force->gain);
  vet->shift[2].centring = in_force->centring + 0.5 * (proposed->centring - in_force->centring);
  vet->stage = 0;
  if (!(proposed->gain < in_force->gain || proposed->gain > in_force->gain ||
        proposed->centring < in_force->centring || proposed->centring > in_force->centring)) {
    decide(vet, FW_SHIFT_STEP_TAKEN);
  }
}

bool fw_shift_vet_done(const fw_shift_vet_t* vet) { return vet->stage < 0; }

// Rollout k of a start set: start k / 2, mirrored when k is odd (the corridor is symmetric:
// lateral fraction 1 - l, target angle and rotation negated).
static void begin_rollout(fw_shift_vet_t* vet, const fw_shift_vet_env_t* env, const fw_shift_vet_starts_t* starts,
                          uint32_t k) {
  const uint32_t i = k / 2U;
  double s[3] = {starts->state[i][0], starts->state[i][1], starts->state[i][2]};
  double omega = starts->omega_radps[i];
  if ((k & 1U) != 0U) {
    s[1] = 1.0 - s[1];
    s[2] = -s[2];
    omega = -omega;
  }
  (void)tasks_corridor_rollout_begin(&vet->ro, &env->spec, s, omega);
  vet->rolling = true;
}

// The candidate under test fails from a start where the shift in force reaches the goal: not
// taken. After the proposed shift half the step is tried (from the first start again); after
// half the step the shift stays.
static void candidate_dropped(fw_shift_vet_t* vet) {
  if (vet->stage == 0) {
    vet->stage = 1;
    vet->start = 0;
  } else {
    decide(vet, FW_SHIFT_STEP_REFUSED);
  }
}

// A rollout ended (status failed or not): what the vet does next.
static void rollout_finished(fw_shift_vet_t* vet, bool failed) {
  vet->rolling = false;
  const int32_t candidate = vet->stage == 0 ? 0 : 2;
  const uint32_t k = vet->start;
  if (vet->checking_in_force) {
    vet->checking_in_force = false;
    vet->failures[1] += failed ? 1 : 0;
    vet->in_force_failed[k] = failed ? 1 : -1;
    if (!failed) {
      candidate_dropped(vet);
      return;
    }
    vet->start++;
    return;
  }
  vet->failures[candidate] += failed ? 1 : 0;
  if (failed && vet->in_force_failed[k] == 0) {
    vet->checking_in_force = true;  // the shift in force from the same start decides
    return;
  }
  if (failed && vet->in_force_failed[k] < 0) {
    candidate_dropped(vet);
    return;
  }
  vet->start++;
}

bool fw_shift_vet_hedger_greedy(void* hedger, const double* s, double* action) {
  return hedger != NULL && hedger_greedy((hedger_t*)hedger, s, action, NULL, NULL) == HEDGER_OK;
}

bool fw_shift_vet_step(fw_shift_vet_t* vet, fw_shift_vet_greedy_fn greedy, void* ctx, const fw_shift_vet_env_t* env,
                       const fw_shift_vet_starts_t* starts, uint32_t periods) {
  const double omega_max = env->spec.omega_max_radps;
  const uint32_t n_rollouts = 2U * starts->n;
  uint32_t budget = periods;
  while (vet->stage >= 0) {
    if (!vet->rolling) {
      if (vet->start >= n_rollouts) {
        // The candidate failed nowhere the shift in force did not.
        decide(vet, vet->stage == 0 ? FW_SHIFT_STEP_TAKEN : FW_SHIFT_STEP_HALVED);
        break;
      }
      begin_rollout(vet, env, starts, vet->start);
    }
    if (budget == 0U) {
      return false;
    }
    tasks_corridor_rollout_t* ro = &vet->ro;
    if (ro->status == TASKS_ROLLOUT_RUNNING) {
      double s[4];
      features_corridor_state(&ro->f, s);
      s[3] = ro->omega_radps;
      double a = 0.0;
      double omega = 0.0;
      if (greedy(ctx, s, &a)) {
        // The learned policy as run.c drives it: the greedy action plus the shift where an action
        // is known, 0 (hold course) where none is.
        const fw_pair_shift_t* sh = &vet->shift[vet->checking_in_force ? 1 : (vet->stage == 0 ? 0 : 2)];
        omega = tasks_clamp_omega(a + fw_pair_shift_at(sh, s), omega_max);
      }
      budget--;
      vet->periods++;
      (void)tasks_corridor_rollout_step(ro, &env->spec, &env->lim, env->dt_s, omega, env->margin_m,
                                        env->spec.step_limit);
    }
    if (ro->status != TASKS_ROLLOUT_RUNNING) {
      rollout_finished(vet, ro->status != TASKS_ROLLOUT_GOAL);
    }
  }
  return true;
}
