// SPDX-License-Identifier: MIT
/// tasks/episode.h — One declared task (tasks/decl.h) as a robot runs it, step by step: the
/// state from a laser scan and odometry in the run's frame, reward and termination, the
/// translation speed, the drivers' action, and the clamp of every command to the base's limits.
///
/// The controller's tick (firmware/core) and the Python environments (sim/env.h) both compute
/// their numbers with these functions, so that a result in one means the same in the other.
///
/// A run in the task frame: at its start the robot stands at start_in_task (a start pose of the
/// task spec, or one given) while the odometry reads odom_at_start; every later odometry pose
/// maps into the task frame by features_odom_to_task. The state vector is the declaration's
/// (tasks_decl_t state_names), e.g.
/// - corridor (3): end distance [m], lateral fraction [0, 1], target angle [rad];
/// - obstacles (5): goal bearing [rad], goal distance [m], the nearest obstacle's bearing [rad]
///   and distance [m], seen or remembered after it left the laser's view, and the time since it
///   was seen [s] (pi, no_obstacle_distance_m and the memory's limit when none is known).
///
/// Memory: tasks_episode_t is a plain caller-owned struct (about 2 KiB: the task's specification
/// and run data as blobs), no allocation. Thread-safety: none per instance; distinct instances
/// are independent. Every function is bounded: observe is linear in the beams, the others O(1).
#ifndef B21R_TASKS_EPISODE_H
#define B21R_TASKS_EPISODE_H

#include <stdint.h>

#include "features/features.h"
#include "tasks/decl.h"
#include "tasks/tasks.h"

#ifdef __cplusplus
extern "C" {
#endif

/// Limits applied to every command sent to the base. Defaults (tasks_command_limits_default) in
/// brackets: the controller's defaults (firmware/app/b21r-controller.conf).
typedef struct tasks_command_limits {
  double max_translation_mps;         ///< |v| limit [0.8]
  double max_rotation_radps;          ///< |omega| limit, also the learner's action range [1.0]
  double max_translation_accel_mps2;  ///< |dv| per period / period [0.7]
  double max_rotation_accel_radps2;   ///< |domega| per period / period [2.86]
} tasks_command_limits_t;

/// Fills lim with the defaults documented on each field. O(1).
void tasks_command_limits_default(tasks_command_limits_t* lim);

/// The command actually sent for a requested (v, omega): first clamped to the velocity limits,
/// then to within (acceleration limit x dt_s) of the previous command (prev_v_mps,
/// prev_omega_radps). A non-finite request, previous command or limit makes both zero (the base
/// is never sent a non-finite number). Returns 1 when the result came from the clamp, 0 when a
/// non-finite value forced the zero command. O(1).
int tasks_command_clamp(const tasks_command_limits_t* lim, double dt_s, double prev_v_mps,
                        double prev_omega_radps, double* v_mps, double* omega_radps);

/// One declared task with the state of the current run. Read the task's specification with
/// tasks_episode_spec (cast by code that knows the task: the declaration's own, tests, tools);
/// change a spec's parameters at any time through tasks_episode_set_param, but call
/// tasks_episode_init again after changing its geometry directly (the run data are derived from
/// it there).
typedef struct tasks_episode {
  const tasks_decl_t* decl;                      ///< the task (never NULL after init)
  uint32_t state_dim;                            ///< decl->state_dim
  features_pose_t start_in_task;                 ///< start pose of the current run, task frame
  features_pose_t odom_at_start;                 ///< odometry pose at the start of the run
  tasks_start_cycle_t start_cycle;               ///< order of the training starts' base poses
  uint32_t n_eval_starts;                        ///< evaluation poses given (0: the declaration's)
  features_pose_t eval_starts[TASKS_MAX_EVAL_STARTS];  ///< evaluation poses given (tasks_episode_set_eval_starts)
  /// the task's specification (decl->spec_size bytes; doubles so that any field is aligned)
  double spec[TASKS_SPEC_BYTES / sizeof(double)];
  double run[TASKS_RUN_BYTES / sizeof(double)];        ///< the task's run data (decl->run_init)
} tasks_episode_t;

/// Sets up the task `decl` with its specification `spec` (NULL: decl->spec_default), which must
/// be decl->spec_size bytes. Clears the run (start pose and odometry at the origin, neutral
/// features). A NULL decl is the corridor. O(1).
void tasks_episode_init(tasks_episode_t* ep, const tasks_decl_t* decl, const void* spec);

/// The task's specification inside the episode (decl->spec_size bytes).
void* tasks_episode_spec(tasks_episode_t* ep);
const void* tasks_episode_spec_const(const tasks_episode_t* ep);
/// The task's run data inside the episode (interpreted by the task's code only).
void* tasks_episode_run(tasks_episode_t* ep);
const void* tasks_episode_run_const(const tasks_episode_t* ep);

/// Sets the specification's parameter `name` to value and derives the run data again. Returns 0,
/// -1 for an unknown name, -2 for a value outside the parameter's range (nothing changed). O(params).
int tasks_episode_set_param(tasks_episode_t* ep, const char* name, double value);

/// Evaluation poses of the configuration's own (n of them, at most TASKS_MAX_EVAL_STARTS; n = 0:
/// the declaration's). Training starts stay around the declaration's poses, so evaluations can
/// be run from poses the learner never saw. O(n).
void tasks_episode_set_eval_starts(tasks_episode_t* ep, const features_pose_t* poses, uint32_t n);

/// Number of evaluation poses in use (the configuration's, else TASKS_N_EVAL_STARTS).
uint32_t tasks_episode_n_eval_starts(const tasks_episode_t* ep);

/// Starts a run: the robot stands at start_in_task while odometry reads odom_at_start; the
/// features' run state (decl->run_begin: a memory of what was seen) starts empty. O(1).
void tasks_episode_begin(tasks_episode_t* ep, features_pose_t start_in_task, features_pose_t odom_at_start);

/// The odometry pose odom_now in the task frame of the current run. O(1).
features_pose_t tasks_episode_pose_in_task(const tasks_episode_t* ep, features_pose_t odom_now);

/// The state from a scan and the odometry pose (what the controller computes each tick): the
/// task's features of scan at the odometry pose mapped into the task frame, kept in the episode;
/// when they are valid, the state vector is written to state[0..state_dim) (otherwise state is
/// left as it was). Returns 1 when the state is usable (valid features, every value finite), 0
/// otherwise: do not learn from it. Cost: features_corridor_compute or
/// features_obstacles_compute.
int tasks_episode_observe(tasks_episode_t* ep, const features_scan_t* scan, features_pose_t odom_now,
                          double* state);

/// The exact state of a robot at a known pose in the task frame (the idealised kinematic model):
/// features_corridor_from_pose, or features_obstacles_from_pose with the spec's obstacles and the
/// LMS200's 180° field of view. Same contract as tasks_episode_observe. O(obstacles).
int tasks_episode_observe_pose(tasks_episode_t* ep, features_pose_t pose_in_task, double* state);

/// Reward and termination of the transition into the newest observed state (tasks_*_outcome with
/// the spec's step limit). contact: the bumper (or the model's collision test) fired on it;
/// steps_taken: actions executed in this run, including the last one. O(1).
tasks_outcome_t tasks_episode_outcome(const tasks_episode_t* ep, uint8_t contact, uint32_t steps_taken);

/// Translation speed for the newest observed state (the task's speed policy) [m/s]. O(1).
double tasks_episode_speed_mps(const tasks_episode_t* ep);

/// The driver's rotation command for the newest observed state (tasks_driver_corridor or
/// tasks_driver_obstacles; advances the driver's state) [rad/s]. O(1).
double tasks_episode_driver_action(const tasks_episode_t* ep, tasks_driver_t* driver);

/// Evaluation start pose `index` (modulo tasks_episode_n_eval_starts), task frame. O(1).
features_pose_t tasks_episode_eval_start(const tasks_episode_t* ep, uint32_t index);

/// The next training start pose: jittered around the evaluation pose the episode's start cycle
/// names (tasks_start_cycle_next: every pose once per ten runs, shuffled), drawn from rng
/// (tasks_*_training_start_near). Advances the cycle. Bounded draws.
features_pose_t tasks_episode_training_start(tasks_episode_t* ep, rng_t* rng);

/// The run's step limit (the spec's; 0 = none). O(1).
uint32_t tasks_episode_step_limit(const tasks_episode_t* ep);

/// The task's action bound omega_max [rad/s], discount gamma, the robot's collision radius [m]
/// and control period [s] (from the spec). O(1).
double tasks_episode_omega_max(const tasks_episode_t* ep);
double tasks_episode_gamma(const tasks_episode_t* ep);
double tasks_episode_robot_radius(const tasks_episode_t* ep);
double tasks_episode_dt_s(const tasks_episode_t* ep);

/// The laser's mounting of the task's features. O(1).
const features_laser_mount_t* tasks_episode_laser_mount(const tasks_episode_t* ep);

/// Bounds of every value the task's features can produce (observation spaces). O(1).
void tasks_episode_state_bounds(const tasks_episode_t* ep, double* lo, double* hi);

/// The declared range of each feature under the episode's specification. O(1).
void tasks_episode_state_range(const tasks_episode_t* ep, double* lo, double* hi);

/// Starts the driver d of `kind` for a run of the episode's task: seeds its private stream with
/// run_seed, draws the run's gain in the declaration's range (every kind, so that the streams
/// of the kinds stay comparable), sets its control law, and a person's temperament (HUMAN).
/// omega_max_radps bounds its output (non-finite or non-positive gives 1.0). O(TASKS_HUMAN_MAX_DELAY).
void tasks_episode_driver_begin(const tasks_episode_t* ep, tasks_driver_t* d, tasks_driver_kind_t kind,
                                double omega_max_radps, uint64_t run_seed);

/// Task-specific views for code that knows the task (tests, tools): the newest features and the
/// feature configuration of a corridor or obstacle episode, NULL for another task. O(1).
const features_corridor_t* tasks_corridor_state(const tasks_episode_t* ep);
const features_corridor_config_t* tasks_corridor_features(const tasks_episode_t* ep);
const features_obstacles_t* tasks_obstacles_state(const tasks_episode_t* ep);
const features_obstacles_config_t* tasks_obstacles_features(const tasks_episode_t* ep);

#ifdef __cplusplus
}
#endif

#endif  // B21R_TASKS_EPISODE_H
