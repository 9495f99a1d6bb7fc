// SPDX-License-Identifier: MIT
/// experiment.h — b21r-experiment: one experiment of the paper, for one seed, in one process.
///
/// An experiment file is a controller config file (fw/config.h: the same format and the same
/// keys, e.g. `task`, `phase_one_driver`, `hedger_capacity`, `phase_switch`) plus keys of the
/// form `experiment.*` that say what to run around the controller (kind, seeds, references,
/// the variants of a sweep, the exploration studies' settings). The keys are documented in
/// one table (settings.c), printed by `b21r-experiment --print-reference-config`.
///
/// Kinds:
/// - learn: the controller's two-phase schedule against the ODE emulator linked in-process
///   (inproc_sim.h), then each reference controller (mode = evaluate) from the same 10 poses
///   against a fresh emulator with the same seed. Result: every evaluation block, every run,
///   who drove each step, store fill, simulated driving time (learn.c).
/// - explore_corridor: the paper's Fig. 6 study on the idealised kinematic model: uniformly
///   random rotation in [-limit, limit] from the corridor's start until the first reward.
/// - explore_goal: the paper's Table I study: the obstacle-free goal task, rotation ~ N(0, var),
///   from a start distance, pointing at the goal, up to a time limit (explore.c).
///   Both take the explore_* keys of the sensitivity study: what is random and how, how long a
///   draw is held, what a collision does and costs, the speeds, the goal's size, the starts, and
///   the back-end (the kinematic model or the ODE emulator).
///
/// One invocation = one (experiment, variant, seed) = one result file (JSON, written atomically:
/// temporary file, fsync, rename), so a sweep can skip finished tasks and merge results.
/// Not on any real-time path: allocation and stdio are free here.
#ifndef B21R_TOOLS_EXPERIMENT_H
#define B21R_TOOLS_EXPERIMENT_H

#include "fw/config.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#define EXP_STR_MAX 256U
#define EXP_ERR_MAX 768U
#define EXP_MAX_REFERENCES 8
#define EXP_MAX_VARIANTS 16

typedef enum exp_kind { EXP_LEARN = 0, EXP_EXPLORE_CORRIDOR = 1, EXP_EXPLORE_GOAL = 2 } exp_kind_t;

/// The settings of an experiment beyond the controller's.
typedef struct exp_settings {
  char name[EXP_STR_MAX];          ///< identifier (result folder name); default: the file's base name
  char title[EXP_STR_MAX];         ///< one line for figures and the report
  int32_t kind;                    ///< exp_kind_t
  int32_t seeds;                   ///< seeds of a sweep: first_seed .. first_seed + seeds - 1
  int32_t first_seed;
  char world[EXP_STR_MAX];         ///< world file ("" = built from the task's specification)
  char config_dir[EXP_STR_MAX];    ///< folder of the experiment file (relative paths start there)
  /// Reference controllers evaluated from the evaluation poses: values of evaluate_policy, or
  /// example@GAIN for the example policy at GAIN [1/s] (evaluate_example_gain).
  char references[EXP_MAX_REFERENCES][16];
  int32_t n_references;
  /// One sweep axis: `key=v1|v2|...` over a controller or experiment key ("" = no variants).
  char vary_key[64];
  char vary_values[EXP_MAX_VARIANTS][64];
  int32_t n_vary;
  /// Controller keys the experiment needs (experiment.requires) that this controller lacks: the
  /// experiment cannot run with this build ("" = none missing).
  char missing[EXP_STR_MAX];
  // Exploration studies (kinds explore_*).
  int32_t explore_runs;            ///< runs per seed
  double explore_time_limit_s;     ///< simulated time limit of one run (one week: 604800)
  double explore_omega_max_radps;  ///< a uniform random rotation is drawn in [-max, max] [rad/s]
  double explore_omega_variance;   ///< a normal random rotation is N(0, variance) [rad^2/s^2]
  double explore_start_distance_m; ///< explore_goal: start distance from the goal [m]
  double explore_start_x_m;        ///< explore_corridor: start distance from the start wall [m]
  bool explore_accel_limits;       ///< use the B21r's acceleration limits (false: idealised model)
  // The assumptions the sensitivity study varies (settings.c documents each key).
  int32_t explore_model;           ///< exp_explore_model_t
  int32_t explore_random;          ///< exp_explore_random_t: what is random
  int32_t explore_rotation;        ///< exp_explore_rotation_t: a random rotation's distribution
  double explore_omega_clip_radps; ///< |normal rotation| clip [rad/s], 0 = none
  int32_t explore_translation;     ///< exp_explore_translation_t: a random translation's distribution
  double explore_v_max_mps;        ///< uniform translation: [-max, max] [m/s]
  double explore_v_variance;       ///< normal translation: N(0, variance) [m^2/s^2]
  double explore_v_clip_mps;       ///< |normal translation| clip [m/s], 0 = none
  double explore_hold_s;           ///< a random draw is held this long [s]; 0 = one control period
  int32_t explore_collision;       ///< exp_explore_collision_t
  double explore_restart_s;        ///< robot time charged per restart [s]
  int32_t explore_attempt_steps;   ///< steps that end an attempt; -1 = the study's default, 0 = none
  double explore_v_wall_mps;       ///< corridor speed policy at the wall [m/s]; < 0 = the task's
  double explore_v_mps;            ///< corridor centre-line speed / goal task speed [m/s]; < 0 = the task's
  double explore_goal_size_m;      ///< corridor goal distance / goal radius [m]; < 0 = the task's
  int32_t explore_start;           ///< exp_explore_start_t
  bool explore_arena_walls;        ///< explore_goal: the arena's walls are there
} exp_settings_t;

/// Back-end of the exploration studies.
typedef enum exp_explore_model { EXP_MODEL_KINEMATIC = 0, EXP_MODEL_ODE = 1 } exp_explore_model_t;
/// What is random: the rotation (the translation is the task's own), the translation (no
/// rotation), or both.
typedef enum exp_explore_random {
  EXP_RANDOM_ROTATION = 0,
  EXP_RANDOM_TRANSLATION = 1,
  EXP_RANDOM_BOTH = 2
} exp_explore_random_t;
/// A random rotation's distribution (AUTO: uniform for explore_corridor, normal for explore_goal).
typedef enum exp_explore_rotation { EXP_ROT_AUTO = 0, EXP_ROT_UNIFORM = 1, EXP_ROT_NORMAL = 2 } exp_explore_rotation_t;
/// A random translation's distribution.
typedef enum exp_explore_translation { EXP_TRANS_NORMAL = 0, EXP_TRANS_UNIFORM = 1 } exp_explore_translation_t;
/// What a collision does.
typedef enum exp_explore_collision { EXP_COLLISION_RESTART = 0, EXP_COLLISION_STAY = 1 } exp_explore_collision_t;
/// Where attempts start.
typedef enum exp_explore_start {
  EXP_START_PAPER = 0,
  EXP_START_ANY_HEADING = 1,
  EXP_START_TRAINING = 2
} exp_explore_start_t;

/// Defaults of every experiment key. O(keys).
void exp_settings_defaults(exp_settings_t* s);

/// True when `name` is a reference of the form example@GAIN with 0 < GAIN <= 100 [1/s] written
/// as plain decimals (digits, at most one inner point); then the gain is written to *gain (when
/// gain is not NULL). O(length of name).
bool exp_reference_example_gain(const char* name, double* gain);

/// Sets one key: an `experiment.*` key into *s, any other into *cfg (fw_config_set). Errors
/// name source, key, value and what is allowed. Returns 0 or -1.
int exp_set(exp_settings_t* s, fw_config_t* cfg, const char* key, const char* value, const char* source, char* err,
            size_t err_cap);

/// Loads an experiment file over (*s, *cfg): controller keys and experiment keys. Sets name
/// (when the file does not) and config_dir. Returns 0 or -1 with "path:line: ..." in err.
int exp_load_file(exp_settings_t* s, fw_config_t* cfg, const char* path, char* err, size_t err_cap);

/// Cross-key checks (kind vs task, references only for learn, ...). Returns 0 or -1.
int exp_validate(const exp_settings_t* s, const fw_config_t* cfg, char* err, size_t err_cap);

/// Documentation of every experiment key in the config file format.
void exp_print_reference(FILE* out);

/// Resolves a path given in the experiment file (relative to its folder). Returns 0 or -1.
int exp_resolve_path(const exp_settings_t* s, const char* path, char* out, size_t cap);

/// A small streaming JSON writer (objects, arrays, numbers, strings) with commas handled.
typedef struct json_writer {
  FILE* f;
  int depth;
  bool first[32];
} json_writer_t;

void json_begin(json_writer_t* w, FILE* f);
void json_object(json_writer_t* w, const char* key);  ///< key NULL inside arrays and at top level
void json_array(json_writer_t* w, const char* key);
void json_end_object(json_writer_t* w);
void json_end_array(json_writer_t* w);
void json_int(json_writer_t* w, const char* key, int64_t v);
void json_num(json_writer_t* w, const char* key, double v);  ///< non-finite → null
void json_bool(json_writer_t* w, const char* key, bool v);
void json_null(json_writer_t* w, const char* key);
void json_str(json_writer_t* w, const char* key, const char* v);

/// What the runner was asked to do for one task.
typedef struct exp_task {
  const char* variant;          ///< label of the variant ("" = none)
  uint64_t seed;
  const char* out_path;         ///< result file (JSON)
  const char* experience_log;   ///< optional LCM event log of B21R_EXPERIENCE (learn only), or NULL
  const char* trace_svg;        ///< optional overhead picture of the learning runs (learn only), or NULL
  bool verbose;                 ///< controller progress lines on stderr
  const char* command_line;     ///< for the result file (reproduction)
} exp_task_t;

/// Runs a learn experiment and writes its result. Returns 0, or -1 with a message in err.
int exp_run_learn(const exp_settings_t* s, const fw_config_t* cfg, const exp_task_t* task, char* err, size_t err_cap);

/// Runs an exploration study and writes its result. Returns 0, or -1 with a message in err.
int exp_run_explore(const exp_settings_t* s, const fw_config_t* cfg, const exp_task_t* task, char* err,
                    size_t err_cap);

/// Writes the header shared by every result (format, experiment, variant, seed, settings).
void exp_write_header(json_writer_t* w, const exp_settings_t* s, const fw_config_t* cfg, const exp_task_t* task);

/// Opens `<path>.tmp` for writing; exp_commit_file() fsyncs, closes and renames it to path.
FILE* exp_open_result(const char* path, char* tmp_path, size_t tmp_cap, char* err, size_t err_cap);
int exp_commit_result(FILE* f, const char* tmp_path, const char* path, char* err, size_t err_cap);

#endif  // B21R_TOOLS_EXPERIMENT_H
