// SPDX-License-Identifier: MIT
// The run lifecycle around the learning framework: repositioning and start poses, the task's
// driver of each run (the example policy, a simulated person, the evaluated reference), the
// observation of each step, and the run's end record. Who acts and what is learned is the
// framework's (lib/learn).
#include "run.h"
#include "learning.h"
#include "outputs.h"

#include <math.h>
#include <string.h>

bool fw_run_running(const fw_loop_t* L) {
  return L->mode == B21R_STATUS_T_MODE_RUNNING || L->mode == B21R_STATUS_T_MODE_EVALUATING;
}

bool fw_run_joystick_drives(const fw_loop_t* L) { return fw_run_running(L) && learn_joystick_drives(L->agent); }

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

bool fw_run_observe(fw_loop_t* L, bool* finite) {
  // The task's features (kept as they were when the scan is unusable), and the learner's state
  // from them and the command of the previous tick after the limits (the rotation the base
  // executes now).
  const bool usable = tasks_episode_observe(&L->ep, &L->scan, fw_run_odom_pose(L), L->features) == 1;
  *finite = learn_observe(L->agent, L->features, L->cmd_w);
  return usable;
}

static const char* run_kind_name(const fw_loop_t* L, const learn_plan_t* plan) {
  if (plan->kind == LEARN_RUN_EVAL) {
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

static features_pose_t next_start_pose(fw_loop_t* L, const learn_plan_t* plan) {
  if (plan->kind == LEARN_RUN_EVAL) {
    return tasks_episode_eval_start(&L->ep, (uint32_t)plan->eval_index);
  }
  if (learn_run_repeats_start(L->agent)) {
    return L->training_start;  // a ranked pair's second run (policy = select): its first's pose
  }
  L->training_start = tasks_episode_training_start(&L->ep, &L->pose_rng);
  return L->training_start;
}

// The id the next run gets (B21R_RUN.run_id), as the start-pose request passes it on.
static uint64_t next_run_id(const fw_loop_t* L) { return (uint64_t)(learn_run_id(L->agent) + 1); }

static void begin_run(fw_loop_t* L) {
  learn_begin_run(L->agent);
  const learn_plan_t plan = learn_plan(L->agent);
  const int32_t run_id = learn_run_id(L->agent);
  L->start_pose_chosen = false;
  L->run_first_seq = L->exp_seq;
  // The driver of this run: the example policy in phase one, the advisor in phase two, or the
  // evaluated reference. Its stream is seeded per run, so a run does not depend on earlier ones.
  uint64_t st = L->driver_seed_base ^ ((uint64_t)(uint32_t)run_id * 0x9E3779B97F4A7C15ULL);
  const uint64_t run_seed = rng_splitmix64(&st);
  tasks_driver_kind_t kind = TASKS_DRIVER_PROPORTIONAL;
  if (L->cfg.mode == FW_MODE_EVALUATE && L->cfg.evaluate_policy == FW_EVAL_OPTIMAL) {
    kind = TASKS_DRIVER_OPTIMAL;
  } else if (L->cfg.mode == FW_MODE_EVALUATE && L->cfg.evaluate_policy == FW_EVAL_HUMAN) {
    kind = TASKS_DRIVER_HUMAN;
  } else if (L->cfg.phase_driver == FW_DRIVER_HUMAN && plan.kind == LEARN_RUN_TRAINING && plan.phase == 1) {
    kind = TASKS_DRIVER_HUMAN;
  }
  tasks_episode_driver_begin(&L->ep, &L->driver, kind, L->omega_max, run_seed);
  const double task_lo = L->ep.decl->gain_min;
  const double task_hi = L->ep.decl->gain_max;
  const bool ranged = L->cfg.example_gain_range_n == 2;
  const double lo = ranged ? L->cfg.example_gain_range[0] : task_lo;
  const double hi = ranged ? L->cfg.example_gain_range[1] : task_hi;
  if (ranged && kind == TASKS_DRIVER_PROPORTIONAL) {
    // The configured range takes the place of the task's: the run's draw is rescaled, not drawn
    // again, so every other stream (start poses, noise) stays the same as with the task's range.
    tasks_driver_set_gain(&L->driver, L->ep.decl, lo + (L->driver.gain - task_lo) * ((hi - lo) / (task_hi - task_lo)));
  }
  if (L->cfg.mode == FW_MODE_EVALUATE && L->cfg.evaluate_policy == FW_EVAL_EXAMPLE) {
    // The example policy at a fixed gain: the configured one, or the middle of the range the
    // training runs draw from.
    tasks_driver_set_gain(&L->driver, L->ep.decl,
                          L->cfg.evaluate_example_gain > 0.0 ? L->cfg.evaluate_example_gain : 0.5 * (lo + hi));
  }
  L->mode = plan.kind == LEARN_RUN_EVAL ? B21R_STATUS_T_MODE_EVALUATING : B21R_STATUS_T_MODE_RUNNING;
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
  const learn_plan_t plan = learn_plan(L->agent);
  L->status_now = true;
  if (plan.kind == LEARN_RUN_NONE) {
    L->mode = B21R_STATUS_T_MODE_DONE;
    L->done = true;
    L->exit_status = 0;
    const learn_schedule_progress_t* p = &learn_schedule(L->agent)->p;
    fw_loop_log(L, 1, "schedule complete: %d training runs, %d evaluation blocks", p->training_runs, p->eval_blocks);
    return;
  }
  if (!L->start_pose_chosen) {
    L->start_pose = next_start_pose(L, &plan);
    L->start_pose_chosen = true;
  }
}

// The run's end record; published by fw_out_run_end once the run's last experience is out.
static void record_run_end(fw_loop_t* L, const learn_run_end_t* e, int8_t end_reason, int32_t stop_reason,
                           const char* why) {
  fw_out_run_end(L);  // one still waiting (never expected: at most one run ends per tick)
  b21r_run_t* r = &L->run_end;
  memset(r, 0, sizeof *r);
  const bool eval = e->plan.kind == LEARN_RUN_EVAL;
  r->utime = L->utime;
  r->run_id = e->run_id;
  r->kind = eval ? B21R_RUN_T_KIND_EVALUATION : B21R_RUN_T_KIND_TRAINING;
  r->phase = (int8_t)e->plan.phase;
  r->task = (int8_t)L->cfg.task;
  r->training_index = eval ? -1 : e->plan.training_index;
  r->eval_block = e->eval_block;
  r->eval_index = eval ? e->plan.eval_index : -1;
  r->start_x_m = L->start_pose.x_m;
  r->start_y_m = L->start_pose.y_m;
  r->start_theta_rad = L->start_pose.theta_rad;
  r->end_reason = end_reason;
  r->stop_reason = (int8_t)stop_reason;
  r->detail = (char*)(uintptr_t)why;
  r->steps = e->steps;
  r->total_reward = e->total_reward;
  r->first_seq = L->run_first_seq;
  for (int i = 0; i < 5; ++i) {
    r->steps_by_source[i] = e->steps_by_source[i];
  }
  L->run_end_ready = true;
}

// The framework has ended the run (e): its record, counts, progress lines and evaluation block.
static void finish_run(fw_loop_t* L, const learn_run_end_t* e, int8_t end_reason, int32_t stop_reason,
                       const char* why) {
  record_run_end(L, e, end_reason, stop_reason, why);
  if (e->aborted) {
    L->runs_aborted++;
  } else {
    L->runs_finished++;
    L->last_run_steps = e->steps;
    L->last_run_goal = e->goal;
  }
  // The run's journal record goes out after this tick's update, and its reports (this record,
  // its progress line, the block it completes) wait until the run is on disk; a training run's
  // replay and checkpoint follow in slices (learning.c).
  fw_learning_run_ended(L, e);
  if (L->cfg.progress) {
    const learn_learner_stats_t ls = learn_learner_stats(learn_get_learner(L->agent));
    fw_loop_log(L, 1, "run %4d  phase %d  %-13s %-9s %4d steps  (%s)  store %u/%u", e->run_id, e->plan.phase,
                run_kind_name(L, &e->plan), e->aborted ? "ABORTED" : (e->goal ? "goal" : "no goal"), e->steps, why,
                ls.fill, ls.capacity);
  }
  if (e->block_done) {
    L->last_block = e->block;
    fw_out_eval(L, &e->block);
    if (L->cfg.progress) {
      fw_loop_log(L, 1, "EVAL block %2d after %3d training runs (phase %d): %2d/%d reached the goal, mean %.1f +- %.1f steps",
                  e->block.block, e->block.training_runs, e->block.phase, e->block.successes, e->block.n_starts,
                  e->block.mean_steps, e->block.ci95_halfwidth);
      if (learn_schedule(L->agent)->p.phase == 2 && e->block.phase == 1) {
        fw_loop_log(L, 1, "PHASE TWO: the learned policy drives from now on");
      }
    }
  }
  fw_run_begin_repositioning(L);
}

void fw_run_abort(fw_loop_t* L, int8_t end_reason, int32_t stop_reason, const char* why) {
  learn_run_end_t e;
  if (fw_run_running(L) && learn_abort_run(L->agent, &e)) {
    finish_run(L, &e, end_reason, stop_reason, why);
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
    const learn_plan_t plan = learn_plan(L->agent);
    if (plan.kind == LEARN_RUN_NONE) {
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

void fw_run_step(fw_loop_t* L, uint8_t contact, double* v_cmd, double* w_cmd) {
  if (learn_has_transition(L->agent)) {
    // The outcome of the last executed action, as the task computes it.
    const tasks_outcome_t o =
        tasks_episode_outcome(&L->ep, contact, (uint32_t)learn_run_actions(L->agent));
    const learn_outcome_t lo = {.reward = o.reward,
                                .terminal = o.terminal != 0,
                                .end_run = o.end_run != 0,
                                .goal = o.reason == TASKS_END_GOAL,
                                .reason = (int8_t)o.reason};
    learn_run_end_t e;
    if (learn_transition(L->agent, &lo, &e)) {
      *v_cmd = 0.0;
      *w_cmd = 0.0;
      const bool goal = o.reason == TASKS_END_GOAL;
      const bool collision = o.reason == TASKS_END_COLLISION;
      finish_run(L, &e,
                 goal ? B21R_RUN_T_END_GOAL : (collision ? B21R_RUN_T_END_COLLISION : B21R_RUN_T_END_STEP_LIMIT), 0,
                 goal ? "goal" : (collision ? "collision" : "step limit"));
      return;
    }
  }
  // The driver runs every step (even when it only advises) so its state follows the run.
  const double advice = tasks_episode_driver_action(&L->ep, &L->driver);
  double a = 0.0;
  int8_t source = LEARN_SOURCE_EXAMPLE;
  learn_act(L->agent, advice, L->teleop_rot_radps, &a, &source);
  // A non-finite action of the learned policy (its action is then 0): the tick commands a stop and
  // the supervisor reports it as a non-finite value on the next tick (loop.c).
  L->policy_fault = learn_policy_fault(L->agent);
  *w_cmd = a;
  *v_cmd = tasks_episode_speed_mps(&L->ep);
}
