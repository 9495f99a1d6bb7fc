// SPDX-License-Identifier: MIT
/// features/doorway.h — Doorway-passing state from a laser scan and odometry: where the door gap
/// in the wall ahead is, found from its two edges (the jambs).
///
/// The door frame (shared with tasks/doorway.h and the emulator's doorway world): origin at the
/// centre of the gap on the dividing wall's centre plane; x_d along the wall's normal, from the
/// robot's side of the wall through the door to the far side (the goal's side); y_d along the
/// wall, positive to the LEFT when looking through the door. The wall is wall_thickness_m thick
/// (its faces at x_d = -t/2 and +t/2); the gap spans |y_d| < door_width_m / 2. The configuration
/// places this frame in the task frame (door_x_m, door_y_m, normal_rad).
///
/// State (what the learner sees, FEATURES_DOORWAY_STATE_DIM = 4), and why:
/// - wall_distance_m: signed distance from the robot centre to the wall's centre plane along the
///   normal, + on the robot's side, - beyond the wall (= -x_d). Progress towards and through the
///   door; continuous through it, unlike a distance to the gap's centre, which falls and rises
///   again and leaves the two sides to be told apart by a bearing that wraps at +-pi behind.
/// - offset_m: lateral offset of the robot centre from the door's centre line (= y_d), + left.
///   With wall_distance_m it places the robot relative to the gap: whether the body fits
///   through (|offset| < door_width/2 - robot radius) is a question of these two alone.
/// - heading_rad: the robot's heading relative to the wall's normal, CCW, (-pi, pi]: 0 = facing
///   straight through the door. The three make the robot's pose in the door frame, so the state is
///   Markov for a fixed door and goal (the goal sits at a fixed point of this frame).
/// - jamb_distance_m: robot centre to the nearer jamb (the end face of the wall on either side of
///   the gap, a segment across the wall's thickness) [m]. Redundant with the first two for a
///   known door, but it is the quantity a collision while passing depends on, and it is a
///   nonlinear (distance-to-segment) function of them that a locally linear value model would
///   otherwise have to piece together near the door, where the value changes fastest.
/// Diagnostics beside the state: the bearing and distance of the gap's centre (what a person,
/// and the example policy, steers on), the measured gap width, and where the values came from.
///
/// Where each quantity comes from:
/// - The wall: a bounded Hough search over wall directions (2° then 0.5° steps) in a window
///   around the direction predicted by odometry (or the whole front half-turn without it): per
///   direction a histogram of the points' offsets along the normal (0.05 m bins) whose best peak
///   (within gate_m of the predicted near face, with odometry) is the near face of the wall;
///   then a least-squares refit of the line (principal axis of the inliers, two passes).
/// - The gap: walking the valid points in beam order (which is their order along the line), the
///   wall's inliers (within inlier_tolerance_m of the line) break where two consecutive inliers
///   lie more than split_gap_m apart along it. At a break, an edge is a JAMB when the beams next
///   to it in the break look beyond the wall's face (through the gap, or at the jamb's end face),
///   or return nothing; it is OCCLUDED when the next return is in front of the face (something
///   stands between the laser and the jamb). A break whose two edges are jambs and whose width
///   is within width_tolerance_m of door_width_m is the door, seen whole (jambs_seen = 2, the
///   centre is the middle of the two jambs). A break with one jamb, the other edge occluded and at
///   least door_width_m - width_tolerance_m wide is the door with one jamb hidden (jambs_seen = 1;
///   the centre is door_width_m / 2 from the visible jamb, towards the other edge). Of several
///   candidates the one nearest to the odometry's prediction wins (without odometry: a whole one
///   before a partial one, then the one nearest to straight ahead).
/// - Fallback: when the wall or the gap is not found, when the robot is within min_view_m of the
///   wall's near face or beyond it (the laser looks past the door or away from it: after passing
///   it, or while passing), or when the laser's door frame disagrees with odometry by more than
///   gate_m or gate_rad, every value comes from the odometry pose (source ODOMETRY), as
///   features_doorway_from_pose gives it. Without a pose and without the gap, valid = 0 and the
///   values are neutral (wall_distance_m = 0, offset 0, heading 0, jamb distance door_width/2).
/// - Without odometry the laser's values are used as found; the wall is assumed to be in front
///   and the robot on the wall's near side.
///
/// Ranges: wall_distance_m and offset_m as the room allows (the laser's within max_range_m of the
/// robot); heading_rad in (-pi, pi]; jamb_distance_m >= 0. Units SI.
/// Accuracy (test/unit/features, synthetic LMS200 scans, 1 cm noise, 1° or 0.5° beams, a 0.1 m
/// thick wall with a 1 m door, robot 1-4 m before it within +-0.7 rad of facing the wall; the
/// laser's values are used from over 95 % of such poses): wall distance within 0.01 m, heading
/// within 0.015 rad, offset within 0.03 m (the jambs' edges are placed between the beams that hit
/// the wall and those that pass it), 0.06 m with 10 % dropouts (a missing beam beside a jamb
/// widens that interval) or with one jamb hidden behind an obstacle.
///
/// Cost: O(n_beams * n_directions): 40 directions with odometry (the default 0.5 rad window: 31
/// coarse, 9 fine), at most 118 without (91 coarse, 9 fine for each of up to 3 candidate lines),
/// then O(n_beams) for the refit and the gap: about 0.06 ms per call at 181 beams and 0.15 ms at
/// 401 with odometry, 0.2-0.35 ms without, on one x86-64 core at -O2. No allocation; about 20 KB
/// of stack. Pure and reentrant. Never produces NaN or infinity.
#ifndef B21R_FEATURES_DOORWAY_H
#define B21R_FEATURES_DOORWAY_H

#include <stdint.h>

#include "features/corridor.h"
#include "features/scan.h"

#ifdef __cplusplus
extern "C" {
#endif

/// State dimensions of the doorway task: wall distance, offset, heading, jamb distance.
#define FEATURES_DOORWAY_STATE_DIM 4

/// Configuration of the door-gap extractor. The door geometry must match the door driven.
typedef struct features_doorway_config {
  features_scan_config_t scan;  ///< beam filtering and laser mount
  double door_x_m;              ///< gap centre on the wall's centre plane, task frame [m], default 0
  double door_y_m;              ///< [m], default 0
  /// Direction of the wall's normal from the robot's side through the door, task frame [rad],
  /// default 0 (+x)
  double normal_rad;
  double door_width_m;          ///< gap width, jamb to jamb [m], default 1.0, > 0
  double wall_thickness_m;      ///< wall thickness [m], default 0.1, >= 0
  double width_tolerance_m;     ///< accepted |measured - nominal| gap width [m], default 0.2
  double inlier_tolerance_m;    ///< max distance of a wall point from its line [m], default 0.05
  /// Wall inliers farther apart than this along the wall break it [m], default 0.3; must be
  /// below door_width_m - width_tolerance_m.
  double split_gap_m;
  uint16_t min_wall_points;     ///< support needed to accept the wall, default 8
  /// Half-width of the wall-direction search window around odometry's prediction [rad], default
  /// 0.5; clamped to [0.05, pi/2]. Without odometry the whole front half-turn is searched.
  double heading_window_rad;
  /// Nearer than this to the wall's near face (or beyond it) the laser is not used [m], default
  /// 0.3: the gap is then beside or behind the laser.
  double min_view_m;
  /// The laser's door frame is rejected when its position differs from odometry's by more than
  /// gate_m [m] (default 0.5) or its heading by more than gate_rad (default 0.3); 0 disables.
  double gate_m;
  double gate_rad;
} features_doorway_config_t;

/// The doorway state and its provenance. All doubles are finite in every case.
typedef struct features_doorway {
  double wall_distance_m;   ///< robot centre to the wall's centre plane along its normal, + before [m]
  double offset_m;          ///< lateral offset from the door's centre line, + left [m]
  double heading_rad;       ///< heading relative to the wall's normal, (-pi, pi]
  double jamb_distance_m;   ///< robot centre to the nearer jamb's end face [m], >= 0
  double gap_bearing_rad;   ///< bearing of the gap's centre (centre plane), robot frame, (-pi, pi]
  double gap_distance_m;    ///< robot centre to the gap's centre [m]
  double width_m;           ///< measured gap width (nominal unless both jambs were seen) [m]
  uint8_t valid;            ///< 1: the state may be used; 0: neutral values
  uint8_t source;           ///< features_source_t of the values (LASER, ODOMETRY or NONE)
  uint8_t wall_seen;        ///< 1 if the wall line had support in this scan
  uint8_t jambs_seen;       ///< jambs of the chosen gap seen in this scan, 0..2
  uint16_t n_points;        ///< beams that produced a point (valid returns)
  uint16_t wall_points;     ///< inliers of the wall line
} features_doorway_t;

/// Fills cfg with the defaults documented on each field. O(1). cfg must not be NULL.
void features_doorway_config_default(features_doorway_config_t* cfg);

/// Computes the doorway state from one scan.
/// - cfg, scan, out: required. pose_in_task: odometry pose of the robot centre in the task frame
///   (see features_odom_to_task), or NULL when not available.
/// Returns FEATURES_OK (check out->valid and out->source), or FEATURES_ERR_INVALID_ARG for NULL
/// cfg/scan/out, n_beams > FEATURES_MAX_BEAMS, a bad increment or a configuration value out of
/// range; then out (if not NULL) holds the neutral invalid state. Cost as in the file comment.
/// Pure: the same inputs give bit-identical outputs.
features_status_t features_doorway_compute(const features_doorway_config_t* cfg, const features_scan_t* scan,
                                           const features_pose_t* pose_in_task, features_doorway_t* out);

/// The exact state of a robot at a known pose in the task frame (ground truth, the odometry
/// fallback, and the idealised kinematic model's observation): source ODOMETRY, valid = 1,
/// wall_seen = 0, jambs_seen = 0, width_m = door_width_m. Returns FEATURES_ERR_INVALID_ARG (out
/// neutral) for NULL arguments, a non-finite pose or an invalid cfg. O(1).
features_status_t features_doorway_from_pose(const features_doorway_config_t* cfg, features_pose_t pose_in_task,
                                             features_doorway_t* out);

/// Robot centre to the nearer jamb's end face for a robot at (x_d, y_d) in the door frame, with
/// a gap of width_m in a wall thickness_m thick [m]. Pure, O(1).
double features_doorway_jamb_distance(double x_d_m, double y_d_m, double width_m, double thickness_m);

/// Writes the learner's state vector (wall_distance_m, offset_m, heading_rad, jamb_distance_m)
/// into state[0..3]. O(1). Both pointers must be valid.
void features_doorway_state(const features_doorway_t* f, double state[FEATURES_DOORWAY_STATE_DIM]);

#ifdef __cplusplus
}
#endif

#endif  // B21R_FEATURES_DOORWAY_H
