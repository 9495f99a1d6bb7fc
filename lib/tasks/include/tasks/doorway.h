// SPDX-License-Identifier: MIT
/// tasks/doorway.h — Doorway passing: a room divided by a wall with a door about 1 m wide; the
/// robot starts on one side and must reach a goal disc beyond the door. Declared in
/// lib/tasks/src/task_doorway.c (tasks_doorway_decl); this header holds its specification and
/// the pure functions that tests and tools use by name.
///
/// Task frame (= the emulator's world frame): the room is the box [room_min_x_m, room_max_x_m] x
/// [room_min_y_m, room_max_y_m]; the dividing wall is the band |x - wall_x_m| <= wall_thickness_m
/// / 2 across the whole room, with the door's gap |y - door_y_m| < door_width_m / 2; the robot
/// starts at x < wall_x_m; the goal disc (goal_x_m, goal_y_m, goal_radius_m) lies beyond the
/// wall. The features' door frame (features/doorway.h) has its origin at (wall_x_m, door_y_m)
/// and its normal along +x.
///
/// State (features/doorway.h, 4 values): wall distance [m] (+ before the wall), lateral offset
/// from the door's centre line [m], heading relative to the wall's normal [rad], distance to the
/// nearer jamb [m]. Reward: goal_reward (+1) when the robot's centre is in the goal disc (the run
/// ends), collision_reward (-1) on a contact with any wall (the run ends; the penalty takes
/// precedence), 0 otherwise; the step limit stops a run without a terminal state. Constant
/// translation speed v_mps; the action is the rotation velocity in [-omega_max, omega_max].
///
/// Everything here is pure, no allocation, O(1) unless stated.
#ifndef B21R_TASKS_DOORWAY_H
#define B21R_TASKS_DOORWAY_H

#include <stdint.h>

#include "features/doorway.h"
#include "features/scan.h"
#include "rng/rng.h"
#include "tasks/tasks.h"

#ifdef __cplusplus
extern "C" {
#endif

/// Discount of the doorway task: runs take about 100-150 steps, and 0.95^120 = 0.002 keeps the
/// value of a start far enough from zero for the value model to tell actions apart.
#define TASKS_DOORWAY_GAMMA 0.95

/// Proportional-gain range of the example policy, drawn uniformly per run [1/s].
#define TASKS_PROPORTIONAL_DOORWAY_GAIN_MIN 1.0
#define TASKS_PROPORTIONAL_DOORWAY_GAIN_MAX 2.0

/// The example policy's staging distance [m]: it heads for the point this far before the door on
/// the door's centre line, then (once no farther from the wall) for the goal.
#define TASKS_DOORWAY_EXAMPLE_APPROACH_M 1.5

/// Doorway-passing task. Defaults (tasks_doorway_spec_default) in brackets.
typedef struct tasks_doorway_spec {
  double room_min_x_m;      ///< the room's walls (an axis-aligned box) [-4.5]
  double room_max_x_m;      ///< [3.0]
  double room_min_y_m;      ///< [-3.0]
  double room_max_y_m;      ///< [3.0]
  double wall_x_m;          ///< the dividing wall's centre plane x = wall_x_m [0.0]
  double wall_thickness_m;  ///< [0.1]
  double door_y_m;          ///< centre of the door's gap along the wall [0.0]
  double door_width_m;      ///< gap width, jamb to jamb [1.0] (the B21r is 0.52 m across)
  double goal_x_m;          ///< goal disc centre, beyond the wall [1.5]
  double goal_y_m;          ///< [0.0]
  double goal_radius_m;     ///< goal reached when the robot centre is within this [0.3]
  double robot_radius_m;    ///< collision radius [TASKS_B21R_RADIUS_M]
  double v_mps;             ///< constant translation speed [0.4]
  double omega_max_radps;   ///< action bound [1.0]
  double dt_s;              ///< control period [0.1]
  uint32_t step_limit;      ///< a run stops after this many steps [500]
  double goal_reward;       ///< [+1]
  double collision_reward;  ///< [-1]
  double gamma;             ///< [TASKS_DOORWAY_GAMMA]
  /// The ten evaluation start poses, task frame: 2.0-3.5 m before the wall, offsets up to 1.8 m
  /// to either side of the door's centre line, headings from facing the wall straight to 0.9
  /// rad off it, towards the door and away from it, so that each pose asks for a different
  /// approach (computed from the door's default position).
  features_pose_t eval_starts[TASKS_N_EVAL_STARTS];
  double train_jitter_x_m;        ///< training-start jitter, as for the other tasks [0.3]
  double train_jitter_y_m;        ///< [0.3]
  double train_jitter_theta_rad;  ///< [0.3]
} tasks_doorway_spec_t;

/// Fills spec with the defaults documented on each field. O(1).
void tasks_doorway_spec_default(tasks_doorway_spec_t* spec);

/// The feature-extractor configuration matching spec (door position, width, wall thickness;
/// laser mount and tolerances left at their defaults). O(1).
void tasks_doorway_features_config(const tasks_doorway_spec_t* spec, features_doorway_config_t* cfg);

/// Evaluation start pose `index` (taken modulo TASKS_N_EVAL_STARTS), task frame.
features_pose_t tasks_doorway_eval_start(const tasks_doorway_spec_t* spec, uint32_t index);

/// A training start near evaluation pose `index` (modulo TASKS_N_EVAL_STARTS): jittered within
/// the jitter box, never the evaluation pose itself, at least robot_radius + 0.1 m clear of every
/// wall and on the robot's side of the dividing wall (the other tasks' rule). Bounded draws.
features_pose_t tasks_doorway_training_start_near(const tasks_doorway_spec_t* spec, uint32_t index, rng_t* rng);

/// 1 when a disc of radius_m at (x, y) overlaps a wall of the spec's world (the room's walls or
/// the dividing wall's solid). O(1).
int tasks_doorway_disc_collides(const tasks_doorway_spec_t* spec, double x_m, double y_m, double radius_m);

/// Reward and termination for the transition into state f_next: contact -> collision_reward,
/// terminal (takes precedence); f_next->valid and the robot's centre (from the features' door
/// frame) within goal_radius_m of the goal -> goal_reward, terminal; otherwise 0, with STEP_LIMIT
/// as for the other tasks.
tasks_outcome_t tasks_doorway_outcome(const tasks_doorway_spec_t* spec, const features_doorway_t* f_next,
                                      uint8_t contact, uint32_t steps_taken);

/// The robot's distance to the goal from the features' door frame [m]. O(1).
double tasks_doorway_goal_distance(const tasks_doorway_spec_t* spec, const features_doorway_t* f);

/// Bearing of the goal from the features' door frame, robot frame [rad]. O(1).
double tasks_doorway_goal_bearing(const tasks_doorway_spec_t* spec, const features_doorway_t* f);

/// The driver's rotation command for the doorway task [rad/s], within [-omega_max, omega_max].
/// PROPORTIONAL (the sloppy example, law = {gain of the run, staging distance, unused}): while
/// the robot is farther from the wall than the staging distance it steers at the staging point
/// on the door's centre line, then at the goal: omega = gain * bearing of the target. It reaches
/// the goal from most starts, on a detour, and a low gain arrives at the staging depth off the
/// line and clips a jamb now and then. HUMAN: the same targets seen through the human model,
/// with a reflex near a jamb. OPTIMAL (law = the searched {gain, look-ahead, unused}): follows
/// the door's centre line with a look-ahead, omega = gain * (-heading - atan2(offset, look-ahead)),
/// until the robot's centre is past the wall's far face, then steers at the goal. An invalid f
/// gives 0 (human: keeps the stick). Advances the human's state.
double tasks_driver_doorway(tasks_driver_t* d, const tasks_doorway_spec_t* spec, const features_doorway_t* f);

/// The doorway task's control laws (its declaration's driver_law).
void tasks_driver_law_doorway(tasks_driver_t* d);

/// Task-specific views for code that knows the task (tests, tools): the newest features and the
/// feature configuration of a doorway episode, NULL for another task. O(1).
struct tasks_episode;
const features_doorway_t* tasks_doorway_state(const struct tasks_episode* ep);
const features_doorway_config_t* tasks_doorway_features(const struct tasks_episode* ep);

#ifdef __cplusplus
}
#endif

#endif  // B21R_TASKS_DOORWAY_H
