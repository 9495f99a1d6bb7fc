// SPDX-License-Identifier: MIT
// The corridor-following task (paper section V-A) as a declaration: its specification
// (tasks_corridor_spec_t), features (features/corridor.h), reward, speed policy, poses, drivers
// and world.
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "tasks/episode.h"
#include "tasks_internal.h"

typedef struct corridor_run {
  features_corridor_config_t features;
  features_corridor_t state;
} corridor_run_t;

_Static_assert(sizeof(tasks_corridor_spec_t) <= TASKS_SPEC_BYTES, "the corridor's spec fits the episode");
_Static_assert(sizeof(corridor_run_t) <= TASKS_RUN_BYTES, "the corridor's run data fit the episode");

static const tasks_corridor_spec_t* spec_of(const tasks_episode_t* ep) {
  return (const tasks_corridor_spec_t*)tasks_episode_spec_const(ep);
}
static corridor_run_t* run_of(tasks_episode_t* ep) { return (corridor_run_t*)tasks_episode_run(ep); }
static const corridor_run_t* run_of_const(const tasks_episode_t* ep) {
  return (const corridor_run_t*)tasks_episode_run_const(ep);
}

static void spec_default(void* spec) { tasks_corridor_spec_default((tasks_corridor_spec_t*)spec); }

static void state_range(const void* spec_v, double* lo, double* hi) {
  const tasks_corridor_spec_t* spec = (const tasks_corridor_spec_t*)spec_v;
  lo[0] = 0.0;  // end distance [m]
  hi[0] = spec->length_m;
  lo[1] = 0.0;  // lateral position, fraction of the width from the left wall
  hi[1] = 1.0;
  lo[2] = -0.5 * TASKS_PI;  // target angle [rad]: beyond +-90 deg the robot faces a wall
  hi[2] = 0.5 * TASKS_PI;
}

static void run_init(tasks_episode_t* ep) {
  corridor_run_t* r = run_of(ep);
  tasks_corridor_features_config(spec_of(ep), &r->features);
  // Neutral features until the first observation: the empty input gives the documented
  // "invalid" state of the feature function.
  const features_pose_t origin = {0.0, 0.0, 0.0};
  (void)features_corridor_from_pose(&r->features, origin, &r->state);
  r->state.valid = 0U;
}

// Writes the state vector of the newest features when they are valid (as the controller does:
// an invalid state leaves the previous vector in place); 1 when it is also finite.
static int write_state(const corridor_run_t* r, features_status_t status, double* state) {
  if (status != FEATURES_OK || r->state.valid == 0U) {
    return 0;
  }
  features_corridor_state(&r->state, state);
  return tasks_all_finite(state, FEATURES_CORRIDOR_STATE_DIM);
}

static int observe(tasks_episode_t* ep, const features_scan_t* scan, features_pose_t pose, double* state) {
  corridor_run_t* r = run_of(ep);
  return write_state(r, features_corridor_compute(&r->features, scan, &pose, &r->state), state);
}

static int observe_pose(tasks_episode_t* ep, features_pose_t pose, double* state) {
  corridor_run_t* r = run_of(ep);
  return write_state(r, features_corridor_from_pose(&r->features, pose, &r->state), state);
}

static tasks_outcome_t outcome(const tasks_episode_t* ep, uint8_t contact, uint32_t steps_taken) {
  return tasks_corridor_outcome(spec_of(ep), &run_of_const(ep)->state, contact, steps_taken);
}

static double speed(const tasks_episode_t* ep) { return tasks_corridor_speed_mps(spec_of(ep), &run_of_const(ep)->state); }

static features_pose_t training_start_near(const void* spec, uint32_t index, rng_t* rng) {
  return tasks_corridor_training_start_near((const tasks_corridor_spec_t*)spec, index, rng);
}

static const features_laser_mount_t* laser_mount(const tasks_episode_t* ep) {
  return &run_of_const(ep)->features.scan.mount;
}

static void state_bounds(const tasks_episode_t* ep, double* lo, double* hi) {
  // The end distance comes from odometry (at most the length) or from the laser, which the
  // features accept only within end_gate_m of odometry.
  lo[0] = 0.0;
  hi[0] = spec_of(ep)->length_m + run_of_const(ep)->features.end_gate_m;
  lo[1] = 0.0;
  hi[1] = 1.0;
  lo[2] = -TASKS_PI;
  hi[2] = TASKS_PI;
}

static double driver_action(const tasks_episode_t* ep, tasks_driver_t* d) {
  return tasks_driver_corridor(d, &run_of_const(ep)->state);
}

static int world(const void* spec_v, const tasks_world_sink_t* sink) {
  const tasks_corridor_spec_t* spec = (const tasks_corridor_spec_t*)spec_v;
  int bad = sink->corridor(sink->user, spec->length_m, spec->width_m, 1);
  for (size_t i = 0; bad == 0 && i < TASKS_N_EVAL_STARTS; ++i) {
    bad = sink->start(sink->user, spec->eval_starts[i]);
  }
  char name[48];
  (void)snprintf(name, sizeof name, "corridor%g", spec->length_m);
  return bad != 0 ? bad : sink->name(sink->user, name);
}

static const char* const k_state_names[] = {"end distance [m]", "lateral fraction of the width [1]",
                                            "target angle [rad]"};

#define P(field) offsetof(tasks_corridor_spec_t, field)
static const tasks_param_t k_params[] = {
    {"length_m", P(length_m), 4.0, 200.0, "start wall to end wall [m]"},
    {"width_m", P(width_m), 1.0, 10.0, "wall to wall [m]"},
    {"goal_distance_m", P(goal_distance_m), 0.1, 5.0, "the goal: robot centre within this of the end wall [m]"},
    {"v_centre_mps", P(v_centre_mps), 0.05, 1.0, "translation speed on the centre line [m/s]"},
    {"v_wall_mps", P(v_wall_mps), 0.0, 1.0, "translation speed with the robot's edge at a wall [m/s]"},
    {"goal_reward", P(goal_reward), 0.0, 1000.0, "reward at the end of the corridor"},
    {"lookahead_m", P(lookahead_m), 0.1, 10.0, "target point ahead on the centre line of the state's angle [m]"},
    {"train_jitter_x_m", P(train_jitter_x_m), 0.0, 5.0, "training starts: jitter around an evaluation pose along x [m]"},
    {"train_jitter_y_m", P(train_jitter_y_m), 0.0, 5.0, "training starts: jitter across [m]"},
    {"train_jitter_theta_rad", P(train_jitter_theta_rad), 0.0, 3.2, "training starts: heading jitter [rad]"},
};

const tasks_decl_t tasks_corridor_decl = {
    .name = "corridor",
    .title = "Corridor following",
    .env_id = "B21rCorridor-v0",
    .id = 0,
    .state_dim = FEATURES_CORRIDOR_STATE_DIM,
    .state_names = k_state_names,
    // One scaled unit is about the distance over which the value of an action changes markedly.
    // Along the corridor the value falls by 1 % per 6 cm of progress: a 1 m scale keeps a
    // neighbourhood within a few tenths of a metre, where the value is nearly linear in the
    // distance; the lateral position at half its useful range; the target angle finer (0.125 rad,
    // about a tenth of its range), so that a run starting far off the axis is judged by runs
    // that started at a similar heading (docs/LEARNING.md). The action's scale sets how far apart
    // two actions must be to count as different.
    .state_scale = {1.0, 0.5, 0.125},
    .action_scale = 0.25,
    // With the fine angle an early state's neighbourhood is often empty; the wider second search
    // answers from runs at other headings (docs/LEARNING.md).
    .greedy_reach = 8.0,
    .state_range = state_range,
    .spec_size = sizeof(tasks_corridor_spec_t),
    .spec_default = spec_default,
    .params = k_params,
    .n_params = sizeof k_params / sizeof k_params[0],
    .off_dt_s = P(dt_s),
    .off_omega_max_radps = P(omega_max_radps),
    .off_step_limit = P(step_limit),
    .off_gamma = P(gamma),
    .off_robot_radius_m = P(robot_radius_m),
    .off_eval_starts = P(eval_starts),
    .run_init = run_init,
    .observe = observe,
    .observe_pose = observe_pose,
    .outcome = outcome,
    .speed_mps = speed,
    .training_start_near = training_start_near,
    .laser_mount = laser_mount,
    .state_bounds = state_bounds,
    .gain_min = TASKS_PROPORTIONAL_CORRIDOR_GAIN_MIN,
    .gain_max = TASKS_PROPORTIONAL_CORRIDOR_GAIN_MAX,
    .driver_law = tasks_driver_law_corridor,
    .driver_human = NULL,
    .driver_action = driver_action,
    .world = world,
};
#undef P

const features_corridor_t* tasks_corridor_state(const tasks_episode_t* ep) {
  return ep->decl == &tasks_corridor_decl ? &run_of_const(ep)->state : NULL;
}

const features_corridor_config_t* tasks_corridor_features(const tasks_episode_t* ep) {
  return ep->decl == &tasks_corridor_decl ? &run_of_const(ep)->features : NULL;
}
