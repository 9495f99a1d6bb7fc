// SPDX-License-Identifier: MIT
// Test helper: a synthetic LMS200 scan of a synthetic world, as a features_scan_t.
#ifndef B21R_TEST_FEATURES_SCAN_FILL_H
#define B21R_TEST_FEATURES_SCAN_FILL_H

#include <b21r_test/synthetic_world.h>
#include <features/features.h>

// Casts a scan from the robot pose into scan (geometry from lidar); returns n_beams or -1.
static inline int scan_fill(features_scan_t* scan, const synth_world_t* w,
                            const synth_lidar_config_t* lidar, synth_rng_t* rng,
                            features_pose_t robot) {
  scan->angle_min_rad = lidar->angle_min_rad;
  scan->angle_increment_rad = lidar->angle_increment_rad;
  scan->n_beams = lidar->n_beams;
  return synth_lidar_scan(w, lidar, rng, robot.x_m, robot.y_m, robot.theta_rad, scan->ranges_m,
                          scan->no_return, FEATURES_MAX_BEAMS);
}

#endif  // B21R_TEST_FEATURES_SCAN_FILL_H
