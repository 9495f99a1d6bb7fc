// SPDX-License-Identifier: MIT
// Task specifications, start poses, reward/termination and translation-speed policies.
#include <math.h>
#include <stddef.h>

#include "tasks/tasks.h"
#include "tasks_internal.h"

// ---------------------------------------------------------------------------------------------
// Corridor
// ---------------------------------------------------------------------------------------------

// Evaluation poses: centred and off-centre starts, heading straight, towards the near wall and
// away from it, so that every pose asks for a different correction.
static const double k_corridor_eval[TASKS_N_EVAL_STARTS][3] = {
    {1.0, 0.0, 0.0},   {1.2, 0.5, 0.0},    {1.2, -0.5, 0.0}, {0.8, 0.3, -0.6},
    {0.8, -0.3, 0.6},  {1.5, 0.0, 0.9},    {1.5, 0.0, -0.9}, {1.0, 0.4, 0.5},
    {1.0, -0.4, -0.5}, {1.6, 0.2, -1.0},
};

void tasks_corridor_spec_default(tasks_corridor_spec_t* spec) {
  spec->length_m = 10.0;
  spec->width_m = 2.0;
  spec->goal_distance_m = 1.0;
  spec->robot_radius_m = TASKS_B21R_RADIUS_M;
  spec->v_centre_mps = 0.6;
  spec->v_wall_mps = 0.2;
  spec->omega_max_radps = 1.0;
  spec->dt_s = 0.1;
  spec->step_limit = 1000U;
  spec->goal_reward = 10.0;
  spec->gamma = TASKS_CORRIDOR_GAMMA;
  spec->lookahead_m = 2.0;
  for (size_t i = 0U; i < TASKS_N_EVAL_STARTS; ++i) {
    spec->eval_starts[i].x_m = k_corridor_eval[i][0];
    spec->eval_starts[i].y_m = k_corridor_eval[i][1];
    spec->eval_starts[i].theta_rad = k_corridor_eval[i][2];
  }
  spec->train_jitter_x_m = 0.3;
  spec->train_jitter_y_m = 0.2;
  spec->train_jitter_theta_rad = 0.25;
}

void tasks_corridor_features_config(const tasks_corridor_spec_t* spec,
                                    features_corridor_config_t* cfg) {
  features_corridor_config_default(cfg);
  cfg->width_m = spec->width_m;
  cfg->length_m = spec->length_m;
  cfg->lookahead_m = spec->lookahead_m;
}

features_pose_t tasks_corridor_eval_start(const tasks_corridor_spec_t* spec, uint32_t index) {
  return spec->eval_starts[index % TASKS_N_EVAL_STARTS];
}

uint32_t tasks_corridor_steps_lower_bound(const tasks_corridor_spec_t* spec, features_pose_t start) {
  const double goal_x = spec->length_m - spec->goal_distance_m;
  const double turn = spec->omega_max_radps * spec->dt_s;
  const double advance = spec->v_centre_mps * spec->dt_s;
  double x = start.x_m;
  double heading = fabs(features_angle_wrap(start.theta_rad));
  uint32_t steps = 0U;
  // |heading| cannot fall faster than omega_max: cos of the turned heading bounds each step's
  // progress along the axis. advance > 0 (a valid spec), so the loop ends; 1 µm absorbs the
  // rounding of the summed advances.
  while (x < goal_x - 1e-6 && advance > 0.0) {
    heading = heading > turn ? heading - turn : 0.0;
    x += advance * cos(heading);
    ++steps;
  }
  return steps;
}

// Offset of a jittered pose from its base, normalised by the jitter box (max norm).
static double jitter_norm(double dx, double dy, double dth, double jx, double jy, double jth) {
  double n = 0.0;
  if (jx > 0.0) n = fmax(n, fabs(dx) / jx);
  if (jy > 0.0) n = fmax(n, fabs(dy) / jy);
  if (jth > 0.0) n = fmax(n, fabs(dth) / jth);
  return n;
}

// The training-start sampler of every task (tasks_internal.h).
int tasks_jittered_start(const features_pose_t eval_starts[TASKS_N_EVAL_STARTS], uint32_t index, double jx,
                         double jy, double jth, int (*is_clear)(const void* spec, features_pose_t),
                         const void* spec, rng_t* rng, features_pose_t* out, features_pose_t* base_out) {
  const features_pose_t base = eval_starts[index % TASKS_N_EVAL_STARTS];
  *base_out = base;
  *out = base;
  for (int attempt = 0; attempt < TASKS_START_ATTEMPTS; ++attempt) {
    const double dx = rng_uniform_range(rng, -jx, jx);
    const double dy = rng_uniform_range(rng, -jy, jy);
    const double dth = rng_uniform_range(rng, -jth, jth);
    features_pose_t p = base;
    p.x_m = base.x_m + dx;
    p.y_m = base.y_m + dy;
    p.theta_rad = features_angle_wrap(base.theta_rad + dth);
    *out = p;
    if (jitter_norm(dx, dy, dth, jx, jy, jth) >= TASKS_MIN_JITTER_NORM && is_clear(spec, p)) {
      return 1;
    }
  }
  return 0;
}

static double clampd(double v, double lo, double hi) { return v < lo ? lo : (v > hi ? hi : v); }

static int corridor_pose_clear(const void* spec_v, features_pose_t p) {
  const tasks_corridor_spec_t* spec = (const tasks_corridor_spec_t*)spec_v;
  const double margin = spec->robot_radius_m + 0.1;
  return fabs(p.y_m) <= 0.5 * spec->width_m - margin && p.x_m >= margin &&
         p.x_m <= spec->length_m - spec->goal_distance_m - 0.5;
}

features_pose_t tasks_corridor_training_start(const tasks_corridor_spec_t* spec, rng_t* rng) {
  return tasks_corridor_training_start_near(spec, rng_below(rng, TASKS_N_EVAL_STARTS), rng);
}

features_pose_t tasks_corridor_training_start_near(const tasks_corridor_spec_t* spec, uint32_t index,
                                                   rng_t* rng) {
  features_pose_t p;
  features_pose_t base;
  if (tasks_jittered_start(spec->eval_starts, index, spec->train_jitter_x_m, spec->train_jitter_y_m,
                     spec->train_jitter_theta_rad, corridor_pose_clear, spec, rng, &p, &base)) {
    return p;
  }
  const double margin = spec->robot_radius_m + 0.1;
  const double ylim = fmax(0.0, 0.5 * spec->width_m - margin);
  p.y_m = clampd(p.y_m, -ylim, ylim);
  p.x_m = clampd(p.x_m, margin, fmax(margin, spec->length_m - spec->goal_distance_m - 0.5));
  return p;
}

static tasks_outcome_t outcome_none(void) {
  tasks_outcome_t o = {0.0, 0U, 0U, (uint8_t)TASKS_END_NONE};
  return o;
}

static void apply_step_limit(tasks_outcome_t* o, uint32_t step_limit, uint32_t steps_taken) {
  if (o->end_run == 0U && step_limit > 0U && steps_taken >= step_limit) {
    o->end_run = 1U;
    o->reason = (uint8_t)TASKS_END_STEP_LIMIT;
  }
}

tasks_outcome_t tasks_corridor_outcome(const tasks_corridor_spec_t* spec,
                                       const features_corridor_t* f_next, uint8_t contact,
                                       uint32_t steps_taken) {
  tasks_outcome_t o = outcome_none();
  if (f_next != NULL && f_next->valid != 0U && f_next->end_distance_m <= spec->goal_distance_m) {
    o.reward = spec->goal_reward;
    o.terminal = 1U;
    o.end_run = 1U;
    o.reason = (uint8_t)TASKS_END_GOAL;
  } else if (contact != 0U) {
    o.terminal = 1U;
    o.end_run = 1U;
    o.reason = (uint8_t)TASKS_END_COLLISION;
  }
  apply_step_limit(&o, spec->step_limit, steps_taken);
  return o;
}

double tasks_corridor_speed_mps(const tasks_corridor_spec_t* spec, const features_corridor_t* f) {
  if (f == NULL || f->valid == 0U || !isfinite(f->lateral_frac)) {
    return spec->v_wall_mps;
  }
  // |2f - 1| is 0 on the centre line and 1 - 2r/W where the robot's edge touches a wall.
  const double touch = 1.0 - 2.0 * spec->robot_radius_m / spec->width_m;
  const double u = fabs(2.0 * f->lateral_frac - 1.0);
  const double q = touch > 0.0 ? fmin(1.0, u / touch) : 1.0;
  return spec->v_wall_mps + (spec->v_centre_mps - spec->v_wall_mps) * (1.0 - q * q);
}

// ---------------------------------------------------------------------------------------------
// Obstacles
// ---------------------------------------------------------------------------------------------

// Evaluation poses as (distance from goal [m], bearing of the start seen from the goal [deg],
// heading offset from the direction to the goal [rad]).
static const double k_obstacles_eval[TASKS_N_EVAL_STARTS][3] = {
    {3.0, 180.0, 0.0},  {3.0, 170.0, 0.3},  {3.0, 190.0, -0.3}, {2.9, 160.0, -0.4},
    {2.9, 200.0, 0.4},  {3.1, 175.0, -0.5}, {3.1, 185.0, 0.5},  {3.2, 150.0, 0.2},
    {3.2, 210.0, -0.2}, {2.8, 180.0, 0.6},
};

void tasks_obstacles_spec_default(tasks_obstacles_spec_t* spec) {
  spec->goal_x_m = 0.0;
  spec->goal_y_m = 0.0;
  spec->goal_radius_m = 0.3;
  spec->n_obstacles = 1U;
  for (size_t k = 0U; k < TASKS_MAX_OBSTACLES; ++k) {
    spec->obstacles[k].x_m = 0.0;
    spec->obstacles[k].y_m = 0.0;
    spec->obstacles[k].radius_m = 0.25;
  }
  spec->obstacles[0].x_m = -1.5;
  spec->obstacles[0].y_m = 0.0;
  spec->arena_min_x_m = -5.0;
  spec->arena_max_x_m = 2.0;
  spec->arena_min_y_m = -3.5;
  spec->arena_max_y_m = 3.5;
  spec->robot_radius_m = TASKS_B21R_RADIUS_M;
  spec->v_mps = 0.3;
  spec->omega_max_radps = 1.0;
  spec->dt_s = 0.1;
  spec->step_limit = 500U;
  spec->goal_reward = 1.0;
  spec->collision_reward = -1.0;
  spec->gamma = TASKS_OBSTACLES_GAMMA;
  const double deg = TASKS_PI / 180.0;
  for (size_t i = 0U; i < TASKS_N_EVAL_STARTS; ++i) {
    const double rho = k_obstacles_eval[i][0];
    const double beta = k_obstacles_eval[i][1] * deg;
    features_pose_t p;
    p.x_m = spec->goal_x_m + rho * cos(beta);
    p.y_m = spec->goal_y_m + rho * sin(beta);
    p.theta_rad = features_angle_wrap(beta + TASKS_PI + k_obstacles_eval[i][2]);
    spec->eval_starts[i] = p;
  }
  spec->train_jitter_x_m = 0.3;
  spec->train_jitter_y_m = 0.3;
  spec->train_jitter_theta_rad = 0.3;
  spec->memory_s = 3.0;
}

void tasks_obstacles_features_config(const tasks_obstacles_spec_t* spec,
                                     features_obstacles_config_t* cfg) {
  features_obstacles_config_default(cfg);
  const double periods = spec->dt_s > 0.0 && spec->memory_s > 0.0 ? floor(spec->memory_s / spec->dt_s + 0.5) : 0.0;
  cfg->memory_max_age = periods < 1e6 ? (uint32_t)periods : 1000000U;
}

features_pose_t tasks_obstacles_eval_start(const tasks_obstacles_spec_t* spec, uint32_t index) {
  return spec->eval_starts[index % TASKS_N_EVAL_STARTS];
}

static int obstacles_pose_clear(const void* spec_v, features_pose_t p) {
  const tasks_obstacles_spec_t* spec = (const tasks_obstacles_spec_t*)spec_v;
  const double margin = spec->robot_radius_m + 0.1;
  if (p.x_m < spec->arena_min_x_m + margin || p.x_m > spec->arena_max_x_m - margin ||
      p.y_m < spec->arena_min_y_m + margin || p.y_m > spec->arena_max_y_m - margin) {
    return 0;
  }
  const uint32_t n = spec->n_obstacles < TASKS_MAX_OBSTACLES ? spec->n_obstacles : TASKS_MAX_OBSTACLES;
  for (uint32_t k = 0U; k < n; ++k) {
    const tasks_circle_t* c = &spec->obstacles[k];
    if (hypot(p.x_m - c->x_m, p.y_m - c->y_m) < c->radius_m + margin) {
      return 0;
    }
  }
  return hypot(p.x_m - spec->goal_x_m, p.y_m - spec->goal_y_m) > spec->goal_radius_m + 0.5;
}

features_pose_t tasks_obstacles_training_start(const tasks_obstacles_spec_t* spec,
                                               rng_t* rng) {
  return tasks_obstacles_training_start_near(spec, rng_below(rng, TASKS_N_EVAL_STARTS), rng);
}

features_pose_t tasks_obstacles_training_start_near(const tasks_obstacles_spec_t* spec, uint32_t index,
                                                    rng_t* rng) {
  features_pose_t p;
  features_pose_t base;
  if (tasks_jittered_start(spec->eval_starts, index, spec->train_jitter_x_m, spec->train_jitter_y_m,
                     spec->train_jitter_theta_rad, obstacles_pose_clear, spec, rng, &p, &base)) {
    return p;
  }
  // Every attempt failed (only possible with a spec whose jitter box is mostly blocked): keep
  // the evaluation position, which the spec guarantees clear, with a turned heading.
  p = base;
  p.theta_rad = features_angle_wrap(base.theta_rad + 0.5 * spec->train_jitter_theta_rad);
  return p;
}

tasks_outcome_t tasks_obstacles_outcome(const tasks_obstacles_spec_t* spec,
                                        const features_obstacles_t* f_next, uint8_t contact,
                                        uint32_t steps_taken) {
  tasks_outcome_t o = outcome_none();
  if (contact != 0U) {
    o.reward = spec->collision_reward;
    o.terminal = 1U;
    o.end_run = 1U;
    o.reason = (uint8_t)TASKS_END_COLLISION;
  } else if (f_next != NULL && f_next->valid != 0U &&
             f_next->goal_distance_m <= spec->goal_radius_m) {
    o.reward = spec->goal_reward;
    o.terminal = 1U;
    o.end_run = 1U;
    o.reason = (uint8_t)TASKS_END_GOAL;
  }
  apply_step_limit(&o, spec->step_limit, steps_taken);
  return o;
}

double tasks_obstacles_speed_mps(const tasks_obstacles_spec_t* spec) { return spec->v_mps; }

double tasks_clamp_omega(double omega_radps, double omega_max_radps) {
  if (!isfinite(omega_radps) || !isfinite(omega_max_radps) || omega_max_radps <= 0.0) {
    return 0.0;
  }
  return clampd(omega_radps, -omega_max_radps, omega_max_radps);
}

uint32_t tasks_start_cycle_next(tasks_start_cycle_t* cycle, rng_t* rng) {
  if (!cycle->started || cycle->next >= TASKS_N_EVAL_STARTS) {
    // Fisher-Yates shuffle of 0..9.
    for (uint32_t i = 0U; i < TASKS_N_EVAL_STARTS; ++i) {
      cycle->order[i] = (uint8_t)i;
    }
    for (uint32_t i = TASKS_N_EVAL_STARTS - 1U; i > 0U; --i) {
      const uint32_t j = rng_below(rng, i + 1U);
      const uint8_t t = cycle->order[i];
      cycle->order[i] = cycle->order[j];
      cycle->order[j] = t;
    }
    cycle->next = 0U;
    cycle->started = 1U;
  }
  return cycle->order[cycle->next++];
}
