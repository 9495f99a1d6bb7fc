// SPDX-License-Identifier: MIT
// Kinds `explore_corridor` and `explore_goal`: learning without examples (paper Fig. 6 and
// Table I) comes down to how long random actions take to find the first reward. Both studies
// run on the idealised synchro-drive model (sim/kinematic.h) with the tasks' own definitions:
// the state from the pose (lib/features), the reward and termination (lib/tasks), the corridor's
// speed policy. No learner is involved: until the first reward every Q-value is the same.
#define _POSIX_C_SOURCE 200809L
#include "experiment.h"

#include <features/features.h>
#include <sim/kinematic.h>
#include <tasks/tasks.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static const double k_pi = 3.14159265358979323846;

typedef struct explore_run {
  bool success;
  double time_s;    // simulated time until the first reward, or the time limit
  int64_t episodes; // corridor: attempts (a collision or the step limit ends one; the clock runs on)
} explore_run_t;

static uint64_t run_seed(uint64_t seed, int32_t run) {
  uint64_t st = seed ^ ((uint64_t)(uint32_t)run * 0x9E3779B97F4A7C15ULL);
  return rng_splitmix64(&st);
}

// Fig. 6: from the centre line at start_x, heading uniform in the half-circle towards the goal,
// rotation uniform in [-max, max] each step, translation from the task's speed policy. A
// collision with a wall or the task's step limit ends an attempt as in the real task: the robot
// is put back at the start (that takes no time) and the clock keeps running until the reward.
static explore_run_t corridor_run(const exp_settings_t* s, const fw_config_t* cfg, double dt, uint64_t seed) {
  tasks_corridor_spec_t spec;
  tasks_corridor_spec_default(&spec);
  spec.length_m = cfg->corridor_length_m;
  spec.omega_max_radps = s->explore_omega_max_radps;
  spec.dt_s = dt;
  if (cfg->max_steps_per_run > 0) {
    spec.step_limit = (uint32_t)cfg->max_steps_per_run;
  }
  features_corridor_config_t fc;
  tasks_corridor_features_config(&spec, &fc);
  sim_kin_limits_t lim;
  sim_kin_limits_default(&lim);
  if (!s->explore_accel_limits) {
    lim.accel_trans_mps2 = 0.0;
    lim.accel_rot_radps2 = 0.0;
  }
  const double half = 0.5 * spec.width_m - spec.robot_radius_m;
  rng_t rng;
  rng_seed(&rng, seed);
  explore_run_t r = {false, 0.0, 0};
  const int64_t max_steps = (int64_t)ceil(s->explore_time_limit_s / dt);
  int64_t t = 0;
  while (t < max_steps) {
    r.episodes++;
    sim_kin_state_t k;
    sim_kin_reset(&k, s->explore_start_x_m, 0.0, rng_uniform_range(&rng, -0.5 * k_pi, 0.5 * k_pi));
    features_corridor_t f;
    features_pose_t pose = {k.x_m, k.y_m, k.theta_rad};
    (void)features_corridor_from_pose(&fc, pose, &f);
    for (uint32_t steps = 1; t < max_steps; ++steps) {
      const double v = tasks_corridor_speed_mps(&spec, &f);
      const double w = rng_uniform_range(&rng, -spec.omega_max_radps, spec.omega_max_radps);
      sim_kin_step(&k, &lim, v, w, dt);
      ++t;
      pose = (features_pose_t){k.x_m, k.y_m, k.theta_rad};
      (void)features_corridor_from_pose(&fc, pose, &f);
      const uint8_t contact = fabs(k.y_m) >= half || k.x_m <= spec.robot_radius_m ||
                              k.x_m >= spec.length_m - spec.robot_radius_m;
      const tasks_outcome_t o = tasks_corridor_outcome(&spec, &f, contact, steps);
      if (o.reason == TASKS_END_GOAL) {
        r.success = true;
        r.time_s = (double)t * dt;
        return r;
      }
      if (o.end_run) {
        break;
      }
    }
  }
  r.time_s = (double)t * dt;
  return r;
}

// Table I: no obstacles, no walls; start `distance` from the goal pointing straight at it,
// constant speed, rotation ~ N(0, variance) each step, until the goal disc or the time limit.
static explore_run_t goal_run(const exp_settings_t* s, double dt, uint64_t seed) {
  tasks_obstacles_spec_t spec;
  tasks_obstacles_spec_default(&spec);
  spec.n_obstacles = 0;
  spec.step_limit = 0;  // the time limit ends a run
  sim_kin_limits_t lim;
  sim_kin_limits_default(&lim);
  if (!s->explore_accel_limits) {
    lim.accel_trans_mps2 = 0.0;
    lim.accel_rot_radps2 = 0.0;
  }
  const double sd = sqrt(s->explore_omega_variance);
  rng_t rng;
  rng_seed(&rng, seed);
  sim_kin_state_t k;
  sim_kin_reset(&k, spec.goal_x_m - s->explore_start_distance_m, spec.goal_y_m, 0.0);
  features_obstacles_t f;
  memset(&f, 0, sizeof f);
  f.valid = 1;  // the goal part of the state from the pose; no scan, no obstacles
  const int64_t max_steps = (int64_t)ceil(s->explore_time_limit_s / dt);
  explore_run_t r = {false, 0.0, 1};
  for (int64_t t = 1; t <= max_steps; ++t) {
    sim_kin_step(&k, &lim, spec.v_mps, sd * rng_normal(&rng), dt);
    f.goal_distance_m = hypot(k.x_m - spec.goal_x_m, k.y_m - spec.goal_y_m);
    if (tasks_obstacles_outcome(&spec, &f, 0, 0).reason == TASKS_END_GOAL) {
      r.success = true;
      r.time_s = (double)t * dt;
      return r;
    }
  }
  r.time_s = (double)max_steps * dt;
  return r;
}

int exp_run_explore(const exp_settings_t* s, const fw_config_t* cfg, const exp_task_t* task, char* err,
                    size_t err_cap) {
  const double dt = (double)fw_config_period_us(cfg) * 1e-6;
  explore_run_t* runs = calloc((size_t)s->explore_runs, sizeof *runs);
  if (runs == NULL) {
    snprintf(err, err_cap, "out of memory");
    return -1;
  }
  struct timespec t0;
  struct timespec t1;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  for (int32_t i = 0; i < s->explore_runs; ++i) {
    const uint64_t rs = run_seed(task->seed, i);
    runs[i] = s->kind == EXP_EXPLORE_CORRIDOR ? corridor_run(s, cfg, dt, rs) : goal_run(s, dt, rs);
  }
  clock_gettime(CLOCK_MONOTONIC, &t1);
  char tmp[EXP_STR_MAX * 2];
  FILE* f = exp_open_result(task->out_path, tmp, sizeof tmp, err, err_cap);
  if (f == NULL) {
    free(runs);
    return -1;
  }
  json_writer_t w;
  json_begin(&w, f);
  json_object(&w, NULL);
  exp_write_header(&w, s, cfg, task);
  json_object(&w, "explore");
  json_num(&w, "wall_time_s", (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec));
  json_num(&w, "dt_s", dt);
  json_num(&w, "time_limit_s", s->explore_time_limit_s);
  json_bool(&w, "accel_limits", s->explore_accel_limits);
  if (s->kind == EXP_EXPLORE_CORRIDOR) {
    json_num(&w, "omega_max_radps", s->explore_omega_max_radps);
    json_num(&w, "corridor_length_m", cfg->corridor_length_m);
    json_num(&w, "start_x_m", s->explore_start_x_m);
  } else {
    json_num(&w, "omega_variance", s->explore_omega_variance);
    json_num(&w, "start_distance_m", s->explore_start_distance_m);
  }
  json_array(&w, "runs");
  for (int32_t i = 0; i < s->explore_runs; ++i) {
    json_object(&w, NULL);
    json_bool(&w, "success", runs[i].success);
    json_num(&w, "time_s", runs[i].time_s);
    json_int(&w, "episodes", runs[i].episodes);
    json_end_object(&w);
  }
  json_end_array(&w);
  json_end_object(&w);
  json_end_object(&w);
  free(runs);
  return exp_commit_result(f, tmp, task->out_path, err, err_cap);
}
