// SPDX-License-Identifier: MIT
/// features/scan.h — The laser scan and pose types that every task feature is computed from.
///
/// Frames and conventions (all SI, angles CCW-positive, right-handed, z up):
/// - Robot frame: origin at the centre of the B21r (the synchro-drive rotation axis), x forward
///   (the direction the wheels drive at positive translation velocity), y to the left.
/// - Laser frame: origin at the LMS200 mirror axis, x along the beam at bearing 0, y to the left.
///   The laser sits on the robot at `features_laser_mount_t` (default: 0.15 m ahead of the
///   centre, facing forward).
/// - Beam i of a scan (0 <= i < n_beams) has bearing angle_min_rad + i * angle_increment_rad in
///   the laser frame. The LMS200 180° variant gives angle_min = -pi/2 and increment pi/180
///   (N = 181) or pi/360 (N = 361); the 100° variant gives -50° with 1°, 0.5° or 0.25° (N = 101,
///   201, 401). Index 0 is the rightmost beam.
/// - Odometry frame: where the base's integrated odometry lives (x, y, heading), see
///   features_pose_t. Task-specific frames (corridor, obstacle arena) are defined in
///   tasks/tasks.h; the helpers below move poses between frames.
///
/// Memory: plain structs, no allocation anywhere in this module. Thread-safety: all functions are
/// pure (reentrant); distinct threads may call them on distinct outputs.
#ifndef B21R_FEATURES_SCAN_H
#define B21R_FEATURES_SCAN_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Capacity of a scan: the largest LMS200 scan (100° field at 0.25°, 401 values).
#define FEATURES_MAX_BEAMS 401

/// Default forward offset of the laser from the robot centre [m]. Player's B21r configuration
/// (University of Auckland) places the LMS200 at x = 0.15 m; the Lewis B21 URDF model has it at
/// 0.29 m. 0.15 m is the default; set the mount to match the robot at hand.
#define FEATURES_LASER_X_DEFAULT_M 0.15

/// Largest range treated as a real return in LMS200 millimetre mode [m]. Raw values >= 8183
/// (8.183 m) are error/saturation codes (no echo, dazzle, overflow, ...), so a decoder that
/// passes the raw value through still produces an invalid beam here.
#define FEATURES_LMS200_MAX_VALID_RANGE_M 8.182

/// Status of a features_* call. Degenerate *data* (no walls seen, no returns) is never an error:
/// it is reported through validity flags in the output. Errors mean the call itself was wrong.
typedef enum features_status {
  FEATURES_OK = 0,
  FEATURES_ERR_INVALID_ARG = 2,  ///< NULL pointer, n_beams > FEATURES_MAX_BEAMS, or a non-finite
                                 ///< or out-of-range configuration value; the output is set to
                                 ///< its "invalid" state (valid = 0, finite fields).
} features_status_t;

/// A planar pose: position [m] and heading [rad] of a body frame in a parent frame.
/// theta_rad is CCW from the parent x axis; functions return it wrapped to (-pi, pi].
typedef struct features_pose {
  double x_m;
  double y_m;
  double theta_rad;
} features_pose_t;

/// Where the laser sits on the robot: the pose of the laser frame in the robot frame.
typedef struct features_laser_mount {
  double x_m;      ///< forward offset of the mirror axis from the robot centre [m], default 0.15
  double y_m;      ///< leftward offset [m], default 0
  double yaw_rad;  ///< bearing of the laser's beam 0° in the robot frame [rad], default 0
} features_laser_mount_t;

/// One laser scan as the features see it. Plain data, caller-owned; typically filled from a
/// decoded LMS200 telegram (lib/proto) or from the b21r_scan_t LCM message (same layout of
/// ranges and reasons).
typedef struct features_scan {
  double angle_min_rad;        ///< bearing of beam 0 in the laser frame [rad]
  double angle_increment_rad;  ///< bearing step between beams [rad], > 0 (CCW sweep)
  uint16_t n_beams;            ///< valid entries below, 0..FEATURES_MAX_BEAMS
  /// Measured range of each beam [m], from the mirror axis. Ignored where no_return[i] != 0.
  float ranges_m[FEATURES_MAX_BEAMS];
  /// 0 = a valid return; any other value = no valid return (no echo, dazzle, overflow, ...; the
  /// value is the decoder's reason code and is only counted, never interpreted, here).
  uint8_t no_return[FEATURES_MAX_BEAMS];
} features_scan_t;

/// How raw beams become points. Beams are discarded (counted as missing) when no_return != 0,
/// the range is not finite, below min_range_m, or above max_range_m.
typedef struct features_scan_config {
  features_laser_mount_t mount;  ///< laser pose on the robot
  double min_range_m;            ///< shortest credible return [m], default 0.05 (LMS200 blind zone)
  double max_range_m;            ///< longest credible return [m], default
                                 ///< FEATURES_LMS200_MAX_VALID_RANGE_M; must be > min_range_m
} features_scan_config_t;

/// Fills cfg with the defaults documented on each field. O(1). cfg must not be NULL.
void features_scan_config_default(features_scan_config_t* cfg);

/// Sets the beam angles of an LMS200 scan: field_deg is 180 or 100, resolution_deg is 1, 0.5 or
/// 0.25 (0.25 only with 100). Sets angle_min, increment and n_beams (ranges untouched).
/// Returns FEATURES_ERR_INVALID_ARG (scan unchanged) for other combinations. O(1).
features_status_t features_scan_set_lms200_geometry(features_scan_t* scan, int field_deg,
                                                    double resolution_deg);

/// Fills a scan from a decoded laser scan: beam geometry (angle_min_rad, angle_increment_rad),
/// n_beams ranges [m] and per-beam no-return reasons (0 = valid return), copied as given. This
/// is how a decoded LMS200 telegram (proto/lms200.h: start_angle_rad, step_rad, range_m,
/// beam_status) becomes the features' input, in the controller and in the Python environment
/// alike. Returns FEATURES_ERR_INVALID_ARG (scan unchanged) for NULL pointers or n_beams >
/// FEATURES_MAX_BEAMS. O(n_beams), no allocation.
features_status_t features_scan_fill(features_scan_t* scan, double angle_min_rad,
                                     double angle_increment_rad, uint16_t n_beams,
                                     const float* ranges_m, const uint8_t* no_return);

/// Wraps an angle to (-pi, pi]. Non-finite input returns 0 (never NaN). O(1).
double features_angle_wrap(double angle_rad);

/// Composition a (+) b: the pose of frame b (given in frame a) expressed in a's parent. O(1).
features_pose_t features_pose_compose(features_pose_t a, features_pose_t b);

/// Inverse of a pose: the parent frame expressed in the frame of a. O(1).
features_pose_t features_pose_inverse(features_pose_t a);

/// Pose of b relative to a, both given in the same parent frame: inverse(a) (+) b. O(1).
features_pose_t features_pose_between(features_pose_t a, features_pose_t b);

/// Maps the current odometry pose into a task frame. At the start of a run the robot stands at
/// start_in_task (from the task spec, or measured) while odometry reads odom_at_start; the robot
/// has since moved to odom_now. Returns start_in_task (+) between(odom_at_start, odom_now).
/// This is how the firmware obtains the pose_in_task arguments of the feature functions. O(1).
features_pose_t features_odom_to_task(features_pose_t start_in_task, features_pose_t odom_at_start,
                                      features_pose_t odom_now);

#ifdef __cplusplus
}
#endif

#endif  // B21R_FEATURES_SCAN_H
