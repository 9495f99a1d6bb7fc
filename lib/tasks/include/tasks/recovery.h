// SPDX-License-Identifier: MIT
/// tasks/recovery.h — Will the robot stay off the corridor's walls? A short kinematic rollout
/// that vets a rotation command before it is sent (the safety filter of the controller's
/// pair_runs, firmware/core/src/run.c); and whole runs of a policy on the same model, in the
/// corridor and among the obstacle task's discs (the vet of the learned policy's shift).
///
/// The question asked is the one a safety filter with a backup controller asks: if this command
/// is sent now and a known recovery law drives from the next period on, does the robot's skirt
/// keep a margin to both side walls? A command that passes keeps the robot in states from which
/// the recovery law is predicted to be safe, so a policy may be perturbed freely as long as every
/// command passes; where one does not, the caller sends a command that does (or the recovery
/// law's own, TASKS_CORRIDOR_RECOVERY_GAIN x target angle). Between two decisions (a period
/// without a new scan) the caller keeps that promise by sending the recovery law's command at
/// the state tasks_corridor_recovery_predict dead-reckons.
///
/// Model (the corridor frame of features/corridor.h): a unicycle, y' = v sin(psi),
/// x' = v cos(psi), psi' = omega, from the features' offset, heading and end distance, between
/// walls at the measured width (never more than the nominal one: the offset is measured from
/// the measured centre line). Every command, the vetted one and the recovery law's, goes
/// through tasks_command_clamp from the previous command (velocity and acceleration limits),
/// with the translation speed of the task's speed policy (tasks_corridor_speed_mps) at the
/// predicted pose, and each axis is taken to ramp linearly to its command over the period (an
/// approximation: a base at those limits gets there at the period's end or sooner). Where the
/// goal condition holds the run ends: the base is told to stop and coasts to a stand under the
/// same limits, which the rollout follows. What the model leaves out the caller's margin must
/// cover: sensing error (offset about 0.02 m, heading about 0.025 rad), latency between the
/// scan and the command, a base that accelerates or brakes more slowly than the limits, slip.
///
/// Pure, no allocation, thread-safe. Cost O(horizon_s / dt_s) plus the coast after the goal
/// (at most 20 s of periods), one atan2, one sin, one cos and two remainder per period: 3 s at
/// 10 Hz take a few microseconds (firmware.bench prints it beside the median tick).
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
/// f->target_angle_rad, within +-spec->omega_max_radps [rad/s]. 0 when an argument is NULL or f
/// is not valid. O(1).
double tasks_corridor_recovery_action(const tasks_corridor_spec_t* spec,
                                      const features_corridor_t* f);

/// The smallest predicted clearance [m] between the robot's skirt (spec->robot_radius_m) and
/// the nearer side wall over the rollout: omega_radps is commanded for one period of dt_s, then
/// the recovery law for the rest of horizon_s (horizon clamped to [dt_s, 20 s]), then, if the
/// goal is reached, the coast to a stand. Commands are clamped by lim from prev_v_mps and
/// prev_omega_radps, the command in force. Negative: contact is predicted. -INFINITY when an
/// argument is NULL, f is not valid, dt_s < 1e-3 s, an input is not finite or the coast would
/// last over 20 s (nothing can be predicted, so nothing passes). Pure; O(horizon_s / dt_s), at
/// most 40,000 periods.
double tasks_corridor_recovery_clearance_m(const tasks_corridor_spec_t* spec,
                                           const tasks_command_limits_t* lim, double dt_s,
                                           const features_corridor_t* f, double prev_v_mps,
                                           double prev_omega_radps, double omega_radps,
                                           double horizon_s);

/// Dead reckoning with the rollout's model: the features one period of dt_s after f, when the
/// command (v_mps, omega_radps) is sent with (prev_v_mps, prev_omega_radps) in force (clamped
/// by lim as the controller clamps it). *out is f with offset, heading, end distance (not below
/// 0), lateral fraction and target angle moved. Returns 1, or 0 (out untouched) for the inputs
/// for which tasks_corridor_recovery_clearance_m returns -INFINITY at once. O(1).
int tasks_corridor_recovery_predict(const tasks_corridor_spec_t* spec,
                                    const tasks_command_limits_t* lim, double dt_s,
                                    const features_corridor_t* f, double prev_v_mps,
                                    double prev_omega_radps, double v_mps, double omega_radps,
                                    features_corridor_t* out);

/// A policy's whole run on the rollout's model (the vet of the learned policy's shift,
/// firmware/core/src/shift_vet.c): the caller asks its policy for a rotation command at ro->f,
/// then tasks_corridor_rollout_step moves the model one period, until the status is no longer
/// TASKS_ROLLOUT_RUNNING. The model, the limits, the speed policy and the coast at the goal are
/// those of tasks_corridor_recovery_clearance_m.
typedef enum tasks_rollout_status {
  TASKS_ROLLOUT_RUNNING = 0,     ///< the run goes on: ask the policy at ro->f
  TASKS_ROLLOUT_GOAL = 1,        ///< the goal was reached (corridor: and the coast kept the margin)
  TASKS_ROLLOUT_WALL = 2,        ///< the skirt came closer than the margin to a wall (or an obstacle)
  TASKS_ROLLOUT_STEP_LIMIT = 3,  ///< step_limit periods passed without reaching the goal
  TASKS_ROLLOUT_INVALID = 4,     ///< a non-finite input or command: nothing can be predicted
} tasks_rollout_status_t;

/// The state of one rollout. Plain data; tasks_corridor_rollout_begin fills it.
typedef struct tasks_corridor_rollout {
  features_corridor_t f;     ///< the features at the model's pose: what the policy decides on
  double v_mps;              ///< the command in force, after the limits [m/s]
  double omega_radps;        ///< [rad/s]
  double least_clearance_m;  ///< the smallest skirt-to-wall clearance so far [m]
  uint32_t periods;          ///< commands executed
  int32_t status;            ///< a tasks_rollout_status_t value
} tasks_corridor_rollout_t;

/// Starts a rollout at the corridor state of features_corridor_state (end distance [m], lateral
/// fraction, target angle [rad]) with the robot standing except for the rotation omega_radps in
/// force: the offset is (0.5 - lateral fraction) x the nominal width, the heading follows from
/// the target angle and spec->lookahead_m. Returns ro->status (TASKS_ROLLOUT_INVALID for a NULL
/// argument or a non-finite input). O(1).
int32_t tasks_corridor_rollout_begin(tasks_corridor_rollout_t* ro, const tasks_corridor_spec_t* spec,
                                     const double* corridor_state, double omega_radps);

/// One period: the command (speed policy, omega_radps) under lim, then the checks: closer than
/// margin_m to a wall, the goal (then the coast to a stand, which must keep the margin too), or
/// step_limit periods. Returns ro->status; a finished rollout stays as it is. O(1), or O(the
/// coast) at the goal: at most 20 s of periods.
int32_t tasks_corridor_rollout_step(tasks_corridor_rollout_t* ro, const tasks_corridor_spec_t* spec,
                                    const tasks_command_limits_t* lim, double dt_s, double omega_radps,
                                    double margin_m, uint32_t step_limit);

/// The obstacle task's whole run on a kinematic model, for the same vet: the unicycle of the
/// corridor's rollout (the same limits and ramp) in the arena frame of tasks.h, at the task's
/// constant speed, among the spec's discs and walls; the policy decides on the features an ideal
/// laser gives at the model's pose (features_obstacles_from_pose, the LMS200's 180° field of
/// view), as the emulator's idealised model does. The coast after the goal is not driven: at
/// 0.3 m/s and the base's deceleration it is a few centimetres, in the open space around the
/// goal. Plain data; tasks_obstacles_rollout_begin fills it.
typedef struct tasks_obstacles_rollout {
  features_obstacles_t f;    ///< the features at the model's pose: what the policy decides on
  features_pose_t pose;      ///< the model's pose, arena frame
  double v_mps;              ///< the command in force, after the limits [m/s]
  double omega_radps;        ///< [rad/s]
  double least_clearance_m;  ///< the smallest skirt-to-disc or skirt-to-wall clearance so far [m]
  uint32_t periods;          ///< commands executed
  int32_t status;            ///< a tasks_rollout_status_t value
} tasks_obstacles_rollout_t;

/// The arena pose that the obstacle state (goal bearing [rad], goal distance [m], nearest
/// obstacle's bearing [rad] and distance [m] from the robot centre to its surface: the first four
/// values of features_obstacles_state) describes, with the goal and discs of spec: the goal's and
/// the obstacle's directions and distances fix the triangle robot-goal-disc, and so the pose,
/// for a disc whose distance from the goal the triangle matches within 0.25 m (with several
/// discs, of those the one whose pose's own features best reproduce the state's obstacle; the
/// state names only the nearest obstacle, so two poses can fit it). Sensing errors of 0.02 m and
/// 0.01 rad move the pose by up to 0.3 m at 6 m from the goal (a bearing error turns the whole
/// triangle). Returns 1 with *pose, or 0 when an argument is NULL or not finite, no obstacle is
/// visible (distance at or beyond fcfg->no_obstacle_distance_m: the pose is not determined) or no
/// disc matches. O(spec->n_obstacles).
int tasks_obstacles_pose_from_state(const tasks_obstacles_spec_t* spec, const features_obstacles_config_t* fcfg,
                                    const double* obstacles_state, features_pose_t* pose);

/// Starts a rollout at the pose tasks_obstacles_pose_from_state gives, standing except for the
/// rotation omega_radps in force. Returns ro->status: TASKS_ROLLOUT_INVALID where no pose is
/// determined (see there) or an input is not finite, else TASKS_ROLLOUT_RUNNING (a start already
/// closer than a margin fails at its first step). O(spec->n_obstacles).
int32_t tasks_obstacles_rollout_begin(tasks_obstacles_rollout_t* ro, const tasks_obstacles_spec_t* spec,
                                      const features_obstacles_config_t* fcfg, const double* obstacles_state,
                                      double omega_radps);

/// One period: the command (spec->v_mps, omega_radps) under lim, then the checks: the skirt
/// closer than margin_m to a disc or a wall (TASKS_ROLLOUT_WALL), the goal (the centre within
/// spec->goal_radius_m), or step_limit periods. Returns ro->status; a finished rollout stays as
/// it is. O(spec->n_obstacles).
int32_t tasks_obstacles_rollout_step(tasks_obstacles_rollout_t* ro, const tasks_obstacles_spec_t* spec,
                                     const features_obstacles_config_t* fcfg, const tasks_command_limits_t* lim,
                                     double dt_s, double omega_radps, double margin_m, uint32_t step_limit);

#ifdef __cplusplus
}
#endif

#endif  // B21R_TASKS_RECOVERY_H
