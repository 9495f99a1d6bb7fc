// SPDX-License-Identifier: MIT
/// tasks/tasks.h — The paper's two tasks: specifications, reward and termination, translation
/// speed policies, example drivers for phase one and the "optimal" reference controllers.
///
/// Task specifications are plain data with SI units; the emulator builds its worlds from them,
/// the firmware takes goal conditions, start poses and speeds from them, and the tests drive the
/// same numbers. Frames:
/// - Corridor frame (see features/corridor.h): x along the corridor from the start wall (x = 0)
///   to the end wall (x = length_m), y lateral, 0 on the centre line, + to the left.
/// - Arena frame (obstacle task): the goal is at (goal_x_m, goal_y_m) (default the origin),
///   obstacles are vertical cylinders, the arena is bounded by four walls.
///
/// Everything here is pure or works on caller-owned state; no allocation, no I/O, O(1) per call
/// unless stated. Randomness comes only from rng_t instances seeded by the caller.
#ifndef B21R_TASKS_TASKS_H
#define B21R_TASKS_TASKS_H

#include <stdint.h>

#include "features/features.h"
#include "rng/rng.h"

#ifdef __cplusplus
extern "C" {
#endif


/// Number of fixed evaluation start poses per task (paper: "ten pre-specified starting poses").
#define TASKS_N_EVAL_STARTS 10
/// Obstacle capacity of the obstacle-task specification.
#define TASKS_MAX_OBSTACLES 4
/// Q-learning constants of the paper (§V): learning rate for both tasks, discount per task.
#define TASKS_ALPHA 0.2
#define TASKS_CORRIDOR_GAMMA 0.99
#define TASKS_OBSTACLES_GAMMA 0.9
/// B21r footprint radius used for collision geometry [m] (base skirt, protocols.md C).
#define TASKS_B21R_RADIUS_M 0.26

/// Why a run ends (or not) after a step.
typedef enum tasks_end_reason {
  TASKS_END_NONE = 0,        ///< the run continues
  TASKS_END_GOAL = 1,        ///< goal reached: terminal (absorbing) state
  TASKS_END_COLLISION = 2,   ///< contact with a wall or obstacle: terminal (absorbing) state
  TASKS_END_STEP_LIMIT = 3,  ///< step limit reached: the run stops, but the state is NOT terminal
                             ///< for learning (bootstrap from s' as usual)
} tasks_end_reason_t;

/// Reward and termination of one transition (s_t, a_t) -> s_{t+1}.
typedef struct tasks_outcome {
  double reward;    ///< r_{t+1}
  uint8_t terminal; ///< 1: s_{t+1} is absorbing (goal or collision): no bootstrap, run ends
  uint8_t end_run;  ///< 1: the run ends after this step (terminal, or step limit)
  uint8_t reason;   ///< tasks_end_reason_t
} tasks_outcome_t;

/// A circular obstacle (a vertical cylinder in the emulator).
typedef struct tasks_circle {
  double x_m;       ///< centre, arena frame [m]
  double y_m;       ///< [m]
  double radius_m;  ///< [m], > 0
} tasks_circle_t;

// ---------------------------------------------------------------------------------------------
// Corridor following (paper §V-A)
// ---------------------------------------------------------------------------------------------

/// Corridor-following task. Defaults (tasks_corridor_spec_default) in brackets.
typedef struct tasks_corridor_spec {
  double length_m;         ///< start wall to end wall [10.0] (the paper's simulated 10 m corridor)
  double width_m;          ///< wall to wall [2.0]
  double goal_distance_m;  ///< goal when end_distance_m <= this [1.0] (robot centre to end wall)
  double robot_radius_m;   ///< collision radius [TASKS_B21R_RADIUS_M]
  double v_centre_mps;     ///< translation speed on the centre line [0.6]
  double v_wall_mps;       ///< translation speed when touching a wall [0.2]
  double omega_max_radps;  ///< action bound: omega in [-omega_max, omega_max] [1.0]
  double dt_s;             ///< control period [0.1] (10 Hz)
  uint32_t step_limit;     ///< a run stops after this many steps [1000]
  double goal_reward;      ///< reward at the end of the corridor [10.0]
  double gamma;            ///< discount [TASKS_CORRIDOR_GAMMA]
  double lookahead_m;      ///< target-point look-ahead L of the state's angle [2.0]
  /// The ten fixed evaluation start poses (robot centre in the corridor frame). Defaults: x in
  /// [0.8, 1.6] m, |y| <= 0.5 m, heading within +-1.0 rad of the corridor axis, spread over
  /// left/right offsets and headings so that each pose needs a different correction.
  features_pose_t eval_starts[TASKS_N_EVAL_STARTS];
  /// Training starts: a uniformly chosen evaluation pose moved by a uniform offset within
  /// +-jitter (x, y, heading), at least min_jitter (normalised by jitter, see
  /// tasks_corridor_training_start) away from it: "similar to, but not the same as" [0.3 m,
  /// 0.2 m, 0.25 rad].
  double train_jitter_x_m;
  double train_jitter_y_m;
  double train_jitter_theta_rad;
} tasks_corridor_spec_t;

/// Fills spec with the defaults documented on each field. O(1).
void tasks_corridor_spec_default(tasks_corridor_spec_t* spec);

/// The feature-extractor configuration matching spec (width, length, look-ahead; laser mount and
/// filtering left at their defaults). O(1).
void tasks_corridor_features_config(const tasks_corridor_spec_t* spec,
                                    features_corridor_config_t* cfg);

/// Evaluation start pose `index` (0..TASKS_N_EVAL_STARTS-1; other values are taken modulo 10).
features_pose_t tasks_corridor_eval_start(const tasks_corridor_spec_t* spec, uint32_t index);

/// Lower bound on the steps any policy needs from `start` to the goal (end_distance_m <=
/// goal_distance_m), from kinematics alone: the robot runs at v_centre_mps from the first step
/// (no acceleration limit, no slow-down near a wall) and turns toward the corridor's axis at
/// omega_max_radps, each step advancing as if its heading were already the turned one. Every
/// constraint is relaxed, so no policy on the emulated or the real base does better (sensing
/// noise aside: the goal is declared from laser features). Used to check the "optimal"
/// reference controller. Returns 0 when start is already at the goal. O(returned steps).
uint32_t tasks_corridor_steps_lower_bound(const tasks_corridor_spec_t* spec, features_pose_t start);

/// A training start pose: evaluation pose k (uniform) plus a uniform offset in the jitter box,
/// redrawn until its normalised size max(|dx|/jx, |dy|/jy, |dth|/jth) is >= 0.25 (never the
/// evaluation pose itself) and the robot stays at least robot_radius + 0.1 m from the walls.
/// Consumes a bounded number of draws (at most 64 attempts; then the last attempt is clamped
/// into the corridor). Deterministic given the rng state.
features_pose_t tasks_corridor_training_start(const tasks_corridor_spec_t* spec, rng_t* rng);

/// As tasks_corridor_training_start, around the given evaluation pose (index modulo
/// TASKS_N_EVAL_STARTS) instead of a uniformly drawn one (see tasks_start_cycle_next).
features_pose_t tasks_corridor_training_start_near(const tasks_corridor_spec_t* spec, uint32_t index,
                                                   rng_t* rng);

/// Reward and termination of the corridor task for the transition into state f_next:
/// - contact (bumper / emulator contact) -> reward 0, terminal (COLLISION): the paper's corridor
///   reward has no penalty; the run cannot continue, so the state is absorbing with value 0;
/// - f_next->valid and f_next->end_distance_m <= goal_distance_m -> goal_reward (10), terminal;
///   (goal takes precedence over a simultaneous contact)
/// - otherwise 0; end_run with STEP_LIMIT when steps_taken >= step_limit (steps_taken counts the
///   actions executed in this run including this one; step_limit 0 = no limit).
tasks_outcome_t tasks_corridor_outcome(const tasks_corridor_spec_t* spec,
                                       const features_corridor_t* f_next, uint8_t contact,
                                       uint32_t steps_taken);

/// Translation speed policy of the corridor task ("fast in the middle, slower near a wall"):
///   q = min(1, |2 f - 1| / (1 - 2 r / W)),   v = v_wall + (v_centre - v_wall) (1 - q^2)
/// with f = lateral_frac, r = robot_radius_m, W = width_m: v_centre on the centre line, falling
/// quadratically to v_wall where the robot's edge touches a wall (0.6 -> 0.2 m/s by default;
/// 0.55 m/s at 0.25 m off centre, 0.42 m/s at 0.5 m). An invalid f gives v_wall. O(1).
double tasks_corridor_speed_mps(const tasks_corridor_spec_t* spec, const features_corridor_t* f);

// ---------------------------------------------------------------------------------------------
// Obstacle avoidance (paper §V-B)
// ---------------------------------------------------------------------------------------------

/// Obstacle-avoidance task. Defaults (tasks_obstacles_spec_default) in brackets.
typedef struct tasks_obstacles_spec {
  double goal_x_m;          ///< goal position, arena frame [0.0]
  double goal_y_m;          ///< [0.0]
  double goal_radius_m;     ///< goal reached when the robot centre is within this [0.3]
  uint32_t n_obstacles;     ///< obstacles in use [1]
  tasks_circle_t obstacles[TASKS_MAX_OBSTACLES];  ///< [one: centre (-1.5, 0), radius 0.25 m]
  double arena_min_x_m;     ///< arena walls (an axis-aligned box) [-5.0]
  double arena_max_x_m;     ///< [2.0]
  double arena_min_y_m;     ///< [-3.5]
  double arena_max_y_m;     ///< [3.5]
  double robot_radius_m;    ///< collision radius [TASKS_B21R_RADIUS_M]
  double v_mps;             ///< constant translation speed [0.3]
  double omega_max_radps;   ///< action bound [1.0]
  double dt_s;              ///< control period [0.1]
  uint32_t step_limit;      ///< a run stops after this many steps [500]
  double goal_reward;       ///< [+1]
  double collision_reward;  ///< [-1]
  double gamma;             ///< [TASKS_OBSTACLES_GAMMA]
  /// The ten evaluation start poses: about 3 m from the goal (2.8..3.2 m), on the far side of
  /// the obstacle (bearing from the goal within +-35° of the -x axis), headings within +-0.6
  /// rad of the direction to the goal. Most straight-line paths pass the obstacle closely.
  features_pose_t eval_starts[TASKS_N_EVAL_STARTS];
  double train_jitter_x_m;       ///< training-start jitter, as for the corridor [0.3]
  double train_jitter_y_m;       ///< [0.3]
  double train_jitter_theta_rad; ///< [0.3]
  /// How long the state remembers the nearest obstacle after it left the laser's view [s]
  /// (features_obstacles_remember; rounded to whole control periods; 0 = no memory) [3.0]: at
  /// 0.3 m/s the robot has moved 0.9 m past it by then.
  double memory_s;
} tasks_obstacles_spec_t;

/// Fills spec with the defaults documented on each field. O(1).
void tasks_obstacles_spec_default(tasks_obstacles_spec_t* spec);

/// The feature-extractor configuration matching spec: defaults, with the memory's age limit
/// memory_s / dt_s control periods (rounded; 0 when memory_s or dt_s is not positive). O(1).
void tasks_obstacles_features_config(const tasks_obstacles_spec_t* spec,
                                     features_obstacles_config_t* cfg);

/// Evaluation start pose `index` (taken modulo TASKS_N_EVAL_STARTS), arena frame.
features_pose_t tasks_obstacles_eval_start(const tasks_obstacles_spec_t* spec, uint32_t index);

/// A training start pose near a uniformly chosen evaluation pose (same rule as the corridor:
/// jittered, never identical, at least robot_radius + 0.1 m clear of obstacles and walls).
features_pose_t tasks_obstacles_training_start(const tasks_obstacles_spec_t* spec,
                                               rng_t* rng);

/// As tasks_obstacles_training_start, around the given evaluation pose (index modulo
/// TASKS_N_EVAL_STARTS).
features_pose_t tasks_obstacles_training_start_near(const tasks_obstacles_spec_t* spec, uint32_t index,
                                                    rng_t* rng);

/// Stratified choice of the evaluation pose a training start is jittered around: each cycle of
/// TASKS_N_EVAL_STARTS training runs visits every pose once, in an order shuffled per cycle, so
/// that after n runs every pose has had floor(n / 10) nearby starts (a uniform draw leaves a pose
/// without any nearby start in 30 runs with probability 0.04, and one of ten with 0.35). Plain
/// data; zero-initialise, then call tasks_start_cycle_next for every training run. O(10).
typedef struct tasks_start_cycle {
  uint8_t order[TASKS_N_EVAL_STARTS];  ///< this cycle's order
  uint32_t next;                       ///< position in order; TASKS_N_EVAL_STARTS or 0 after init = reshuffle
  uint8_t started;                     ///< 0 until the first shuffle
} tasks_start_cycle_t;

/// The evaluation-pose index of the next training start (see tasks_start_cycle_t); consumes
/// TASKS_N_EVAL_STARTS - 1 draws of rng at the start of each cycle, none otherwise.
uint32_t tasks_start_cycle_next(tasks_start_cycle_t* cycle, rng_t* rng);

/// Reward and termination of the obstacle task for the transition into state f_next:
/// contact -> collision_reward (-1), terminal (takes precedence); f_next->valid and
/// goal_distance_m <= goal_radius_m -> goal_reward (+1), terminal; otherwise 0, with STEP_LIMIT
/// as for the corridor.
tasks_outcome_t tasks_obstacles_outcome(const tasks_obstacles_spec_t* spec,
                                        const features_obstacles_t* f_next, uint8_t contact,
                                        uint32_t steps_taken);

/// Translation speed of the obstacle task: the constant v_mps. O(1).
double tasks_obstacles_speed_mps(const tasks_obstacles_spec_t* spec);

/// Clamps a rotation command to [-omega_max, omega_max]; non-finite input gives 0. O(1).
double tasks_clamp_omega(double omega_radps, double omega_max_radps);

// ---------------------------------------------------------------------------------------------
// Drivers: example policies for phase one, and the "optimal" reference
// ---------------------------------------------------------------------------------------------

/// Kind of driver.
typedef enum tasks_driver_kind {
  /// The paper's "simple policy": omega = k * theta, k drawn per run (uniform in the task's gain
  /// range, see tasks_driver_begin_run in tasks/decl.h). Corridor: theta = target_angle_rad. Obstacles: theta =
  /// goal bearing bent away from a near obstacle (see tasks_driver_obstacles).
  TASKS_DRIVER_PROPORTIONAL = 0,
  /// A simulated person with a joystick: reaction delay (0.3..0.8 s), a dead band (ignores small
  /// errors, then corrects late and too hard), coarse stick positions held for a while, hand
  /// noise, slow drift, lapses of attention, personal preferences (corridor: a favourite
  /// lateral offset and aim point; obstacles: a wide personal clearance and sometimes passing on
  /// the far side), and a reflex when a collision looks imminent. Per-run temperament drawn from
  /// the seed. Reaches the goal, far less directly and far less predictably.
  TASKS_DRIVER_HUMAN = 1,
  /// The best controller found for the task (the paper's "optimal" line): the task's control
  /// law (see law[] in tasks_driver_t) with constants from a grid search in the synthetic world
  /// (test/unit/tasks/tasks_optimal_search.c: fewest mean steps to the goal from the ten
  /// evaluation starts, three sensor-noise seeds, no failure, the robot's edge never closer than
  /// 0.10 m to a wall or obstacle). Deterministic.
  TASKS_DRIVER_OPTIMAL = 2,
} tasks_driver_kind_t;

/// Capacity of the human driver's reaction-delay line [steps].
#define TASKS_HUMAN_MAX_DELAY 16

/// Number of parameters of a driver's control law.
#define TASKS_DRIVER_LAW_PARAMS 3

/// A driver's complete state; caller-owned, plain data (copyable), about 360 bytes.
/// Set up with tasks_driver_begin_run (tasks/decl.h) at the start of every run.
typedef struct tasks_driver {
  uint8_t kind;             ///< tasks_driver_kind_t
  uint8_t task;             ///< the task's id (tasks_decl_t.id)
  double omega_max_radps;   ///< output bound
  double gain;              ///< proportional gain of this run [1/s] (PROPORTIONAL, HUMAN)
  /// Control-law parameters. Corridor (used by OPTIMAL): {gain [1/s], look-ahead [m], unused}:
  /// omega = gain * (-heading - atan2(offset, look-ahead)). Obstacles (all kinds): {gain [1/s], clearance [m],
  /// avoidance range [m]} of the bent goal-seeking law (see tasks_driver_obstacles). begin_run
  /// sets them (OPTIMAL: the searched constants); a parameter search may overwrite them.
  double law[TASKS_DRIVER_LAW_PARAMS];
  int8_t avoid_side;        ///< side chosen to pass the obstacle: +1 left, -1 right, 0 none
  uint32_t pass_steps;      ///< steps left to hold course after the obstacle left the view
  rng_t rng;          ///< the driver's private stream (human noise)
  // Human temperament of this run (drawn in begin_run).
  uint32_t delay_steps;     ///< reaction delay [steps], < TASKS_HUMAN_MAX_DELAY
  double deadband_rad;      ///< errors below this are ignored while not correcting [rad]
  double release_rad;       ///< a correction stops when the error falls below this [rad]
  double noise_radps;       ///< stick noise standard deviation [rad/s]
  double drift_radps;       ///< slow wander amplitude [rad/s]
  double lapse_prob;        ///< chance per step of starting a lapse of attention
  double pref_offset_m;     ///< corridor: the lateral offset the person likes to drive at [m]
  double pref_lookahead_m;  ///< corridor: how far ahead the person aims [m]
  int8_t side_pref;         ///< obstacles: +1 pass on the goal's side, -1 on the far side
  // Human state.
  double delay_line[TASKS_HUMAN_MAX_DELAY];  ///< perceived error, delayed
  uint32_t head;            ///< next write position in delay_line
  uint32_t steps;           ///< steps since begin_run
  double stick_radps;       ///< current stick command
  double drift_state;       ///< current drift value [rad/s]
  uint32_t hold_steps;      ///< remaining steps the stick is held
  uint32_t lapse_steps;     ///< remaining steps of a lapse (no corrections, the hand relaxes)
  uint8_t correcting;       ///< 1 while a correction is in progress
} tasks_driver_t;

/// Proportional-gain ranges of the example policy, drawn uniformly per run [1/s].
#define TASKS_PROPORTIONAL_CORRIDOR_GAIN_MIN 0.5
#define TASKS_PROPORTIONAL_CORRIDOR_GAIN_MAX 2.0
#define TASKS_PROPORTIONAL_OBSTACLES_GAIN_MIN 0.8
#define TASKS_PROPORTIONAL_OBSTACLES_GAIN_MAX 2.0

/// The common start of a driver's run (tasks_episode_driver_begin calls it, then the task's
/// law and, for a person, tasks_driver_begin_human and the task's own temperament): sets kind,
/// the task's id and the bound (a non-finite or non-positive omega_max gives 1.0), seeds the
/// private stream with run_seed and draws the run's gain uniformly in [gain_min, gain_max] for
/// every kind, so that the streams of the kinds stay comparable. An invalid kind is PROPORTIONAL.
void tasks_driver_begin_common(tasks_driver_t* d, tasks_driver_kind_t kind, uint8_t task_id, double omega_max_radps,
                               uint64_t run_seed, double gain_min, double gain_max);

/// A simulated person's temperament for this run (HUMAN): gain, reaction delay, dead band,
/// hand noise, drift, lapses, a favourite offset, aim distance and side. Draws from d->rng.
void tasks_driver_begin_human(tasks_driver_t* d);

/// The simulated person's hand for one step: `error` is what the person tries to null (an angle,
/// +: turn left), seen after the reaction delay and through the dead band, with coarse stick
/// positions held a while, hand noise, drift and lapses; `danger` (a collision looks imminent)
/// cuts a lapse short and forces a correction after 0.1 s. Any task's HUMAN driver uses it.
/// Returns the stick command [rad/s] within the bound. Advances the person's state. O(1).
double tasks_driver_human_step(tasks_driver_t* d, double error, int danger);

/// The corridor's and the obstacle task's control laws and the obstacle task's temperament
/// (their declarations' driver_law / driver_human).
void tasks_driver_law_corridor(tasks_driver_t* d);
void tasks_driver_law_obstacles(tasks_driver_t* d);
void tasks_driver_human_obstacles(tasks_driver_t* d);

/// The driver's rotation command for the corridor task given this tick's state [rad/s], within
/// [-omega_max, omega_max], finite. PROPORTIONAL: gain * target_angle_rad (the paper's simple
/// policy). OPTIMAL: the law above with the searched constants. HUMAN: the angle to the
/// person's own aim point (favourite offset, own look-ahead) seen through the human model. An invalid f (valid = 0) gives 0 (hold course) for the proportional
/// and optimal drivers; the human keeps the stick. Advances the human's state.
double tasks_driver_corridor(tasks_driver_t* d, const features_corridor_t* f);

/// Steps the obstacle drivers' law holds course after the obstacle it was avoiding slipped out of
/// the laser's view beside the robot (1 s at 10 Hz): the LMS200 sees 180° forward from 0.15 m ahead
/// of the centre, so an obstacle being passed leaves its view while the skirt is still centimetres
/// from it, and turning to the goal at once would clip it. The controller's learned policy holds
/// the same way (obstacle_pass_hold_steps, fw_pass_hold_observe).
#define TASKS_OBSTACLES_PASS_HOLD_STEPS 10U

/// Half-angle of the cone around an obstacle at distance_m [m, robot centre to its nearest
/// return] that a course must stay outside to pass it clearance_m away [rad]:
/// asin(clearance_m / distance_m), or pi/2 at or within the clearance. The obstacle drivers' law
/// (below) bends toward its edge. Pure, O(1).
double tasks_obstacles_cone_half_angle_rad(double clearance_m, double distance_m);

/// The driver's rotation command for the obstacle task [rad/s]. The law: theta = goal bearing,
/// bent away from the nearest obstacle when it is visible, nearer than law[2] (the avoidance
/// range) and nearer than the goal, and the goal direction passes it closer than law[1] (the
/// clearance): then theta is the edge of the cone of half-angle asin(clearance / distance)
/// around the obstacle's bearing. The side is chosen once per encounter: the side of least
/// turning when the obstacle is off to one side, the goal's side when it is nearly dead ahead;
/// it is kept while avoiding (no dithering), and when the obstacle leaves the field of view
/// beside the robot the course is held for 1 s before turning to the goal (it is still there).
/// omega = law[0] * theta.
/// PROPORTIONAL: law = {gain of the run, 0.55 m, 1.5 m}. HUMAN: the same target, with a wide
/// personal clearance, seen through the human model. OPTIMAL: the searched constants. Invalid f
/// gives 0 (human: keeps the stick).
double tasks_driver_obstacles(tasks_driver_t* d, const features_obstacles_t* f);

#ifdef __cplusplus
}
#endif

#endif  // B21R_TASKS_TASKS_H
