// SPDX-License-Identifier: MIT
// Internal: beams -> points in the robot frame, validation helpers shared by the feature sources.
#ifndef B21R_FEATURES_SCAN_POINTS_H
#define B21R_FEATURES_SCAN_POINTS_H

#include <stdint.h>

#include "features/scan.h"

// Strict C11 has no M_PI.
#define FEAT_PI 3.14159265358979323846

/// One beam as a point in the robot frame.
typedef struct features_point {
  double x_m;
  double y_m;
  double range_m;  ///< range from the laser (not from the robot centre)
  uint8_t valid;   ///< 0: missing beam (fields zero)
} features_point_t;

/// 1 if every configuration value is finite and in range.
int features_scan_config_ok(const features_scan_config_t* cfg);

/// 1 if the scan's header is usable (beam count within capacity, finite positive increment).
int features_scan_ok(const features_scan_t* scan);

/// Converts every beam i < n_beams into pts[i] (robot frame); returns the number of valid points.
/// O(n_beams).
uint16_t features_scan_points(const features_scan_config_t* cfg, const features_scan_t* scan,
                              features_point_t* pts);

#endif  // B21R_FEATURES_SCAN_POINTS_H
