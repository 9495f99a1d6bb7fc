// SPDX-License-Identifier: MIT
// Example drivers for phase one (proportional, simulated human) and the optimal references.
#include <math.h>
#include <stddef.h>
#include <string.h>

#include "tasks/tasks.h"
#include "tasks_internal.h"

// The "optimal" references: the best constants of each task's control law found by the grid
// search in test/unit/tasks/tasks_optimal_search.c over the ten evaluation starts in the
// synthetic world (kinematic synchro drive at 10 Hz, features from synthetic LMS200 scans, three
// noise seeds, the robot's edge kept at least 0.10 m from everything). Mean steps to the goal at
// the time of the search: corridor 133.7, obstacles 95.2. Re-run the search after changing a
// task, a law or the features.
#define OPTIMAL_CORRIDOR_GAIN 2.25
#define OPTIMAL_CORRIDOR_LOOKAHEAD_M 1.0
#define OPTIMAL_OBSTACLES_GAIN 5.0
#define OPTIMAL_OBSTACLES_CLEARANCE_M 0.40
#define OPTIMAL_OBSTACLES_RANGE_M 1.25

// Fixed avoidance geometry of the example (proportional) obstacle policy.
#define EXAMPLE_OBSTACLES_CLEARANCE_M 0.55
#define EXAMPLE_OBSTACLES_RANGE_M 1.5

void tasks_driver_begin_common(tasks_driver_t* d, tasks_driver_kind_t kind, uint8_t task_id, double omega_max_radps,
                               uint64_t run_seed, double gain_min, double gain_max) {
  memset(d, 0, sizeof(*d));
  d->kind = (uint8_t)((kind == TASKS_DRIVER_HUMAN || kind == TASKS_DRIVER_OPTIMAL)
                          ? kind : TASKS_DRIVER_PROPORTIONAL);
  d->task = task_id;
  d->omega_max_radps =
      (isfinite(omega_max_radps) && omega_max_radps > 0.0) ? omega_max_radps : 1.0;
  rng_seed(&d->rng, run_seed);
  // The gain is drawn first for every kind, so that the streams of the kinds stay comparable.
  d->gain = rng_uniform_range(&d->rng, gain_min, gain_max);
}

void tasks_driver_begin_human(tasks_driver_t* d) {
  // A person's temperament for this run: a heavy hand (gain well above what is needed), a
  // reaction delay of 0.3..0.8 s, a dead band before anything is done, a noisy hand and slow
  // drift, and now and then a lapse of attention; and their preferences (an offset and an aim
  // distance where a task has a line to follow, a side where it has something to pass).
  d->gain = rng_uniform_range(&d->rng, 1.5, 3.5);
  d->delay_steps = 3U + rng_below(&d->rng, 6U);
  d->deadband_rad = rng_uniform_range(&d->rng, 0.15, 0.4);
  d->release_rad = rng_uniform_range(&d->rng, 0.02, 0.08);
  d->noise_radps = rng_uniform_range(&d->rng, 0.05, 0.2);
  d->drift_radps = rng_uniform_range(&d->rng, 0.1, 0.35);
  d->lapse_prob = rng_uniform_range(&d->rng, 0.01, 0.05);
  d->pref_offset_m = rng_uniform_range(&d->rng, -0.35, 0.35);
  d->pref_lookahead_m = rng_uniform_range(&d->rng, 1.0, 3.0);
  d->side_pref = (int8_t)(rng_uniform(&d->rng) < 0.3 ? -1 : 1);
}

void tasks_driver_law_corridor(tasks_driver_t* d) {
  d->law[0] = OPTIMAL_CORRIDOR_GAIN;
  d->law[1] = OPTIMAL_CORRIDOR_LOOKAHEAD_M;
}

void tasks_driver_law_obstacles(tasks_driver_t* d) {
  if (d->kind == (uint8_t)TASKS_DRIVER_OPTIMAL) {
    d->law[0] = OPTIMAL_OBSTACLES_GAIN;
    d->law[1] = OPTIMAL_OBSTACLES_CLEARANCE_M;
    d->law[2] = OPTIMAL_OBSTACLES_RANGE_M;
  } else {
    d->law[0] = d->gain;
    d->law[1] = EXAMPLE_OBSTACLES_CLEARANCE_M;
    d->law[2] = EXAMPLE_OBSTACLES_RANGE_M;
  }
}

void tasks_driver_human_obstacles(tasks_driver_t* d) {
  // People give obstacles a wide berth and start early.
  d->law[1] = rng_uniform_range(&d->rng, 0.6, 1.0);
  d->law[2] = rng_uniform_range(&d->rng, 1.5, 2.5);
}

// The human model. `error` is what the person is trying to null (an angle, +: turn left);
// `danger` says a collision looks imminent, which cuts a lapse short and forces a correction.
double tasks_driver_human_step(tasks_driver_t* d, double error, int danger) {
  const double perceived = error + 0.03 * rng_normal(&d->rng);
  d->delay_line[d->head] = perceived;
  d->head = (d->head + 1U) % TASKS_HUMAN_MAX_DELAY;
  ++d->steps;
  // What the person acts on now is what they saw delay_steps ago (or the oldest so far); an
  // imminent collision is a reflex, acted on after 0.1 s.
  const uint32_t delay = danger ? 1U : d->delay_steps;
  const uint32_t lag = d->steps <= delay ? d->steps - 1U : delay;
  const double e = d->delay_line[(d->head + TASKS_HUMAN_MAX_DELAY - 1U - lag) % TASKS_HUMAN_MAX_DELAY];

  d->drift_state = 0.95 * d->drift_state + 0.3 * d->drift_radps * rng_normal(&d->rng);
  d->drift_state = fmax(-d->drift_radps, fmin(d->drift_radps, d->drift_state));
  const double u_lapse = rng_uniform(&d->rng);
  const double hand = d->noise_radps * rng_normal(&d->rng);
  if (danger) {
    d->lapse_steps = 0U;
    d->hold_steps = 0U;
  }
  if (d->lapse_steps > 0U) {
    --d->lapse_steps;
    d->stick_radps *= 0.8;  // attention elsewhere: the hand relaxes
  } else if (d->hold_steps > 0U) {
    --d->hold_steps;
  } else {
    if (!d->correcting && (fabs(e) > d->deadband_rad || danger)) {
      d->correcting = 1U;
    } else if (d->correcting && fabs(e) < d->release_rad && !danger) {
      d->correcting = 0U;
    }
    const double k = danger ? fmax(d->gain, 3.0) : d->gain;
    // Joystick positions are coarse: a tenth of the range per notch.
    const double want = d->correcting ? k * e : 0.0;
    d->stick_radps = 0.1 * d->omega_max_radps * floor(want / (0.1 * d->omega_max_radps) + 0.5);
    d->hold_steps = 1U + rng_below(&d->rng, 4U);
    // Attention wanders when things look calm, not in the middle of a hard turn.
    if (u_lapse < d->lapse_prob && !danger && fabs(d->stick_radps) < 0.5 * d->omega_max_radps) {
      d->lapse_steps = 5U + rng_below(&d->rng, 21U);
    }
  }
  // In a reflex the hand is firm: no drift.
  const double drift = danger ? 0.0 : d->drift_state;
  return tasks_clamp_omega(d->stick_radps + drift + hand, d->omega_max_radps);
}

double tasks_driver_corridor(tasks_driver_t* d, const features_corridor_t* f) {
  if (d == NULL) {
    return 0.0;
  }
  if (f == NULL || f->valid == 0U) {
    return d->kind == (uint8_t)TASKS_DRIVER_HUMAN ? tasks_clamp_omega(d->stick_radps, d->omega_max_radps)
                                                  : 0.0;
  }
  switch (d->kind) {
    case TASKS_DRIVER_OPTIMAL: {
      const double theta = -f->heading_rad - atan2(f->offset_m, d->law[1]);
      return tasks_clamp_omega(d->law[0] * theta, d->omega_max_radps);
    }
    case TASKS_DRIVER_HUMAN: {
      // Danger: within 0.3 of the width from a wall and still heading towards it, or pointing
      // at a wall (more than 1.1 rad off the corridor axis).
      const int danger = (f->lateral_frac < 0.3 && f->heading_rad > 0.0) ||
                         (f->lateral_frac > 0.7 && f->heading_rad < 0.0) ||
                         fabs(f->heading_rad) > 1.1;
      // The person aims at their favourite line, at their own distance ahead.
      const double aim = -f->heading_rad - atan2(f->offset_m - d->pref_offset_m, d->pref_lookahead_m);
      return tasks_driver_human_step(d, features_angle_wrap(aim), danger);
    }
    default:
      return tasks_clamp_omega(d->gain * f->target_angle_rad, d->omega_max_radps);
  }
}

double tasks_obstacles_cone_half_angle_rad(double clearance_m, double distance_m) {
  return distance_m > clearance_m ? asin(clearance_m / distance_m) : 0.5 * TASKS_PI;
}

// Goal bearing bent around the nearest obstacle (see tasks.h).
static double obstacle_target(tasks_driver_t* d, const features_obstacles_t* f) {
  const double g = f->goal_bearing_rad;
  const features_obstacle_t* o = &f->obstacle[0];
  const double clearance = d->law[1];
  const double range = d->law[2];
  if (o->visible == 0U || o->distance_m >= range || o->distance_m >= f->goal_distance_m) {
    if (d->avoid_side != 0 && o->visible == 0U) {
      // The obstacle slipped out of view beside the robot while being avoided: it is still
      // there, so hold the course a little before turning to the goal.
      d->pass_steps = TASKS_OBSTACLES_PASS_HOLD_STEPS;
    }
    d->avoid_side = 0;
    if (d->pass_steps > 0U) {
      --d->pass_steps;
      return 0.0;
    }
    return g;
  }
  d->pass_steps = 0U;
  const double alpha = tasks_obstacles_cone_half_angle_rad(clearance, o->distance_m);
  const double rel = features_angle_wrap(g - o->bearing_rad);
  if (fabs(rel) >= alpha && d->avoid_side == 0) {
    return g;
  }
  if (d->avoid_side == 0) {
    if (fabs(o->bearing_rad) > 0.5 * alpha || o->distance_m < 1.5 * clearance) {
      // Off to one side, or already close: pass it on the side that needs the least turning.
      d->avoid_side = (int8_t)(o->bearing_rad > 0.0 ? -1 : 1);
    } else {
      // Nearly dead ahead: the goal's side, or, for a person who prefers it, the far side.
      const int goal_side = rel >= 0.0 ? 1 : -1;
      d->avoid_side = (int8_t)(d->side_pref < 0 ? -goal_side : goal_side);
    }
  }
  const double edge = o->bearing_rad + (double)d->avoid_side * alpha;
  // Once the goal lies outside the cone on the chosen side, head for the goal again.
  if ((double)d->avoid_side * features_angle_wrap(g - edge) >= 0.0) {
    return g;
  }
  return features_angle_wrap(edge);
}

double tasks_driver_obstacles(tasks_driver_t* d, const features_obstacles_t* f) {
  if (d == NULL) {
    return 0.0;
  }
  if (f == NULL || f->valid == 0U) {
    return d->kind == (uint8_t)TASKS_DRIVER_HUMAN ? tasks_clamp_omega(d->stick_radps, d->omega_max_radps)
                                                  : 0.0;
  }
  const double theta = obstacle_target(d, f);
  if (d->kind == (uint8_t)TASKS_DRIVER_HUMAN) {
    const features_obstacle_t* o = &f->obstacle[0];
    const int danger = o->visible != 0U && o->distance_m < 0.8 && fabs(o->bearing_rad) < 1.0;
    return tasks_driver_human_step(d, theta, danger);
  }
  return tasks_clamp_omega(d->law[0] * theta, d->omega_max_radps);
}
