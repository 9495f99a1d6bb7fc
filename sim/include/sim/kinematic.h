// SPDX-License-Identifier: MIT
/// sim/kinematic.h — The idealised synchro-drive forward model of the B21r, without ODE.
///
/// This is the model the paper's random-exploration studies run on (weeks of simulated time):
///   x' = v cos(theta),  y' = v sin(theta),  theta' = omega
/// discretised the way the rFLEX odometry integrates it (protocols.md C and A.5): each step
/// first moves both axis velocities towards their commands under the acceleration limits, then
/// turns the heading by omega*dt, then translates v*dt along the *new* heading. The ODE plant
/// (sim/plant.h) uses exactly the same per-substep update in free space, so the two agree to
/// rounding until a contact happens.
///
/// Units: SI (m, rad, s); angles CCW-positive; theta is kept wrapped to (-pi, pi].
/// Memory: plain structs, no allocation. Thread-safety: functions are pure over their
/// arguments; distinct states may be stepped from distinct threads.
/// Cost: one sincos call per step, no allocation: about 18-20 million steps/s measured on the
/// project's shared 2-core machine (the sim.bench benchmark requires at least 10 million).
/// Library: b21r::sim_kinematic (pure C, links neither ODE nor anything else but libm).
#ifndef B21R_SIM_KINEMATIC_H
#define B21R_SIM_KINEMATIC_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Default translational acceleration limit [m/s^2]: Player's B21r configuration (0.5 m/s^2).
#define SIM_KIN_ACCEL_TRANS_DEFAULT_MPS2 0.5
/// Default rotational acceleration limit [rad/s^2]: every driver's 100000 counts/s^2 at
/// K_a = 35000 counts/rad (about 2.857 rad/s^2).
#define SIM_KIN_ACCEL_ROT_DEFAULT_RADPS2 (100000.0 / 35000.0)

/// Acceleration limits of the two axes. A limit <= 0 or non-finite means "unlimited": the axis
/// reaches its command within one step (the paper's idealised model).
typedef struct sim_kin_limits {
  double accel_trans_mps2;   ///< translation axis |dv/dt| limit [m/s^2], default 0.5
  double accel_rot_radps2;   ///< rotation axis |domega/dt| limit [rad/s^2], default ~2.857
} sim_kin_limits_t;

/// State of the synchro-drive body: planar pose and the actual axis velocities.
typedef struct sim_kin_state {
  double x_m;          ///< position [m] in the world frame
  double y_m;          ///< position [m]
  double theta_rad;    ///< heading (steering direction) [rad], wrapped to (-pi, pi]
  double v_mps;        ///< actual translation axis velocity [m/s]
  double omega_radps;  ///< actual rotation axis velocity [rad/s]
} sim_kin_state_t;

/// Fills lim with the defaults above. O(1). lim must not be NULL.
void sim_kin_limits_default(sim_kin_limits_t* lim);

/// Places the body at (x, y, theta) at rest. theta is wrapped to (-pi, pi]. O(1).
void sim_kin_reset(sim_kin_state_t* s, double x_m, double y_m, double theta_rad);

/// Moves `current` towards `command` by at most accel*dt (unlimited when accel <= 0 or is not
/// finite) and returns the new value. O(1). Exposed so that the ODE plant shares the rule.
double sim_kin_axis_approach(double current, double command, double accel, double dt_s);

/// One step of dt_s seconds under commands (v_cmd_mps, omega_cmd_radps): axis velocities first
/// (acceleration limits), then heading, then translation along the new heading. dt_s > 0.
/// Non-finite commands are treated as 0 (the body never becomes NaN). O(1), no allocation.
void sim_kin_step(sim_kin_state_t* s, const sim_kin_limits_t* lim, double v_cmd_mps,
                  double omega_cmd_radps, double dt_s);

/// n_steps steps under constant commands (a loop over sim_kin_step). O(n_steps).
void sim_kin_run(sim_kin_state_t* s, const sim_kin_limits_t* lim, double v_cmd_mps,
                 double omega_cmd_radps, double dt_s, uint64_t n_steps);

/// Wraps an angle to (-pi, pi]. Non-finite input returns 0. O(1).
double sim_angle_wrap(double angle_rad);

#ifdef __cplusplus
}
#endif

#endif  // B21R_SIM_KINEMATIC_H
