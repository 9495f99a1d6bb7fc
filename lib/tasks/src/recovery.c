// SPDX-License-Identifier: MIT
// The corridor's recovery rollout (see tasks/recovery.h).
#include "tasks/recovery.h"

#include <math.h>


// The longest rollout: 20 s is several times the recovery law's settling time (about 3 s).
#define RECOVERY_MAX_HORIZON_S 20.0

double tasks_corridor_recovery_action(const tasks_corridor_spec_t* spec, const features_corridor_t* f) {
  if (f == NULL || f->valid == 0U || !isfinite(f->target_angle_rad)) {
    return 0.0;
  }
  return tasks_clamp_omega(TASKS_CORRIDOR_RECOVERY_GAIN * f->target_angle_rad, spec->omega_max_radps);
}

double tasks_corridor_recovery_clearance_m(const tasks_corridor_spec_t* spec, const tasks_command_limits_t* lim,
                                           double dt_s, const features_corridor_t* f, double prev_v_mps,
                                           double prev_omega_radps, double omega_radps, double horizon_s) {
  if (f == NULL || f->valid == 0U || !(dt_s > 0.0) || !isfinite(f->offset_m) || !isfinite(f->heading_rad) ||
      !isfinite(f->end_distance_m) || !isfinite(prev_v_mps) || !isfinite(prev_omega_radps) ||
      !isfinite(omega_radps) || !isfinite(horizon_s)) {
    return -INFINITY;
  }
  const double half_free = 0.5 * spec->width_m - spec->robot_radius_m;  // |y| where the skirt touches
  const double h = fmin(fmax(horizon_s, dt_s), RECOVERY_MAX_HORIZON_S);
  const int32_t n = (int32_t)ceil(h / dt_s - 1e-9);
  double y = f->offset_m;
  double psi = f->heading_rad;
  double ahead = f->end_distance_m;
  double v = prev_v_mps;
  double w = prev_omega_radps;
  double least = INFINITY;
  for (int32_t k = 0; k < n; ++k) {
    // The features the speed policy and the recovery law see at the predicted pose.
    features_corridor_t at = *f;
    at.offset_m = y;
    at.heading_rad = psi;
    at.lateral_frac = 0.5 - y / spec->width_m;
    at.target_angle_rad = -psi - atan2(y, spec->lookahead_m);
    double v_cmd = tasks_corridor_speed_mps(spec, &at);
    double w_cmd = k == 0 ? omega_radps : tasks_corridor_recovery_action(spec, &at);
    (void)tasks_command_clamp(lim, dt_s, v, w, &v_cmd, &w_cmd);
    // The base ramps each axis from the previous command to the new one over the period (the
    // clamp keeps the step within its acceleration limit): the mean velocities drive the step,
    // and the heading at the period's middle, psi + dt (3 w_prev + w_cmd) / 8, gives its
    // direction (second order in the heading change).
    const double psi_mid = psi + dt_s * (3.0 * w + w_cmd) / 8.0;
    const double ds = 0.5 * (v + v_cmd) * dt_s;
    y += ds * sin(psi_mid);
    ahead -= ds * cos(psi_mid);
    psi += 0.5 * (w + w_cmd) * dt_s;
    v = v_cmd;
    w = w_cmd;
    least = fmin(least, half_free - fabs(y));
    if (ahead <= spec->goal_distance_m) {
      break;  // the run ends at the goal
    }
  }
  return least;
}
