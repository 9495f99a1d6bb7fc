// SPDX-License-Identifier: MIT
// The obstacle-avoidance task (paper section V-B) as a declaration: its specification
// (tasks_obstacles_spec_t), features (features/obstacles.h), reward, speed, poses, drivers and
// world.
//
// The state: goal bearing and distance, the nearest obstacle's bearing and distance, and the time
// since that obstacle was seen. The obstacle is the one the laser sees or, after it left the
// 180° view (an obstacle being passed does, while the robot is still beside it), the one the
// features remember (features_obstacles_remember: the disc it was seen as, carried along by
// odometry, for memory_s). So the state does not say "no obstacle" beside an obstacle, and the values can
// learn when it is safe to turn to the goal; the age says how old the remembered position is.
// The obstacle's two entries are the seen ones whenever it is in view, so the state of a visible
// obstacle is the paper's four values and a zero. The drivers (examples and the reference, which
// only evaluates) keep steering by what the laser sees (features_obstacles_t obstacle[0]).
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "tasks/episode.h"
#include "tasks_internal.h"

typedef struct obstacles_run {
  features_obstacles_config_t features;
  features_obstacles_t state;
  features_obstacle_memory_t memory;  // of the nearest obstacle seen in this run
  double period_s;                    // one observation per control period, in whole microseconds
} obstacles_run_t;

_Static_assert(sizeof(tasks_obstacles_spec_t) <= TASKS_SPEC_BYTES, "the obstacle task's spec fits the episode");
_Static_assert(sizeof(obstacles_run_t) <= TASKS_RUN_BYTES, "the obstacle task's run data fit the episode");

static const tasks_obstacles_spec_t* spec_of(const tasks_episode_t* ep) {
  return (const tasks_obstacles_spec_t*)tasks_episode_spec_const(ep);
}
static obstacles_run_t* run_of(tasks_episode_t* ep) { return (obstacles_run_t*)tasks_episode_run(ep); }
static const obstacles_run_t* run_of_const(const tasks_episode_t* ep) {
  return (const obstacles_run_t*)tasks_episode_run_const(ep);
}

static void spec_default(void* spec) { tasks_obstacles_spec_default((tasks_obstacles_spec_t*)spec); }

static void state_range(const void* spec_v, double* lo, double* hi) {
  const tasks_obstacles_spec_t* spec = (const tasks_obstacles_spec_t*)spec_v;
  lo[0] = -TASKS_PI;  // goal bearing [rad]
  hi[0] = TASKS_PI;
  lo[1] = 0.0;        // goal distance [m]
  hi[1] = 8.0;
  lo[2] = -TASKS_PI;  // obstacle bearing [rad]
  hi[2] = TASKS_PI;
  lo[3] = 0.0;        // obstacle distance [m], 8 = the edge of sensing
  hi[3] = 8.0;
  lo[4] = 0.0;        // time since the obstacle was seen [s]: up to the memory's span
  hi[4] = spec->memory_s > spec->dt_s ? spec->memory_s : spec->dt_s;
}

static void run_init(tasks_episode_t* ep) {
  obstacles_run_t* r = run_of(ep);
  const tasks_obstacles_spec_t* spec = spec_of(ep);
  tasks_obstacles_features_config(spec, &r->features);
  // The period as the controller's tick counts it (whole microseconds), so that the age in
  // seconds is the same number whether dt_s was given as 0.1 or derived as 100000 x 1e-6.
  const double us = spec->dt_s > 0.0 && spec->dt_s < 1e3 ? floor(spec->dt_s * 1e6 + 0.5) : 0.0;
  r->period_s = us >= 1.0 ? us / 1e6 : 0.1;
  features_obstacle_memory_reset(&r->memory);
  // Neutral features until the first observation.
  const features_pose_t origin = {0.0, 0.0, 0.0};
  (void)features_obstacles_from_pose(&r->features, origin, spec->goal_x_m, spec->goal_y_m, NULL, 0U, TASKS_PI,
                                     &r->state);
  r->state.valid = 0U;
}

static void run_begin(tasks_episode_t* ep) { features_obstacle_memory_reset(&run_of(ep)->memory); }

// The memory takes in the newest features (measured or exact alike), then the state vector is
// written when they are valid.
static int write_state(obstacles_run_t* r, features_status_t status, features_pose_t pose, double* state) {
  if (status != FEATURES_OK || r->state.valid == 0U ||
      features_obstacles_remember(&r->features, &r->memory, pose, &r->state) != FEATURES_OK) {
    return 0;
  }
  (void)features_obstacles_memory_state(&r->state, r->period_s, state, TASKS_MAX_STATE_DIM);
  return tasks_all_finite(state, FEATURES_OBSTACLES_MEMORY_STATE_DIM);
}

static int observe(tasks_episode_t* ep, const features_scan_t* scan, features_pose_t pose, double* state) {
  obstacles_run_t* r = run_of(ep);
  const tasks_obstacles_spec_t* spec = spec_of(ep);
  return write_state(r, features_obstacles_compute(&r->features, scan, &pose, spec->goal_x_m, spec->goal_y_m, &r->state),
                     pose, state);
}

static int observe_pose(tasks_episode_t* ep, features_pose_t pose, double* state) {
  obstacles_run_t* r = run_of(ep);
  return write_state(r, tasks_obstacles_features_at_pose(spec_of(ep), &r->features, pose, &r->state), pose, state);
}

static tasks_outcome_t outcome(const tasks_episode_t* ep, uint8_t contact, uint32_t steps_taken) {
  return tasks_obstacles_outcome(spec_of(ep), &run_of_const(ep)->state, contact, steps_taken);
}

static double speed(const tasks_episode_t* ep) { return tasks_obstacles_speed_mps(spec_of(ep)); }

static features_pose_t training_start_near(const void* spec, uint32_t index, rng_t* rng) {
  return tasks_obstacles_training_start_near((const tasks_obstacles_spec_t*)spec, index, rng);
}

static const features_laser_mount_t* laser_mount(const tasks_episode_t* ep) {
  return &run_of_const(ep)->features.scan.mount;
}

static void state_bounds(const tasks_episode_t* ep, double* lo, double* hi) {
  const tasks_obstacles_spec_t* o = spec_of(ep);
  const obstacles_run_t* r = run_of_const(ep);
  const double gx = fmax(fabs(o->arena_min_x_m - o->goal_x_m), fabs(o->arena_max_x_m - o->goal_x_m));
  const double gy = fmax(fabs(o->arena_min_y_m - o->goal_y_m), fabs(o->arena_max_y_m - o->goal_y_m));
  const features_scan_config_t* sc = &r->features.scan;
  lo[0] = -TASKS_PI;
  hi[0] = TASKS_PI;
  // Inside the arena; odometry may drift a little beyond it.
  lo[1] = 0.0;
  hi[1] = hypot(gx, gy) + 1.0;
  lo[2] = -TASKS_PI;
  hi[2] = TASKS_PI;
  lo[3] = 0.0;
  hi[3] = fmax(r->features.no_obstacle_distance_m, sc->max_range_m + hypot(sc->mount.x_m, sc->mount.y_m));
  // The age saturates at the memory's limit (the value of "none known").
  lo[4] = 0.0;
  hi[4] = (double)(r->features.memory_max_age > 0U ? r->features.memory_max_age : 1U) * r->period_s;
}

static double driver_action(const tasks_episode_t* ep, tasks_driver_t* d) {
  return tasks_driver_obstacles(d, &run_of_const(ep)->state);
}

static int world(const void* spec_v, const tasks_world_sink_t* sink) {
  const tasks_obstacles_spec_t* spec = (const tasks_obstacles_spec_t*)spec_v;
  if (spec->n_obstacles > TASKS_MAX_OBSTACLES || !(spec->goal_radius_m > 0.0)) {
    return -1;
  }
  int bad = sink->arena(sink->user, spec->arena_min_x_m, spec->arena_min_y_m, spec->arena_max_x_m,
                        spec->arena_max_y_m);
  for (uint32_t k = 0; bad == 0 && k < spec->n_obstacles; ++k) {
    const tasks_circle_t* c = &spec->obstacles[k];
    bad = sink->cylinder(sink->user, c->x_m, c->y_m, c->radius_m);
  }
  for (size_t i = 0; bad == 0 && i < TASKS_N_EVAL_STARTS; ++i) {
    bad = sink->start(sink->user, spec->eval_starts[i]);
  }
  if (bad == 0) {
    bad = sink->goal(sink->user, spec->goal_x_m, spec->goal_y_m, spec->goal_radius_m);
  }
  char name[48];
  (void)snprintf(name, sizeof name, "obstacles%u", (unsigned)spec->n_obstacles);
  return bad != 0 ? bad : sink->name(sink->user, name);
}

static const char* const k_state_names[] = {"goal bearing [rad]", "goal distance [m]",
                                            "nearest obstacle's bearing, seen or remembered [rad]",
                                            "nearest obstacle's distance, seen or remembered [m]",
                                            "time since that obstacle was seen [s]"};
_Static_assert(sizeof k_state_names / sizeof k_state_names[0] == FEATURES_OBSTACLES_MEMORY_STATE_DIM,
               "a name for every state value");

#define P(field) offsetof(tasks_obstacles_spec_t, field)
static const tasks_param_t k_params[] = {
    {"goal_x_m", P(goal_x_m), -50.0, 50.0, "goal position, arena frame [m]"},
    {"goal_y_m", P(goal_y_m), -50.0, 50.0, "goal position, arena frame [m]"},
    {"goal_radius_m", P(goal_radius_m), 0.05, 5.0, "the goal: robot centre within this of the goal position [m]"},
    {"v_mps", P(v_mps), 0.05, 1.0, "constant translation speed [m/s]"},
    {"goal_reward", P(goal_reward), -1000.0, 1000.0, "reward at the goal"},
    {"collision_reward", P(collision_reward), -1000.0, 1000.0, "reward on a collision"},
    {"arena_min_x_m", P(arena_min_x_m), -50.0, 50.0, "the arena's walls: the box's lowest x [m]"},
    {"arena_max_x_m", P(arena_max_x_m), -50.0, 50.0, "the box's highest x [m]"},
    {"arena_min_y_m", P(arena_min_y_m), -50.0, 50.0, "the box's lowest y [m]"},
    {"arena_max_y_m", P(arena_max_y_m), -50.0, 50.0, "the box's highest y [m]"},
    {"train_jitter_x_m", P(train_jitter_x_m), 0.0, 5.0, "training starts: jitter around an evaluation pose along x [m]"},
    {"train_jitter_y_m", P(train_jitter_y_m), 0.0, 5.0, "training starts: jitter along y [m]"},
    {"train_jitter_theta_rad", P(train_jitter_theta_rad), 0.0, 3.2, "training starts: heading jitter [rad]"},
    {"memory_s", P(memory_s), 0.0, 60.0,
     "the state remembers the nearest obstacle this long after it left the laser's view [s] (0 = no memory)"},
};

const tasks_decl_t tasks_obstacles_decl = {
    .name = "obstacles",
    .title = "Obstacle avoidance",
    .env_id = "B21rObstacles-v0",
    .id = 1,
    .state_dim = FEATURES_OBSTACLES_MEMORY_STATE_DIM,
    .state_names = k_state_names,
    // The age in units of the default memory's span: it tells a fresh sighting from an old one
    // without splitting the learner's data finely by age.
    .state_scale = {1.0, 1.0, 1.0, 1.0, 3.0},
    .action_scale = 0.5,
    .greedy_reach = 3.0,
    .state_range = state_range,
    .spec_size = sizeof(tasks_obstacles_spec_t),
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
    .run_begin = run_begin,
    .observe = observe,
    .observe_pose = observe_pose,
    .outcome = outcome,
    .speed_mps = speed,
    .training_start_near = training_start_near,
    .laser_mount = laser_mount,
    .state_bounds = state_bounds,
    .gain_min = TASKS_PROPORTIONAL_OBSTACLES_GAIN_MIN,
    .gain_max = TASKS_PROPORTIONAL_OBSTACLES_GAIN_MAX,
    .driver_law = tasks_driver_law_obstacles,
    .driver_human = tasks_driver_human_obstacles,
    .driver_action = driver_action,
    .world = world,
};
#undef P

const features_obstacles_t* tasks_obstacles_state(const tasks_episode_t* ep) {
  return ep->decl == &tasks_obstacles_decl ? &run_of_const(ep)->state : NULL;
}

const features_obstacles_config_t* tasks_obstacles_features(const tasks_episode_t* ep) {
  return ep->decl == &tasks_obstacles_decl ? &run_of_const(ep)->features : NULL;
}
