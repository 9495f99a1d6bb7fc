// SPDX-License-Identifier: MIT
/// features/obstacles.h — Obstacle-avoidance state from a laser scan and odometry (paper §V-B).
///
/// State (paper Fig. 8: "the direction and distance to the goal state and the obstacles"):
/// - goal_bearing_rad: bearing of the goal in the robot frame, CCW positive, (-pi, pi];
///   goal_distance_m: distance from the robot centre to the goal [m]. Both from odometry: the
///   goal is a point given in the same frame as the odometry pose (see features_odom_to_task).
/// - obstacle[k].bearing_rad / distance_m: the k-th nearest obstacle (k = 0 nearest), measured
///   from the robot centre: distance to the obstacle's nearest laser return (its surface, not its
///   centre), bearing = mean direction of the returns within 0.03 m of that distance (around its
///   nearest point a surface is flat in range, so the single nearest return would wander over
///   several beams with range noise). Only what the laser sees can be reported: with the laser
///   0.15 m ahead of the centre, the surface point nearest to the centre of an obstacle beside
///   the robot may be hidden from it.
/// - Accuracy (test/unit/features, synthetic LMS200 scans, 1 cm noise, up to 10 % dropouts):
///   distance within 0.04 m and bearing within 0.05 rad of the nearest visible surface point
///   (0.1 rad beyond +-1.1 rad, where the view of the obstacle is cut off); every obstacle with
///   6 or more beams on it found; no wall of the arena ever reported as an obstacle.
///
/// Segmentation: valid beams are turned into points in the robot frame; consecutive valid points
/// (missing beams skipped, they neither split nor join) form a cluster while the gap between
/// neighbours is at most cluster_gap_m. A cluster is an obstacle when
///   (a) it has at least min_cluster_points points,
///   (b) its extent (first to last point) is at most max_obstacle_width_m (longer = wall), and
///   (c) it stands out from its background: on each side, the nearest valid point outside the
///       cluster is at least standout_m farther from the laser than the cluster's end point, or
///       there is no valid point on that side (field-of-view edge, or only missing beams).
/// (c) rejects wall fragments (split by grazing incidence or dropouts) whose neighbours continue
/// the wall, and a corner. Known limit: an obstacle touching a wall with no range jump merges
/// into the wall and is not reported.
///
/// The obstacle task's state (tasks/src/task_obstacles.c) uses the memory below
/// (features_obstacles_memory_state): goal bearing, goal distance, the known obstacle's bearing and
/// distance, and the time since it was seen.
///
/// Convention when fewer obstacles are visible than slots: the empty slot has visible = 0,
/// distance_m = no_obstacle_distance_m (default 8.0 m, the edge of sensing) and bearing_rad = pi
/// ("behind": an obstacle that left the 180° field of view is most likely behind the robot). The
/// value pi never occurs for a visible obstacle (the field of view is at most 180° forward), so
/// the learner sees "no obstacle" as its own region of the state space.
///
/// Memory (features_obstacles_remember): an obstacle being passed leaves the 180° field of view
/// while the robot is still beside it. The optional memory keeps the nearest obstacle seen after
/// it left the view: where it was seen, as a disc in the frame of the poses (its centre behind
/// its nearest return along the bearing, by half its width, from the best view of it), carried
/// along with the pose (its bearing and distance recomputed from the stored disc and the
/// current pose, i.e. through odometry) and its age (observations since it was last seen). The
/// memory is run state owned by the caller (features_obstacle_memory_t, reset at each run's
/// start); it is updated from the features of each observation, so the measured
/// (features_obstacles_compute) and the exact (features_obstacles_from_pose) features get the same
/// memory from the same rule. See features_obstacles_remember for the rule. Accuracy
/// (test/unit/features, noise-free synthetic scans, an obstacle of radius 0.25 m passed 0.3 m
/// from the robot's skirt, straight and turning): the remembered centre within 0.08 m of the true
/// one, its distance within 0.05 m of the true surface distance; exact from the exact features.
///
/// Cost: O(n_beams), no allocation, < 1 KB of stack. Pure and reentrant. Never NaN.
#ifndef B21R_FEATURES_OBSTACLES_H
#define B21R_FEATURES_OBSTACLES_H

#include <stddef.h>
#include <stdint.h>

#include "features/scan.h"

#ifdef __cplusplus
extern "C" {
#endif

/// Obstacle slots reported (nearest first).
#define FEATURES_MAX_OBSTACLES 2

/// State dimensions for the paper's task (one obstacle): goal bearing, goal distance, obstacle
/// bearing, obstacle distance. With two obstacles it is 6 (features_obstacles_state).
#define FEATURES_OBSTACLES_STATE_DIM 4

/// State dimensions with the memory (features_obstacles_memory_state): goal bearing, goal
/// distance, the known obstacle's bearing and distance, and the time since it was seen.
#define FEATURES_OBSTACLES_MEMORY_STATE_DIM 5

/// Configuration of the obstacle feature extractor.
typedef struct features_obstacles_config {
  features_scan_config_t scan;    ///< beam filtering and laser mount
  double cluster_gap_m;           ///< max gap between neighbouring points of one cluster, default 0.25
  double max_obstacle_width_m;    ///< clusters wider than this are walls [m], default 1.0
  double standout_m;              ///< range jump that separates an obstacle from its background
                                  ///< [m], default 0.3
  uint16_t min_cluster_points;    ///< fewer points = noise, default 3
  double no_obstacle_distance_m;  ///< distance reported for an empty slot [m], default 8.0, > 0
  /// Memory: observations an obstacle is remembered after it was last seen, default 30 (3 s at
  /// 10 Hz); 0 = no memory (the known obstacle is the one seen, if any).
  uint32_t memory_max_age;
  /// Memory: a remembered obstacle gives way to a seen one unless it is nearer than the seen one
  /// by more than this [m], default 0.1 (range noise and the error of a remembered disc stay
  /// below it), >= 0.
  double memory_margin_m;
} features_obstacles_config_t;

/// One obstacle slot.
typedef struct features_obstacle {
  double bearing_rad;  ///< bearing of the nearest return, robot frame [rad]; pi if not visible
  double distance_m;   ///< robot centre to the nearest return [m]; no_obstacle_distance_m if not
  double width_m;      ///< extent of the cluster [m]; 0 if not visible
  double centre_x_m;   ///< mean of the cluster's points, robot frame [m]; 0 if not visible
  double centre_y_m;   ///< (same) [m]
  uint16_t n_points;   ///< returns in the cluster; 0 if not visible
  uint8_t visible;     ///< 1 if this slot holds a segmented obstacle
} features_obstacle_t;

/// The obstacle-task state and diagnostics. All doubles finite in every case.
typedef struct features_obstacles {
  double goal_bearing_rad;  ///< goal bearing in the robot frame [rad], (-pi, pi]
  double goal_distance_m;   ///< robot centre to goal [m], >= 0
  features_obstacle_t obstacle[FEATURES_MAX_OBSTACLES];  ///< nearest first
  uint8_t n_visible;        ///< obstacles segmented (may exceed FEATURES_MAX_OBSTACLES; capped 255)
  uint8_t valid;            ///< 1 if the goal part is valid (pose given and finite)
  uint8_t scan_valid;       ///< 1 if the scan had at least one valid return
  uint16_t n_points;        ///< valid returns
  uint16_t n_clusters;      ///< clusters found
  uint16_t n_wall_clusters; ///< clusters rejected as walls/background
  double nearest_any_m;     ///< nearest valid return of any kind (walls too) from the robot centre
                            ///< [m]; no_obstacle_distance_m if none
  double nearest_any_bearing_rad;  ///< its bearing [rad]; pi if none
  /// The nearest obstacle known: the one seen in this observation, or the remembered one
  /// (features_obstacles_remember). compute and from_pose set it without memory: obstacle[0]
  /// when visible (age 0), else the empty slot (age memory_max_age). A remembered obstacle has
  /// visible = 0, bearing_rad = the direction of the remembered disc's centre, distance_m = the
  /// distance to its surface (0 inside it), width_m = its diameter, centre_x/y_m = its centre in
  /// the robot frame, n_points = 0.
  features_obstacle_t known;
  /// Observations since `known` was seen: 0 when seen in this one; memory_max_age when there is
  /// none (saturating: the oldest a remembered obstacle can be).
  uint32_t known_age;
} features_obstacles_t;

/// The memory of the nearest obstacle seen: run state, caller-owned plain data (copyable). Reset
/// it (features_obstacle_memory_reset) at every run's start.
typedef struct features_obstacle_memory {
  double x_m;        ///< the remembered disc's centre, in the frame of the poses given [m]
  double y_m;        ///< [m]
  double radius_m;   ///< its radius [m]
  uint32_t age;      ///< observations since it was seen (0: in the newest one)
  uint16_t n_points; ///< returns of the view the disc comes from (0: exact features)
  uint8_t held;      ///< 1 while an obstacle is remembered
} features_obstacle_memory_t;

/// Fills cfg with the defaults documented on each field. O(1). cfg must not be NULL.
void features_obstacles_config_default(features_obstacles_config_t* cfg);

/// Computes the obstacle-task state.
/// - pose: robot pose in some frame (odometry, or the task frame), NULL if unknown (then
///   valid = 0 and the goal fields are 0). goal_x_m, goal_y_m: the goal in the same frame.
/// Returns FEATURES_OK (check out->valid / out->scan_valid), or FEATURES_ERR_INVALID_ARG for NULL
/// cfg/scan/out, n_beams > FEATURES_MAX_BEAMS, a bad increment or configuration; then out (if
/// not NULL) holds the empty state. O(n_beams), pure.
features_status_t features_obstacles_compute(const features_obstacles_config_t* cfg,
                                             const features_scan_t* scan,
                                             const features_pose_t* pose, double goal_x_m,
                                             double goal_y_m, features_obstacles_t* out);

/// An obstacle whose geometry is known exactly: a vertical cylinder, in the frame of the pose
/// given to features_obstacles_from_pose (the task frame).
typedef struct features_disc {
  double x_m;       ///< centre [m]
  double y_m;       ///< [m]
  double radius_m;  ///< [m], > 0
} features_disc_t;

/// The obstacle-task state of a robot at a known pose among known obstacles: what an ideal laser
/// (no noise, unlimited angular resolution, no occlusion) at cfg->scan.mount would give. This is
/// the observation of the idealised kinematic model (sim/env.h), as features_corridor_from_pose
/// is for the corridor.
/// - Goal fields exactly as features_obstacles_compute computes them from the same pose.
/// - Obstacle k is visible when the point of its surface nearest to the robot centre lies in the
///   laser's field of view (|bearing from the mount| <= field_of_view_rad / 2, range from the
///   mount within [min_range_m, max_range_m]); then distance_m = robot centre to that point (0
///   when the centre is inside the disc), bearing_rad = its bearing from the robot centre (the
///   direction of the disc's centre), width_m = 2 radius, centre_x/y_m = the disc centre in the
///   robot frame, n_points = 0 (no beams). Nearest first, empty slots as documented above.
/// - nearest_any_m / _bearing_rad: the nearest visible obstacle (walls are not known here);
///   n_points, n_clusters, n_wall_clusters = 0; scan_valid = 1.
/// Returns FEATURES_ERR_INVALID_ARG (out = the empty state) for NULL cfg/out, obstacles == NULL
/// with n_obstacles > 0, a non-finite pose, goal or disc, a radius <= 0, a field of view outside
/// (0, 2 pi] or a bad configuration. O(n_obstacles), no allocation, pure.
features_status_t features_obstacles_from_pose(const features_obstacles_config_t* cfg,
                                               features_pose_t pose, double goal_x_m,
                                               double goal_y_m, const features_disc_t* obstacles,
                                               uint32_t n_obstacles, double field_of_view_rad,
                                               features_obstacles_t* out);

/// Empties the memory (no obstacle remembered). O(1). mem must not be NULL.
void features_obstacle_memory_reset(features_obstacle_memory_t* mem);

/// Updates the memory with the features f of the newest observation, made at `pose` (the pose
/// given to features_obstacles_compute or features_obstacles_from_pose for f), and sets f->known
/// and f->known_age. The rule, per observation:
/// 1. A remembered obstacle ages by one observation; its bearing (to the disc's centre) and
///    distance (to its surface) are recomputed from the remembered disc and `pose`. It is forgotten when its age exceeds
///    cfg->memory_max_age or its distance reaches cfg->no_obstacle_distance_m (beyond sensing).
/// 2. When an obstacle is seen (f->obstacle[0].visible) it is the known one (age 0): the
///    remembered one when its nearest return lies within the remembered radius +
///    cfg->cluster_gap_m of the remembered centre (the same obstacle), else another one, which
///    replaces the remembered one unless that is nearer than it by more than
///    cfg->memory_margin_m (an obstacle beside the robot that left the view while another one is
///    seen farther ahead stays the known one until it is forgotten or farther). The disc
///    remembered: radius r = half its width_m (at most max_obstacle_width_m / 2), centre r beyond
///    its nearest return along its bearing; but when the same obstacle is seen in a view with
///    fewer returns (n_points) than the one the remembered disc came from, the disc is kept:
///    an obstacle being passed is seen less and less (its nearest return cut off at the edge of
///    the view, its width shrinking), and the best view of it places it best (assuming obstacles
///    that do not move). From features_obstacles_from_pose (n_points 0, width = the diameter,
///    bearing = the centre's direction) the disc is always the exact one.
/// 3. f->known = the seen obstacle exactly as obstacle[0] when it was just (re)placed, the
///    remembered disc (as documented at `known`) otherwise, the empty slot (bearing pi,
///    no_obstacle_distance_m) when none; f->known_age = its age, or memory_max_age when none.
/// Returns FEATURES_OK, or FEATURES_ERR_INVALID_ARG (memory and f unchanged) for NULL arguments,
/// a bad configuration or a non-finite pose. O(1), no allocation, deterministic.
features_status_t features_obstacles_remember(const features_obstacles_config_t* cfg,
                                              features_obstacle_memory_t* mem, features_pose_t pose,
                                              features_obstacles_t* f);

/// Writes the state vector with the memory: goal_bearing, goal_distance, known.bearing_rad,
/// known.distance_m and known_age x period_s (the time since the known obstacle was seen [s]
/// when one observation is made per period_s). Returns FEATURES_OBSTACLES_MEMORY_STATE_DIM, or 0
/// (nothing written) for NULL pointers, a capacity below it or a period that is not finite and
/// > 0. O(1).
size_t features_obstacles_memory_state(const features_obstacles_t* f, double period_s, double* state,
                                       size_t capacity);

/// Writes the learner's state vector: goal_bearing, goal_distance, then (bearing, distance) of
/// the first n_obstacles slots (1 = the paper's task, 4 values; 2 gives 6). Returns the number
/// of values written, or 0 if n_obstacles is 0 or > FEATURES_MAX_OBSTACLES or capacity is too
/// small (nothing written). O(1).
size_t features_obstacles_state(const features_obstacles_t* f, uint32_t n_obstacles, double* state,
                                size_t capacity);

#ifdef __cplusplus
}
#endif

#endif  // B21R_FEATURES_OBSTACLES_H
