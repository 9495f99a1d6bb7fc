// SPDX-License-Identifier: MIT
/// fw/config.h — The controller's configuration: one struct, its documented defaults, and a
/// parser for `key = value` files and `--set key=value` overrides.
///
/// File format (see firmware/app/b21r-controller.conf, the reference file):
/// - one `key = value` per line; blanks around `=` and at both ends are ignored;
/// - `#` starts a comment anywhere outside a double-quoted value; blank lines are ignored;
/// - string values may be double-quoted (`log_file = "out dir/log"`), which keeps spaces and `#`;
///   a value itself may not contain a double quote or a control character (tab, line break, ...),
///   so that fw_config_print() always writes a file that loads back to the same settings;
/// - a key may appear once per file; later sources (more files, then `--set`) override earlier ones.
/// Every error names the source (`file:line` or `--set`), the key, the bad value and what is
/// allowed (range, choices), so the operator can fix it without reading code. An unknown key
/// suggests the nearest known one and points to `b21r-controller --print-reference-config`.
/// fw_config_t remembers where each key was last set (fw_config_origins_t), so that the
/// cross-key checks of fw_config_validate() can name the file and line of the keys involved.
///
/// Memory: fw_config_t is a plain value (no pointers, strings are fixed arrays); parsing uses the
/// stack and stdio only. Not used on the tick path. Thread-safety: none needed (start-up only).
#ifndef FW_CONFIG_H
#define FW_CONFIG_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Capacity of every string setting (paths, URLs), including the terminating NUL.
#define FW_CONFIG_STR_MAX 256U
/// Largest number of values of a list key (hedger_input_scale: state dimensions + action).
#define FW_CONFIG_MAX_SCALES 9
/// CPUs a CPU list key (rt_cpus) can name: 0 to FW_CONFIG_MAX_CPUS - 1.
#define FW_CONFIG_MAX_CPUS 64
/// Capacity of an error message produced by the parser, including the NUL.
#define FW_CONFIG_ERR_MAX 512U
/// Ceiling of the number of keys (the table in config.c has fewer; checked at compile time).
#define FW_CONFIG_MAX_KEYS 128U
/// Distinct sources (config files, "--set", ...) whose names errors can cite; a key set from a
/// further source is cited as "an earlier setting".
#define FW_CONFIG_MAX_SOURCES 8U
/// Longest decision a configuration can give (decision_ticks: 1 to this many control ticks).
#define FW_DECISION_TICKS_MAX 10

/// The declared task's name of an id (tasks_decl_t.id) as the task key takes it ("corridor",
/// "obstacles", ...); "unknown" for an id no declaration has (a log or file written by something
/// else). Pure, O(tasks); a static string.
const char* fw_task_name(int32_t task);
/// Evaluation poses a configuration can give (eval_poses).
#define FW_CONFIG_MAX_POSES 16
/// Wire protocol of the base.
typedef enum fw_base_protocol { FW_BASE_RFLEX = 0, FW_BASE_CANOPEN = 1 } fw_base_protocol_t;
/// Who drives in phase one.
typedef enum fw_driver {
  FW_DRIVER_EXAMPLE = 0,   ///< the paper's proportional controller, gain varied per run
  FW_DRIVER_JOYSTICK = 1,  ///< the operator over B21R_TELEOP (deadman)
  FW_DRIVER_HUMAN = 2,     ///< a simulated sloppy joystick driver (lib/tasks), for emulator studies
} fw_driver_t;
/// When phase two starts.
typedef enum fw_phase_switch {
  FW_SWITCH_RUNS = 0,      ///< after phase_one_runs training runs (the paper: 30)
  FW_SWITCH_OPERATOR = 1,  ///< only on B21R_COMMAND START_PHASE_TWO
  FW_SWITCH_AUTO = 2,      ///< when an evaluation block shows the learned policy is ready
} fw_phase_switch_t;
/// How the robot reaches the next start pose between runs.
typedef enum fw_reposition {
  FW_REPOSITION_OPERATOR = 0,  ///< status REPOSITIONING until B21R_COMMAND CONFIRM_START_POSE
  FW_REPOSITION_EMULATOR = 1,  ///< the emulator's control socket `reset x y theta`
} fw_reposition_t;
/// Who may exchange LCM messages with the controller (fw/lcm_scope.h).
typedef enum fw_lcm_scope {
  FW_LCM_SCOPE_HOST = 0,     ///< this host only: ttl=0, receive confined to loopback
  FW_LCM_SCOPE_NETWORK = 1,  ///< other hosts too (operator messages still authenticated)
} fw_lcm_scope_t;
/// What the controller does when a device is gone (end of file, EIO, ENODEV, hang-up).
typedef enum fw_device_lost_action {
  FW_DEVICE_LOST_REOPEN = 0,   ///< stop, close it, reopen with back-off, resume when it is back
  FW_DEVICE_LOST_EXIT = 1,     ///< stop, then exit with FW_EXIT_DEVICE_LOST (a supervisor restarts us)
} fw_device_lost_action_t;
/// What the process does.
typedef enum fw_mode {
  FW_MODE_LEARN = 0,     ///< the two-phase learning schedule
  FW_MODE_EVALUATE = 1,  ///< one evaluation block of evaluate_policy, learning off, then exit
} fw_mode_t;
/// The value-function learner (the learner ablation of issue 12 compares them on the same data).
typedef enum fw_learner_kind {
  FW_LEARNER_HEDGER = 0,   ///< HEDGER: LWR guarded by the hull and plausibility tests, LWA fallback
  FW_LEARNER_LWA = 1,      ///< HEDGER with every prediction by locally weighted averaging
  FW_LEARNER_TABULAR = 2,  ///< tabular Q-learning on a discretised state and action (lib/tabq)
} fw_learner_kind_t;
/// Who acts where the learned policy acts (the values of learn_policy_t).
typedef enum fw_policy {
  FW_POLICY_ACTOR = 0,   ///< the actor learned from the rewards between runs (lib/actor)
  FW_POLICY_GREEDY = 1,  ///< HEDGER's greedy action (the paper's; the default)
  FW_POLICY_SELECT = 2,  ///< either, as ranked pairs of phase-two runs favour (learn/learn.h)
} fw_policy_t;
/// Policy evaluated in FW_MODE_EVALUATE.
typedef enum fw_eval_policy {
  FW_EVAL_LEARNED = 0,   ///< the learned policy (the configured policy, from the checkpoint)
  FW_EVAL_EXAMPLE = 1,   ///< the example policy at its nominal gain
  FW_EVAL_OPTIMAL = 2,   ///< the hand-tuned reference controller (the paper's "optimal" line)
  FW_EVAL_HUMAN = 3,     ///< the simulated sloppy human driver (phase_one_driver = human's examples)
} fw_eval_policy_t;

/// Scheduling policy of the process (config rt_scheduler; POSIX sched_setscheduler).
typedef enum fw_rt_scheduler {
  FW_RT_OTHER = 0,  ///< SCHED_OTHER: the normal time-sharing scheduler
  FW_RT_FIFO = 1,   ///< SCHED_FIFO at rt_priority
  FW_RT_RR = 2,     ///< SCHED_RR at rt_priority
} fw_rt_scheduler_t;

/// Where each key was last set, for error messages: not a setting (fw_config_print() ignores it,
/// and two configs with equal settings may differ here). Filled by fw_config_set() and its
/// callers; a field assigned directly keeps the origin of its last fw_config_set().
typedef struct fw_config_origins {
  /// Source names without the line ("robot.conf", "--set"); entry 0 is unused (= default value).
  char source[FW_CONFIG_MAX_SOURCES][FW_CONFIG_STR_MAX];
  uint8_t key_source[FW_CONFIG_MAX_KEYS]; ///< per key (table order): index into source[]; 0 = default
  uint32_t key_line[FW_CONFIG_MAX_KEYS];  ///< per key: line in that source, 0 = not a file line
} fw_config_origins_t;

/// Every setting of the controller. Field names carry units. Defaults: fw_config_defaults().
typedef struct fw_config {
  // What to do.
  int32_t task;                    ///< the declared task's id (tasks_decl_t.id; key: its name)
  /// the task's parameters as "name=value,name=value" (tasks_decl_t.params; "" = the defaults)
  char task_params[FW_CONFIG_STR_MAX];
  int32_t mode;                    ///< fw_mode_t
  int32_t evaluate_policy;         ///< fw_eval_policy_t (mode = evaluate only)
  double evaluate_example_gain;    ///< evaluate_policy = example: its gain [1/s]; 0 = nominal
  /// The example policy's gains [1/s], {lowest, highest}: each run draws its gain uniformly in
  /// between (the same draw as the task's default range, rescaled). Unset (n = 0): the task's range.
  double example_gain_range[FW_CONFIG_MAX_SCALES];
  int32_t example_gain_range_n;    ///< entries set: 0 (the task's range) or 2
  uint64_t seed;                   ///< root of every random generator
  double corridor_length_m;        ///< corridor task: start wall to end wall [m] (default 10)

  // Loop timing.
  double tick_rate_hz;             ///< control rate [1, 100], default 10
  bool lockstep;                   ///< tick when the emulator's data for t_k has arrived
  double lockstep_timeout_s;       ///< lockstep: a device silent this long ends the loop (exit 5)
  double lockstep_realtime_factor; ///< lockstep: pace ticks to at most this × real time; 0 = unpaced
  double late_start_threshold_s;   ///< real time: a tick starting later than this is a late start

  // Real time (applied by the onboard program before the loop starts; firmware/app/realtime.h).
  int32_t rt_scheduler;            ///< fw_rt_scheduler_t
  int32_t rt_priority;             ///< SCHED_FIFO / SCHED_RR priority [1, 99]
  uint64_t rt_cpus;                ///< CPU affinity: bit i = CPU i; 0 = any CPU
  bool rt_lock_memory;             ///< mlockall(MCL_CURRENT | MCL_FUTURE)
  bool rt_prefault;                ///< touch every buffer at start-up (fw/prefault.h)

  // Devices.
  char laser_device[FW_CONFIG_STR_MAX];  ///< serial device of the LMS200
  int32_t laser_baud;              ///< operating rate after switching: 9600|19200|38400|500000
  int32_t laser_start_baud;        ///< rate the LMS200 powers up with (9600)
  int32_t laser_fov_deg;           ///< 180 | 100
  int32_t laser_resolution_cdeg;   ///< 100 | 50 | 25 (0.25 only with fov 100)
  int32_t base_protocol;           ///< fw_base_protocol_t
  char base_device[FW_CONFIG_STR_MAX];   ///< rFLEX serial device
  int32_t base_baud;               ///< rFLEX rate (115200)
  int32_t base_write_gap_us;       ///< rFLEX: pause after each written packet [µs]
  char can_interface[FW_CONFIG_STR_MAX]; ///< SocketCAN interface (CANopen), e.g. can0
  char can_socket[FW_CONFIG_STR_MAX];    ///< seqpacket CAN socket path; overrides can_interface
  int32_t can_node_translation;    ///< CiA 402 node id of the translation drive [1, 127]
  int32_t can_node_rotation;       ///< CiA 402 node id of the rotation drive [1, 127]
  double can_heartbeat_timeout_s;  ///< drive heartbeat silence that counts as a fault
  int32_t can_node_bumpers;        ///< CiA 401 node id of the bump-panel inputs [1, 127], not a drive's
  double can_bumper_timeout_s;     ///< no bump-panel TPDO1 for this long → base fault [s] (lockstep: ticks)
  double distance_counts_per_m;    ///< base conversion K_d (rFLEX: 103000)
  double angle_counts_per_rad;     ///< base conversion K_a (rFLEX: 35000)
  int32_t reposition;              ///< fw_reposition_t
  char emulator_control[FW_CONFIG_STR_MAX]; ///< emulator control socket (reposition = emulator)
  double emulator_reply_timeout_s; ///< an unanswered start-pose request fails after this long [s]

  // Command limits.
  double max_translation_mps;      ///< |v| limit
  double max_rotation_radps;       ///< |ω| limit, also the learner's action range
  double max_translation_accel_mps2;  ///< |Δv|/dt limit
  double max_rotation_accel_radps2;   ///< |Δω|/dt limit

  // Safety.
  double laser_timeout_s;          ///< no scan for this long → stop (lockstep: in ticks)
  double base_timeout_s;           ///< no odometry for this long → stop (lockstep: in ticks)
  double teleop_timeout_s;         ///< no fresh deadman message for this long → stop
  bool safety_auto_resume;         ///< resume (with a new run) once the cause has cleared
  int32_t safety_clear_ticks;      ///< ticks without the cause before resuming
  int32_t device_lost_action;      ///< fw_device_lost_action_t
  double device_reopen_backoff_s;  ///< first wait before reopening a lost device [s]
  double device_reopen_backoff_max_s; ///< longest wait between reopen attempts [s]

  // Learning.
  double alpha;                    ///< learning rate (paper: 0.2)
  double gamma;                    ///< discount; 0 = the task's (paper: corridor 0.99, obstacles 0.9)
  int32_t policy;                  ///< fw_policy_t
  int32_t actor_capacity;          ///< actor: recorded transitions kept (fixed memory)
  int32_t actor_hidden;            ///< actor: tanh units of its network
  int32_t actor_runs;              ///< actor: recent runs whose returns fit V and whose states are queried
  int32_t actor_queries;           ///< actor: largest query set per run
  double actor_step_gain;          ///< actor: target step per tick of discounting of slope
  double actor_step_max;           ///< actor: largest target step per run [rad/s]
  double actor_trust_radius;       ///< actor: largest distance of a target from the recorded action [rad/s]; 0 none
  double actor_guard_se;           ///< actor: replaced by the greedy action where the values put it this many SE below; 0 never
  bool actor_guard_range;          ///< actor: kept within the actions the learned data hold at the state
  double actor_slope_min_t;        ///< actor: steps only where |slope| >= this many standard errors; 0 every slope
  bool actor_rewarded_window;      ///< actor: the value window reaches back to actor_runs rewarded runs
  int32_t actor_fit_steps;         ///< actor: Adam steps per fit
  int32_t actor_clone_steps;       ///< actor: Adam steps of the first run's behaviour cloning
  double actor_learning_rate;      ///< actor: Adam's learning rate
  int32_t actor_work_per_tick;     ///< between runs: the actor's work units per tick (bounds the tick)
  int32_t learner;                 ///< fw_learner_kind_t
  int32_t tabular_bins;            ///< tabular: bins per state dimension over the task's state range
  int32_t tabular_actions;         ///< tabular: evenly spaced actions over [-omega_max, omega_max]
  int32_t hedger_capacity;         ///< stored samples (fixed memory)
  int32_t hedger_k_min;            ///< fewer neighbours → unknown
  int32_t hedger_k_max;            ///< neighbourhood size
  double hedger_bandwidth;         ///< kernel width h in scaled input units
  double hedger_input_scale[FW_CONFIG_MAX_SCALES]; ///< raw units per scaled unit: state..., action
  int32_t hedger_input_scale_n;    ///< entries set (0 = the task's defaults)
  double hedger_merge_radius;      ///< merge a new point into a stored one closer than this (scaled)
  int32_t hedger_greedy_actions;   ///< evenly spaced actions scanned by the greedy search
  bool hedger_replay;              ///< replay each finished training run backwards
  int32_t learn_updates_per_tick;  ///< between runs: replay updates per tick (bounds the tick)
  int32_t checkpoint_points_per_tick; ///< between runs: stored points serialised per tick
  int32_t hedger_replay_passes;    ///< backward passes per replayed run
  double hedger_replay_lambda;     ///< λ of the replay's λ-return target (0 Q-learning, 1 the run's return)
  double hedger_replay_alpha;      ///< learning rate of the replay's updates (0 = alpha)
  int32_t hedger_greedy_method;    ///< hedger_greedy_method_t
  double hedger_greedy_pessimism;  ///< κ: greedy ranks by value − κ · standard error
  double hedger_greedy_reach;      ///< state model: kernel widening where the state has too few neighbours (0 = the task's)
  int32_t phase_driver;            ///< fw_driver_t: who drives phase one
  int32_t phase_switch;            ///< fw_phase_switch_t
  int32_t phase_one_runs;          ///< training runs in phase one (paper: 30)
  int32_t phase_two_runs;          ///< training runs in phase two (paper: 35); then done
  int32_t auto_switch_min_runs;    ///< phase_switch = auto: earliest switch
  double auto_switch_ratio;        ///< auto: ready when eval mean ≤ ratio × mean example run
  int32_t eval_every_runs;         ///< an evaluation block every N training runs (paper: 5)
  int32_t eval_starts;             ///< evaluation start poses per block [1, 16] (paper: 10)
  /// evaluation poses of the configuration's own: x, y, theta per pose (task frame; n poses set,
  /// 0 = the task's); training starts stay around the task's poses
  double eval_poses[3 * FW_CONFIG_MAX_POSES];
  int32_t eval_poses_n;
  bool eval_at_start;              ///< also evaluate before the first training run
  int32_t max_steps_per_run;       ///< step limit of a run (0 = the task's default)
  double explore_sigma_radps;      ///< phase two: std-dev of the exploration noise
  double explore_probability;      ///< probability per step of starting an exploration segment
  double explore_hold_s;           ///< duration of an exploration segment (one held offset)
  bool advisor;                    ///< phase two: example policy acts where the learned policy knows nothing
  double example_noise_radps;      ///< phase one, example driver: std-dev of a dither segment's offset
  bool state_rotation;             ///< the state ends with the rotation the base executes [rad/s] (default)
  int32_t decision_ticks;          ///< the driver and the policy decide every this many ticks [1, FW_DECISION_TICKS_MAX]

  // Output.
  char lcm_url[FW_CONFIG_STR_MAX]; ///< LCM provider URL; "" = LCM's default; "none" = off
  int32_t lcm_scope;               ///< fw_lcm_scope_t: host (default) or network (fw/lcm_scope.h)
  /// operator key (fw/opauth.h): B21R_TELEOP / B21R_COMMAND are taken only signed with it; "" =
  /// none (every operator message refused)
  char operator_key_file[FW_CONFIG_STR_MAX];
  int32_t status_period_ticks;     ///< publish STATUS every N ticks
  bool publish_scan;               ///< also publish B21R_SCAN
  int32_t queue_capacity;          ///< publisher queue slots (power of two)
  char checkpoint_file[FW_CONFIG_STR_MAX];     ///< "" = no checkpoints (learned data lost!)
  char log_file[FW_CONFIG_STR_MAX];            ///< LCM event log of every channel ("" = none)
  char experience_log_file[FW_CONFIG_STR_MAX]; ///< LCM event log of EXPERIENCE only
  bool progress;                   ///< print one line per run / evaluation block on stdout

  /// Where each key came from (last member: settings end at offsetof(fw_config_t, origins)).
  fw_config_origins_t origins;
} fw_config_t;

/// Fills cfg with the documented defaults (the values in firmware/app/b21r-controller.conf).
/// O(number of keys); never fails.
void fw_config_defaults(fw_config_t* cfg);

/// Sets one key from its textual value. `source` names where it came from ("--set",
/// "file.conf:12"): it is used in the error text and remembered as the key's origin. Returns 0,
/// or -1 with a message in err (capacity FW_CONFIG_ERR_MAX) naming source, key, value and the
/// allowed range or choices (an unknown key: the nearest known key, if one is close); cfg is
/// then unchanged. Booleans are exactly `true` or `false`. O(number of keys × key length).
int fw_config_set(fw_config_t* cfg, const char* key, const char* value, const char* source,
                  char* err, size_t err_cap);

/// True when `key` is a key of the controller (tools use it to tell an unknown key from a key of a
/// newer controller). O(number of keys).
bool fw_config_has_key(const char* key);

/// Applies a `key=value` command-line override (the argument of `--set`). Same errors as
/// fw_config_set, plus a missing `=`.
int fw_config_set_arg(fw_config_t* cfg, const char* key_eq_value, char* err, size_t err_cap);

/// Parses a whole config file over cfg (keys not in the file keep their value). Returns 0, or
/// -1 with the first error in err ("path:line: ..."), including an unreadable file. cfg may hold
/// the keys of lines before the error. Lines longer than 1023 characters are an error.
int fw_config_load_file(fw_config_t* cfg, const char* path, char* err, size_t err_cap);

/// Handler of keys the controller does not know, for tools whose files add their own keys to the
/// controller's format (e.g. the experiment runner's `experiment.*` keys). Returns 0 when it took
/// the key, 1 when the key is not its either (the parser then reports an unknown key), -1 with a
/// message in err naming source, key and value when the value is bad.
typedef int (*fw_config_extra_key_fn)(void* user, const char* key, const char* value, const char* source,
                                      char* err, size_t err_cap);

/// fw_config_load_file, with keys unknown to the controller handed to `extra` (may be NULL:
/// then it is fw_config_load_file). A key may appear once per file, extra keys included.
int fw_config_load_file_with(fw_config_t* cfg, const char* path, fw_config_extra_key_fn extra, void* user,
                             char* err, size_t err_cap);

/// Cross-key checks after all sources were applied (e.g. 0.25° needs the 100° field, k_min ≤
/// k_max, reposition = emulator needs emulator_control). Returns 0 or -1 with a message that
/// starts with the origin of the offending key ("robot.conf:12: ", "--set: ", "default: ") and
/// names the origin of every other key involved.
int fw_config_validate(const fw_config_t* cfg, char* err, size_t err_cap);

/// fw_config_validate, plus the checks of the b21r-controller program, where operator input
/// arrives over LCM from a person in real time: phase_one_driver = joystick is refused with
/// lockstep = true (the emulator's time only moves with the loop) and with lcm_url = none (no
/// B21R_TELEOP can arrive). The message names both keys and where they were set. (In-process
/// tools and tests that post B21R_TELEOP themselves use fw_config_validate.)
int fw_config_validate_program(const fw_config_t* cfg, char* err, size_t err_cap);

/// Writes where key was last set into out: "file:line", "--set", "default", ... (cap bytes,
/// NUL-terminated; "unknown key" for a name that is not a key). O(number of keys).
void fw_config_origin(const fw_config_t* cfg, const char* key, char* out, size_t out_cap);

/// Writes the documentation of every key (default, allowed values, meaning) to out, in the
/// config file format, so the output is itself a valid config file.
void fw_config_print_reference(FILE* out);

/// Writes the current value of every key to out in the config file format.
void fw_config_print(const fw_config_t* cfg, FILE* out);

/// Writes a CPU mask as the list syntax of rt_cpus ("0,2-3"; "" for 0) into out (cap bytes,
/// NUL-terminated, truncated if too small). O(FW_CONFIG_MAX_CPUS).
void fw_config_format_cpus(uint64_t mask, char* out, size_t cap);

/// Writes n numbers as a list key reads them (hedger_input_scale: "1,0.5,0.125"), each the
/// shorter of %.15g and %.17g that reads back as the same double (0.1, not 0.10000000000000001),
/// into out (cap bytes, NUL-terminated). Returns 0, or -1 when it does not fit. O(n).
int fw_config_format_doubles(const double* v, uint32_t n, char* out, size_t cap);

/// Calls fn(user, name, value) for each parameter of task_params, in order, after checking that
/// the task declares it and the value is in its range (fn may be NULL: checks only). Returns 0,
/// or -1 with a message naming the parameter, the task's parameters or the range. O(length).
typedef void (*fw_config_task_param_fn)(void* user, const char* name, double value);
int fw_config_each_task_param(const fw_config_t* cfg, fw_config_task_param_fn fn, void* user, char* err,
                              size_t err_cap);

/// Tick period [µs] derived from tick_rate_hz (rounded to the nearest µs).
int64_t fw_config_period_us(const fw_config_t* cfg);

/// A timeout in seconds expressed in whole ticks at the configured rate (at least 1).
int32_t fw_config_ticks(const fw_config_t* cfg, double seconds);

#ifdef __cplusplus
}
#endif

#endif  // FW_CONFIG_H
