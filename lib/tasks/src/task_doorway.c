// SPDX-License-Identifier: MIT
// The doorway-passing task as a declaration: its specification (tasks/doorway.h), features
// (features/doorway.h), reward, speed, poses, drivers, reference controller and world.
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "tasks/doorway.h"
#include "tasks/episode.h"
#include "tasks_internal.h"

// The "optimal" reference: the best constants of the line-following law found by the grid search
// in test/unit/tasks/tasks_optimal_search.c (doorway) over the ten evaluation starts in the
// synthetic world (kinematic synchro drive at 10 Hz, features from synthetic LMS200 scans, three
// noise seeds, the robot's edge kept at least 0.10 m from every wall; gains 0.5-4 in steps of
// 0.25, look-aheads 0.25-3 m in steps of 0.25 m). Mean steps to the goal at the time of the
// search: 105.9 (the example policy at its nominal gain 1.5: 113.0). Re-run the search after
// changing the task, the law or the features. It exists to evaluate the learner; nothing of it
// reaches the learner.
#define OPTIMAL_DOORWAY_GAIN 0.75
#define OPTIMAL_DOORWAY_LOOKAHEAD_M 1.25

typedef struct doorway_run {
  features_doorway_config_t features;
  features_doorway_t state;
} doorway_run_t;

_Static_assert(sizeof(tasks_doorway_spec_t) <= TASKS_SPEC_BYTES, "the doorway's spec fits the episode");
_Static_assert(sizeof(doorway_run_t) <= TASKS_RUN_BYTES, "the doorway's run data fit the episode");
_Static_assert(FEATURES_DOORWAY_STATE_DIM <= TASKS_MAX_STATE_DIM, "the doorway's state fits");

// ---- specification ------------------------------------------------------------------------------

// Evaluation poses relative to the door: (distance before the wall's centre plane [m], offset
// from the door's centre line [m], heading relative to the wall's normal [rad]).
static const double k_eval[TASKS_N_EVAL_STARTS][3] = {
    {3.0, 0.0, 0.0},   {2.5, 1.0, 0.0},  {2.5, -1.0, 0.0}, {3.5, 1.5, -0.4}, {3.5, -1.5, 0.4},
    {2.0, 1.2, -0.7},  {2.0, -1.2, 0.7}, {3.0, 0.5, 0.5},  {3.0, -0.5, -0.5}, {2.5, -1.8, 0.9},
};

void tasks_doorway_spec_default(tasks_doorway_spec_t* spec) {
  memset(spec, 0, sizeof *spec);
  spec->room_min_x_m = -4.5;
  spec->room_max_x_m = 3.0;
  spec->room_min_y_m = -3.0;
  spec->room_max_y_m = 3.0;
  spec->wall_x_m = 0.0;
  spec->wall_thickness_m = 0.1;
  spec->door_y_m = 0.0;
  spec->door_width_m = 1.0;
  spec->goal_x_m = 1.5;
  spec->goal_y_m = 0.0;
  spec->goal_radius_m = 0.3;
  spec->robot_radius_m = TASKS_B21R_RADIUS_M;
  spec->v_mps = 0.4;
  spec->omega_max_radps = 1.0;
  spec->dt_s = 0.1;
  spec->step_limit = 500U;
  spec->goal_reward = 1.0;
  spec->collision_reward = -1.0;
  spec->gamma = TASKS_DOORWAY_GAMMA;
  for (size_t i = 0U; i < TASKS_N_EVAL_STARTS; ++i) {
    spec->eval_starts[i].x_m = spec->wall_x_m - k_eval[i][0];
    spec->eval_starts[i].y_m = spec->door_y_m + k_eval[i][1];
    spec->eval_starts[i].theta_rad = k_eval[i][2];
  }
  spec->train_jitter_x_m = 0.3;
  spec->train_jitter_y_m = 0.3;
  spec->train_jitter_theta_rad = 0.3;
}

void tasks_doorway_features_config(const tasks_doorway_spec_t* spec, features_doorway_config_t* cfg) {
  features_doorway_config_default(cfg);
  cfg->door_x_m = spec->wall_x_m;
  cfg->door_y_m = spec->door_y_m;
  cfg->normal_rad = 0.0;
  cfg->door_width_m = spec->door_width_m;
  cfg->wall_thickness_m = spec->wall_thickness_m;
}

features_pose_t tasks_doorway_eval_start(const tasks_doorway_spec_t* spec, uint32_t index) {
  return spec->eval_starts[index % TASKS_N_EVAL_STARTS];
}

// Distance from (x, y) to the box [x0, x1] x [y0, y1] (0 inside).
static double box_distance(double x, double y, double x0, double y0, double x1, double y1) {
  const double dx = x < x0 ? x0 - x : (x > x1 ? x - x1 : 0.0);
  const double dy = y < y0 ? y0 - y : (y > y1 ? y - y1 : 0.0);
  return hypot(dx, dy);
}

int tasks_doorway_disc_collides(const tasks_doorway_spec_t* spec, double x_m, double y_m, double radius_m) {
  // The room's walls: the disc must stay inside the box.
  if (x_m - radius_m < spec->room_min_x_m || x_m + radius_m > spec->room_max_x_m ||
      y_m - radius_m < spec->room_min_y_m || y_m + radius_m > spec->room_max_y_m) {
    return 1;
  }
  // The dividing wall's two solids on either side of the gap.
  const double h = 0.5 * spec->wall_thickness_m;
  const double g0 = spec->door_y_m - 0.5 * spec->door_width_m;
  const double g1 = spec->door_y_m + 0.5 * spec->door_width_m;
  const double below = box_distance(x_m, y_m, spec->wall_x_m - h, spec->room_min_y_m, spec->wall_x_m + h, g0);
  const double above = box_distance(x_m, y_m, spec->wall_x_m - h, g1, spec->wall_x_m + h, spec->room_max_y_m);
  return below < radius_m || above < radius_m;
}

static int pose_clear(const void* spec_v, features_pose_t p) {
  const tasks_doorway_spec_t* spec = (const tasks_doorway_spec_t*)spec_v;
  const double margin = spec->robot_radius_m + 0.1;
  return p.x_m < spec->wall_x_m - 0.5 * spec->wall_thickness_m - margin &&
         !tasks_doorway_disc_collides(spec, p.x_m, p.y_m, margin);
}

features_pose_t tasks_doorway_training_start_near(const tasks_doorway_spec_t* spec, uint32_t index, rng_t* rng) {
  features_pose_t p;
  features_pose_t base;
  if (tasks_jittered_start(spec->eval_starts, index, spec->train_jitter_x_m, spec->train_jitter_y_m,
                           spec->train_jitter_theta_rad, pose_clear, spec, rng, &p, &base)) {
    return p;
  }
  // Every attempt failed (only with a jitter box mostly in the walls): the evaluation position,
  // which the defaults keep clear, with a turned heading.
  p = base;
  p.theta_rad = features_angle_wrap(base.theta_rad + 0.5 * spec->train_jitter_theta_rad);
  return p;
}

// The robot's position in the task frame from the features' door frame (normal +x).
static void position_of(const tasks_doorway_spec_t* spec, const features_doorway_t* f, double* x, double* y) {
  *x = spec->wall_x_m - f->wall_distance_m;
  *y = spec->door_y_m + f->offset_m;
}

double tasks_doorway_goal_distance(const tasks_doorway_spec_t* spec, const features_doorway_t* f) {
  double x, y;
  position_of(spec, f, &x, &y);
  return hypot(spec->goal_x_m - x, spec->goal_y_m - y);
}

double tasks_doorway_goal_bearing(const tasks_doorway_spec_t* spec, const features_doorway_t* f) {
  double x, y;
  position_of(spec, f, &x, &y);
  // The robot's heading in the task frame is its heading relative to the normal (+x).
  return features_angle_wrap(atan2(spec->goal_y_m - y, spec->goal_x_m - x) - f->heading_rad);
}

tasks_outcome_t tasks_doorway_outcome(const tasks_doorway_spec_t* spec, const features_doorway_t* f_next,
                                      uint8_t contact, uint32_t steps_taken) {
  tasks_outcome_t o = {0.0, 0U, 0U, (uint8_t)TASKS_END_NONE};
  if (contact != 0U) {
    o.reward = spec->collision_reward;
    o.terminal = 1U;
    o.end_run = 1U;
    o.reason = (uint8_t)TASKS_END_COLLISION;
  } else if (f_next != NULL && f_next->valid != 0U &&
             tasks_doorway_goal_distance(spec, f_next) <= spec->goal_radius_m) {
    o.reward = spec->goal_reward;
    o.terminal = 1U;
    o.end_run = 1U;
    o.reason = (uint8_t)TASKS_END_GOAL;
  }
  if (o.end_run == 0U && spec->step_limit > 0U && steps_taken >= spec->step_limit) {
    o.end_run = 1U;
    o.reason = (uint8_t)TASKS_END_STEP_LIMIT;
  }
  return o;
}

// ---- drivers ----------------------------------------------------------------------------------

void tasks_driver_law_doorway(tasks_driver_t* d) {
  if (d->kind == (uint8_t)TASKS_DRIVER_OPTIMAL) {
    d->law[0] = OPTIMAL_DOORWAY_GAIN;
    d->law[1] = OPTIMAL_DOORWAY_LOOKAHEAD_M;
    d->law[2] = 0.0;
  } else {
    d->law[0] = d->gain;
    d->law[1] = TASKS_DOORWAY_EXAMPLE_APPROACH_M;
    d->law[2] = 0.0;
  }
}

// The example's target: the staging point on the door's centre line law[1] before the wall while
// the robot is farther from the wall than that, then the goal. Its bearing, robot frame.
static double example_target(const tasks_driver_t* d, const tasks_doorway_spec_t* spec,
                             const features_doorway_t* f) {
  const double approach = d->law[1];
  if (f->wall_distance_m > approach) {
    // The staging point is at (-approach, 0) in the door frame; the robot at (-wall distance,
    // offset), heading `heading` from the normal.
    return features_angle_wrap(atan2(-f->offset_m, f->wall_distance_m - approach) - f->heading_rad);
  }
  return tasks_doorway_goal_bearing(spec, f);
}

double tasks_driver_doorway(tasks_driver_t* d, const tasks_doorway_spec_t* spec, const features_doorway_t* f) {
  if (d == NULL) {
    return 0.0;
  }
  if (spec == NULL || f == NULL || f->valid == 0U) {
    return d->kind == (uint8_t)TASKS_DRIVER_HUMAN ? tasks_clamp_omega(d->stick_radps, d->omega_max_radps) : 0.0;
  }
  switch (d->kind) {
    case TASKS_DRIVER_OPTIMAL: {
      // Line following on the door's centre line until the body is through the wall, then the goal.
      const double through = -0.5 * spec->wall_thickness_m - spec->robot_radius_m;
      const double theta = f->wall_distance_m > through
                               ? -f->heading_rad - atan2(f->offset_m, d->law[1])
                               : tasks_doorway_goal_bearing(spec, f);
      return tasks_clamp_omega(d->law[0] * features_angle_wrap(theta), d->omega_max_radps);
    }
    case TASKS_DRIVER_HUMAN: {
      // A jamb within a hand's breadth of the skirt: a reflex.
      const int danger = f->jamb_distance_m < spec->robot_radius_m + 0.15;
      return tasks_driver_human_step(d, example_target(d, spec, f), danger);
    }
    default:
      return tasks_clamp_omega(d->law[0] * example_target(d, spec, f), d->omega_max_radps);
  }
}

// ---- the declaration ------------------------------------------------------------------------

static const tasks_doorway_spec_t* spec_of(const tasks_episode_t* ep) {
  return (const tasks_doorway_spec_t*)tasks_episode_spec_const(ep);
}
static doorway_run_t* run_of(tasks_episode_t* ep) { return (doorway_run_t*)tasks_episode_run(ep); }
static const doorway_run_t* run_of_const(const tasks_episode_t* ep) {
  return (const doorway_run_t*)tasks_episode_run_const(ep);
}

static void spec_default(void* spec) { tasks_doorway_spec_default((tasks_doorway_spec_t*)spec); }

// The farthest a point of the room is from the door's jambs (a bound of the jamb distance).
static double room_reach(const tasks_doorway_spec_t* s) {
  const double dx = fmax(fabs(s->room_min_x_m - s->wall_x_m), fabs(s->room_max_x_m - s->wall_x_m));
  const double dy = fmax(fabs(s->room_min_y_m - s->door_y_m), fabs(s->room_max_y_m - s->door_y_m));
  return hypot(dx, dy + 0.5 * s->door_width_m);
}

static void state_range(const void* spec_v, double* lo, double* hi) {
  const tasks_doorway_spec_t* s = (const tasks_doorway_spec_t*)spec_v;
  lo[0] = s->wall_x_m - s->room_max_x_m;  // wall distance [m]: beyond the wall negative
  hi[0] = s->wall_x_m - s->room_min_x_m;
  lo[1] = s->room_min_y_m - s->door_y_m;  // offset [m]
  hi[1] = s->room_max_y_m - s->door_y_m;
  lo[2] = -0.5 * TASKS_PI;  // heading [rad]: beyond +-90 deg the robot faces away from the door
  hi[2] = 0.5 * TASKS_PI;
  lo[3] = 0.0;  // jamb distance [m]
  hi[3] = room_reach(s);
}

static void run_init(tasks_episode_t* ep) {
  doorway_run_t* r = run_of(ep);
  tasks_doorway_features_config(spec_of(ep), &r->features);
  const features_pose_t origin = {0.0, 0.0, 0.0};
  (void)features_doorway_from_pose(&r->features, origin, &r->state);
  r->state.valid = 0U;
}

static int write_state(const doorway_run_t* r, features_status_t status, double* state) {
  if (status != FEATURES_OK || r->state.valid == 0U) {
    return 0;
  }
  features_doorway_state(&r->state, state);
  return tasks_all_finite(state, FEATURES_DOORWAY_STATE_DIM);
}

static int observe(tasks_episode_t* ep, const features_scan_t* scan, features_pose_t pose, double* state) {
  doorway_run_t* r = run_of(ep);
  return write_state(r, features_doorway_compute(&r->features, scan, &pose, &r->state), state);
}

static int observe_pose(tasks_episode_t* ep, features_pose_t pose, double* state) {
  doorway_run_t* r = run_of(ep);
  return write_state(r, features_doorway_from_pose(&r->features, pose, &r->state), state);
}

static tasks_outcome_t outcome(const tasks_episode_t* ep, uint8_t contact, uint32_t steps_taken) {
  return tasks_doorway_outcome(spec_of(ep), &run_of_const(ep)->state, contact, steps_taken);
}

static double speed(const tasks_episode_t* ep) { return spec_of(ep)->v_mps; }

static features_pose_t training_start_near(const void* spec, uint32_t index, rng_t* rng) {
  return tasks_doorway_training_start_near((const tasks_doorway_spec_t*)spec, index, rng);
}

static const features_laser_mount_t* laser_mount(const tasks_episode_t* ep) {
  return &run_of_const(ep)->features.scan.mount;
}

static void state_bounds(const tasks_episode_t* ep, double* lo, double* hi) {
  // Odometry's values stay in the room (drift may take them a little beyond its walls); the
  // laser's are accepted only within gate_m of odometry's.
  const tasks_doorway_spec_t* s = spec_of(ep);
  const double slack = 1.0 + run_of_const(ep)->features.gate_m;
  lo[0] = s->wall_x_m - s->room_max_x_m - slack;
  hi[0] = s->wall_x_m - s->room_min_x_m + slack;
  lo[1] = s->room_min_y_m - s->door_y_m - slack;
  hi[1] = s->room_max_y_m - s->door_y_m + slack;
  lo[2] = -TASKS_PI;
  hi[2] = TASKS_PI;
  lo[3] = 0.0;
  hi[3] = room_reach(s) + 2.0 * slack;
}

static double driver_action(const tasks_episode_t* ep, tasks_driver_t* d) {
  return tasks_driver_doorway(d, spec_of(ep), &run_of_const(ep)->state);
}

static int world(const void* spec_v, const tasks_world_sink_t* sink) {
  const tasks_doorway_spec_t* s = (const tasks_doorway_spec_t*)spec_v;
  const double g0 = s->door_y_m - 0.5 * s->door_width_m;
  const double g1 = s->door_y_m + 0.5 * s->door_width_m;
  if (!(s->room_min_x_m < s->wall_x_m && s->wall_x_m < s->room_max_x_m && s->room_min_y_m < g0 &&
        g1 < s->room_max_y_m && s->wall_thickness_m > 0.0 && s->goal_radius_m > 0.0 && s->door_width_m > 0.0)) {
    return -1;
  }
  int bad = sink->arena(sink->user, s->room_min_x_m, s->room_min_y_m, s->room_max_x_m, s->room_max_y_m);
  // The dividing wall on either side of the gap, centred on x = wall_x_m.
  if (bad == 0) bad = sink->wall(sink->user, s->wall_x_m, s->room_min_y_m, s->wall_x_m, g0, s->wall_thickness_m);
  if (bad == 0) bad = sink->wall(sink->user, s->wall_x_m, g1, s->wall_x_m, s->room_max_y_m, s->wall_thickness_m);
  for (size_t i = 0; bad == 0 && i < TASKS_N_EVAL_STARTS; ++i) {
    bad = sink->start(sink->user, s->eval_starts[i]);
  }
  if (bad == 0) {
    bad = sink->goal(sink->user, s->goal_x_m, s->goal_y_m, s->goal_radius_m);
  }
  return bad != 0 ? bad : sink->name(sink->user, "doorway");
}

static const char* const k_state_names[] = {"wall distance [m]", "offset from the door's centre line [m]",
                                            "heading relative to the wall's normal [rad]",
                                            "nearer jamb's distance [m]"};

#define P(field) offsetof(tasks_doorway_spec_t, field)
static const tasks_param_t k_params[] = {
    {"room_min_x_m", P(room_min_x_m), -50.0, 50.0, "the room's walls: the box's lowest x [m]"},
    {"room_max_x_m", P(room_max_x_m), -50.0, 50.0, "the box's highest x [m]"},
    {"room_min_y_m", P(room_min_y_m), -50.0, 50.0, "the box's lowest y [m]"},
    {"room_max_y_m", P(room_max_y_m), -50.0, 50.0, "the box's highest y [m]"},
    {"wall_x_m", P(wall_x_m), -50.0, 50.0, "the dividing wall's centre plane, x [m]"},
    {"wall_thickness_m", P(wall_thickness_m), 0.02, 0.5, "the dividing wall's thickness [m]"},
    {"door_y_m", P(door_y_m), -50.0, 50.0, "the door's centre along the wall, y [m]"},
    {"door_width_m", P(door_width_m), 0.6, 3.0, "the door's gap, jamb to jamb [m]"},
    {"goal_x_m", P(goal_x_m), -50.0, 50.0, "goal position beyond the wall [m]"},
    {"goal_y_m", P(goal_y_m), -50.0, 50.0, "goal position [m]"},
    {"goal_radius_m", P(goal_radius_m), 0.05, 5.0, "the goal: robot centre within this of the goal position [m]"},
    {"v_mps", P(v_mps), 0.05, 1.0, "constant translation speed [m/s]"},
    {"goal_reward", P(goal_reward), -1000.0, 1000.0, "reward at the goal"},
    {"collision_reward", P(collision_reward), -1000.0, 1000.0, "reward on a collision"},
    {"train_jitter_x_m", P(train_jitter_x_m), 0.0, 5.0, "training starts: jitter around an evaluation pose along x [m]"},
    {"train_jitter_y_m", P(train_jitter_y_m), 0.0, 5.0, "training starts: jitter along y [m]"},
    {"train_jitter_theta_rad", P(train_jitter_theta_rad), 0.0, 3.2, "training starts: heading jitter [rad]"},
};

const tasks_decl_t tasks_doorway_decl = {
    .name = "doorway",
    .title = "Doorway passing",
    .env_id = "B21rDoorway-v0",
    .id = 2,
    .state_dim = FEATURES_DOORWAY_STATE_DIM,
    .state_names = k_state_names,
    // Raw units per scaled unit: about the change over which the value of an action changes
    // markedly. Progress towards the wall at a metre (as the corridor's end distance); the offset
    // at half a metre, the door's half-width (through, or into a jamb); the heading at a quarter
    // radian; the jamb distance at a metre, as it repeats what the first two say and only
    // sharpens them near the jambs; actions 0.25 rad/s apart count as different (as the
    // corridor's). Of four candidates on the experiment's schedule (10 seeds) this one ended best
    // against the example policy; all 1 (the obstacle task's) learned far worse (docs/experiments.md).
    .state_scale = {1.0, 0.5, 0.25, 1.0},
    .action_scale = 0.25,
    .greedy_reach = 3.0,
    .state_range = state_range,
    .spec_size = sizeof(tasks_doorway_spec_t),
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
    .gain_min = TASKS_PROPORTIONAL_DOORWAY_GAIN_MIN,
    .gain_max = TASKS_PROPORTIONAL_DOORWAY_GAIN_MAX,
    .driver_law = tasks_driver_law_doorway,
    .driver_human = NULL,
    .driver_action = driver_action,
    .world = world,
};
#undef P

const features_doorway_t* tasks_doorway_state(const tasks_episode_t* ep) {
  return ep->decl == &tasks_doorway_decl ? &run_of_const(ep)->state : NULL;
}

const features_doorway_config_t* tasks_doorway_features(const tasks_episode_t* ep) {
  return ep->decl == &tasks_doorway_decl ? &run_of_const(ep)->features : NULL;
}
