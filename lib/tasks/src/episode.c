// SPDX-License-Identifier: MIT
// A task as a robot runs it: run frame, state from scan + odometry, outcome, speed, command clamp.
#include "tasks/episode.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "tasks_internal.h"

void tasks_command_limits_default(tasks_command_limits_t* lim) {
  lim->max_translation_mps = 0.8;
  lim->max_rotation_radps = 1.0;
  lim->max_translation_accel_mps2 = 0.7;
  lim->max_rotation_accel_radps2 = 2.86;
}

static double clampd(double x, double lo, double hi) { return x < lo ? lo : (x > hi ? hi : x); }

int tasks_command_clamp(const tasks_command_limits_t* lim, double dt_s, double prev_v_mps,
                        double prev_omega_radps, double* v_mps, double* omega_radps) {
  const double dv = lim->max_translation_accel_mps2 * dt_s;
  const double dw = lim->max_rotation_accel_radps2 * dt_s;
  double v = clampd(*v_mps, -lim->max_translation_mps, lim->max_translation_mps);
  double w = clampd(*omega_radps, -lim->max_rotation_radps, lim->max_rotation_radps);
  v = clampd(v, prev_v_mps - dv, prev_v_mps + dv);
  w = clampd(w, prev_omega_radps - dw, prev_omega_radps + dw);
  if (!isfinite(v) || !isfinite(w)) {
    *v_mps = 0.0;
    *omega_radps = 0.0;
    return 0;
  }
  *v_mps = v;
  *omega_radps = w;
  return 1;
}

static int is_corridor(const tasks_episode_t* ep) { return ep->task != TASKS_TASK_OBSTACLES; }

void tasks_episode_init(tasks_episode_t* ep, tasks_task_t task, const tasks_corridor_spec_t* corridor,
                        const tasks_obstacles_spec_t* obstacles) {
  memset(ep, 0, sizeof *ep);
  ep->task = task == TASKS_TASK_OBSTACLES ? TASKS_TASK_OBSTACLES : TASKS_TASK_CORRIDOR;
  if (corridor != NULL) {
    ep->corridor = *corridor;
  } else {
    tasks_corridor_spec_default(&ep->corridor);
  }
  if (obstacles != NULL) {
    ep->obstacles = *obstacles;
  } else {
    tasks_obstacles_spec_default(&ep->obstacles);
  }
  tasks_corridor_features_config(&ep->corridor, &ep->corridor_features);
  tasks_obstacles_features_config(&ep->obstacles, &ep->obstacles_features);
  ep->state_dim = is_corridor(ep) ? FEATURES_CORRIDOR_STATE_DIM : FEATURES_OBSTACLES_STATE_DIM;
  // Neutral features until the first observation: the empty inputs give the documented
  // "invalid" states of the feature functions.
  const features_pose_t origin = {0.0, 0.0, 0.0};
  (void)features_corridor_from_pose(&ep->corridor_features, origin, &ep->corridor_state);
  ep->corridor_state.valid = 0U;
  (void)features_obstacles_from_pose(&ep->obstacles_features, origin, ep->obstacles.goal_x_m,
                                     ep->obstacles.goal_y_m, NULL, 0U, TASKS_PI, &ep->obstacles_state);
  ep->obstacles_state.valid = 0U;
}

void tasks_episode_begin(tasks_episode_t* ep, features_pose_t start_in_task, features_pose_t odom_at_start) {
  ep->start_in_task = start_in_task;
  ep->odom_at_start = odom_at_start;
}

features_pose_t tasks_episode_pose_in_task(const tasks_episode_t* ep, features_pose_t odom_now) {
  return features_odom_to_task(ep->start_in_task, ep->odom_at_start, odom_now);
}

static int all_finite(const double* v, uint32_t n) {
  for (uint32_t i = 0U; i < n; ++i) {
    if (!isfinite(v[i])) {
      return 0;
    }
  }
  return 1;
}

// Writes the state vector of the newest features when they are valid (as the controller does:
// an invalid state leaves the previous vector in place); 1 when it is also finite.
static int write_state(const tasks_episode_t* ep, features_status_t status, double* state) {
  if (status != FEATURES_OK) {
    return 0;
  }
  if (is_corridor(ep)) {
    if (ep->corridor_state.valid == 0U) {
      return 0;
    }
    features_corridor_state(&ep->corridor_state, state);
  } else {
    if (ep->obstacles_state.valid == 0U) {
      return 0;
    }
    (void)features_obstacles_state(&ep->obstacles_state, 1U, state, TASKS_MAX_STATE_DIM);
  }
  return all_finite(state, ep->state_dim);
}

int tasks_episode_observe(tasks_episode_t* ep, const features_scan_t* scan, features_pose_t odom_now,
                          double* state) {
  const features_pose_t pose = tasks_episode_pose_in_task(ep, odom_now);
  features_status_t st;
  if (is_corridor(ep)) {
    st = features_corridor_compute(&ep->corridor_features, scan, &pose, &ep->corridor_state);
  } else {
    st = features_obstacles_compute(&ep->obstacles_features, scan, &pose, ep->obstacles.goal_x_m,
                                    ep->obstacles.goal_y_m, &ep->obstacles_state);
  }
  return write_state(ep, st, state);
}

features_status_t tasks_obstacles_features_at_pose(const tasks_obstacles_spec_t* spec,
                                                   const features_obstacles_config_t* fcfg, features_pose_t pose,
                                                   features_obstacles_t* out) {
  features_disc_t discs[TASKS_MAX_OBSTACLES];
  const uint32_t n = spec->n_obstacles < TASKS_MAX_OBSTACLES ? spec->n_obstacles : TASKS_MAX_OBSTACLES;
  for (uint32_t k = 0U; k < n; ++k) {
    discs[k].x_m = spec->obstacles[k].x_m;
    discs[k].y_m = spec->obstacles[k].y_m;
    discs[k].radius_m = spec->obstacles[k].radius_m;
  }
  return features_obstacles_from_pose(fcfg, pose, spec->goal_x_m, spec->goal_y_m, discs, n, TASKS_PI, out);
}

int tasks_episode_observe_pose(tasks_episode_t* ep, features_pose_t pose_in_task, double* state) {
  features_status_t st;
  if (is_corridor(ep)) {
    st = features_corridor_from_pose(&ep->corridor_features, pose_in_task, &ep->corridor_state);
  } else {
    st = tasks_obstacles_features_at_pose(&ep->obstacles, &ep->obstacles_features, pose_in_task,
                                          &ep->obstacles_state);
  }
  return write_state(ep, st, state);
}

tasks_outcome_t tasks_episode_outcome(const tasks_episode_t* ep, uint8_t contact, uint32_t steps_taken) {
  return is_corridor(ep) ? tasks_corridor_outcome(&ep->corridor, &ep->corridor_state, contact, steps_taken)
                         : tasks_obstacles_outcome(&ep->obstacles, &ep->obstacles_state, contact, steps_taken);
}

double tasks_episode_speed_mps(const tasks_episode_t* ep) {
  return is_corridor(ep) ? tasks_corridor_speed_mps(&ep->corridor, &ep->corridor_state)
                         : tasks_obstacles_speed_mps(&ep->obstacles);
}

double tasks_episode_driver_action(const tasks_episode_t* ep, tasks_driver_t* driver) {
  return is_corridor(ep) ? tasks_driver_corridor(driver, &ep->corridor_state)
                         : tasks_driver_obstacles(driver, &ep->obstacles_state);
}

features_pose_t tasks_episode_eval_start(const tasks_episode_t* ep, uint32_t index) {
  return is_corridor(ep) ? tasks_corridor_eval_start(&ep->corridor, index)
                         : tasks_obstacles_eval_start(&ep->obstacles, index);
}

features_pose_t tasks_episode_training_start(tasks_episode_t* ep, rng_t* rng) {
  const uint32_t k = tasks_start_cycle_next(&ep->start_cycle, rng);
  return is_corridor(ep) ? tasks_corridor_training_start_near(&ep->corridor, k, rng)
                         : tasks_obstacles_training_start_near(&ep->obstacles, k, rng);
}

uint32_t tasks_episode_step_limit(const tasks_episode_t* ep) {
  return is_corridor(ep) ? ep->corridor.step_limit : ep->obstacles.step_limit;
}

double tasks_episode_omega_max(const tasks_episode_t* ep) {
  return is_corridor(ep) ? ep->corridor.omega_max_radps : ep->obstacles.omega_max_radps;
}

double tasks_episode_gamma(const tasks_episode_t* ep) {
  return is_corridor(ep) ? ep->corridor.gamma : ep->obstacles.gamma;
}

double tasks_episode_robot_radius(const tasks_episode_t* ep) {
  return is_corridor(ep) ? ep->corridor.robot_radius_m : ep->obstacles.robot_radius_m;
}
