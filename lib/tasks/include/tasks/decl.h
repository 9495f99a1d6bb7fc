// SPDX-License-Identifier: MIT
/// tasks/decl.h — A task as one declaration: its specification (with named parameters), its
/// features, state scales and ranges, reward and termination, speed policy, start and evaluation
/// poses, the emulator's world, its example drivers and the reference controller used only to
/// evaluate. The registry lists every declared task; everything else (the controller's loop, the
/// learning framework, the trainer, the experiment runner, the emulator and the Python
/// environments) takes any task through this table, never through a task's name.
///
/// Adding a task: a file lib/tasks/src/task_<name>.c with its declaration (and the feature
/// extractor it needs in lib/features), and one line in the registry (registry.c).
///
/// The declaration's data is constant; its functions are pure (no I/O, no allocation), work on
/// caller-owned memory and are bounded (feature extraction is linear in the beams; the rest O(1)
/// or O(obstacles)). Specifications and run data live in tasks_episode_t (tasks/episode.h) as
/// blobs of at most TASKS_SPEC_BYTES / TASKS_RUN_BYTES that only the task's own code interprets.
#ifndef B21R_TASKS_DECL_H
#define B21R_TASKS_DECL_H

#include <stddef.h>
#include <stdint.h>

#include "features/features.h"
#include "rng/rng.h"
#include "tasks/tasks.h"

#ifdef __cplusplus
extern "C" {
#endif

/// Largest task state dimension (features) of any declared task.
#define TASKS_MAX_STATE_DIM 6
/// Room for a task's specification and for its run data (derived configuration, newest
/// features) in tasks_episode_t [bytes]; each task checks its own at compile time.
#define TASKS_SPEC_BYTES 1024U
#define TASKS_RUN_BYTES 768U
/// Largest number of evaluation poses (the declarations give TASKS_N_EVAL_STARTS; a
/// configuration may give up to this many of its own, tasks_episode_set_eval_starts).
#define TASKS_MAX_EVAL_STARTS 16U

struct tasks_episode;

/// A named parameter of a task's specification (a double at `offset`), settable by name.
typedef struct tasks_param {
  const char* name;   ///< e.g. "length_m"
  size_t offset;      ///< of the double in the specification struct
  double min;         ///< allowed range
  double max;
  const char* help;   ///< one line, with the unit
} tasks_param_t;

/// Where a declaration writes its world (the emulator's sim/task_worlds.c implements it):
/// SI units, the task frame. Each function returns 0, or nonzero when the world is full.
typedef struct tasks_world_sink {
  void* user;
  /// The walls of a corridor along +x from x = 0 to length_m, width_m wide, closed at the far end
  /// when end != 0 (and always at x = 0).
  int (*corridor)(void* user, double length_m, double width_m, int end);
  /// Four walls around the box [min_x, max_x] x [min_y, max_y].
  int (*arena)(void* user, double min_x, double min_y, double max_x, double max_y);
  /// A straight wall from (x0, y0) to (x1, y1), thickness_m thick (centred on the line).
  int (*wall)(void* user, double x0, double y0, double x1, double y1, double thickness_m);
  /// A vertical cylindrical obstacle.
  int (*cylinder)(void* user, double x, double y, double radius_m);
  /// The goal disc (metadata for pictures and goal tests; not an obstacle).
  int (*goal)(void* user, double x, double y, double radius_m);
  /// A start pose (the evaluation poses, in order).
  int (*start)(void* user, features_pose_t pose);
  /// The world's name ([A-Za-z0-9_.-]).
  int (*name)(void* user, const char* name);
} tasks_world_sink_t;

/// A task's declaration.
typedef struct tasks_decl {
  const char* name;         ///< the configuration's `task` value, e.g. "corridor"
  const char* title;        ///< e.g. "Corridor following"
  const char* env_id;       ///< the Gymnasium environment's id, e.g. "B21rCorridor-v0"
  uint8_t id;               ///< the messages' task byte (b21r.experience_t TASK_*): unique, stable
  uint32_t state_dim;       ///< features, 1..TASKS_MAX_STATE_DIM
  const char* const* state_names;  ///< state_dim names with their units, e.g. "end distance [m]"

  // What the learner may know besides the reward: declared scales (raw units per scaled unit),
  // the action's scale, and the learner's wider second search (hedger.h greedy_reach).
  double state_scale[TASKS_MAX_STATE_DIM];
  double action_scale;
  double greedy_reach;
  /// The declared range of each feature under spec (tabular bins, observation bounds). O(1).
  void (*state_range)(const void* spec, double* lo, double* hi);

  // The specification: its size, defaults and named parameters, and where its common fields are.
  size_t spec_size;                          ///< <= TASKS_SPEC_BYTES
  void (*spec_default)(void* spec);
  const tasks_param_t* params;               ///< n_params entries
  uint32_t n_params;
  size_t off_dt_s;                           ///< double: control period [s]
  size_t off_omega_max_radps;                ///< double: the action bound
  size_t off_step_limit;                     ///< uint32_t: a run stops after this many steps
  size_t off_gamma;                          ///< double: the discount
  size_t off_robot_radius_m;                 ///< double: collision radius
  size_t off_eval_starts;                    ///< features_pose_t[TASKS_N_EVAL_STARTS]: evaluation poses

  // A run (tasks/episode.h calls these on the episode's blobs).
  /// Derives the run data (feature configuration, neutral features) from the specification.
  void (*run_init)(struct tasks_episode* ep);
  /// Clears the features' run state at a run's start (tasks_episode_begin calls it), e.g. the
  /// obstacle task's memory of the obstacles seen; NULL when the features keep none.
  void (*run_begin)(struct tasks_episode* ep);
  /// The state from a scan at a pose in the task frame (tasks_episode_observe's contract).
  int (*observe)(struct tasks_episode* ep, const features_scan_t* scan, features_pose_t pose, double* state);
  /// The exact state at a pose (the idealised model; tasks_episode_observe_pose's contract).
  int (*observe_pose)(struct tasks_episode* ep, features_pose_t pose, double* state);
  /// Reward and termination of the transition into the newest state.
  tasks_outcome_t (*outcome)(const struct tasks_episode* ep, uint8_t contact, uint32_t steps_taken);
  /// Translation speed for the newest state [m/s].
  double (*speed_mps)(const struct tasks_episode* ep);
  /// A training start jittered around evaluation pose `index` (bounded draws from rng).
  features_pose_t (*training_start_near)(const void* spec, uint32_t index, rng_t* rng);
  /// The laser's mounting (the features' scan configuration).
  const features_laser_mount_t* (*laser_mount)(const struct tasks_episode* ep);
  /// Bounds of every value the features can produce (lo[i] <= state[i] <= hi[i]; observation
  /// spaces), under ep's specification and feature configuration.
  void (*state_bounds)(const struct tasks_episode* ep, double* lo, double* hi);

  // Drivers: the example policy (its gain drawn per run in [gain_min, gain_max]), a simulated
  // person, and the reference ("optimal") controller, which exists to evaluate only.
  double gain_min;
  double gain_max;
  /// Sets d's control law for its kind (after the gain draw; draws nothing).
  void (*driver_law)(tasks_driver_t* d);
  /// A simulated person's task-specific temperament (after the common one; may draw from d->rng);
  /// NULL: the common temperament only.
  void (*driver_human)(tasks_driver_t* d);
  /// The driver's rotation command for the newest state [rad/s] (advances its state).
  double (*driver_action)(const struct tasks_episode* ep, tasks_driver_t* d);

  /// Writes the task's world (the emulator builds it from this). Returns 0, or nonzero when a
  /// sink call failed.
  int (*world)(const void* spec, const tasks_world_sink_t* sink);
} tasks_decl_t;

/// Number of declared tasks. O(1).
uint32_t tasks_count(void);
/// Declaration i (0..tasks_count()-1), NULL beyond. O(1).
const tasks_decl_t* tasks_decl_at(uint32_t i);
/// The declaration named `name` (the configuration's task value), NULL when none is. O(tasks).
const tasks_decl_t* tasks_find(const char* name);
/// The declaration whose message id is `id`, NULL when none is. O(tasks).
const tasks_decl_t* tasks_by_id(int32_t id);

/// The declaration's parameter named `name` (NULL when it has none). O(params).
const tasks_param_t* tasks_param_find(const tasks_decl_t* decl, const char* name);

/// Sets the specification's parameter `name` to value: 0, -1 for an unknown name, -2 for a value
/// outside its range (nothing changed). O(params).
int tasks_spec_set_param(const tasks_decl_t* decl, void* spec, const char* name, double value);
/// The parameter's value (NAN for an unknown name). O(params).
double tasks_spec_get_param(const tasks_decl_t* decl, const void* spec, const char* name);

/// Common fields of a specification through the declaration's offsets. O(1).
double tasks_spec_dt_s(const tasks_decl_t* decl, const void* spec);
double tasks_spec_omega_max(const tasks_decl_t* decl, const void* spec);
uint32_t tasks_spec_step_limit(const tasks_decl_t* decl, const void* spec);
double tasks_spec_gamma(const tasks_decl_t* decl, const void* spec);
double tasks_spec_robot_radius(const tasks_decl_t* decl, const void* spec);
features_pose_t tasks_spec_eval_start(const tasks_decl_t* decl, const void* spec, uint32_t index);
void tasks_spec_set_dt_s(const tasks_decl_t* decl, void* spec, double dt_s);
void tasks_spec_set_omega_max(const tasks_decl_t* decl, void* spec, double omega_max_radps);
void tasks_spec_set_step_limit(const tasks_decl_t* decl, void* spec, uint32_t step_limit);

/// Starts the driver d of `kind` for a run of task decl: tasks_driver_begin_common with the
/// declaration's gain range, its control law (decl->driver_law), and for a person
/// tasks_driver_begin_human and the task's own temperament (decl->driver_human). A NULL decl is
/// the corridor. O(TASKS_HUMAN_MAX_DELAY).
void tasks_driver_begin_run(tasks_driver_t* d, tasks_driver_kind_t kind, const tasks_decl_t* decl,
                            double omega_max_radps, uint64_t run_seed);

/// Sets the run's gain of the example policy (a configured range or a fixed evaluation gain) and,
/// for the proportional kind, its control law again (which may hold the gain). O(1).
void tasks_driver_set_gain(tasks_driver_t* d, const tasks_decl_t* decl, double gain);

/// The declared tasks (their definitions, for tests and tools that need one by name).
extern const tasks_decl_t tasks_corridor_decl;
extern const tasks_decl_t tasks_obstacles_decl;
extern const tasks_decl_t tasks_doorway_decl;

#ifdef __cplusplus
}
#endif

#endif  // B21R_TASKS_DECL_H
