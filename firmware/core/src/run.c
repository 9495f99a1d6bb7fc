// SPDX-License-Identifier: MIT
// The run lifecycle (repositioning, runs, the schedule) and the action of each step.
#include "loop_internal.h"

#include <math.h>
#include <string.h>

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
  return tasks_episode_observe(&L->ep, &L->scan, fw_run_odom_pose(L), L->s) == 1;
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

static features_pose_t next_start_pose(fw_loop_t* L, const fw_run_plan_t* plan) {
  if (plan->kind == FW_RUN_EVAL) {
    return tasks_episode_eval_start(&L->ep, (uint32_t)plan->eval_index);
  }
  return tasks_episode_training_start(&L->ep, &L->pose_rng);
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
  const uint64_t run_seed = rng_splitmix64(&st);
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
  L->run_end_ready = true;
}

static void finish_run(fw_loop_t* L, bool reached_goal, int8_t end_reason, int32_t stop_reason, const char* why) {
  const bool aborted = end_reason == B21R_RUN_T_END_SAFETY_STOP || end_reason == B21R_RUN_T_END_SHUTDOWN;
  const bool training = L->plan.kind == FW_RUN_TRAINING && L->cfg.mode == FW_MODE_LEARN;
  const int32_t steps = reached_goal ? L->actions_taken : (int32_t)fw_run_step_limit(L);
  record_run_end(L, end_reason, stop_reason, why);
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
    if (sigma <= 0.0 || !(rng_uniform(&L->explore_rng) < L->cfg.explore_probability)) {
      return false;
    }
    const int64_t hold = (int64_t)floor(L->cfg.explore_hold_s / L->dt_s + 0.5);
    L->explore_steps_left = hold > 1 ? (int32_t)hold : 1;
    L->explore_offset = sigma * rng_normal(&L->explore_rng);
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
  if (learned_policy) {
    double value = 0.0;
    greedy_known = fw_learner_greedy(&L->learner, L->s, &greedy_action, &value);
    if (greedy_known) {
      greedy_action = tasks_clamp_omega(greedy_action, L->omega_max);
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
  if (!learned_policy) {
    if (fw_run_joystick_drives(L)) {
      a = L->teleop_rot_radps;
      source = B21R_EXPERIENCE_T_SOURCE_JOYSTICK;
    } else {
      a = advice;
      if (!evaluating && L->cfg.example_noise_radps > 0.0 && explore_offset(L, L->cfg.example_noise_radps, &offset)) {
        a += offset;  // phase-one dither: the learner sees actions around the example's
      }
    }
  } else if (greedy_known) {
    a = greedy_action;
    source = B21R_EXPERIENCE_T_SOURCE_GREEDY;
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
  *w_cmd = a;
  *v_cmd = tasks_episode_speed_mps(&L->ep);
  L->prev_source = source;
}
