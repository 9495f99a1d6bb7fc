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

void tasks_episode_init(tasks_episode_t* ep, const tasks_decl_t* decl, const void* spec) {
  memset(ep, 0, sizeof *ep);
  ep->decl = decl != NULL ? decl : &tasks_corridor_decl;
  ep->state_dim = ep->decl->state_dim;
  if (spec != NULL) {
    memcpy(ep->spec, spec, ep->decl->spec_size);
  } else {
    ep->decl->spec_default(ep->spec);
  }
  ep->decl->run_init(ep);
}

void* tasks_episode_spec(tasks_episode_t* ep) { return ep->spec; }
const void* tasks_episode_spec_const(const tasks_episode_t* ep) { return ep->spec; }
void* tasks_episode_run(tasks_episode_t* ep) { return ep->run; }
const void* tasks_episode_run_const(const tasks_episode_t* ep) { return ep->run; }

int tasks_episode_set_param(tasks_episode_t* ep, const char* name, double value) {
  const int r = tasks_spec_set_param(ep->decl, ep->spec, name, value);
  if (r == 0) {
    ep->decl->run_init(ep);
  }
  return r;
}

void tasks_episode_set_eval_starts(tasks_episode_t* ep, const features_pose_t* poses, uint32_t n) {
  ep->n_eval_starts = n < TASKS_MAX_EVAL_STARTS ? n : TASKS_MAX_EVAL_STARTS;
  for (uint32_t i = 0U; i < ep->n_eval_starts; ++i) {
    ep->eval_starts[i] = poses[i];
  }
}

uint32_t tasks_episode_n_eval_starts(const tasks_episode_t* ep) {
  return ep->n_eval_starts > 0U ? ep->n_eval_starts : TASKS_N_EVAL_STARTS;
}

void tasks_episode_begin(tasks_episode_t* ep, features_pose_t start_in_task, features_pose_t odom_at_start) {
  ep->start_in_task = start_in_task;
  ep->odom_at_start = odom_at_start;
  if (ep->decl->run_begin != NULL) {
    ep->decl->run_begin(ep);
  }
}

features_pose_t tasks_episode_pose_in_task(const tasks_episode_t* ep, features_pose_t odom_now) {
  return features_odom_to_task(ep->start_in_task, ep->odom_at_start, odom_now);
}

int tasks_episode_observe(tasks_episode_t* ep, const features_scan_t* scan, features_pose_t odom_now,
                          double* state) {
  return ep->decl->observe(ep, scan, tasks_episode_pose_in_task(ep, odom_now), state);
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
  return ep->decl->observe_pose(ep, pose_in_task, state);
}

tasks_outcome_t tasks_episode_outcome(const tasks_episode_t* ep, uint8_t contact, uint32_t steps_taken) {
  return ep->decl->outcome(ep, contact, steps_taken);
}

double tasks_episode_speed_mps(const tasks_episode_t* ep) { return ep->decl->speed_mps(ep); }

double tasks_episode_driver_action(const tasks_episode_t* ep, tasks_driver_t* driver) {
  return ep->decl->driver_action(ep, driver);
}

features_pose_t tasks_episode_eval_start(const tasks_episode_t* ep, uint32_t index) {
  if (ep->n_eval_starts > 0U) {
    return ep->eval_starts[index % ep->n_eval_starts];
  }
  return tasks_spec_eval_start(ep->decl, ep->spec, index);
}

features_pose_t tasks_episode_training_start(tasks_episode_t* ep, rng_t* rng) {
  const uint32_t k = tasks_start_cycle_next(&ep->start_cycle, rng);
  return ep->decl->training_start_near(ep->spec, k, rng);
}

uint32_t tasks_episode_step_limit(const tasks_episode_t* ep) { return tasks_spec_step_limit(ep->decl, ep->spec); }

double tasks_episode_omega_max(const tasks_episode_t* ep) { return tasks_spec_omega_max(ep->decl, ep->spec); }

double tasks_episode_gamma(const tasks_episode_t* ep) { return tasks_spec_gamma(ep->decl, ep->spec); }

double tasks_episode_robot_radius(const tasks_episode_t* ep) { return tasks_spec_robot_radius(ep->decl, ep->spec); }

double tasks_episode_dt_s(const tasks_episode_t* ep) { return tasks_spec_dt_s(ep->decl, ep->spec); }

const features_laser_mount_t* tasks_episode_laser_mount(const tasks_episode_t* ep) { return ep->decl->laser_mount(ep); }

void tasks_episode_state_bounds(const tasks_episode_t* ep, double* lo, double* hi) {
  ep->decl->state_bounds(ep, lo, hi);
}

void tasks_episode_state_range(const tasks_episode_t* ep, double* lo, double* hi) {
  ep->decl->state_range(ep->spec, lo, hi);
}

void tasks_driver_begin_run(tasks_driver_t* d, tasks_driver_kind_t kind, const tasks_decl_t* decl,
                            double omega_max_radps, uint64_t run_seed) {
  const tasks_decl_t* t = decl != NULL ? decl : &tasks_corridor_decl;
  tasks_driver_begin_common(d, kind, t->id, omega_max_radps, run_seed, t->gain_min, t->gain_max);
  t->driver_law(d);
  if (d->kind == (uint8_t)TASKS_DRIVER_HUMAN) {
    tasks_driver_begin_human(d);
    if (t->driver_human != NULL) {
      t->driver_human(d);
    }
  }
}

void tasks_driver_set_gain(tasks_driver_t* d, const tasks_decl_t* decl, double gain) {
  d->gain = gain;
  if (d->kind == (uint8_t)TASKS_DRIVER_PROPORTIONAL) {
    (decl != NULL ? decl : &tasks_corridor_decl)->driver_law(d);
  }
}

void tasks_episode_driver_begin(const tasks_episode_t* ep, tasks_driver_t* d, tasks_driver_kind_t kind,
                                double omega_max_radps, uint64_t run_seed) {
  tasks_driver_begin_run(d, kind, ep->decl, omega_max_radps, run_seed);
}
