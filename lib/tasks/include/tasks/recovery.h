// SPDX-License-Identifier: MIT
/// tasks/recovery.h — Will the robot stay off the corridor's walls? A short kinematic rollout
/// that vets a rotation command before it is sent (the safety filter of the controller's
/// pair_runs, firmware/core/src/run.c).
///
/// The question asked is the one a safety filter with a backup controller asks: if this command
/// is sent now and a known recovery law drives from the next tick on, does the robot's skirt keep
/// a margin to both side walls? A command that passes keeps the robot in states from which the
/// recovery law is predicted to be safe, so a policy may be perturbed freely as long as every
/// command passes; where one does not, the caller sends a command that does (or the recovery
/// law's own, TASKS_CORRIDOR_RECOVERY_GAIN x target angle).
///
/// Model (the corridor frame of features/corridor.h): a unicycle, y' = v sin(psi),
/// x' = v cos(psi), psi' = omega, from the features' offset, heading and end distance. Every
/// command, the vetted one and the recovery law's, goes through tasks_command_clamp from the
/// previous command (velocity and acceleration limits), with the translation speed of the task's
/// speed policy (tasks_corridor_speed_mps) at the predicted lateral position, and the base ramps
/// each axis linearly to it over the control period dt_s (as a base at that acceleration limit
/// does). What the model leaves out (sensing error, latency, slip) the caller's margin covers.
/// The rollout stops at the horizon or where the goal condition holds (the run ends there).
///
/// Pure, no allocation; cost O(horizon_s / dt_s) with one atan2, one sin and one cos per step
/// (3 s at 10 Hz: about 1.5 us; firmware.bench prints it beside the median tick).
#ifndef B21R_TASKS_RECOVERY_H
#define B21R_TASKS_RECOVERY_H

#include "features/features.h"
#include "tasks/episode.h"
#include "tasks/tasks.h"

#ifdef __cplusplus
extern "C" {
#endif

/// The recovery law's gain on the target angle [rad/s per rad]: the example policy at the top
/// of its training range (TASKS_PROPORTIONAL_CORRIDOR_GAIN_MAX): of the example gains the one
/// that turns away from a wall hardest and reaches the goal fastest from the evaluation poses.
#define TASKS_CORRIDOR_RECOVERY_GAIN TASKS_PROPORTIONAL_CORRIDOR_GAIN_MAX

/// The recovery law's rotation command at features f: TASKS_CORRIDOR_RECOVERY_GAIN x
/// f->target_angle_rad, within +-spec->omega_max_radps [rad/s]. 0 when f is not valid. O(1).
double tasks_corridor_recovery_action(const tasks_corridor_spec_t* spec, const features_corridor_t* f);

/// The smallest predicted clearance [m] between the robot's skirt (spec->robot_radius_m) and the
/// nearer side wall over the rollout: omega_radps is commanded for one period, then the recovery
/// law for the rest of horizon_s (both clamped by lim from prev_v_mps, prev_omega_radps, the
/// command sent last). Negative: contact is predicted. -INFINITY when f is not valid or an input
/// is not finite (nothing can be predicted, so nothing is vetted). horizon_s is clamped to
/// [dt_s, 20 s]; dt_s must be > 0. Pure; O(horizon_s / dt_s).
double tasks_corridor_recovery_clearance_m(const tasks_corridor_spec_t* spec, const tasks_command_limits_t* lim,
                                           double dt_s, const features_corridor_t* f, double prev_v_mps,
                                           double prev_omega_radps, double omega_radps, double horizon_s);

#ifdef __cplusplus
}
#endif

#endif  // B21R_TASKS_RECOVERY_H
