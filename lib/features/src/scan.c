// SPDX-License-Identifier: MIT
// Scan geometry and planar pose algebra shared by the corridor and obstacle features.
#include "features/scan.h"

#include <math.h>
#include <stddef.h>

#include "scan_points.h"

void features_scan_config_default(features_scan_config_t* cfg) {
  cfg->mount.x_m = FEATURES_LASER_X_DEFAULT_M;
  cfg->mount.y_m = 0.0;
  cfg->mount.yaw_rad = 0.0;
  cfg->min_range_m = 0.05;
  cfg->max_range_m = FEATURES_LMS200_MAX_VALID_RANGE_M;
}

features_status_t features_scan_set_lms200_geometry(features_scan_t* scan, int field_deg,
                                                    double resolution_deg) {
  if (scan == NULL) {
    return FEATURES_ERR_INVALID_ARG;
  }
  // Resolutions are exact binary fractions, so comparing them with a tolerance is only to avoid
  // -Wfloat-equal; the tolerance is far below the gap between legal values.
  const double tol = 1e-9;
  unsigned steps_per_deg = 0U;
  if (fabs(resolution_deg - 1.0) < tol) {
    steps_per_deg = 1U;
  } else if (fabs(resolution_deg - 0.5) < tol) {
    steps_per_deg = 2U;
  } else if (fabs(resolution_deg - 0.25) < tol) {
    steps_per_deg = 4U;
  } else {
    return FEATURES_ERR_INVALID_ARG;
  }
  if (field_deg != 180 && field_deg != 100) {
    return FEATURES_ERR_INVALID_ARG;
  }
  if (field_deg == 180 && steps_per_deg == 4U) {
    return FEATURES_ERR_INVALID_ARG;  // the LMS200 offers 0.25° only with the 100° field
  }
  const double deg = FEAT_PI / 180.0;
  scan->angle_min_rad = -0.5 * (double)field_deg * deg;
  scan->angle_increment_rad = deg / (double)steps_per_deg;
  scan->n_beams = (uint16_t)((unsigned)field_deg * steps_per_deg + 1U);
  return FEATURES_OK;
}

features_status_t features_scan_fill(features_scan_t* scan, double angle_min_rad,
                                     double angle_increment_rad, uint16_t n_beams,
                                     const float* ranges_m, const uint8_t* no_return) {
  if (scan == NULL || (n_beams > 0U && (ranges_m == NULL || no_return == NULL)) ||
      n_beams > FEATURES_MAX_BEAMS) {
    return FEATURES_ERR_INVALID_ARG;
  }
  scan->angle_min_rad = angle_min_rad;
  scan->angle_increment_rad = angle_increment_rad;
  scan->n_beams = n_beams;
  for (uint16_t i = 0U; i < n_beams; ++i) {
    scan->ranges_m[i] = ranges_m[i];
    scan->no_return[i] = no_return[i];
  }
  return FEATURES_OK;
}

double features_angle_wrap(double angle_rad) {
  if (!isfinite(angle_rad)) {
    return 0.0;
  }
  double a = fmod(angle_rad, 2.0 * FEAT_PI);  // (-2pi, 2pi)
  if (a > FEAT_PI) {
    a -= 2.0 * FEAT_PI;
  } else if (a <= -FEAT_PI) {
    a += 2.0 * FEAT_PI;
  }
  return a;
}

features_pose_t features_pose_compose(features_pose_t a, features_pose_t b) {
  const double c = cos(a.theta_rad);
  const double s = sin(a.theta_rad);
  features_pose_t r;
  r.x_m = a.x_m + c * b.x_m - s * b.y_m;
  r.y_m = a.y_m + s * b.x_m + c * b.y_m;
  r.theta_rad = features_angle_wrap(a.theta_rad + b.theta_rad);
  return r;
}

features_pose_t features_pose_inverse(features_pose_t a) {
  const double c = cos(a.theta_rad);
  const double s = sin(a.theta_rad);
  features_pose_t r;
  r.x_m = -c * a.x_m - s * a.y_m;
  r.y_m = s * a.x_m - c * a.y_m;
  r.theta_rad = features_angle_wrap(-a.theta_rad);
  return r;
}

features_pose_t features_pose_between(features_pose_t a, features_pose_t b) {
  return features_pose_compose(features_pose_inverse(a), b);
}

features_pose_t features_odom_to_task(features_pose_t start_in_task, features_pose_t odom_at_start,
                                      features_pose_t odom_now) {
  return features_pose_compose(start_in_task, features_pose_between(odom_at_start, odom_now));
}

int features_scan_config_ok(const features_scan_config_t* cfg) {
  return isfinite(cfg->mount.x_m) && isfinite(cfg->mount.y_m) && isfinite(cfg->mount.yaw_rad) &&
         isfinite(cfg->min_range_m) && isfinite(cfg->max_range_m) && cfg->min_range_m >= 0.0 &&
         cfg->max_range_m > cfg->min_range_m;
}

int features_scan_ok(const features_scan_t* scan) {
  return scan->n_beams <= FEATURES_MAX_BEAMS && isfinite(scan->angle_min_rad) &&
         isfinite(scan->angle_increment_rad) && scan->angle_increment_rad > 0.0 &&
         scan->angle_increment_rad * (double)scan->n_beams <= 2.0 * FEAT_PI + 1e-6;
}

uint16_t features_scan_points(const features_scan_config_t* cfg, const features_scan_t* scan,
                              features_point_t* pts) {
  const double cm = cos(cfg->mount.yaw_rad);
  const double sm = sin(cfg->mount.yaw_rad);
  uint16_t n = 0U;
  for (uint16_t i = 0U; i < scan->n_beams; ++i) {
    const double r = (double)scan->ranges_m[i];
    pts[i].valid = 0U;
    pts[i].x_m = 0.0;
    pts[i].y_m = 0.0;
    pts[i].range_m = 0.0;
    if (scan->no_return[i] != 0U || !isfinite(r) || r < cfg->min_range_m || r > cfg->max_range_m) {
      continue;
    }
    const double a = scan->angle_min_rad + (double)i * scan->angle_increment_rad;
    const double lx = r * cos(a);
    const double ly = r * sin(a);
    pts[i].x_m = cfg->mount.x_m + cm * lx - sm * ly;
    pts[i].y_m = cfg->mount.y_m + sm * lx + cm * ly;
    pts[i].range_m = r;
    pts[i].valid = 1U;
    ++n;
  }
  return n;
}
