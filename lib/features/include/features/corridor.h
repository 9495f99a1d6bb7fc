// SPDX-License-Identifier: MIT
/// features/corridor.h — Corridor-following state from a laser scan and odometry (paper §V-A).
///
/// The corridor frame (shared with tasks/tasks.h and the emulator's corridor world):
/// - x runs along the corridor axis from the start wall (x = 0) towards the end wall
///   (x = length_m); y is lateral, 0 on the centre line, positive to the LEFT when facing the end.
///   The left wall is the line y = +width_m/2, the right wall y = -width_m/2.
///
/// State (what the learner sees), computed each tick:
/// - end_distance_m: distance from the robot centre to the end wall along the corridor axis [m].
/// - lateral_frac: distance from the LEFT wall as a fraction of the corridor width, 0 at the left
///   wall, 0.5 on the centre line, 1 at the right wall.
/// - target_angle_rad: bearing, in the robot frame, of a target point on the centre line a fixed
///   look-ahead L (lookahead_m, default 2.0 m) ahead of the robot along the corridor axis.
///   With d = the robot's signed lateral offset from the centre line (positive = left of centre,
///   offset_m below) and phi = the direction of the corridor axis in the robot frame (= -heading,
///   heading_rad below), target_angle = phi - atan2(d, L). For d > 0 this is exactly the paper's
///   theta = atan(L/d) + phi - pi/2 (atan(L/d) = pi/2 - atan(d/L)); atan2 keeps it continuous
///   through d = 0 and d < 0, where the paper's expression jumps by pi. The paper gives the
///   look-ahead as "20" without a unit; L = 2.0 m is this product's choice (one corridor width).
///   Positive target_angle = target to the left: omega = k * target_angle with k > 0 steers there.
///
/// Where each quantity comes from:
/// - Walls: the two side walls are found in the scan as a pair of parallel lines about width_m
///   apart with the robot between them. A bounded Hough search runs over wall directions (3° then 1°
///   steps) inside a window around the odometry-predicted direction: per direction, a histogram
///   of lateral offsets (0.05 m bins) scores the best pair of peaks whose separation is within
///   width_tolerance_m of width_m (or the best single wall), plus the best cross wall (an
///   along-axis peak spanning half the width), which sharpens the direction near the end. A
///   peak counts as a wall only if its points extend at least min_wall_length_m along the axis,
///   and points laterally beyond it count against it (a wall bounds the corridor), so a person,
///   a door frame or the corner of the end wall cannot pose as a side wall. Then a joint
///   least-squares refit (shared direction: the principal axis of the pooled scatter of both
///   walls' inliers, with the cross wall's inliers rotated by 90°; two passes with a wide band,
///   two with inlier_tolerance_m). Missing beams and error codes only remove support. When only
///   one wall has support the other is placed width_m away (flagged). lateral_frac, offset_m,
///   heading_rad and target_angle_rad come from the walls whenever at least one is seen.
/// - End wall: among points between the walls, the farthest cluster along the axis that spans at
///   least half the corridor width (a person spans less) is the end wall. The LMS200 sees at most
///   8.18 m in millimetre mode, so in a 10 m corridor the end wall is out of range for the first
///   metres: end_distance_m is the laser measurement when the end wall is seen (and agrees with
///   odometry within end_gate_m, if odometry is given), otherwise length_m - x from odometry.
///   The source used is reported. Odometry drift therefore only matters far from the end, where
///   an error of a few centimetres in the state is harmless; near the goal the laser decides.
/// - Fallback: if no side wall is seen (all beams missing, heavy clutter, the last metre before
///   the end wall), the lateral quantities come from the odometry pose (if given), walls_seen = 0
///   and lateral_source = ODOMETRY; if neither laser nor odometry is available, valid = 0 and the
///   outputs hold the neutral values (end_distance_m = length_m, lateral_frac = 0.5, angles 0).
///   With walls but neither end wall nor odometry, valid = 1 and end_source = NONE
///   (end_distance_m = length_m).
/// - Without odometry the whole half-turn of directions is searched and the axis is taken to
///   point into the robot's front half-plane. Within about 2 m of the end wall, when only one
///   side wall and the end wall are in view, the laser alone cannot tell which is which (an L
///   corner); pass odometry there.
/// - Accuracy (test/unit/features, synthetic LMS200 scans with 1 cm noise, 0.5° or 1° beams,
///   up to 10 % dropouts, 2-5 % error codes, a person in the corridor, odometry heading off by
///   up to 0.1 rad): offset within 0.02 m, lateral_frac within 0.01, heading and target angle
///   within 0.025 rad, measured end distance within 0.02 m, for robot positions from the start
///   to 0.8 m before the end wall.
///
/// Cost: O(n_beams * n_directions); the direction search runs coarse to fine (3° steps over the
/// window, then 1° steps around the best), about 30 directions with the default window and 65
/// for a full search: about 0.4 ms per call at 401 beams with odometry and 0.6 ms for a full
/// search on one x86-64 core at -O2. No allocation; about 20 KB of stack. Pure and reentrant.
/// Never produces NaN or infinity: non-finite inputs are discarded or reported as invalid.
#ifndef B21R_FEATURES_CORRIDOR_H
#define B21R_FEATURES_CORRIDOR_H

#include <stdint.h>

#include "features/scan.h"

#ifdef __cplusplus
extern "C" {
#endif

/// Number of state dimensions of the corridor task (end distance, lateral fraction, angle).
#define FEATURES_CORRIDOR_STATE_DIM 3

/// Where a feature value came from this tick.
typedef enum features_source {
  FEATURES_SOURCE_NONE = 0,      ///< no information: neutral value, valid = 0
  FEATURES_SOURCE_LASER = 1,     ///< measured in this scan
  FEATURES_SOURCE_ODOMETRY = 2,  ///< from the odometry pose in the task frame
} features_source_t;

/// Configuration of the corridor feature extractor. Geometry must match the corridor driven.
typedef struct features_corridor_config {
  features_scan_config_t scan;  ///< beam filtering and laser mount
  double width_m;               ///< nominal corridor width [m], default 2.0 (tasks spec)
  double length_m;              ///< start wall to end wall [m], default 10.0 (tasks spec)
  double lookahead_m;           ///< L, distance of the target point ahead [m], default 2.0, > 0
  double width_tolerance_m;     ///< accepted |measured - nominal| width [m], default 0.4
  double inlier_tolerance_m;    ///< max distance of a wall point from its line [m], default 0.08
  uint16_t min_wall_points;     ///< support needed to accept a wall, default 6
  uint16_t min_end_points;      ///< support needed to accept the end wall, default 5
  /// A side wall's support must extend at least this far along the axis [m], default 0.4; this
  /// keeps the end wall, a person or a door frame from posing as a side wall.
  double min_wall_length_m;
  /// Half-width of the wall-direction search window around the direction predicted by the
  /// odometry pose [rad], default 0.6 (about 34°); clamped to [0.05, pi/2]. Without odometry,
  /// or with a value >= pi/2, all directions are searched and the axis is taken to point to the
  /// robot's front half-plane.
  double heading_window_rad;
  /// Laser end distance is rejected when it differs from odometry by more than this [m], default
  /// 1.5; 0 disables the gate. Guards against a cross wall or a crowd being taken for the end.
  double end_gate_m;
} features_corridor_config_t;

/// The corridor state and its provenance. All doubles are finite in every case.
typedef struct features_corridor {
  double end_distance_m;    ///< robot centre to end wall along the axis [m], >= 0
  double lateral_frac;      ///< distance from the left wall / width, clamped to [0, 1]
  double target_angle_rad;  ///< bearing of the look-ahead target [rad], (-pi, pi]
  double offset_m;          ///< d: signed lateral offset from the centre line, + = left [m]
  double heading_rad;       ///< robot heading relative to the corridor axis, CCW [rad], (-pi, pi]
  double width_m;           ///< measured width (nominal if fewer than two walls seen) [m]
  uint8_t valid;            ///< 1: the state may be used (laser and/or odometry); 0: neutral values
  uint8_t walls_seen;       ///< number of side walls found in this scan, 0..2
  uint8_t left_wall_seen;   ///< 1 if the left wall had support
  uint8_t right_wall_seen;  ///< 1 if the right wall had support
  uint8_t end_wall_seen;    ///< 1 if the end wall was measured (and passed the odometry gate)
  uint8_t lateral_source;   ///< features_source_t of lateral_frac, offset, heading, target angle
  uint8_t end_source;       ///< features_source_t of end_distance_m
  uint16_t n_points;        ///< beams that produced a point (valid returns)
  uint16_t left_points;     ///< inliers of the left wall
  uint16_t right_points;    ///< inliers of the right wall
  uint16_t end_points;      ///< inliers of the end wall
  double fit_rms_m;         ///< RMS distance of the side-wall inliers from their lines [m]
} features_corridor_t;

/// Fills cfg with the defaults documented on each field. O(1). cfg must not be NULL.
void features_corridor_config_default(features_corridor_config_t* cfg);

/// Computes the corridor state from one scan.
/// - cfg, scan, out: required. pose_in_corridor: odometry pose of the robot centre in the
///   corridor frame (see features_odom_to_task), or NULL when not available.
/// Returns FEATURES_OK (check out->valid), or FEATURES_ERR_INVALID_ARG for NULL cfg/scan/out,
/// n_beams > FEATURES_MAX_BEAMS, a non-finite or non-positive increment, or a configuration value
/// out of range; then out (if not NULL) holds the neutral invalid state.
/// Cost as in the file comment. Pure: the same inputs give bit-identical outputs.
features_status_t features_corridor_compute(const features_corridor_config_t* cfg,
                                            const features_scan_t* scan,
                                            const features_pose_t* pose_in_corridor,
                                            features_corridor_t* out);

/// The exact state of a robot at a known pose in the corridor frame (ground truth, the odometry
/// fallback, and the idealised kinematic model's observation). Sources are set to ODOMETRY,
/// walls_seen = 0, valid = 1. Returns FEATURES_ERR_INVALID_ARG for NULL arguments, a
/// non-finite pose or an invalid cfg. O(1).
features_status_t features_corridor_from_pose(const features_corridor_config_t* cfg,
                                              features_pose_t pose_in_corridor,
                                              features_corridor_t* out);

/// Writes the learner's state vector (end_distance_m, lateral_frac, target_angle_rad) into
/// state[0..2]. O(1). Both pointers must be valid.
void features_corridor_state(const features_corridor_t* f, double state[FEATURES_CORRIDOR_STATE_DIM]);

#ifdef __cplusplus
}
#endif

#endif  // B21R_FEATURES_CORRIDOR_H
