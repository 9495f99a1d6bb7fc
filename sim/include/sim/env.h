// SPDX-License-Identifier: MIT
/// sim/env.h — Any declared task (tasks/decl.h) as a step-by-step environment (reset / step),
/// the C core of the Python environments (B21rCorridor-v0, B21rObstacles-v0, ... one per
/// declaration: tools/python/b21r_learn).
///
/// One step = one control period (the task's dt_s, 0.1 s): the action (rotation velocity
/// [rad/s]) and the task's translation speed are clamped exactly as the controller clamps its
/// commands (tasks_command_clamp: velocity limits, then acceleration limits against the previous
/// command), the robot moves for one period, and the new state, reward and termination come from
/// lib/tasks (tasks_episode_*), as in the controller's tick. Two back-ends:
///
/// - SIM_ENV_ODE: the emulated B21r of sim/emulator.h in lockstep, spoken to over the real byte
///   protocols: the rFLEX command pair (velocities quantised to counts, rflex_make_velocity),
///   the ODE plant with contacts, the ray-cast LMS200 with its range noise and millimetre
///   telegrams, rFLEX odometry reports integrated by rflex_odom_update, bump panels over DIO.
///   The state is the task's features of the decoded scan at the odometry pose: what the
///   controller sees. A reset reproduces the controller's own
///   sequence between runs (a zero-command period ending the previous run, the robot placed at
///   the start pose, a zero-command period, then the first state), so that, with the emulator
///   seeded alike, an episode is step for step the controller's run from the same start pose
///   with the same actions (test/python/test_env_equivalence.py).
///   Cost per step: one emulator period (10 ODE substeps, a 181-beam ray cast, telegram encoding
///   and decoding) plus the features; see the env benchmark (test/bench/python) for numbers.
/// - SIM_ENV_KINEMATIC: the idealised model of sim/kinematic.h (the same per-substep update as
///   the plant in free space, no contacts, no quantisation, no sensor), with the exact state of
///   the true pose (tasks_episode_observe_pose) and the collision test of the world's geometry
///   (sim_world_disc_collides). For long studies: about a microsecond per step.
///
/// Frames and units: SI, the task frame of tasks/tasks.h (which is the emulator's world frame:
/// the worlds are built from the task specs, sim/task_worlds.h).
///
/// Seeds: sim_env_seed(seed) seeds everything: the ODE back-end's emulator gets `seed` itself (so
/// an episode can be compared with the controller against `b21r-sim --seed <seed>`), and the
/// training-start sampler a stream derived from it. Same seed + same calls = identical results.
///
/// Memory: sim_env_create allocates the environment (about 25 KiB) and, for the ODE back-end,
/// the emulator (sim_emu_create); sim_env_seed re-creates the emulator. Steps allocate nothing
/// of their own (ODE reuses its step arena). Not thread-safe: one thread per environment (ODE's
/// collision data is per thread); distinct environments are independent.
#ifndef B21R_SIM_ENV_H
#define B21R_SIM_ENV_H

#include <stddef.h>
#include <stdint.h>

#include <features/features.h>
#include <tasks/episode.h>
#include <tasks/tasks.h>

#include "sim/world.h"

#ifdef __cplusplus
extern "C" {
#endif

/// Dynamics and sensing back-end.
typedef enum sim_env_backend {
  SIM_ENV_ODE = 0,        ///< the emulated B21r over its protocols (what the controller sees)
  SIM_ENV_KINEMATIC = 1,  ///< the idealised kinematic model with the exact state
} sim_env_backend_t;

/// Status of the sim_env functions. Failed calls leave the environment unchanged.
typedef enum sim_env_status {
  SIM_ENV_OK = 0,
  SIM_ENV_ERR_INVALID_ARG = 2,  ///< NULL, a bad configuration, a non-finite action or pose, a start
                                ///< pose that overlaps a wall or obstacle
  SIM_ENV_ERR_STATE = 3,        ///< step before the first reset or after the episode ended
  SIM_ENV_ERR_DEVICE = 4,       ///< the emulator sent no scan or odometry for a period (a defect)
  SIM_ENV_ERR_NO_MEMORY = 5,    ///< the emulator could not be created
} sim_env_status_t;

/// Where an episode starts.
typedef enum sim_env_start {
  SIM_ENV_START_TRAINING = 0,  ///< a training start drawn from the seeded sampler (tasks_*_training_start)
  SIM_ENV_START_EVAL = 1,      ///< evaluation start pose `eval_index` (0..9) of the task spec
  SIM_ENV_START_POSE = 2,      ///< the given pose (task frame)
} sim_env_start_t;

/// Configuration. Defaults (sim_env_config_default) in brackets.
typedef struct sim_env_config {
  const tasks_decl_t* task;           ///< the declared task [as given]
  sim_env_backend_t backend;          ///< [as given]
  /// the task's specification, task->spec_size bytes [task->spec_default]; set its parameters
  /// with tasks_spec_set_param
  double spec[TASKS_SPEC_BYTES / sizeof(double)];
  tasks_command_limits_t limits;      ///< command clamp [tasks_command_limits_default]; its
                                      ///< max_rotation_radps is also the action range (written
                                      ///< into the spec's omega_max_radps, as the controller does)
  double laser_noise_sigma_m;         ///< ODE: LMS200 range noise, standard deviation [0.005]
  double laser_error_code_prob;       ///< ODE: per-beam probability of a dazzle/SNR code [0]
} sim_env_config_t;

/// One step's result.
typedef struct sim_env_transition {
  double state[TASKS_MAX_STATE_DIM];  ///< s_{t+1}, state_dim values
  double reward;                      ///< r_{t+1}
  uint8_t terminated;                 ///< goal or collision: absorbing
  uint8_t truncated;                  ///< the step limit ended the episode (or an unusable state, see state_ok)
  uint8_t reason;                     ///< tasks_end_reason_t
  uint8_t contact;                    ///< the bumper (ODE) or the collision test (kinematic) fired
  uint8_t state_ok;                   ///< 0: the features gave no usable state (never seen with the
                                      ///< emulator's worlds); the episode is then truncated
  double action_radps;                ///< rotation actually commanded (after the clamp)
  double translation_mps;             ///< translation actually commanded
  uint32_t steps;                     ///< actions executed in this episode, this one included
} sim_env_transition_t;

/// Ground truth and what the controller would know.
typedef struct sim_env_truth {
  features_pose_t pose;       ///< true pose of the robot centre, task frame
  features_pose_t odom_pose;  ///< odometry mapped into the task frame (ODE; = pose for kinematic)
  double v_mps;               ///< translation axis velocity
  double omega_radps;         ///< rotation axis velocity
  uint8_t collided;           ///< touched a wall or obstacle since the episode's start
  double time_s;              ///< simulated time since the last sim_env_seed
} sim_env_truth_t;

typedef struct sim_env sim_env_t;

/// Fills cfg with the defaults documented above for task and backend. O(1).
void sim_env_config_default(sim_env_config_t* cfg, const tasks_decl_t* task, sim_env_backend_t backend);

/// Creates an environment, seeded with 0 (sim_env_seed). Returns NULL on an invalid
/// configuration or out of memory, with a message in err (if err_cap > 0).
sim_env_t* sim_env_create(const sim_env_config_t* cfg, char* err, size_t err_cap);
void sim_env_destroy(sim_env_t* env);

/// Re-seeds: a fresh emulator seeded with `seed` (ODE), the start sampler reseeded. The next
/// reset starts from a robot just powered up. O(world) for ODE (allocates), O(1) otherwise.
sim_env_status_t sim_env_seed(sim_env_t* env, uint64_t seed);

/// Starts an episode (see the file comment for the ODE back-end's sequence) and writes the first
/// state to state[0..state_dim). eval_index is used with SIM_ENV_START_EVAL (taken modulo 10),
/// pose with SIM_ENV_START_POSE. Errors: INVALID_ARG (NULL, bad start kind, non-finite pose or
/// one whose disc overlaps the world), DEVICE. Cost: up to two periods (ODE).
sim_env_status_t sim_env_reset(sim_env_t* env, sim_env_start_t start, uint32_t eval_index,
                               features_pose_t pose, double* state);

/// One control period with rotation command omega_radps (clamped as documented above).
/// Errors: INVALID_ARG (NULL, non-finite action), STATE (no reset yet, or the episode already
/// ended), DEVICE. No allocation. Cost: see the file comment.
sim_env_status_t sim_env_step(sim_env_t* env, double omega_radps, sim_env_transition_t* out);

/// The example drivers of lib/tasks on this environment: the driver's action for the newest
/// state (tasks_episode_driver_action; advances the driver's state). O(1).
double sim_env_driver_action(const sim_env_t* env, tasks_driver_t* driver);

/// Ground truth of the robot now. O(1).
void sim_env_get_truth(const sim_env_t* env, sim_env_truth_t* out);

/// The laser's view for drawing: n ranges [m] of beams at bearings angle_min + i * increment
/// (laser frame, mount at the task's features configuration), NaN where a beam has no return.
/// ODE: the newest decoded scan; kinematic: a noise-free ray cast from the true pose
/// (sim_world_raycast, 181 beams over 180°). Returns the number written (<= cap). O(n * world).
size_t sim_env_laser_view(sim_env_t* env, double* angle_min_rad, double* increment_rad, double* ranges_m,
                          size_t cap);

/// The world (walls, cylinders, goal), the task (specs, features of the newest state) and the
/// configuration in use. Owned by the environment. O(1).
const sim_world_t* sim_env_world(const sim_env_t* env);
const tasks_episode_t* sim_env_episode(const sim_env_t* env);
const sim_env_config_t* sim_env_get_config(const sim_env_t* env);

/// Bounds of every state component (low[i] <= state[i] <= high[i] for every state the
/// environment can produce), state_dim values each. O(1).
void sim_env_state_bounds(const sim_env_t* env, double* low, double* high);

/// A constant English description of a status. Never NULL.
const char* sim_env_status_str(sim_env_status_t status);

#ifdef __cplusplus
}
#endif

#endif  // B21R_SIM_ENV_H
