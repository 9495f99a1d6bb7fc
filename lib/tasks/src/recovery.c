// SPDX-License-Identifier: MIT
// The corridor's recovery rollout and the whole-run rollouts of both tasks (see tasks/recovery.h).
#include "tasks/recovery.h"

#include "tasks_internal.h"

#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <string.h>

// The longest rollout: 20 s is several times the recovery law's settling time (about 3 s).
#define RECOVERY_MAX_HORIZON_S 20.0
// Control periods below this are refused (the step count would not be bounded).
#define RECOVERY_MIN_DT_S 1e-3

// The model's state: the pose in the corridor frame and the axes' velocities.
typedef struct model {
  double y;      // lateral offset from the (measured) centre line, + = left [m]
  double psi;    // heading to the corridor axis, CCW [rad]
  double ahead;  // distance to the end wall [m]
  double v;      // translation velocity [m/s]
  double w;      // rotation velocity [rad/s]
} model_t;

// To [-pi, pi] (the rollout's heading stays within 20 s x the rotation limit of its start).
static double wrap_pi(double a) { return remainder(a, 2.0 * 3.14159265358979323846); }

// The width the walls are at: the measured one where it is smaller than the nominal one (the
// features' offset is measured from the measured centre line), never more than nominal.
static double wall_width_m(const tasks_corridor_spec_t* spec, const features_corridor_t* f) {
  const double w = f->width_m;
  return isfinite(w) && w > 0.0 ? fmin(w, spec->width_m) : spec->width_m;
}

static bool inputs_ok(const tasks_corridor_spec_t* spec, const tasks_command_limits_t* lim, double dt_s,
                      const features_corridor_t* f) {
  return spec != NULL && lim != NULL && f != NULL && f->valid != 0U && dt_s >= RECOVERY_MIN_DT_S &&
         isfinite(dt_s) && isfinite(f->offset_m) && isfinite(f->heading_rad) && isfinite(f->end_distance_m);
}

// The features the speed policy and the recovery law see at the model's pose.
static features_corridor_t features_at(const tasks_corridor_spec_t* spec, const features_corridor_t* f,
                                       double width_m, const model_t* m) {
  features_corridor_t at = *f;
  at.offset_m = m->y;
  at.heading_rad = wrap_pi(m->psi);
  at.end_distance_m = m->ahead;
  at.lateral_frac = fmin(1.0, fmax(0.0, (0.5 * width_m - m->y) / width_m));
  at.target_angle_rad = wrap_pi(-m->psi - atan2(m->y, spec->lookahead_m));
  return at;
}

// One control period: the command (clamped from the one in force) and the axes' linear ramp to
// it; the heading at the period's middle, psi + dt (3 w_prev + w_cmd) / 8, gives the direction.
static void step(const tasks_command_limits_t* lim, double dt_s, double v_cmd, double w_cmd, model_t* m) {
  (void)tasks_command_clamp(lim, dt_s, m->v, m->w, &v_cmd, &w_cmd);
  const double psi_mid = m->psi + dt_s * (3.0 * m->w + w_cmd) / 8.0;
  const double ds = 0.5 * (m->v + v_cmd) * dt_s;
  m->y += ds * sin(psi_mid);
  m->ahead -= ds * cos(psi_mid);
  m->psi += 0.5 * (m->w + w_cmd) * dt_s;
  m->v = v_cmd;
  m->w = w_cmd;
}

double tasks_corridor_recovery_action(const tasks_corridor_spec_t* spec, const features_corridor_t* f) {
  if (spec == NULL || f == NULL || f->valid == 0U || !isfinite(f->target_angle_rad)) {
    return 0.0;
  }
  return tasks_clamp_omega(TASKS_CORRIDOR_RECOVERY_GAIN * f->target_angle_rad, spec->omega_max_radps);
}

// The run ends at the goal and the base is told to stop: it coasts to a stand under its
// acceleration limits, on its heading, and may still reach a wall. *least takes the clearance of
// every period of the coast (half_free: |y| where the skirt touches). False when the base would
// not stand within 20 s (a limit near 0): nothing can be predicted.
static bool coast_to_stand(const tasks_command_limits_t* lim, double dt_s, double half_free, model_t* m,
                           double* least) {
  const int32_t n_max = (int32_t)ceil(RECOVERY_MAX_HORIZON_S / dt_s);
  for (int32_t k = 0; fabs(m->v) > 0.0 || fabs(m->w) > 0.0; ++k) {
    if (k == n_max) {
      return false;
    }
    step(lim, dt_s, 0.0, 0.0, m);
    *least = fmin(*least, half_free - fabs(m->y));
  }
  return true;
}

double tasks_corridor_recovery_clearance_m(const tasks_corridor_spec_t* spec, const tasks_command_limits_t* lim,
                                           double dt_s, const features_corridor_t* f, double prev_v_mps,
                                           double prev_omega_radps, double omega_radps, double horizon_s) {
  if (!inputs_ok(spec, lim, dt_s, f) || !isfinite(prev_v_mps) || !isfinite(prev_omega_radps) ||
      !isfinite(omega_radps) || !isfinite(horizon_s)) {
    return -HUGE_VAL;
  }
  const double width = wall_width_m(spec, f);
  const double half_free = 0.5 * width - spec->robot_radius_m;  // |y| where the skirt touches
  const double h = fmin(fmax(horizon_s, dt_s), RECOVERY_MAX_HORIZON_S);
  const int32_t n = (int32_t)ceil(h / dt_s - 1e-9);  // <= 20 / 1e-3
  model_t m = {f->offset_m, f->heading_rad, f->end_distance_m, prev_v_mps, prev_omega_radps};
  double least = HUGE_VAL;
  bool at_goal = false;
  for (int32_t k = 0; k < n && !at_goal; ++k) {
    const features_corridor_t at = features_at(spec, f, width, &m);
    step(lim, dt_s, tasks_corridor_speed_mps(spec, &at), k == 0 ? omega_radps : tasks_corridor_recovery_action(spec, &at),
         &m);
    least = fmin(least, half_free - fabs(m.y));
    at_goal = m.ahead <= spec->goal_distance_m;
  }
  if (at_goal && !coast_to_stand(lim, dt_s, half_free, &m, &least)) {
    return -HUGE_VAL;
  }
  return least;
}

int tasks_corridor_recovery_predict(const tasks_corridor_spec_t* spec, const tasks_command_limits_t* lim, double dt_s,
                                    const features_corridor_t* f, double prev_v_mps, double prev_omega_radps,
                                    double v_mps, double omega_radps, features_corridor_t* out) {
  if (out == NULL || !inputs_ok(spec, lim, dt_s, f) || !isfinite(prev_v_mps) || !isfinite(prev_omega_radps) ||
      !isfinite(v_mps) || !isfinite(omega_radps)) {
    return 0;
  }
  const double width = wall_width_m(spec, f);
  model_t m = {f->offset_m, f->heading_rad, f->end_distance_m, prev_v_mps, prev_omega_radps};
  step(lim, dt_s, v_mps, omega_radps, &m);
  m.ahead = fmax(0.0, m.ahead);
  *out = features_at(spec, f, width, &m);
  return 1;
}

int32_t tasks_corridor_rollout_begin(tasks_corridor_rollout_t* ro, const tasks_corridor_spec_t* spec,
                                     const double* corridor_state, double omega_radps) {
  if (ro == NULL) {
    return TASKS_ROLLOUT_INVALID;
  }
  memset(ro, 0, sizeof *ro);
  ro->status = TASKS_ROLLOUT_INVALID;
  if (spec == NULL || corridor_state == NULL || !isfinite(corridor_state[0]) || !isfinite(corridor_state[1]) ||
      !isfinite(corridor_state[2]) || !isfinite(omega_radps)) {
    return ro->status;
  }
  const double width = spec->width_m;
  const double y = (0.5 - corridor_state[1]) * width;
  const model_t m = {y, -corridor_state[2] - atan2(y, spec->lookahead_m), corridor_state[0], 0.0, omega_radps};
  features_corridor_t base;
  memset(&base, 0, sizeof base);
  base.width_m = width;
  base.valid = 1U;
  ro->f = features_at(spec, &base, width, &m);
  ro->omega_radps = omega_radps;
  ro->least_clearance_m = 0.5 * width - spec->robot_radius_m - fabs(y);
  ro->status = TASKS_ROLLOUT_RUNNING;
  return ro->status;
}

int32_t tasks_corridor_rollout_step(tasks_corridor_rollout_t* ro, const tasks_corridor_spec_t* spec,
                                    const tasks_command_limits_t* lim, double dt_s, double omega_radps,
                                    double margin_m, uint32_t step_limit) {
  if (ro == NULL) {
    return TASKS_ROLLOUT_INVALID;
  }
  if (ro->status != TASKS_ROLLOUT_RUNNING) {
    return ro->status;
  }
  if (!inputs_ok(spec, lim, dt_s, &ro->f) || !isfinite(omega_radps) || !isfinite(margin_m)) {
    ro->status = TASKS_ROLLOUT_INVALID;
    return ro->status;
  }
  const double width = wall_width_m(spec, &ro->f);
  const double half_free = 0.5 * width - spec->robot_radius_m;
  model_t m = {ro->f.offset_m, ro->f.heading_rad, ro->f.end_distance_m, ro->v_mps, ro->omega_radps};
  step(lim, dt_s, tasks_corridor_speed_mps(spec, &ro->f), omega_radps, &m);
  ro->periods++;
  ro->least_clearance_m = fmin(ro->least_clearance_m, half_free - fabs(m.y));
  if (m.ahead <= spec->goal_distance_m && !coast_to_stand(lim, dt_s, half_free, &m, &ro->least_clearance_m)) {
    ro->status = TASKS_ROLLOUT_INVALID;
    return ro->status;
  }
  ro->v_mps = m.v;
  ro->omega_radps = m.w;
  m.ahead = fmax(0.0, m.ahead);
  ro->f = features_at(spec, &ro->f, width, &m);
  if (ro->least_clearance_m < margin_m) {
    ro->status = TASKS_ROLLOUT_WALL;
  } else if (m.ahead <= spec->goal_distance_m) {
    ro->status = TASKS_ROLLOUT_GOAL;
  } else if (ro->periods >= step_limit) {
    ro->status = TASKS_ROLLOUT_STEP_LIMIT;
  }
  return ro->status;
}

// ---------------------------------------------------------------------------------------------
// The obstacle task's whole run. The corridor's model_t and step() serve in the arena frame with
// y = the pose's y, psi = its heading and ahead = -x (step moves ahead by -ds cos psi, so x by
// +ds cos psi).

// How far the triangle robot-goal-disc may miss a disc's distance from the goal and still be
// taken for it [m]: the laser's distance and bearing errors (about 0.02 m and 0.01 rad at 3 m)
// with room to spare, well below the distance between two discs' circles around the goal.
#define OBSTACLES_MATCH_TOLERANCE_M 0.25

// The features an ideal laser gives at the model's pose (tasks_episode_observe_pose's), valid.
static bool obstacles_features_at(const tasks_obstacles_spec_t* spec, const features_obstacles_config_t* fcfg,
                                  features_pose_t p, features_obstacles_t* f) {
  return tasks_obstacles_features_at_pose(spec, fcfg, p, f) == FEATURES_OK && f->valid != 0U;
}

static bool obstacles_inputs_ok(const tasks_obstacles_spec_t* spec, const features_obstacles_config_t* fcfg) {
  return spec != NULL && fcfg != NULL && spec->n_obstacles <= TASKS_MAX_OBSTACLES && isfinite(spec->goal_x_m) &&
         isfinite(spec->goal_y_m);
}

int tasks_obstacles_pose_from_state(const tasks_obstacles_spec_t* spec, const features_obstacles_config_t* fcfg,
                                    const double* obstacles_state, features_pose_t* pose) {
  if (!obstacles_inputs_ok(spec, fcfg) || obstacles_state == NULL || pose == NULL) {
    return 0;
  }
  const double goal_bearing = obstacles_state[0];
  const double goal_distance = obstacles_state[1];
  const double obstacle_bearing = obstacles_state[2];
  const double obstacle_distance = obstacles_state[3];
  if (!isfinite(goal_bearing) || !isfinite(goal_distance) || !isfinite(obstacle_bearing) ||
      !isfinite(obstacle_distance) || goal_distance < 0.0 || obstacle_distance < 0.0 ||
      obstacle_distance >= fcfg->no_obstacle_distance_m) {
    return 0;
  }
  // Each disc whose distance from the goal the triangle matches gives a pose. With one disc that
  // is the pose; with several the distance alone can match the wrong disc, so the pose whose own
  // features best reproduce the state's obstacle is taken (one where no obstacle is in view, at
  // the field of view's edge, only when no other candidate shows one).
  bool found = false;
  double best_score = HUGE_VAL;
  for (uint32_t k = 0U; k < spec->n_obstacles; ++k) {
    const tasks_circle_t* c = &spec->obstacles[k];
    // The goal-to-disc-centre vector in the robot frame: robot to disc centre minus robot to goal.
    const double rho = obstacle_distance + c->radius_m;
    const double wx = rho * cos(obstacle_bearing) - goal_distance * cos(goal_bearing);
    const double wy = rho * sin(obstacle_bearing) - goal_distance * sin(goal_bearing);
    const double miss = fabs(hypot(wx, wy) - hypot(c->x_m - spec->goal_x_m, c->y_m - spec->goal_y_m));
    if (!(miss <= OBSTACLES_MATCH_TOLERANCE_M)) {
      continue;
    }
    // The heading turns the robot-frame vector onto the arena's goal-to-disc vector.
    const double heading = wrap_pi(atan2(c->y_m - spec->goal_y_m, c->x_m - spec->goal_x_m) - atan2(wy, wx));
    const features_pose_t p = {spec->goal_x_m - goal_distance * cos(heading + goal_bearing),
                               spec->goal_y_m - goal_distance * sin(heading + goal_bearing), heading};
    double score = 1e6 + miss;
    features_obstacles_t f;
    if (spec->n_obstacles > 1U && obstacles_features_at(spec, fcfg, p, &f) && f.n_visible > 0U) {
      score = fabs(f.obstacle[0].distance_m - obstacle_distance) +
              fabs(remainder(f.obstacle[0].bearing_rad - obstacle_bearing, 2.0 * TASKS_PI));
    }
    if (score < best_score) {
      found = true;
      best_score = score;
      *pose = p;
    }
  }
  return found ? 1 : 0;
}

// The skirt's least clearance to the spec's discs and the arena's walls at pose p [m].
static double obstacles_clearance_m(const tasks_obstacles_spec_t* spec, features_pose_t p) {
  const double r = spec->robot_radius_m;
  double least = fmin(fmin(p.x_m - spec->arena_min_x_m, spec->arena_max_x_m - p.x_m),
                      fmin(p.y_m - spec->arena_min_y_m, spec->arena_max_y_m - p.y_m)) - r;
  for (uint32_t k = 0U; k < spec->n_obstacles; ++k) {
    const tasks_circle_t* c = &spec->obstacles[k];
    least = fmin(least, hypot(p.x_m - c->x_m, p.y_m - c->y_m) - c->radius_m - r);
  }
  return least;
}


int32_t tasks_obstacles_rollout_begin(tasks_obstacles_rollout_t* ro, const tasks_obstacles_spec_t* spec,
                                      const features_obstacles_config_t* fcfg, const double* obstacles_state,
                                      double omega_radps) {
  if (ro == NULL) {
    return TASKS_ROLLOUT_INVALID;
  }
  memset(ro, 0, sizeof *ro);
  ro->status = TASKS_ROLLOUT_INVALID;
  features_pose_t p;
  if (!isfinite(omega_radps) || tasks_obstacles_pose_from_state(spec, fcfg, obstacles_state, &p) == 0 ||
      !obstacles_features_at(spec, fcfg, p, &ro->f)) {
    return ro->status;
  }
  ro->pose = p;
  ro->omega_radps = omega_radps;
  ro->least_clearance_m = obstacles_clearance_m(spec, p);
  ro->status = TASKS_ROLLOUT_RUNNING;
  return ro->status;
}

int32_t tasks_obstacles_rollout_step(tasks_obstacles_rollout_t* ro, const tasks_obstacles_spec_t* spec,
                                     const features_obstacles_config_t* fcfg, const tasks_command_limits_t* lim,
                                     double dt_s, double omega_radps, double margin_m, uint32_t step_limit) {
  if (ro == NULL) {
    return TASKS_ROLLOUT_INVALID;
  }
  if (ro->status != TASKS_ROLLOUT_RUNNING) {
    return ro->status;
  }
  if (!obstacles_inputs_ok(spec, fcfg) || lim == NULL || !(dt_s >= RECOVERY_MIN_DT_S) || !isfinite(dt_s) ||
      !isfinite(omega_radps) || !isfinite(margin_m) || !isfinite(spec->v_mps)) {
    ro->status = TASKS_ROLLOUT_INVALID;
    return ro->status;
  }
  model_t m = {ro->pose.y_m, ro->pose.theta_rad, -ro->pose.x_m, ro->v_mps, ro->omega_radps};
  step(lim, dt_s, spec->v_mps, omega_radps, &m);
  ro->periods++;
  ro->pose.x_m = -m.ahead;
  ro->pose.y_m = m.y;
  ro->pose.theta_rad = wrap_pi(m.psi);
  ro->v_mps = m.v;
  ro->omega_radps = m.w;
  ro->least_clearance_m = fmin(ro->least_clearance_m, obstacles_clearance_m(spec, ro->pose));
  if (!obstacles_features_at(spec, fcfg, ro->pose, &ro->f)) {
    ro->status = TASKS_ROLLOUT_INVALID;
  } else if (ro->least_clearance_m < margin_m) {
    ro->status = TASKS_ROLLOUT_WALL;
  } else if (ro->f.goal_distance_m <= spec->goal_radius_m) {
    ro->status = TASKS_ROLLOUT_GOAL;
  } else if (ro->periods >= step_limit) {
    ro->status = TASKS_ROLLOUT_STEP_LIMIT;
  }
  return ro->status;
}
