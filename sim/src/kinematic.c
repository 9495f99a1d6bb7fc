// SPDX-License-Identifier: MIT
// The idealised synchro-drive forward model (heading first, then translation).
#include "sim/kinematic.h"

#include <math.h>

static const double k_pi = 3.14159265358979323846;

void sim_kin_limits_default(sim_kin_limits_t* lim) {
  lim->accel_trans_mps2 = SIM_KIN_ACCEL_TRANS_DEFAULT_MPS2;
  lim->accel_rot_radps2 = SIM_KIN_ACCEL_ROT_DEFAULT_RADPS2;
}

double sim_angle_wrap(double angle_rad) {
  if (!isfinite(angle_rad)) {
    return 0.0;
  }
  // The common case (one step past the seam) costs two compares; fmod only for far-off input.
  if (angle_rad > k_pi || angle_rad <= -k_pi) {
    if (angle_rad > 3.0 * k_pi || angle_rad <= -3.0 * k_pi) {
      angle_rad = fmod(angle_rad, 2.0 * k_pi);
    }
    if (angle_rad > k_pi) {
      angle_rad -= 2.0 * k_pi;
    } else if (angle_rad <= -k_pi) {
      angle_rad += 2.0 * k_pi;
    }
  }
  return angle_rad;
}

void sim_kin_reset(sim_kin_state_t* s, double x_m, double y_m, double theta_rad) {
  s->x_m = x_m;
  s->y_m = y_m;
  s->theta_rad = sim_angle_wrap(theta_rad);
  s->v_mps = 0.0;
  s->omega_radps = 0.0;
}

double sim_kin_axis_approach(double current, double command, double accel, double dt_s) {
  if (!(accel > 0.0) || !isfinite(accel)) {
    return command;
  }
  const double max_delta = accel * dt_s;
  const double delta = command - current;
  if (delta > max_delta) {
    return current + max_delta;
  }
  if (delta < -max_delta) {
    return current - max_delta;
  }
  return command;
}

void sim_kin_step(sim_kin_state_t* s, const sim_kin_limits_t* lim, double v_cmd_mps,
                  double omega_cmd_radps, double dt_s) {
  if (!isfinite(v_cmd_mps)) {
    v_cmd_mps = 0.0;
  }
  if (!isfinite(omega_cmd_radps)) {
    omega_cmd_radps = 0.0;
  }
  s->v_mps = sim_kin_axis_approach(s->v_mps, v_cmd_mps, lim->accel_trans_mps2, dt_s);
  s->omega_radps = sim_kin_axis_approach(s->omega_radps, omega_cmd_radps, lim->accel_rot_radps2, dt_s);
  // Heading first, then translation along the new heading: the order of the rFLEX odometry.
  // The product order dt * (v * cos) is the one ODE's integrator uses (pos += h * vel), which
  // keeps the ODE plant bit-identical to this model in free space.
  s->theta_rad = sim_angle_wrap(s->theta_rad + s->omega_radps * dt_s);
  s->x_m += dt_s * (s->v_mps * cos(s->theta_rad));
  s->y_m += dt_s * (s->v_mps * sin(s->theta_rad));
}

void sim_kin_run(sim_kin_state_t* s, const sim_kin_limits_t* lim, double v_cmd_mps,
                 double omega_cmd_radps, double dt_s, uint64_t n_steps) {
  for (uint64_t i = 0; i < n_steps; ++i) {
    sim_kin_step(s, lim, v_cmd_mps, omega_cmd_radps, dt_s);
  }
}
