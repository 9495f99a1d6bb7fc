// SPDX-License-Identifier: MIT
// Test helper: whole episodes of the tasks in the synthetic world (kinematic synchro drive
// at the spec's control period, features from synthetic LMS200 scans, the tasks' rewards).
#ifndef B21R_TEST_TASKS_TASK_SIM_H
#define B21R_TEST_TASKS_TASK_SIM_H

#include <stdint.h>

#include <b21r_test/synthetic_world.h>
#include <features/features.h>
#include <tasks/doorway.h>
#include <tasks/tasks.h>

/// Episode options. task_sim_opts_default: LMS200 180° at 1°, 1 cm noise, exact odometry, no
/// clutter, no acceleration limits.
typedef struct task_sim_opts {
  synth_lidar_config_t lidar;
  uint64_t sensor_seed;          ///< seeds the scan noise
  int person;                    ///< corridor: a person (r 0.2 m) standing at (5.5, 0.75), by the left wall
  double odom_heading_drift;     ///< odometry heading error per metre travelled [rad/m]
  synth_drive_limits_t limits;   ///< acceleration limits (0 = none)
} task_sim_opts_t;

void task_sim_opts_default(task_sim_opts_t* o);

/// What happened in one run.
typedef struct task_sim_result {
  uint8_t reason;        ///< tasks_end_reason_t of the last step
  uint32_t steps;        ///< steps taken
  double return_sum;     ///< undiscounted sum of rewards
  double path_m;         ///< distance driven
  double sum_abs_omega;  ///< sum over steps of |omega| [rad/s]
  double min_clearance_m;///< closest approach of the robot's edge to any geometry
  double final_x_m, final_y_m;
} task_sim_result_t;

/// Runs the corridor task from `start` (corridor frame) with the driver (already begun).
task_sim_result_t task_sim_corridor(const tasks_corridor_spec_t* spec, features_pose_t start,
                                    tasks_driver_t* driver, const task_sim_opts_t* opts);

/// Runs the obstacle task from `start` (arena frame) with the driver (already begun).
task_sim_result_t task_sim_obstacles(const tasks_obstacles_spec_t* spec, features_pose_t start,
                                     tasks_driver_t* driver, const task_sim_opts_t* opts);

/// Runs the doorway task from `start` (task frame) with the driver (already begun). The dividing
/// wall is two solid blocks (faces, far faces and the jambs' end faces as segments).
task_sim_result_t task_sim_doorway(const tasks_doorway_spec_t* spec, features_pose_t start,
                                   tasks_driver_t* driver, const task_sim_opts_t* opts);

#endif  // B21R_TEST_TASKS_TASK_SIM_H
