// SPDX-License-Identifier: MIT
// The run lifecycle (repositioning, runs, the schedule) and the action of each step.
#include "loop_internal.h"

#include <math.h>
#include <string.h>

#include "tasks/recovery.h"

bool fw_run_is_corridor(const fw_loop_t* L) { return L->cfg.task == FW_TASK_CORRIDOR; }

uint32_t fw_run_step_limit(const fw_loop_t* L) { return tasks_episode_step_limit(&L->ep); }

bool fw_run_running(const fw_loop_t* L) {
  return L->mode == B21R_STATUS_T_MODE_RUNNING || L->mode == B21R_STATUS_T_MODE_EVALUATING;
}

bool fw_run_joystick_drives(const fw_loop_t* L) {
  return L->cfg.mode == FW_MODE_LEARN && L->cfg.phase_driver == FW_DRIVER_JOYSTICK &&
         L->plan.kind == FW_RUN_TRAINING && L->plan.phase == 1 && fw_run_running(L);
}

features_pose_t fw_run_odom_pose(const fw_loop_t* L) {
  const features_pose_t p = {L->run_odometry.x_m, L->run_odometry.y_m, L->run_odometry.theta_rad};
  return p;
}

void fw_run_odometry_update(fw_loop_t* L, bool run_starting) {
  if (run_starting) {
    L->run_odometry = L->base.odometry;  // its baseline: the counts of this tick
    rflex_odom_set_pose(&L->run_odometry, 0.0, 0.0, 0.0);
    return;
  }
  (void)rflex_odom_follow(&L->run_odometry, &L->base.odometry);
}

bool fw_run_observe(fw_loop_t* L) {
  if (L->cfg.state_rotation) {
    // The command of the previous tick after the limits: the rotation the base executes now, and
    // the one the acceleration limit measures this tick's change against. Known exactly, unlike
    // the odometry's noisy rate, so a lockstep run stays a function of its inputs.
    L->s[L->ep.state_dim] = L->cmd_w;
  }
  if (tasks_episode_observe(&L->ep, &L->scan, fw_run_odom_pose(L), L->s) != 1) {
    return false;
  }
  (void)fw_pass_hold_observe(&L->pass_hold, (fw_task_t)L->cfg.task, L->s,
                             (uint32_t)L->cfg.obstacle_pass_hold_steps);
  return true;
}

static const char* run_kind_name(const fw_loop_t* L) {
  if (L->plan.kind == FW_RUN_EVAL) {
    if (L->cfg.mode == FW_MODE_EVALUATE) {
      switch (L->cfg.evaluate_policy) {
        case FW_EVAL_OPTIMAL:
          return "eval(optimal)";
        case FW_EVAL_EXAMPLE:
          return "eval(example)";
        case FW_EVAL_HUMAN:
          return "eval(human)";
        default:
          return "eval(learned)";
      }
    }
    return "eval";
  }
  return "train";
}

// pair_runs: a phase-two training run (pair_phase_one: also a phase-one example run from
// pair_phase_one_from_run on) that starts a pair draws its pose; the one that ends the pair
// starts from the same pose (and replays the same exploration noise and, in phase one, the same
// example gain), so that the two runs differ mainly by their perturbation (the sensor noise of
// each run is its own).
static bool pair_run_planned(const fw_loop_t* L, const fw_run_plan_t* plan) {
  if (L->cfg.mode != FW_MODE_LEARN || plan->kind != FW_RUN_TRAINING) {
    return false;
  }
  if (plan->phase == 1) {
    return fw_config_pair_phase_one_active(&L->cfg) && plan->training_index >= L->cfg.pair_phase_one_from_run;
  }
  return plan->phase == 2 && fw_config_pair_runs_active(&L->cfg);
}

// Whether a planned pair run is the second of the pair under way: a pair never spans the switch
// from phase one to phase two (a first run left then stays without its pair).
static bool pair_continues(const fw_loop_t* L, const fw_run_plan_t* plan) {
  return L->pair_next_member == 1 && plan->phase == L->pair_phase;
}

static features_pose_t next_start_pose(fw_loop_t* L, const fw_run_plan_t* plan) {
  if (plan->kind == FW_RUN_EVAL) {
    return tasks_episode_eval_start(&L->ep, (uint32_t)plan->eval_index);
  }
  if (pair_run_planned(L, plan) && pair_continues(L, plan)) {
    return L->pair_pose;
  }
  const features_pose_t pose = tasks_episode_training_start(&L->ep, &L->pose_rng);
  if (pair_run_planned(L, plan)) {
    L->pair_pose = pose;
  }
  return pose;
}

// pair_runs: the run under way is one of a pair. The first run draws the perturbation and keeps
// the exploration stream's state; the second replays that stream (common random numbers: the
// same exploration noise, so the pair's difference in steps measures the perturbation).
static void pair_begin_run(fw_loop_t* L) {
  L->pair_member = -1;
  L->pair_run_vetoed = false;
  L->pair_model_ok = false;
  if (!fw_config_pair_learner(&L->cfg) || L->cfg.mode != FW_MODE_LEARN || L->plan.kind != FW_RUN_TRAINING) {
    return;
  }
  // Every training run's points carry its tag, so that runs can be ranked and fade with age: its
  // id, or one past the learner's tag when a resumed store is ahead of the ids (fw_pair_run_tag:
  // tags increase from run to run, so no two runs share one).
  L->run_tag = fw_pair_run_tag(L->run_id, fw_learner_run_tag(&L->learner));
  (void)fw_learner_set_run_tag(&L->learner, L->run_tag);
  if (!pair_run_planned(L, &L->plan)) {
    return;
  }
  L->pair_member = pair_continues(L, &L->plan) ? 1 : 0;
  L->pair_phase = L->plan.phase;
  if (L->pair_member == 0) {
    L->pair_gain = L->cfg.pair_gain_sigma * tasks_rng_normal(&L->explore_rng);
    L->pair_centring = L->cfg.pair_centring_sigma * tasks_rng_normal(&L->explore_rng);
    // Drawn only where it is perturbed, so that runs without it keep their noise.
    L->pair_imitation =
        L->cfg.pair_imitation_sigma > 0.0 ? L->cfg.pair_imitation_sigma * tasks_rng_normal(&L->explore_rng) : 0.0;
    L->pair_explore_rng = L->explore_rng;
  } else {
    L->explore_rng = L->pair_explore_rng;
  }
}

uint32_t fw_pair_run_tag(int32_t run_id, uint32_t current) {
  if (run_id >= 0 && (uint32_t)run_id > current) {
    return (uint32_t)run_id;
  }
  return current < UINT32_MAX ? current + 1U : current;
}

int32_t fw_pair_ranker_end(fw_pair_ranker_t* r, const fw_config_t* cfg, bool examples, int32_t member, bool aborted,
                           bool goal, int32_t steps, uint32_t tag, double gain, double centring, double imitation,
                           uint32_t tags[2], double weights[2]) {
  // Runs of the example policy are imitated whole when the ranking goes into the shift: their +
  // and - perturbations cancel in the imitation, and the shift was not in their commands.
  const double imitated = examples && cfg->pair_shift_rate > 0.0 ? 1.0 : 0.0;
  if (aborted || member == 0) {
    r->first_pending = !aborted;
    r->first_goal = goal;
    r->first_steps = steps;
    r->first_tag = tag;
    tags[0] = tag;
    weights[0] = imitated;
    return 1;
  }
  if (!r->first_pending) {
    return 0;
  }
  r->first_pending = false;
  tags[0] = r->first_tag;
  tags[1] = tag;
  const double d = (double)steps - (double)r->first_steps;  // > 0: the first run was faster
  if (cfg->pair_shift_rate > 0.0) {
    weights[0] = imitated;
    weights[1] = imitated;
    double u = 0.0;
    if (r->first_goal && goal) {
      u = tanh(d / cfg->pair_shift_tau_steps);
    } else if (r->first_goal != goal) {
      u = r->first_goal ? 1.0 : -1.0;
    }
    const double k = cfg->pair_shift_decay_pairs;
    fw_pair_shift_t* sh = &r->shift;
    const double rate = k > 0.0 ? cfg->pair_shift_rate * k / (k + (double)sh->pairs) : cfg->pair_shift_rate;
    sh->pairs += sh->pairs < UINT32_MAX ? 1U : 0U;
    const double step_gain = rate * u * gain;
    const double step_centring = rate * u * centring;
    const double step_imitation = rate * u * imitation;
    if (isfinite(step_gain) && isfinite(step_centring) && isfinite(step_imitation)) {  // (a damaged log's record: no step)
      sh->gain = fmin(FW_PAIR_SHIFT_MAX, fmax(-FW_PAIR_SHIFT_MAX, sh->gain + step_gain));
      // Among obstacles the bend's coefficient only widens the berth (b >= 0): a negative one
      // aims inside the cone pair_obstacle_clearance_m keeps, closer than the clearance, where
      // the model and the emulator part (FW_PAIR_OBSTACLE_CENTRING_MIN, fw/progress.h).
      const double centring_min = cfg->task == FW_TASK_OBSTACLES ? FW_PAIR_OBSTACLE_CENTRING_MIN : -FW_PAIR_SHIFT_MAX;
      sh->centring = fmin(FW_PAIR_SHIFT_MAX, fmax(centring_min, sh->centring + step_centring));
      sh->imitation = fmin(FW_PAIR_IMITATION_MAX, fmax(FW_PAIR_IMITATION_MIN, sh->imitation + step_imitation));
    }
    return 2;
  }
  weights[0] = r->first_goal ? 2.0 : 0.0;
  weights[1] = goal ? 2.0 : 0.0;
  if (r->first_goal && goal) {
    weights[0] = 2.0 / (1.0 + exp(-d / cfg->pair_tau_steps));
    weights[1] = 2.0 - weights[0];
  }
  return 2;
}

void fw_pair_basis(fw_task_t task, double obstacle_clearance_m, const double* s, double basis[2]) {
  if (task == FW_TASK_CORRIDOR) {
    basis[0] = s[2];
    basis[1] = s[1] - 0.5;
    return;
  }
  // Obstacles: the goal direction bent around the nearest obstacle (the target the reference law
  // steers for with the obstacle nearly dead ahead: the goal-side edge of its cone,
  // tasks_driver_obstacles; without a memory of the side, so a pure function of s that the vet's
  // model and the mirror image see alike), and the bend alone. The first term is the obstacle
  // task's target angle, as the corridor's first is its own: a shift along it turns harder toward
  // the course that keeps the clearance, not toward the obstacle; the second widens (+) or
  // tightens (-) the berth. (With the goal bearing itself as the first term a harder turn toward
  // the goal needed a matching wider bend, a ridge beside a cliff that the ranked pairs climbed
  // slowly: docs/LEARNING.md, "The bent goal direction as the first term".) The bent direction is
  // the cone's edge, obstacle bearing ± half-cone, within ±π (a visible obstacle lies within
  // ±π/2, the half-cone at most π/2): no wrap.
  const double goal_bearing = s[0];
  const double goal_distance = s[1];
  const double obstacle_bearing = s[2];
  const double obstacle_distance = s[3];
  double bend = 0.0;
  // No bend without an obstacle near (none visible: its distance is the features' far value) or
  // with it beyond the goal.
  if (obstacle_distance < FW_PAIR_OBSTACLE_RANGE_M && obstacle_distance < goal_distance) {
    const double half_cone = tasks_obstacles_cone_half_angle_rad(obstacle_clearance_m, obstacle_distance);
    const double rel = features_angle_wrap(goal_bearing - obstacle_bearing);
    if (fabs(rel) < half_cone && fabs(rel) > 0.0) {
      // The goal direction passes the obstacle closer than the clearance: the target is the
      // cone's edge on the goal's side (the goal exactly behind it has no side, as its mirror
      // image).
      bend = (rel > 0.0 ? half_cone : -half_cone) - rel;
    }
  }
  basis[0] = goal_bearing + bend;
  basis[1] = bend;
}

double fw_pair_shift_at(const fw_pair_shift_t* shift, fw_task_t task, double obstacle_clearance_m, const double* s) {
  double basis[2];
  fw_pair_basis(task, obstacle_clearance_m, s, basis);
  return shift->gain * basis[0] + shift->centring * basis[1];
}

double fw_pair_policy_action(const fw_pair_shift_t* shift, fw_task_t task, double obstacle_clearance_m, const double* s,
                             double greedy, bool held) {
  if (held) {
    return 0.0;
  }
  return (1.0 + shift->imitation) * greedy + fw_pair_shift_at(shift, task, obstacle_clearance_m, s);
}

// pair_runs: the run under way ended. A perturbed run is not imitated until its pair is ranked:
// the first run's points weigh 0 at once (so the second run does not imitate it either), and so
// do the points of a run that was aborted or is left without its pair. After the second run the
// pair is ranked (fw_pair_ranker_end): by default it proposes a step of the learned policy's shift
// toward the faster run (taken, cut or refused by the vet between runs, pair_shift_vet:
// learning.c) and both runs keep weight 0, so the imitation stays the teachers' and the shift
// alone carries what phase two found (imitating the shifted runs as well would add the shift
// twice). Phase one's pairs of example runs keep weight 1 by default: their + and - perturbations
// cancel in the imitation (a run left without its pair, or corrected by the filter, keeps its
// side's: a small bias, as rare as those runs). A run the safety filter had to correct (pair_vet)
// counts as one that missed the goal: its perturbation was predicted to reach a wall, and a
// policy that learns from it would lean on a filter that evaluations and greedy runs do not have.
// The ranking is O(1) arithmetic; learning.c applies the weights and vets the step between runs,
// and the shift in force acts from the next run. Every ranked pair passes the vet stage (a step
// that moves nothing is decided at once, at the cost of one between-run tick).
static void pair_finish_run(fw_loop_t* L, bool aborted, bool goal, int32_t steps) {
  if (L->pair_member < 0) {
    return;
  }
  goal = goal && !L->pair_run_vetoed;
  L->pair_runs_vetoed += L->pair_run_vetoed ? 1 : 0;
  L->pair_runs_missed += goal ? 0 : 1;
  const fw_pair_shift_t in_force = L->pair_ranker.shift;
  L->pair_weigh_n = fw_pair_ranker_end(&L->pair_ranker, &L->cfg, L->plan.phase == 1, L->pair_member, aborted, goal,
                                       steps, L->run_tag, L->pair_gain, L->pair_centring, L->pair_imitation,
                                       L->pair_weigh_tag, L->pair_weigh_w);
  if (L->pair_weigh_n == 2 && L->cfg.pair_shift_vet) {
    // pair_shift_vet: the step waits for the vet between runs (learning.c), which puts in force
    // the step, a half, a quarter or an eighth of it, or none; the pair counts at once.
    // Every term waits; only the pair count moves now.
    L->shift_proposed = L->pair_ranker.shift;
    L->pair_ranker.shift = in_force;
    L->pair_ranker.shift.pairs = L->shift_proposed.pairs;
    L->shift_vet_pending = true;
  }
  L->pair_next_member = aborted || L->pair_member == 1 ? 0 : 1;
  L->pair_member = -1;
}

// pair_runs: the perturbation of the run under way at state s (g, c on the task's two terms,
// fw_pair_basis, m on `own`, the unperturbed policy's own action: the greedy action before the
// shift, or the example's); + in the pair's first run, - in its second [rad/s].
static double pair_offset(const fw_loop_t* L, double own) {
  const double sign = L->pair_member == 0 ? 1.0 : -1.0;
  double basis[2];
  fw_pair_basis((fw_task_t)L->cfg.task, L->cfg.pair_obstacle_clearance_m, L->s, basis);
  return sign * (L->pair_gain * basis[0] + L->pair_centring * basis[1] + L->pair_imitation * own);
}

// pair_safety: a pair run's command a goes only if the recovery rollout (tasks/recovery.h) keeps
// pair_safety_margin_m to both walls; otherwise the unperturbed policy's own action (phase two:
// the learned policy's, when one is known; phase one: the example's), if it does, and else the
// recovery law's. The first correction vetoes the run (it counts as failed in its pair and its
// perturbation ends): whatever failed the check, the run needed the filter. Runs before the command is sent: three rollouts at most (30 periods each at the
// defaults).
// pair_safety: the recovery rollout from this tick's state keeps the margin after command a.
static bool pair_passes(const fw_loop_t* L, double a) {
  return tasks_corridor_recovery_clearance_m(&L->ep.corridor, &L->limits, L->dt_s, &L->ep.corridor_state, L->cmd_v,
                                             L->cmd_w, a, L->cfg.pair_safety_horizon_s) >= L->cfg.pair_safety_margin_m;
}

static void pair_vet(fw_loop_t* L, bool own_known, double own_action, int8_t own_source, double* a,
                     int8_t* source) {
  if (pair_passes(L, *a)) {
    return;
  }
  L->pair_safety_overrides++;
  L->pair_run_vetoed = true;
  if (own_known && pair_passes(L, own_action)) {
    *a = own_action;
    *source = own_source;
    return;
  }
  *a = tasks_corridor_recovery_action(&L->ep.corridor, &L->ep.corridor_state);
  *source = B21R_EXPERIENCE_T_SOURCE_ADVISOR;
  if (!pair_passes(L, *a)) {
    L->pair_safety_short++;  // even the recovery law is predicted to come closer than the margin
  }
}

// pair_safety: the state at the last decision of a pair run and the command in force before it,
// for dead reckoning through periods without a new scan (fw_run_pair_hold).
static void pair_keep_model(fw_loop_t* L) {
  L->pair_model = L->ep.corridor_state;
  L->pair_model_v = L->cmd_v;
  L->pair_model_w = L->cmd_w;
  L->pair_model_ok = true;
  L->pair_model_periods = 0;
}

bool fw_run_pair_hold(fw_loop_t* L, double* v_cmd, double* w_cmd) {
  // Dead reckoning drifts: beyond the rollout's horizon (features unusable while scans arrive;
  // a silent laser stops the robot sooner) the command is held as outside pair runs.
  if (L->pair_member < 0 || !L->cfg.pair_safety || !L->pair_model_ok ||
      (double)L->pair_model_periods * L->dt_s >= L->cfg.pair_safety_horizon_s) {
    return false;
  }
  features_corridor_t next;
  if (!tasks_corridor_recovery_predict(&L->ep.corridor, &L->limits, L->dt_s, &L->pair_model, L->pair_model_v,
                                       L->pair_model_w, L->cmd_v, L->cmd_w, &next)) {
    return false;
  }
  L->pair_model = next;
  L->pair_model_v = L->cmd_v;
  L->pair_model_w = L->cmd_w;
  L->pair_model_periods++;
  *v_cmd = tasks_corridor_speed_mps(&L->ep.corridor, &next);
  *w_cmd = tasks_corridor_recovery_action(&L->ep.corridor, &next);
  // The recovery law drove this period: the action the next transition records is its command
  // (act() keeps the command sent), so it is recorded, and counted, as the advisor's.
  L->prev_source = B21R_EXPERIENCE_T_SOURCE_ADVISOR;
  L->pair_safety_held++;
  return true;
}

// The id begin_run gives the next run (B21R_RUN.run_id), as the start-pose request passes it on.
static uint64_t next_run_id(const fw_loop_t* L) { return (uint64_t)(L->run_id + 1); }

static void begin_run(fw_loop_t* L) {
  L->run_id++;
  L->start_pose_chosen = false;
  L->explore_steps_left = 0;
  L->actions_taken = 0;
  L->have_prev = false;
  L->run_return = 0.0;
  L->run_first_seq = L->exp_seq;
  memset(L->run_steps_by_source, 0, sizeof L->run_steps_by_source);
  // The driver of this run: the example policy in phase one, the advisor in phase two, or the
  // evaluated reference. Its stream is seeded per run, so a run does not depend on earlier ones.
  uint64_t st = L->driver_seed_base ^ ((uint64_t)(uint32_t)L->run_id * 0x9E3779B97F4A7C15ULL);
  uint64_t run_seed = tasks_rng_splitmix64(&st);
  if (pair_run_planned(L, &L->plan) && L->plan.phase == 1) {
    // A phase-one pair probes the example policy at one gain: its second run repeats the first's.
    if (pair_continues(L, &L->plan)) {
      run_seed = L->pair_driver_seed;
    } else {
      L->pair_driver_seed = run_seed;
    }
  }
  tasks_driver_kind_t kind = TASKS_DRIVER_PROPORTIONAL;
  if (L->cfg.mode == FW_MODE_EVALUATE && L->cfg.evaluate_policy == FW_EVAL_OPTIMAL) {
    kind = TASKS_DRIVER_OPTIMAL;
  } else if (L->cfg.mode == FW_MODE_EVALUATE && L->cfg.evaluate_policy == FW_EVAL_HUMAN) {
    kind = TASKS_DRIVER_HUMAN;
  } else if (L->cfg.phase_driver == FW_DRIVER_HUMAN && L->plan.kind == FW_RUN_TRAINING && L->plan.phase == 1) {
    kind = TASKS_DRIVER_HUMAN;
  }
  tasks_driver_begin_run(&L->driver, kind, fw_run_is_corridor(L) ? TASKS_TASK_CORRIDOR : TASKS_TASK_OBSTACLES,
                         L->omega_max, run_seed);
  const double task_lo = fw_run_is_corridor(L) ? TASKS_PROPORTIONAL_CORRIDOR_GAIN_MIN : TASKS_PROPORTIONAL_OBSTACLES_GAIN_MIN;
  const double task_hi = fw_run_is_corridor(L) ? TASKS_PROPORTIONAL_CORRIDOR_GAIN_MAX : TASKS_PROPORTIONAL_OBSTACLES_GAIN_MAX;
  const bool ranged = L->cfg.example_gain_range_n == 2;
  const double lo = ranged ? L->cfg.example_gain_range[0] : task_lo;
  const double hi = ranged ? L->cfg.example_gain_range[1] : task_hi;
  if (ranged && kind == TASKS_DRIVER_PROPORTIONAL) {
    // The configured range takes the place of the task's: the run's draw is rescaled, not drawn
    // again, so every other stream (start poses, noise) stays the same as with the task's range.
    L->driver.gain = lo + (L->driver.gain - task_lo) * ((hi - lo) / (task_hi - task_lo));
  }
  if (L->cfg.mode == FW_MODE_EVALUATE && L->cfg.evaluate_policy == FW_EVAL_EXAMPLE) {
    // The example policy at a fixed gain: the configured one, or the middle of the range the
    // training runs draw from.
    L->driver.gain = L->cfg.evaluate_example_gain > 0.0 ? L->cfg.evaluate_example_gain : 0.5 * (lo + hi);
  }
  if (!fw_run_is_corridor(L) && kind == TASKS_DRIVER_PROPORTIONAL) {
    L->driver.law[0] = L->driver.gain;  // the obstacle example policy's law holds its gain
  }
  pair_begin_run(L);
  L->mode = L->plan.kind == FW_RUN_EVAL ? B21R_STATUS_T_MODE_EVALUATING : B21R_STATUS_T_MODE_RUNNING;
  L->status_now = true;
}

void fw_run_begin_repositioning(fw_loop_t* L) {
  L->mode = B21R_STATUS_T_MODE_REPOSITIONING;
  // The emulator places the robot again once the learner is done, even when a stop already put
  // it there to free a bumper: the run then starts the same number of periods after its reset
  // whatever happened before (see fw_run_reposition). A person placed it once and has confirmed.
  L->pose_requested = L->stopped_pose_requested && L->cfg.reposition != FW_REPOSITION_EMULATOR;
  L->stopped_pose_requested = false;
  L->stopped_pose_pending = false;
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
  if (!L->start_pose_chosen) {
    L->start_pose = next_start_pose(L, &L->plan);
    L->start_pose_chosen = true;
  }
}

// The run's end record; published by fw_out_run_end once the run's last experience is out.
static void record_run_end(fw_loop_t* L, int8_t end_reason, int32_t stop_reason, const char* why) {
  fw_out_run_end(L);  // one still waiting (never expected: at most one run ends per tick)
  b21r_run_t* r = &L->run_end;
  memset(r, 0, sizeof *r);
  const bool eval = L->plan.kind == FW_RUN_EVAL;
  r->utime = L->utime;
  r->run_id = L->run_id;
  r->kind = eval ? B21R_RUN_T_KIND_EVALUATION : B21R_RUN_T_KIND_TRAINING;
  r->phase = (int8_t)L->plan.phase;
  r->task = (int8_t)L->cfg.task;
  r->training_index = eval ? -1 : L->plan.training_index;
  r->eval_block = eval ? L->sched.p.eval_blocks : -1;  // blocks finished so far = this block's number
  r->eval_index = eval ? L->plan.eval_index : -1;
  r->start_x_m = L->start_pose.x_m;
  r->start_y_m = L->start_pose.y_m;
  r->start_theta_rad = L->start_pose.theta_rad;
  r->end_reason = end_reason;
  r->stop_reason = (int8_t)stop_reason;
  r->detail = (char*)(uintptr_t)why;
  r->steps = L->actions_taken;
  r->total_reward = L->run_return;
  r->first_seq = L->run_first_seq;
  for (int i = 0; i < 5; ++i) {
    r->steps_by_source[i] = L->run_steps_by_source[i];
  }
  r->pair_member = (int8_t)L->pair_member;  // still the run's: pair_finish_run comes after
  r->pair_vetoed = L->pair_run_vetoed;
  r->pair_gain = L->pair_member >= 0 ? L->pair_gain : 0.0;
  r->pair_centring = L->pair_member >= 0 ? L->pair_centring : 0.0;
  r->pair_imitation = L->pair_member >= 0 ? L->pair_imitation : 0.0;
  const fw_pair_shift_t* shift = &L->pair_ranker.shift;  // pair_finish_run, which may move it, comes after
  r->shift_gain = shift->gain;
  r->shift_centring = shift->centring;
  r->shift_imitation = shift->imitation;
  r->shift_pairs = (int32_t)(shift->pairs <= (uint32_t)INT32_MAX ? shift->pairs : (uint32_t)INT32_MAX);
  L->run_end_ready = true;
}

static void finish_run(fw_loop_t* L, bool reached_goal, int8_t end_reason, int32_t stop_reason, const char* why) {
  const bool aborted = end_reason == B21R_RUN_T_END_SAFETY_STOP || end_reason == B21R_RUN_T_END_SHUTDOWN;
  const bool training = L->plan.kind == FW_RUN_TRAINING && L->cfg.mode == FW_MODE_LEARN;
  const int32_t steps = reached_goal ? L->actions_taken : (int32_t)fw_run_step_limit(L);
  record_run_end(L, end_reason, stop_reason, why);
  pair_finish_run(L, aborted, reached_goal, steps);
  fw_eval_block_t block;
  const bool block_done = fw_schedule_finish_run(&L->sched, steps, reached_goal, aborted, &block);
  if (aborted) {
    L->runs_aborted++;
  } else {
    L->runs_finished++;
    L->last_run_steps = L->actions_taken;
    L->last_run_goal = reached_goal;
  }
  if (training) {
    // The replay of the run and the checkpoint run after this tick's command, in slices; the
    // run's progress line waits until its checkpoint is written (see learning.c).
    fw_learning_run_ended(L);
  }
  if (L->cfg.progress) {
    fw_loop_log(L, 1, "run %4d  phase %d  %-13s %-9s %4d steps  (%s)  store %u/%u", L->run_id, L->plan.phase,
                run_kind_name(L), aborted ? "ABORTED" : (reached_goal ? "goal" : "no goal"), L->actions_taken, why,
                fw_learner_stats(&L->learner).fill, fw_learner_stats(&L->learner).capacity);
  }
  if (block_done) {
    L->last_block = block;
    fw_out_eval(L, &block);
    if (L->cfg.progress) {
      fw_loop_log(L, 1, "EVAL block %2d after %3d training runs (phase %d): %2d/%d reached the goal, mean %.1f +- %.1f steps",
                  block.block, block.training_runs, block.phase, block.successes, block.n_starts, block.mean_steps,
                  block.ci95_halfwidth);
      if (L->sched.p.phase == 2 && block.phase == 1) {
        fw_loop_log(L, 1, "PHASE TWO: the learned policy drives from now on");
      }
    }
  }
  fw_run_begin_repositioning(L);
}

void fw_run_abort(fw_loop_t* L, int8_t end_reason, int32_t stop_reason, const char* why) {
  if (fw_run_running(L)) {
    finish_run(L, false, end_reason, stop_reason, why);
  }
}

bool fw_run_reposition(fw_loop_t* L, bool state_ok, double* v, double* w) {
  if (!L->pose_requested) {
    if (L->retry_countdown > 0) {
      L->retry_countdown--;
      return false;
    }
    // The emulator places the robot (and restarts the run's sensor noise) only once the learner
    // has finished with the last run: the run then starts a fixed number of periods after the
    // reset, so its scans do not depend on how long the learner took (other learners, other
    // settings). A person is asked at once: they place the robot while the learner works.
    if (L->cfg.reposition == FW_REPOSITION_EMULATOR && !fw_learning_idle(L)) {
      return false;
    }
    const int r = L->io.vt->request_start_pose == NULL
                      ? 0
                      : L->io.vt->request_start_pose(L->io.user, L->start_pose.x_m, L->start_pose.y_m,
                                                     L->start_pose.theta_rad, next_run_id(L));
    if (r == 1) {
      L->pose_requested = true;
      // Lockstep: the data of the next period is already taken at the new pose. Real time: let a
      // few scans pass that may predate the reset.
      L->settle_ticks = L->cfg.lockstep ? 0 : 3;
    } else if (r == 2) {
      // Under way: asked again (same pose) next tick; the tick does not wait for the answer.
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
    return false;
  }
  if (L->settle_ticks > 0) {
    L->settle_ticks--;
    return false;
  }
  // The run starts on a new scan at the start pose (confirmed by the operator where a person
  // places the robot) once the learner has finished with the last run.
  if (L->scan_new && (!L->awaiting_confirm || L->confirm_pending) && state_ok && fw_learning_idle(L)) {
    begin_run(L);
    fw_run_step(L, 0, v, w);
    return true;
  }
  return false;
}

void fw_run_request_pose_while_stopped(fw_loop_t* L) {
  // A bumped robot cannot clear its bumper by itself: with the emulator, reset it to the next
  // start pose while stopped (on the robot the operator frees it).
  if (L->safety.reason != FW_STOP_BUMPER || L->stopped_pose_requested || L->io.vt->request_start_pose == NULL ||
      L->cfg.reposition != FW_REPOSITION_EMULATOR) {
    return;
  }
  if (!L->start_pose_chosen) {
    const fw_run_plan_t plan = fw_schedule_next(&L->sched);
    if (plan.kind == FW_RUN_NONE) {
      return;
    }
    L->start_pose = next_start_pose(L, &plan);
    L->start_pose_chosen = true;
  }
  const int r = L->io.vt->request_start_pose(L->io.user, L->start_pose.x_m, L->start_pose.y_m,
                                             L->start_pose.theta_rad, next_run_id(L));
  L->stopped_pose_pending = r == 2;
  L->stopped_pose_requested = r == 1;
}

// Exploration of a training step: with explore_probability per step a segment starts that adds
// one offset ~ N(0, sigma) to the actions for explore_hold_s (at least one step). Returns true
// (with the offset) while a segment is running.
static bool explore_offset(fw_loop_t* L, double sigma, double* offset) {
  if (L->explore_steps_left == 0) {
    if (sigma <= 0.0 || !(tasks_rng_uniform(&L->explore_rng) < L->cfg.explore_probability)) {
      return false;
    }
    const int64_t hold = (int64_t)floor(L->cfg.explore_hold_s / L->dt_s + 0.5);
    L->explore_steps_left = hold > 1 ? (int32_t)hold : 1;
    L->explore_offset = sigma * tasks_rng_normal(&L->explore_rng);
  }
  L->explore_steps_left--;
  *offset = L->explore_offset;
  return true;
}

// The transition (prev_s, prev_a) -> s with its reward waits for learning.c, after the command.
static void queue_transition(fw_loop_t* L, const tasks_outcome_t* o, bool learning) {
  fw_pending_step_t* p = &L->pending;
  p->active = true;
  p->learning = learning;
  p->need_greedy = true;
  p->q_next = 0.0;
  p->reward = o->reward;
  p->terminal = o->terminal != 0;
  p->end_reason = (int8_t)o->reason;
  memcpy(p->s, L->prev_s, sizeof p->s);
  memcpy(p->s_next, L->s, sizeof p->s_next);
  p->a = L->prev_a;
  p->v = L->prev_v;
  p->source = L->prev_source;
  p->run_id = L->run_id;
  p->step_id = L->actions_taken - 1;
  p->phase = L->plan.phase;
  p->evaluating = L->plan.kind == FW_RUN_EVAL;
}

void fw_run_step(fw_loop_t* L, uint8_t contact, double* v_cmd, double* w_cmd) {
  const bool evaluating = L->plan.kind == FW_RUN_EVAL;
  const bool learning = !evaluating && L->cfg.mode == FW_MODE_LEARN;
  const bool learned_policy =
      (evaluating && !(L->cfg.mode == FW_MODE_EVALUATE && L->cfg.evaluate_policy != FW_EVAL_LEARNED)) ||
      (!evaluating && L->plan.phase == 2);
  if (L->have_prev) {
    const tasks_outcome_t o = tasks_episode_outcome(&L->ep, contact, (uint32_t)L->actions_taken);
    queue_transition(L, &o, learning);
    L->steps++;
    L->run_return += o.reward;
    if (o.end_run) {
      *v_cmd = 0.0;
      *w_cmd = 0.0;
      const bool goal = o.reason == TASKS_END_GOAL;
      const bool collision = o.reason == TASKS_END_COLLISION;
      finish_run(L, goal,
                 goal ? B21R_RUN_T_END_GOAL : (collision ? B21R_RUN_T_END_COLLISION : B21R_RUN_T_END_STEP_LIMIT), 0,
                 goal ? "goal" : (collision ? "collision" : "step limit"));
      return;
    }
  }
  // The greedy search at s chooses the learned policy's action; its value is also the q' of the
  // transition into s (learned after the command), so it runs once.
  bool greedy_known = false;
  double greedy_action = 0.0;
  double greedy_imitated = 0.0;  // HEDGER's greedy action itself, before the shift
  if (learned_policy) {
    double value = 0.0;
    greedy_known = fw_learner_greedy(&L->learner, L->s, &greedy_imitated, &value);
    if (greedy_known) {
      // The learned policy: HEDGER's greedy action, weighted by 1 + the imitation's weight, plus
      // the shift the ranked pairs learned (both 0 until a pair is ranked). The value stays the
      // greedy action's (the learning target).
      greedy_action = tasks_clamp_omega(
          fw_pair_policy_action(&L->pair_ranker.shift, (fw_task_t)L->cfg.task, L->cfg.pair_obstacle_clearance_m, L->s,
                                greedy_imitated, fw_pass_hold_active(&L->pass_hold)), L->omega_max);
    }
    if (L->pending.active) {
      L->pending.need_greedy = false;
      L->pending.q_next = value;  // the default value (0) when no action is known
    }
  }
  // The driver runs every step (even when it only advises) so its state follows the run.
  const double advice = tasks_episode_driver_action(&L->ep, &L->driver);
  double a = 0.0;
  double offset = 0.0;
  int8_t source = B21R_EXPERIENCE_T_SOURCE_EXAMPLE;
  // The unperturbed policy's command, for the safety filter of a pair run (pair_vet).
  bool own_known = greedy_known;
  double own_action = greedy_action;
  int8_t own_source = greedy_known ? B21R_EXPERIENCE_T_SOURCE_GREEDY : B21R_EXPERIENCE_T_SOURCE_EXAMPLE;
  if (!learned_policy) {
    if (fw_run_joystick_drives(L)) {
      a = L->teleop_rot_radps;
      source = B21R_EXPERIENCE_T_SOURCE_JOYSTICK;
    } else {
      a = advice;
      if (!evaluating && L->cfg.example_noise_radps > 0.0 && explore_offset(L, L->cfg.example_noise_radps, &offset)) {
        a += offset;  // phase-one dither: the learner sees actions around the example's
      }
      own_known = true;  // the example's command: the safety filter's first fallback in a pair run
      own_action = a;
      if (!evaluating && L->pair_member >= 0 && !L->pair_run_vetoed) {
        a = tasks_clamp_omega(a + pair_offset(L, advice), L->omega_max);  // a phase-one pair run
      }
    }
  } else if (greedy_known) {
    a = greedy_action;
    source = B21R_EXPERIENCE_T_SOURCE_GREEDY;
    if (!evaluating && L->pair_member >= 0 && !L->pair_run_vetoed && !fw_pass_hold_active(&L->pass_hold)) {
      // A pair run: the learned policy with the pair's perturbation, within the action bounds.
      // Once the safety filter has corrected it the run counts as failed: the learned policy
      // drives the rest of the way, which ends it sooner than the perturbation would. (Held
      // past an obstacle, both runs of the pair hold course unperturbed; the exploration noise
      // below still applies, as everywhere in training.)
      a = tasks_clamp_omega(a + pair_offset(L, greedy_imitated), L->omega_max);
      source = B21R_EXPERIENCE_T_SOURCE_EXPLORATION;
    }
    if (!evaluating && explore_offset(L, L->cfg.explore_sigma_radps, &offset)) {
      a += offset;
      source = B21R_EXPERIENCE_T_SOURCE_EXPLORATION;
    }
  } else if (!evaluating && L->cfg.advisor) {
    a = advice;  // the learner knows no action here: the example policy advises
    source = B21R_EXPERIENCE_T_SOURCE_ADVISOR;
  } else {
    a = 0.0;  // nothing known: hold course (evaluations measure the learned policy alone)
    source = B21R_EXPERIENCE_T_SOURCE_GREEDY;
  }
  // The safety filter is the corridor's: the obstacle task has none (its pairs run in the
  // emulator only, fw_config_validate_program; the vet of the shift covers its evaluations).
  if (!evaluating && L->pair_member >= 0 && L->cfg.pair_safety && fw_run_is_corridor(L)) {
    pair_vet(L, own_known, own_action, own_source, &a, &source);  // every command of a pair run
    pair_keep_model(L);
  }
  *w_cmd = a;
  *v_cmd = tasks_episode_speed_mps(&L->ep);
  L->prev_source = source;
}
