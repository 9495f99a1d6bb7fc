// SPDX-License-Identifier: MIT
// Table-driven configuration: one row per key carries its type, range, default and help text, so
// the parser, the error messages, --help and the reference file cannot drift apart.
#include "fw/config.h"
#include "fw/errfmt.h"

#include <hedger/hedger.h>
#include <tasks/decl.h>

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef enum key_kind {
  KIND_BOOL,
  KIND_INT,
  KIND_U64,
  KIND_DOUBLE,
  KIND_STRING,
  KIND_ENUM,
  KIND_DLIST,
  KIND_CPUS,  // CPU list "0,2-3" stored as a uint64_t mask
  KIND_TASK,  // a declared task's name (tasks/decl.h), stored as its id (int32_t)
  KIND_POSES, // "x,y,theta; x,y,theta; ...", stored as doubles followed by the pose count (int32_t)
} key_kind_t;

typedef struct choice {
  const char* name;
  int32_t value;
} choice_t;

typedef struct key_desc {
  const char* section;  // non-NULL starts a new section in the reference output
  const char* name;
  key_kind_t kind;
  size_t offset;
  double min;           // KIND_INT / KIND_DOUBLE: inclusive unless *_open
  double max;
  bool min_open;
  bool max_open;
  const choice_t* choices;  // KIND_ENUM: NULL-terminated
  const char* def;      // default, as text (parsed by the same code as the file)
  const char* doc;
} key_desc_t;

#define OFF(field) offsetof(fw_config_t, field)
// A list key stores its count right after its values.
_Static_assert(offsetof(fw_config_t, hedger_input_scale_n) ==
                   offsetof(fw_config_t, hedger_input_scale) + FW_CONFIG_MAX_SCALES * sizeof(double),
               "list count must follow the list");
_Static_assert(offsetof(fw_config_t, eval_poses_n) == offsetof(fw_config_t, eval_poses) + 3 * FW_CONFIG_MAX_POSES * sizeof(double),
               "the pose count must follow the poses");
_Static_assert(offsetof(fw_config_t, example_gain_range_n) ==
                   offsetof(fw_config_t, example_gain_range) + FW_CONFIG_MAX_SCALES * sizeof(double),
               "list count must follow the list");

static const choice_t k_mode[] = {{"learn", FW_MODE_LEARN}, {"evaluate", FW_MODE_EVALUATE}, {NULL, 0}};
static const choice_t k_eval_policy[] = {
    {"learned", FW_EVAL_LEARNED}, {"example", FW_EVAL_EXAMPLE}, {"optimal", FW_EVAL_OPTIMAL},
    {"human", FW_EVAL_HUMAN},   {NULL, 0}};
static const choice_t k_baud_laser[] = {
    {"9600", 9600}, {"19200", 19200}, {"38400", 38400}, {"500000", 500000}, {NULL, 0}};
static const choice_t k_fov[] = {{"180", 180}, {"100", 100}, {NULL, 0}};
static const choice_t k_res[] = {{"1", 100}, {"0.5", 50}, {"0.25", 25}, {NULL, 0}};
static const choice_t k_proto[] = {{"rflex", FW_BASE_RFLEX}, {"canopen", FW_BASE_CANOPEN}, {NULL, 0}};
static const choice_t k_baud_base[] = {
    {"9600", 9600}, {"19200", 19200}, {"38400", 38400}, {"57600", 57600}, {"115200", 115200}, {NULL, 0}};
static const choice_t k_reposition[] = {
    {"operator", FW_REPOSITION_OPERATOR}, {"emulator", FW_REPOSITION_EMULATOR}, {NULL, 0}};
static const choice_t k_device_lost[] = {
    {"reopen", FW_DEVICE_LOST_REOPEN}, {"exit", FW_DEVICE_LOST_EXIT}, {NULL, 0}};
static const choice_t k_driver[] = {
    {"example", FW_DRIVER_EXAMPLE}, {"joystick", FW_DRIVER_JOYSTICK}, {"human", FW_DRIVER_HUMAN}, {NULL, 0}};
static const choice_t k_greedy[] = {
    {"per_action", HEDGER_GREEDY_PER_ACTION}, {"state_model", HEDGER_GREEDY_STATE_MODEL}, {NULL, 0}};
static const choice_t k_rt_scheduler[] = {
    {"other", FW_RT_OTHER}, {"fifo", FW_RT_FIFO}, {"rr", FW_RT_RR}, {NULL, 0}};
static const choice_t k_learner[] = {
    {"hedger", FW_LEARNER_HEDGER}, {"lwa", FW_LEARNER_LWA}, {"tabular", FW_LEARNER_TABULAR}, {NULL, 0}};
static const choice_t k_lcm_scope[] = {{"host", FW_LCM_SCOPE_HOST}, {"network", FW_LCM_SCOPE_NETWORK}, {NULL, 0}};
static const choice_t k_policy[] = {
    {"actor", FW_POLICY_ACTOR}, {"greedy", FW_POLICY_GREEDY}, {"select", FW_POLICY_SELECT}, {NULL, 0}};
static const choice_t k_switch[] = {
    {"runs", FW_SWITCH_RUNS}, {"operator", FW_SWITCH_OPERATOR}, {"auto", FW_SWITCH_AUTO}, {NULL, 0}};

// clang-format off
static const key_desc_t k_keys[] = {
  {"What to do", "task", KIND_TASK, OFF(task), 0, 0, false, false, NULL, "corridor",
   "learning task: one of the declared tasks (lib/tasks; b21r-controller --print-task-params lists "
   "them)"},
  {NULL, "task_params", KIND_STRING, OFF(task_params), 0, 0, false, false, NULL, "",
   "the task's parameters as name=value,name=value (each task declares its own, with its range: "
   "b21r-controller --print-task-params; \"\" = the task's defaults)"},
  {NULL, "mode", KIND_ENUM, OFF(mode), 0, 0, false, false, k_mode, "learn",
   "learn: the two-phase schedule; evaluate: one evaluation block of evaluate_policy, then exit"},
  {NULL, "evaluate_policy", KIND_ENUM, OFF(evaluate_policy), 0, 0, false, false, k_eval_policy, "learned",
   "policy evaluated when mode = evaluate (learned = the configured policy with the checkpoint's learned "
   "state; optimal = the hand-tuned reference controller; human = the simulated human driver)"},
  {NULL, "evaluate_example_gain", KIND_DOUBLE, OFF(evaluate_example_gain), 0, 100, false, false, NULL, "0",
   "evaluate_policy = example: the example policy's gain [1/s] (0 = the middle of its training range)"},
  {NULL, "example_gain_range", KIND_DLIST, OFF(example_gain_range), 0, 100, true, false, NULL, "",
   "the example policy's gains [1/s] as lowest,highest: each run's gain is drawn uniformly in between "
   "(\"\" = the task's range: b21r-controller --print-task-params)"},
  {NULL, "seed", KIND_U64, OFF(seed), 0, 9.2e18, false, false, NULL, "1",
   "root seed of every random generator (example gains, start poses, exploration)"},
  {NULL, "corridor_length_m", KIND_DOUBLE, OFF(corridor_length_m), 4, 200, false, false, NULL, "10",
   "corridor task: length from the start wall to the end wall [m]; must match the corridor driven "
   "(the paper's first corridor and its simulation: 10 m)"},

  {"Loop timing", "tick_rate_hz", KIND_DOUBLE, OFF(tick_rate_hz), 1, 100, false, false, NULL, "10",
   "control rate; absolute deadlines on the monotonic clock"},
  {NULL, "lockstep", KIND_BOOL, OFF(lockstep), 0, 0, false, false, NULL, "false",
   "tick when the emulator's data for the next period has arrived instead of on the clock"},
  {NULL, "lockstep_timeout_s", KIND_DOUBLE, OFF(lockstep_timeout_s), 0.01, 600, false, false, NULL, "30",
   "lockstep: a device silent this long (wall clock) ends the loop with status 5; the tick never runs without "
   "the period's data (generous: a loaded machine may stall the emulator for seconds). At start-up each CANopen "
   "enable cycle waits as long for the drives' answers (status 4 if one stays away)"},
  {NULL, "lockstep_realtime_factor", KIND_DOUBLE, OFF(lockstep_realtime_factor), 0, 10000, false, false, NULL, "0",
   "lockstep: at most this many times real time (1 = real time, 20 = 20 ticks of 0.1 s per second), so that "
   "lcm-spy and lcm-logger over UDP keep up; 0 = as fast as the emulator answers. The experiences do not "
   "depend on it"},
  {NULL, "late_start_threshold_s", KIND_DOUBLE, OFF(late_start_threshold_s), 0, 10, false, false, NULL, "0.01",
   "real time: a tick that starts more than this after its scheduled time counts as a late start (STATUS "
   "late_starts; a start a whole period late is a missed period)"},

  {"Real time (applied at start-up; see README, Real-time operation)", "rt_scheduler", KIND_ENUM,
   OFF(rt_scheduler), 0, 0, false, false, k_rt_scheduler, "other",
   "scheduling policy: other (time-sharing), fifo or rr (real-time; needs CAP_SYS_NICE or an RLIMIT_RTPRIO of "
   "at least rt_priority)"},
  {NULL, "rt_priority", KIND_INT, OFF(rt_priority), 1, 99, false, false, NULL, "50",
   "priority with rt_scheduler = fifo or rr (ignored with other); the kernel's interrupt threads run at 50"},
  {NULL, "rt_cpus", KIND_CPUS, OFF(rt_cpus), 0, 0, false, false, NULL, "",
   "CPUs the controller may run on, e.g. \"1\" or \"0,2-3\" (\"\" = any); pinning to a CPU kept free of "
   "other work (isolcpus) shortens wake-up latency"},
  {NULL, "rt_lock_memory", KIND_BOOL, OFF(rt_lock_memory), 0, 0, false, false, NULL, "false",
   "lock all memory in RAM (mlockall): no page is ever swapped out or faulted in during a tick; needs "
   "CAP_IPC_LOCK or an RLIMIT_MEMLOCK above the controller's size"},
  {NULL, "rt_prefault", KIND_BOOL, OFF(rt_prefault), 0, 0, false, false, NULL, "false",
   "touch every buffer (the learner's store, queues, checkpoint buffers, the stack) at start-up, so that no "
   "page fault happens in a tick while the store fills"},

  {"Devices", "laser_device", KIND_STRING, OFF(laser_device), 0, 0, false, false, NULL, "/dev/ttyUSB0",
   "serial device of the SICK LMS200"},
  {NULL, "laser_baud", KIND_ENUM, OFF(laser_baud), 0, 0, false, false, k_baud_laser, "38400",
   "LMS200 operating rate (the driver switches to it from laser_start_baud)"},
  {NULL, "laser_start_baud", KIND_ENUM, OFF(laser_start_baud), 0, 0, false, false, k_baud_laser, "9600",
   "rate the LMS200 listens on after power-up"},
  {NULL, "laser_fov_deg", KIND_ENUM, OFF(laser_fov_deg), 0, 0, false, false, k_fov, "180",
   "scan field [deg]"},
  {NULL, "laser_resolution_deg", KIND_ENUM, OFF(laser_resolution_cdeg), 0, 0, false, false, k_res, "1",
   "angular resolution [deg]; 0.25 only with laser_fov_deg = 100"},
  {NULL, "base_protocol", KIND_ENUM, OFF(base_protocol), 0, 0, false, false, k_proto, "rflex",
   "rflex: the B21r's serial base controller; canopen: CiA 402 drives over CAN"},
  {NULL, "base_device", KIND_STRING, OFF(base_device), 0, 0, false, false, NULL, "/dev/ttyS0",
   "rFLEX serial device"},
  {NULL, "base_baud", KIND_ENUM, OFF(base_baud), 0, 0, false, false, k_baud_base, "115200",
   "rFLEX serial rate"},
  {NULL, "base_write_gap_us", KIND_INT, OFF(base_write_gap_us), 0, 100000, false, false, NULL, "1000",
   "rFLEX: pause after each written packet (the controller's input buffer overflows otherwise; 0 for "
   "the emulator)"},
  {NULL, "can_interface", KIND_STRING, OFF(can_interface), 0, 0, false, false, NULL, "can0",
   "SocketCAN interface of the CANopen drives"},
  {NULL, "can_socket", KIND_STRING, OFF(can_socket), 0, 0, false, false, NULL, "",
   "SOCK_SEQPACKET socket of an emulated CAN bus; when set, used instead of can_interface"},
  {NULL, "can_node_translation", KIND_INT, OFF(can_node_translation), 1, 127, false, false, NULL, "1",
   "CANopen node id of the translation drive"},
  {NULL, "can_node_rotation", KIND_INT, OFF(can_node_rotation), 1, 127, false, false, NULL, "2",
   "CANopen node id of the rotation (steering) drive"},
  {NULL, "can_heartbeat_timeout_s", KIND_DOUBLE, OFF(can_heartbeat_timeout_s), 0, 10, false, false, NULL, "0.5",
   "a node's heartbeat (the drives', the bump-panel node's) silent this long is a base fault (0 = no heartbeat supervision; nodes that send none need 0)"},
  {NULL, "can_node_bumpers", KIND_INT, OFF(can_node_bumpers), 1, 127, false, false, NULL, "16",
   "CANopen node id of the CiA 401 digital-input node that reads the 14 bump panels (TPDO1 = COB-ID "
   "0x180 + id); with base_protocol = canopen the controller does not start without it"},
  {NULL, "can_bumper_timeout_s", KIND_DOUBLE, OFF(can_bumper_timeout_s), 0.05, 10, false, false, NULL, "0.35",
   "no bump-panel TPDO1 for this long is a base fault, since the bumpers are no longer watched (the node "
   "sends every 0.1 s; lockstep: rounded up to whole ticks)"},
  {NULL, "distance_counts_per_m", KIND_DOUBLE, OFF(distance_counts_per_m), 1, 1e7, false, false, NULL, "103000",
   "base translation conversion K_d (B21r rFLEX: 103000 counts/m)"},
  {NULL, "angle_counts_per_rad", KIND_DOUBLE, OFF(angle_counts_per_rad), 1, 1e7, false, false, NULL, "35000",
   "base rotation conversion K_a (B21r rFLEX: 35000 counts/rad)"},
  {NULL, "reposition", KIND_ENUM, OFF(reposition), 0, 0, false, false, k_reposition, "operator",
   "between runs: operator places the robot and sends CONFIRM_START_POSE, or the emulator resets it"},
  {NULL, "emulator_control", KIND_STRING, OFF(emulator_control), 0, 0, false, false, NULL, "",
   "control socket of the emulator (needed by reposition = emulator)"},
  {NULL, "emulator_reply_timeout_s", KIND_DOUBLE, OFF(emulator_reply_timeout_s), 0.01, 60, false, false, NULL, "5",
   "reposition = emulator: a start-pose request unanswered this long fails (and is retried). Real time: the "
   "tick never waits for the answer; lockstep: the answer is awaited as the period's data are, up to "
   "lockstep_timeout_s"},

  {"Command limits", "max_translation_mps", KIND_DOUBLE, OFF(max_translation_mps), 0, 2, false, false, NULL, "0.8",
   "translation speed limit [m/s]"},
  {NULL, "max_rotation_radps", KIND_DOUBLE, OFF(max_rotation_radps), 0, 4, true, false, NULL, "1",
   "rotation speed limit [rad/s]; also the learned action range [-limit, limit]"},
  {NULL, "max_translation_accel_mps2", KIND_DOUBLE, OFF(max_translation_accel_mps2), 0, 5, true, false, NULL, "0.7",
   "translation acceleration limit of commands [m/s^2]"},
  {NULL, "max_rotation_accel_radps2", KIND_DOUBLE, OFF(max_rotation_accel_radps2), 0, 20, true, false, NULL, "2.86",
   "rotation acceleration limit of commands [rad/s^2]"},

  {"Safety", "laser_timeout_s", KIND_DOUBLE, OFF(laser_timeout_s), 0.01, 10, false, false, NULL, "0.35",
   "no laser scan for this long stops the robot (lockstep: rounded up to whole ticks)"},
  {NULL, "base_timeout_s", KIND_DOUBLE, OFF(base_timeout_s), 0.01, 10, false, false, NULL, "0.35",
   "no odometry from the base for this long stops the robot (lockstep: whole ticks)"},
  {NULL, "teleop_timeout_s", KIND_DOUBLE, OFF(teleop_timeout_s), 0.01, 10, false, false, NULL, "0.3",
   "joystick driving: no fresh B21R_TELEOP with the deadman held for this long stops the robot"},
  {NULL, "safety_auto_resume", KIND_BOOL, OFF(safety_auto_resume), 0, 0, false, false, NULL, "true",
   "after a safety stop whose cause has cleared, start a new run without an operator RESUME"},
  {NULL, "safety_clear_ticks", KIND_INT, OFF(safety_clear_ticks), 1, 10000, false, false, NULL, "10",
   "ticks the cause must stay absent before resuming"},
  {NULL, "device_lost_action", KIND_ENUM, OFF(device_lost_action), 0, 0, false, false, k_device_lost, "reopen",
   "a device gone (end of file, EIO, ENODEV, hang-up): stop and reopen it with back-off until it is back, "
   "or stop and exit with status 6"},
  {NULL, "device_reopen_backoff_s", KIND_DOUBLE, OFF(device_reopen_backoff_s), 0.01, 60, false, false, NULL, "0.5",
   "first wait before reopening a lost device; doubles after each failed attempt"},
  {NULL, "device_reopen_backoff_max_s", KIND_DOUBLE, OFF(device_reopen_backoff_max_s), 0.01, 600, false, false, NULL,
   "5", "longest wait between attempts to reopen a lost device"},

  {"Learning", "alpha", KIND_DOUBLE, OFF(alpha), 0, 1, true, false, NULL, "0.2",
   "learning rate (the paper: 0.2)"},
  {NULL, "gamma", KIND_DOUBLE, OFF(gamma), 0, 1, false, true, NULL, "0",
   "discount factor; 0 = the task's (b21r-controller --print-task-params; the paper: corridor 0.99, "
   "obstacles 0.9)"},
  {NULL, "policy", KIND_ENUM, OFF(policy), 0, 0, false, false, k_policy, "greedy",
   "who acts where the learned policy acts: greedy = HEDGER's greedy action (the paper's, which imitates "
   "its teachers); actor = a policy learned between runs from the rewards of every training run (the "
   "slope of the return in the action, through local models of the dynamics and of the state value), "
   "guarded by HEDGER's values; select = both: phase two's training runs come in pairs from one start "
   "pose, one run each, and the one that saved more steps over the pairs acts in every other run "
   "(docs/LEARNING.md: what each gains and loses; the actor's between-run work costs about 0.94 billion "
   "instructions a run). HEDGER learns either way"},
  {NULL, "actor_capacity", KIND_INT, OFF(actor_capacity), 16, 4194304, false, false, NULL, "20000",
   "policy = actor or select: recorded transitions it keeps (fixed memory, about 270 bytes each with its models)"},
  {NULL, "actor_hidden", KIND_INT, OFF(actor_hidden), 1, 64, false, false, NULL, "16",
   "policy = actor or select: tanh units of its one hidden layer"},
  {NULL, "actor_runs", KIND_INT, OFF(actor_runs), 1, 100000, false, false, NULL, "10",
   "policy = actor or select: the recent runs whose returns give the state value and whose states it is improved at"},
  {NULL, "actor_queries", KIND_INT, OFF(actor_queries), 1, 4194304, false, false, NULL, "4000",
   "policy = actor or select: largest set of recent states it is improved at after a run (at most actor_capacity)"},
  {NULL, "actor_step_gain", KIND_DOUBLE, OFF(actor_step_gain), 0, 100, false, false, NULL, "0.3",
   "policy = actor or select: target step [rad/s] per tick of discounting that one rad/s gains"},
  {NULL, "actor_step_max", KIND_DOUBLE, OFF(actor_step_max), 0, 4, false, false, NULL, "0.1",
   "policy = actor or select: largest change of its target action after one run [rad/s]"},
  {NULL, "actor_trust_radius", KIND_DOUBLE, OFF(actor_trust_radius), 0, 4, false, false, NULL, "0",
   "policy = actor or select: largest distance of its target action from the action the runs took at that state [rad/s] "
   "(0: no bound)"},
  {NULL, "actor_guard_se", KIND_DOUBLE, OFF(actor_guard_se), 0, 100, false, false, NULL, "1",
   "policy = actor or select: its action is replaced by HEDGER's greedy action where the learned values put it more "
   "than this many standard errors below (0: never; docs/LEARNING.md)"},
  {NULL, "actor_guard_range", KIND_BOOL, OFF(actor_guard_range), 0, 0, false, false, NULL, "true",
   "policy = actor or select: its action is kept within the actions the learned data hold at the state, where the "
   "values judge it (docs/LEARNING.md)"},
  {NULL, "actor_slope_min_t", KIND_DOUBLE, OFF(actor_slope_min_t), 0, 100, false, false, NULL, "3",
   "policy = actor or select: it steps only where the slope of the return in the action is at least this many standard "
   "errors (clustered by run) from 0 (0: every slope)"},
  {NULL, "actor_rewarded_window", KIND_BOOL, OFF(actor_rewarded_window), 0, 0, false, false, NULL, "true",
   "policy = actor or select: the value window reaches back until it holds actor_runs runs that collected a reward "
   "(false: the last actor_runs runs)"},
  {NULL, "actor_fit_steps", KIND_INT, OFF(actor_fit_steps), 0, 100000, false, false, NULL, "200",
   "policy = actor or select: Adam steps of each fit to its targets"},
  {NULL, "actor_clone_steps", KIND_INT, OFF(actor_clone_steps), 0, 100000, false, false, NULL, "300",
   "policy = actor or select: Adam steps of the behaviour cloning after the first training run"},
  {NULL, "actor_learning_rate", KIND_DOUBLE, OFF(actor_learning_rate), 0, 1, true, false, NULL, "0.003",
   "policy = actor or select: Adam's learning rate"},
  {NULL, "actor_work_per_tick", KIND_INT, OFF(actor_work_per_tick), 1, 100000000, false, false, NULL, "1500",
   "between runs (the robot stands): the actor's learning per tick in work units of at most 2000 "
   "instructions (a slice may pass it by one query's 200 units); the default costs about what "
   "learn_updates_per_tick's 4 replay updates cost; bounds the tick's time"},
  {NULL, "learner", KIND_ENUM, OFF(learner), 0, 0, false, false, k_learner, "hedger",
   "value function: hedger (the paper's); lwa = HEDGER with locally weighted averaging only; tabular = "
   "Q-learning on a table of tabular_bins per state dimension x tabular_actions (no checkpoints)"},
  {NULL, "tabular_bins", KIND_INT, OFF(tabular_bins), 1, 64, false, false, NULL, "10",
   "learner = tabular: equal bins per state dimension over the task's state range (table = bins^dims x "
   "actions cells, 12 bytes each)"},
  {NULL, "tabular_actions", KIND_INT, OFF(tabular_actions), 2, 64, false, false, NULL, "9",
   "learner = tabular: evenly spaced rotation velocities over [-max_rotation_radps, max_rotation_radps]"},
  {NULL, "hedger_capacity", KIND_INT, OFF(hedger_capacity), 64, 1000000, false, false, NULL, "20000",
   "stored samples of the value function (fixed memory)"},
  {NULL, "hedger_k_min", KIND_INT, OFF(hedger_k_min), 1, 64, false, false, NULL, "6",
   "fewer neighbours than this and HEDGER answers 'unknown'"},
  {NULL, "hedger_k_max", KIND_INT, OFF(hedger_k_max), 2, 64, false, false, NULL, "48",
   "neighbourhood size of a prediction (cost: the tick's greedy search and update grow with it)"},
  {NULL, "hedger_bandwidth", KIND_DOUBLE, OFF(hedger_bandwidth), 0, 100, true, false, NULL, "0.25",
   "kernel bandwidth h in scaled input units (inputs scaled to about [0, 1])"},
  {NULL, "hedger_input_scale", KIND_DLIST, OFF(hedger_input_scale), 0, 1000, true, false, NULL, "",
   "raw units per scaled unit, comma-separated: each state dimension then the action (\"\" = the task's: "
   "b21r-controller --print-task-params; with state_rotation the executed rotation comes before the action, at "
   "1 rad/s)"},
  {NULL, "hedger_merge_radius", KIND_DOUBLE, OFF(hedger_merge_radius), 0, 10, false, false, NULL, "0.02",
   "a new sample closer than this (scaled units) to a stored one is merged into it"},
  {NULL, "hedger_greedy_actions", KIND_INT, OFF(hedger_greedy_actions), 2, 64, false, false, NULL, "9",
   "evenly spaced actions the greedy search scans before refining"},
  {NULL, "hedger_replay", KIND_BOOL, OFF(hedger_replay), 0, 0, false, false, NULL, "true",
   "replay every finished training run backwards (propagates the sparse reward faster)"},
  {NULL, "learn_updates_per_tick", KIND_INT, OFF(learn_updates_per_tick), 1, 100000, false, false, NULL, "4",
   "between runs (the robot stands): backward-replay updates per tick; bounds the tick's time (one update "
   "costs about 0.27 ms of CPU at 20k stored points on a 2-core x86-64; see README)"},
  {NULL, "checkpoint_points_per_tick", KIND_INT, OFF(checkpoint_points_per_tick), 1, 100000000, false, false, NULL,
   "4096", "between runs: stored points serialised into the checkpoint per tick; bounds the tick's time"},
  {NULL, "hedger_replay_passes", KIND_INT, OFF(hedger_replay_passes), 1, 64, false, false, NULL, "3",
   "backward passes over every finished training run (between runs, sliced over ticks)"},
  {NULL, "hedger_replay_lambda", KIND_DOUBLE, OFF(hedger_replay_lambda), 0, 1, false, false, NULL, "0.9",
   "target of the replay: the lambda-return, 0 = Q-learning's r + gamma max Q, 1 = the run's own return"},
  {NULL, "hedger_replay_alpha", KIND_DOUBLE, OFF(hedger_replay_alpha), 0, 1, false, false, NULL, "0.7741",
   "learning rate of the replay's updates (0 = alpha): 3 passes of 0.7741 move a value as far as 20 passes "
   "of alpha 0.2 (1 - 0.7741 = 0.8^(20/3)) with 3/20 of the updates; with another alpha or pass count, "
   "1 - (1 - alpha)^(20 / passes) keeps that reach"},
  {NULL, "hedger_greedy_method", KIND_ENUM, OFF(hedger_greedy_method), 0, 0, false, false, k_greedy, "state_model",
   "greedy action: per_action = one prediction per candidate; state_model = one local model at the "
   "state, quadratic in the action (falls back to per_action where it cannot be formed)"},
  {NULL, "hedger_greedy_pessimism", KIND_DOUBLE, OFF(hedger_greedy_pessimism), 0, 1000, false, false, NULL, "4",
   "the greedy search ranks actions by value - this x the regression's standard error"},
  {NULL, "hedger_greedy_reach", KIND_DOUBLE, OFF(hedger_greedy_reach), 0, 100, false, false, NULL, "0",
   "state_model: where a state has too few neighbours, form the model again with the kernel widened by "
   "this factor (1 = no; 0 = the task's: b21r-controller --print-task-params)"},
  {NULL, "phase_one_driver", KIND_ENUM, OFF(phase_driver), 0, 0, false, false, k_driver, "example",
   "phase one is driven by the example policy (code), the operator's joystick (B21R_TELEOP), or a "
   "simulated sloppy human driver (code)"},
  {NULL, "phase_switch", KIND_ENUM, OFF(phase_switch), 0, 0, false, false, k_switch, "runs",
   "phase two starts after phase_one_runs, only on START_PHASE_TWO, or automatically when ready"},
  {NULL, "phase_one_runs", KIND_INT, OFF(phase_one_runs), 0, 100000, false, false, NULL, "30",
   "training runs in phase one (the paper: 30); upper bound for phase_switch = auto"},
  {NULL, "phase_two_runs", KIND_INT, OFF(phase_two_runs), 0, 100000, false, false, NULL, "35",
   "training runs in phase two before the schedule ends (the paper: 35)"},
  {NULL, "auto_switch_min_runs", KIND_INT, OFF(auto_switch_min_runs), 0, 100000, false, false, NULL, "5",
   "phase_switch = auto: never before this many phase-one runs"},
  {NULL, "auto_switch_ratio", KIND_DOUBLE, OFF(auto_switch_ratio), 0, 10, true, false, NULL, "1.5",
   "auto: switch when an evaluation reaches the goal from every start and its mean steps are at most "
   "ratio x the mean of the phase-one runs"},
  {NULL, "eval_every_runs", KIND_INT, OFF(eval_every_runs), 1, 100000, false, false, NULL, "5",
   "an evaluation block (learning off) after every N training runs (the paper: 5)"},
  {NULL, "eval_starts", KIND_INT, OFF(eval_starts), 1, 16, false, false, NULL, "10",
   "fixed start poses per evaluation block (the paper: 10)"},
  {NULL, "eval_poses", KIND_POSES, OFF(eval_poses), 0, 0, false, false, NULL, "",
   "the evaluation blocks' start poses as \"x,y,theta; x,y,theta; ...\" [m, m, rad; the task frame], at least "
   "eval_starts of them (\"\" = the task's own poses); training starts stay around the task's poses, so the "
   "learned policy can be evaluated from poses it never started near"},
  {NULL, "eval_at_start", KIND_BOOL, OFF(eval_at_start), 0, 0, false, false, NULL, "false",
   "also run an evaluation block before the first training run"},
  {NULL, "max_steps_per_run", KIND_INT, OFF(max_steps_per_run), 0, 1000000, false, false, NULL, "0",
   "step limit of a run (0 = the task's own limit)"},
  {NULL, "explore_sigma_radps", KIND_DOUBLE, OFF(explore_sigma_radps), 0, 4, false, false, NULL, "0.1",
   "phase two: standard deviation of the offset an exploration segment adds to the greedy action [rad/s]"},
  {NULL, "explore_probability", KIND_DOUBLE, OFF(explore_probability), 0, 1, false, false, NULL, "0.2",
   "probability per training decision (outside a segment; a decision is decision_ticks steps) that an "
   "exploration segment starts; phase one's example dither (example_noise_radps) starts its segments the "
   "same way"},
  {NULL, "explore_hold_s", KIND_DOUBLE, OFF(explore_hold_s), 0, 100, false, false, NULL, "0",
   "duration of an exploration segment, and of a phase-one dither segment: one offset held this long (0 = "
   "one step)"},
  {NULL, "advisor", KIND_BOOL, OFF(advisor), 0, 0, false, false, NULL, "true",
   "phase two training: the example policy acts where the learned policy knows no action at all (greedy: "
   "HEDGER knows none at the state; actor: nothing learned yet)"},
  {NULL, "example_noise_radps", KIND_DOUBLE, OFF(example_noise_radps), 0, 4, false, false, NULL, "0.3",
   "phase one, example driver: standard deviation of the Gaussian offset a dither segment adds to the "
   "example's action [rad/s]; segments start with explore_probability per step and last explore_hold_s "
   "(spreads the actions the learner sees around the example's)"},
  {NULL, "state_rotation", KIND_BOOL, OFF(state_rotation), 0, 0, false, false, NULL, "true",
   "the learner's state ends with the rotation the base executes, the last command sent [rad/s]: the "
   "acceleration limit ties the next rotation to it (false = the paper's task features alone)"},
  {NULL, "decision_ticks", KIND_INT, OFF(decision_ticks), 1, FW_DECISION_TICKS_MAX, false, false, NULL, "2",
   "the driver and the learned policy decide every this many control ticks and the rotation holds in "
   "between; the learner learns each decision as one step (discount gamma^N): a decision moves the robot "
   "far enough for the values to rank it (2: with the greedy policy as short or shorter paths than 1 on "
   "every task measured, Fig. 5's human corridor 5 % shorter; 1 = every tick, the paper's: "
   "docs/LEARNING.md). Exploration and dither segments count decisions"},

  {"Output", "lcm_url", KIND_STRING, OFF(lcm_url), 0, 0, false, false, NULL, "",
   "LCM provider (\"\" = LCM's default or $LCM_DEFAULT_URL; \"none\" = no LCM)"},
  {NULL, "lcm_scope", KIND_ENUM, OFF(lcm_scope), 0, 0, false, false, k_lcm_scope, "host",
   "who exchanges LCM messages with the controller. host: this machine only (udpm with ttl=0, memq or "
   "file; the controller takes only what came over loopback, so no other machine reaches it, not even by "
   "unicast to its port). network: other machines too (a udpm ttl of 1, tcpq): everyone on that network sees "
   "every message and can send to the controller, which still takes only operator messages signed with "
   "operator_key_file (docs/robot.md, \"Network and security\")"},
  {NULL, "operator_key_file", KIND_STRING, OFF(operator_key_file), 0, 0, false, false, NULL, "",
   "operator key: B21R_TELEOP and B21R_COMMAND are taken only when signed with it for this start of the "
   "controller (B21R_SESSION); a file of 64 hexadecimal digits that only its owner (the controller's user or "
   "root) may read or write, made by tools/b21r_key.py create FILE (e.g. /etc/b21r/operator.key). \"\" = no "
   "key: every operator message is refused, so joystick driving and reposition = operator need one"},
  {NULL, "status_period_ticks", KIND_INT, OFF(status_period_ticks), 1, 100000, false, false, NULL, "1",
   "publish B21R_STATUS every N ticks"},
  {NULL, "publish_scan", KIND_BOOL, OFF(publish_scan), 0, 0, false, false, NULL, "false",
   "also publish every decoded scan on B21R_SCAN"},
  {NULL, "queue_capacity", KIND_INT, OFF(queue_capacity), 16, 65536, false, false, NULL, "1024",
   "publisher queue slots (a power of two); a full queue drops and counts, never blocks the tick"},
  {NULL, "checkpoint_file", KIND_STRING, OFF(checkpoint_file), 0, 0, false, false, NULL, "",
   "learned state, written atomically after every run and at shutdown; loaded at start-up "
   "(\"\" = no checkpoints: learned data is lost at exit)"},
  {NULL, "log_file", KIND_STRING, OFF(log_file), 0, 0, false, false, NULL, "",
   "LCM event log of every published message, the received B21R_TELEOP / B21R_COMMAND and B21R_CONFIG "
   "(\"\" = none); event timestamps are wall clock, the controller's time is each message's utime"},
  {NULL, "experience_log_file", KIND_STRING, OFF(experience_log_file), 0, 0, false, false, NULL, "",
   "LCM event log of B21R_EXPERIENCE only (\"\" = none); bit-identical for identical runs in lockstep"},
  {NULL, "progress", KIND_BOOL, OFF(progress), 0, 0, false, false, NULL, "false",
   "print one line per finished run and evaluation block on stdout"},
};
// clang-format on

#define N_KEYS (sizeof k_keys / sizeof k_keys[0])
_Static_assert(N_KEYS <= FW_CONFIG_MAX_KEYS, "raise FW_CONFIG_MAX_KEYS");
_Static_assert(FW_CONFIG_MAX_SOURCES <= 255U, "source indices are uint8_t");

// The program that reads these settings, for the hints in error messages.
#define REFERENCE_HINT "b21r-controller --print-reference-config lists every key with its documentation"

static const key_desc_t* find_key(const char* name) {
  for (size_t i = 0; i < N_KEYS; ++i) {
    // The first letter rules out most keys without a string comparison.
    if (k_keys[i].name[0] == name[0] && strcmp(k_keys[i].name, name) == 0) {
      return &k_keys[i];
    }
  }
  return NULL;
}

// Edit distance with adjacent transpositions (optimal string alignment), so that one typo, a
// dropped or extra letter, or two swapped letters each count 1. Three rolling rows; names are
// compared on their first KEY_CMP_MAX characters (every key is shorter).
#define KEY_CMP_MAX 48U
static size_t bounded_len(const char* s) {
  size_t n = 0;
  while (n < KEY_CMP_MAX && s[n] != '\0') {
    ++n;
  }
  return n;
}

// Returns the distance, or some value above `limit` as soon as it is certain to exceed it. Only
// the diagonal band |i - j| <= limit is computed (a cell outside it is above the limit: "far", the
// limit + 1), and a row's minimum never falls below the smaller of the previous row's minimum and
// the one before's plus one, so two rows in a row above the limit end the work. An unknown name
// costs a few short rows per key instead of the whole table.
static size_t edit_distance_within(const char* a, const char* b, size_t limit) {
  const size_t na = bounded_len(a);
  const size_t nb = bounded_len(b);
  const size_t far = limit + 1U;
  if ((na > nb ? na - nb : nb - na) > limit) {
    return far;
  }
  size_t rows[3][KEY_CMP_MAX + 2U];
  size_t* prev2 = rows[0];
  size_t* prev = rows[1];
  size_t* cur = rows[2];
  for (size_t j = 0; j <= nb + 1U; ++j) {
    prev[j] = j <= limit ? j : far;
    prev2[j] = far;
  }
  bool prev_over = false;  // the previous row's minimum exceeds the limit
  for (size_t i = 1; i <= na; ++i) {
    const size_t lo = i > limit ? i - limit : 1U;
    const size_t hi = i + limit < nb ? i + limit : nb;
    cur[lo - 1U] = lo == 1U && i <= limit ? i : far;
    size_t row_min = cur[lo - 1U];
    for (size_t j = lo; j <= hi; ++j) {
      const size_t cost = a[i - 1] == b[j - 1] ? 0U : 1U;
      size_t best = prev[j] + 1U;
      if (cur[j - 1] + 1U < best) {
        best = cur[j - 1] + 1U;
      }
      if (prev[j - 1] + cost < best) {
        best = prev[j - 1] + cost;
      }
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] && prev2[j - 2] + 1U < best) {
        best = prev2[j - 2] + 1U;
      }
      cur[j] = best < far ? best : far;
      row_min = cur[j] < row_min ? cur[j] : row_min;
    }
    if (hi < nb) {
      cur[hi + 1U] = far;  // read by the next row as its band moves right
    }
    if (row_min > limit && prev_over) {
      return far;
    }
    prev_over = row_min > limit;
    size_t* t = prev2;
    prev2 = prev;
    prev = cur;
    cur = t;
  }
  return prev[nb];
}

// The known key an unknown name most likely meant, or NULL when none is close: within a third
// of the name's length in edits (at least 2, at most 6), or a key that starts with the name (a
// unit suffix left out: "max_rotation" → "max_rotation_radps"). Ties go to the earlier key.
static const key_desc_t* nearest_key(const char* name) {
  const size_t n = strlen(name);
  const size_t limit = n / 3U < 2U ? 2U : (n / 3U > 6U ? 6U : n / 3U);
  const key_desc_t* best = NULL;
  size_t best_d = SIZE_MAX;
  for (size_t i = 0; i < N_KEYS; ++i) {
    // The distance is at least the difference of the lengths: a key too short or too long to be
    // within the limit is only a candidate by the prefix rule (a long name costs no table scan).
    const size_t kn = strlen(k_keys[i].name);
    size_t d = (kn > n ? kn - n : n - kn) > limit ? SIZE_MAX : edit_distance_within(name, k_keys[i].name, limit);
    if (d > limit && n >= 4U && strncmp(k_keys[i].name, name, n) == 0) {
      d = limit;  // a prefix of a key counts as close, after any real near-miss
    }
    if (d <= limit && d < best_d) {
      best = &k_keys[i];
      best_d = d;
    }
  }
  return best;
}

// Splits "path:123" into the source name and the line (0 when the source is not "name:digits").
static uint32_t split_source(const char* source, size_t* name_len) {
  const char* colon = strrchr(source, ':');
  *name_len = strlen(source);
  if (colon == NULL || colon[1] == '\0') {
    return 0;
  }
  uint32_t line = 0;
  for (const char* p = colon + 1; *p != '\0'; ++p) {
    if (*p < '0' || *p > '9' || line > 100000000U) {
      return 0;
    }
    line = line * 10U + (uint32_t)(*p - '0');
  }
  *name_len = (size_t)(colon - source);
  return line;
}

// Remembers that key k was set from source ("default" = the table's default).
static void note_origin(fw_config_t* cfg, const key_desc_t* k, const char* source) {
  fw_config_origins_t* o = &cfg->origins;
  const size_t ki = (size_t)(k - k_keys);
  size_t len = 0;
  const uint32_t line = split_source(source, &len);
  uint8_t index = 0;
  if (strcmp(source, "default") != 0) {
    index = FW_CONFIG_MAX_SOURCES;  // none yet
    for (uint8_t i = 1; i < FW_CONFIG_MAX_SOURCES; ++i) {
      if (o->source[i][0] == '\0' && len < FW_CONFIG_STR_MAX) {
        memcpy(o->source[i], source, len);
        o->source[i][len] = '\0';
        index = i;
        break;
      }
      if (strlen(o->source[i]) == len && strncmp(o->source[i], source, len) == 0) {
        index = i;
        break;
      }
    }
  }
  o->key_source[ki] = index;
  o->key_line[ki] = line;
}

static void origin_text(const fw_config_t* cfg, const key_desc_t* k, char* out, size_t cap) {
  const fw_config_origins_t* o = &cfg->origins;
  const size_t ki = (size_t)(k - k_keys);
  const uint8_t index = o->key_source[ki];
  if (index == 0) {
    snprintf(out, cap, "default");
  } else if (index >= FW_CONFIG_MAX_SOURCES) {
    snprintf(out, cap, "an earlier setting");
  } else if (o->key_line[ki] > 0) {
    snprintf(out, cap, "%s:%u", o->source[index], (unsigned)o->key_line[ki]);
  } else {
    snprintf(out, cap, "%s", o->source[index]);
  }
}

void fw_config_origin(const fw_config_t* cfg, const char* key, char* out, size_t out_cap) {
  const key_desc_t* k = find_key(key);
  if (k == NULL) {
    snprintf(out, out_cap, "unknown key");
    return;
  }
  origin_text(cfg, k, out, out_cap);
}

// Text of the allowed values of a key, for error messages and the reference output.
static void describe_allowed(const key_desc_t* k, char* out, size_t cap) {
  switch (k->kind) {
    case KIND_BOOL:
      snprintf(out, cap, "true or false");  // exactly what parse_bool accepts
      break;
    case KIND_INT:
      snprintf(out, cap, "an integer in [%.0f, %.0f]", k->min, k->max);
      break;
    case KIND_U64:
      snprintf(out, cap, "an integer in [0, %.3g]", k->max);
      break;
    case KIND_DOUBLE:
      snprintf(out, cap, "a number in %c%g, %g%c", k->min_open ? '(' : '[', k->min, k->max,
               k->max_open ? ')' : ']');
      break;
    case KIND_STRING:
      snprintf(out, cap, "text of at most %u characters, without double quotes or control characters",
               FW_CONFIG_STR_MAX - 1U);
      break;
    case KIND_DLIST:
      snprintf(out, cap, "empty, or 1 to %d comma-separated numbers in (%g, %g]", FW_CONFIG_MAX_SCALES, k->min, k->max);
      break;
    case KIND_CPUS:
      snprintf(out, cap, "empty (any CPU), or comma-separated CPU numbers and ranges in [0, %d], e.g. 1 or 0,2-3",
               FW_CONFIG_MAX_CPUS - 1);
      break;
    case KIND_ENUM: {
      size_t used = (size_t)snprintf(out, cap, "one of");
      for (const choice_t* c = k->choices; c->name != NULL && used < cap; ++c) {
        used += (size_t)snprintf(out + used, cap - used, "%s %s", c == k->choices ? "" : ",", c->name);
      }
      break;
    }
    case KIND_TASK: {
      size_t used = (size_t)snprintf(out, cap, "one of the declared tasks:");
      for (uint32_t t = 0; t < tasks_count() && used < cap; ++t) {
        used += (size_t)snprintf(out + used, cap - used, "%s %s", t == 0 ? "" : ",", tasks_decl_at(t)->name);
      }
      break;
    }
    case KIND_POSES:
      snprintf(out, cap, "empty, or 1 to %d poses \"x,y,theta\" separated by ';' (finite numbers)", FW_CONFIG_MAX_POSES);
      break;
  }
}

// "x,y,theta; x,y,theta; ..." into out (3 doubles per pose); the pose count, or -1 when malformed.
static int parse_poses(const char* v, double* out) {
  int n = 0;
  const char* p = v;
  while (*p == ' ') {
    ++p;
  }
  if (*p == '\0') {
    return 0;
  }
  for (;;) {
    if (n >= FW_CONFIG_MAX_POSES) {
      return -1;
    }
    for (int c = 0; c < 3; ++c) {
      char* end = NULL;
      errno = 0;
      const double x = strtod(p, &end);
      if (end == p || errno != 0 || !isfinite(x)) {
        return -1;
      }
      out[3 * n + c] = x;
      p = end;
      while (*p == ' ') {
        ++p;
      }
      if (c < 2) {
        if (*p != ',') {
          return -1;
        }
        ++p;
      }
    }
    ++n;
    if (*p == '\0') {
      return n;
    }
    if (*p != ';') {
      return -1;
    }
    ++p;
  }
}

// One spelling per value, the one fw_config_print() writes and the error text names.
static bool parse_bool(const char* v, bool* out) {
  if (strcmp(v, "true") == 0 || strcmp(v, "false") == 0) {
    *out = v[0] == 't';
    return true;
  }
  return false;
}

static bool parse_double(const char* v, double* out) {
  if (*v == '\0') {
    return false;
  }
  char* end = NULL;
  errno = 0;
  const double d = strtod(v, &end);
  if (errno != 0 || end == v || *end != '\0' || !isfinite(d)) {
    return false;
  }
  *out = d;
  return true;
}

// A string setting must survive fw_config_print and a reload: the file format has no escapes, so
// a double quote (or a line break, or another control character) in a value cannot be written.
static bool printable_text(const char* v) {
  for (const unsigned char* p = (const unsigned char*)v; *p != '\0'; ++p) {
    if (*p == '"' || *p < 0x20U || *p == 0x7FU) {
      return false;
    }
  }
  return true;
}

static bool in_range(const key_desc_t* k, double d) {
  const bool lo = k->min_open ? d > k->min : d >= k->min;
  const bool hi = k->max_open ? d < k->max : d <= k->max;
  return lo && hi;
}

// A CPU number in [0, FW_CONFIG_MAX_CPUS) at *p (digits only); advances *p.
static bool parse_cpu(const char** p, int* cpu) {
  const char* s = *p;
  int n = 0;
  if (*s < '0' || *s > '9') {
    return false;
  }
  while (*s >= '0' && *s <= '9') {
    n = n * 10 + (*s - '0');
    if (n >= FW_CONFIG_MAX_CPUS) {
      return false;
    }
    ++s;
  }
  *p = s;
  *cpu = n;
  return true;
}

// "" or "a,b-c,..." (blanks around items allowed) → mask. A range must not run backwards.
static bool parse_cpus(const char* v, uint64_t* out) {
  uint64_t mask = 0;
  const char* p = v;
  while (*p == ' ') {
    ++p;
  }
  if (*p == '\0') {
    *out = 0;
    return true;
  }
  for (;;) {
    while (*p == ' ') {
      ++p;
    }
    int lo = 0;
    if (!parse_cpu(&p, &lo)) {
      return false;
    }
    int hi = lo;
    if (*p == '-') {
      ++p;
      if (!parse_cpu(&p, &hi) || hi < lo) {
        return false;
      }
    }
    for (int c = lo; c <= hi; ++c) {
      mask |= UINT64_C(1) << c;
    }
    while (*p == ' ') {
      ++p;
    }
    if (*p == '\0') {
      break;
    }
    if (*p != ',') {
      return false;
    }
    ++p;
  }
  *out = mask;
  return true;
}

void fw_config_format_cpus(uint64_t mask, char* out, size_t cap) {
  if (cap == 0) {
    return;
  }
  out[0] = '\0';
  size_t used = 0;
  for (int c = 0; c < FW_CONFIG_MAX_CPUS && used < cap;) {
    if ((mask >> c & 1U) == 0U) {
      ++c;
      continue;
    }
    int end = c;
    while (end + 1 < FW_CONFIG_MAX_CPUS && (mask >> (end + 1) & 1U) != 0U) {
      ++end;
    }
    const char* sep = used == 0 ? "" : ",";
    const int w = end == c ? snprintf(out + used, cap - used, "%s%d", sep, c)
                           : snprintf(out + used, cap - used, "%s%d-%d", sep, c, end);
    used += w > 0 ? (size_t)w : 0U;
    c = end + 1;
  }
}

// Parses value into k's field. Returns 0, or -1 (the field is then unchanged).
static int set_value(fw_config_t* cfg, const key_desc_t* k, const char* value) {
  char* field = (char*)cfg + k->offset;
  switch (k->kind) {
    case KIND_BOOL: {
      bool b = false;
      if (!parse_bool(value, &b)) {
        break;
      }
      memcpy(field, &b, sizeof b);
      return 0;
    }
    case KIND_INT: {
      char* end = NULL;
      errno = 0;
      const long long n = strtoll(value, &end, 10);
      if (*value == '\0' || errno != 0 || *end != '\0' || !in_range(k, (double)n)) {
        break;
      }
      const int32_t i = (int32_t)n;
      memcpy(field, &i, sizeof i);
      return 0;
    }
    case KIND_U64: {
      char* end = NULL;
      errno = 0;
      if (*value == '\0' || value[0] == '-' || value[0] == '+') {
        break;
      }
      const unsigned long long n = strtoull(value, &end, 10);
      if (errno != 0 || *end != '\0' || (double)n > k->max) {
        break;
      }
      const uint64_t u = (uint64_t)n;
      memcpy(field, &u, sizeof u);
      return 0;
    }
    case KIND_DOUBLE: {
      double d = 0.0;
      if (!parse_double(value, &d) || !in_range(k, d)) {
        break;
      }
      memcpy(field, &d, sizeof d);
      return 0;
    }
    case KIND_STRING: {
      const size_t n = strlen(value);
      if (n >= FW_CONFIG_STR_MAX || !printable_text(value)) {
        break;
      }
      // The whole field, so that no tail of an earlier, longer value stays behind the NUL: equal
      // settings are equal bytes.
      memset(field, 0, FW_CONFIG_STR_MAX);
      memcpy(field, value, n);
      return 0;
    }
    case KIND_DLIST: {
      double vals[FW_CONFIG_MAX_SCALES];
      int32_t n = 0;
      bool ok = true;
      char buf[FW_CONFIG_STR_MAX];
      if (strlen(value) >= sizeof buf) {
        break;
      }
      strcpy(buf, value);
      for (char* tok = buf; ok && *tok != '\0';) {
        char* comma = strchr(tok, ',');
        if (comma != NULL) {
          *comma = '\0';
        }
        char* t = tok;
        while (*t == ' ') {
          ++t;
        }
        size_t tl = strlen(t);
        while (tl > 0 && t[tl - 1] == ' ') {
          t[--tl] = '\0';
        }
        double d = 0.0;
        if (n >= FW_CONFIG_MAX_SCALES || !parse_double(t, &d) || !in_range(k, d)) {
          ok = false;
          break;
        }
        vals[n++] = d;
        if (comma == NULL) {
          break;
        }
        tok = comma + 1;
        if (*tok == '\0') {
          ok = false;  // trailing comma
        }
      }
      if (!ok) {
        break;
      }
      double* dst = (double*)(void*)field;
      memset(dst, 0, FW_CONFIG_MAX_SCALES * sizeof(double));
      memcpy(dst, vals, (size_t)n * sizeof(double));
      memcpy(field + FW_CONFIG_MAX_SCALES * sizeof(double), &n, sizeof n);
      return 0;
    }
    case KIND_CPUS: {
      uint64_t mask = 0;
      if (!parse_cpus(value, &mask)) {
        break;
      }
      memcpy(field, &mask, sizeof mask);
      return 0;
    }
    case KIND_ENUM:
      for (const choice_t* c = k->choices; c->name != NULL; ++c) {
        if (strcmp(c->name, value) == 0) {
          memcpy(field, &c->value, sizeof c->value);
          return 0;
        }
      }
      break;
    case KIND_TASK: {
      const tasks_decl_t* d = tasks_find(value);
      if (d == NULL) {
        break;
      }
      const int32_t id = (int32_t)d->id;
      memcpy(field, &id, sizeof id);
      return 0;
    }
    case KIND_POSES: {
      double poses[3 * FW_CONFIG_MAX_POSES];
      const int n = parse_poses(value, poses);
      if (n < 0) {
        break;
      }
      double* dst = (double*)(void*)field;
      memset(dst, 0, sizeof poses);
      memcpy(dst, poses, (size_t)n * 3U * sizeof(double));
      const int32_t count = n;
      memcpy(field + sizeof poses, &count, sizeof count);
      return 0;
    }
  }
  return -1;
}

// Keys of earlier controllers that no longer exist, with why: a file that sets one meant a
// behaviour this controller does not have, so it is refused with the fix rather than ignored.
static const char* const k_retired_pairs[] = {
    "pair_runs", "pair_gain_sigma", "pair_centring_sigma", "pair_imitation_sigma", "pair_obstacle_clearance_m",
    "pair_tau_steps", "pair_recency_runs", "pair_shift_rate", "pair_shift_tau_steps", "pair_shift_decay_pairs",
    "pair_phase_one", "pair_phase_one_from_run", "pair_safety", "pair_safety_margin_m", "pair_safety_horizon_s",
    "pair_shift_vet", "pair_shift_vet_starts", "pair_shift_vet_periods_per_tick", "obstacle_pass_hold_steps", NULL};

static bool retired(const char* key) {
  for (const char* const* r = k_retired_pairs; *r != NULL; ++r) {
    if (strcmp(*r, key) == 0) {
      return true;
    }
  }
  return false;
}

int fw_config_set(fw_config_t* cfg, const char* key, const char* value, const char* source, char* err,
                  size_t err_cap) {
  const key_desc_t* k = find_key(key);
  if (k == NULL && retired(key)) {
    fw_errfmt(err, err_cap,
              "%s: key '%s' no longer exists: the ranked pairs of runs, their policy shift and the hold past the "
              "obstacle were removed (the learned policy now comes from the learned values alone, docs/LEARNING.md); "
              "delete the line",
              source, key);
    return -1;
  }
  if (k == NULL) {
    const key_desc_t* near = nearest_key(key);
    if (near != NULL) {
      fw_errfmt(err, err_cap, "%s: unknown key '%s'; did you mean '%s'? (%s)", source, key, near->name, REFERENCE_HINT);
    } else {
      fw_errfmt(err, err_cap, "%s: unknown key '%s' (%s)", source, key, REFERENCE_HINT);
    }
    return -1;
  }
  if (set_value(cfg, k, value) == 0) {
    note_origin(cfg, k, source);
    return 0;
  }
  char allowed[256];
  describe_allowed(k, allowed, sizeof allowed);
  fw_errfmt(err, err_cap, "%s: bad value '%s' for key '%s': expected %s (default %s)", source, value, key, allowed,
      k->def[0] != '\0' ? k->def : "\"\"");
  return -1;
}

bool fw_config_has_key(const char* key) { return find_key(key) != NULL; }

void fw_config_defaults(fw_config_t* cfg) {
  memset(cfg, 0, sizeof *cfg);
  for (size_t i = 0; i < N_KEYS; ++i) {
    // The defaults are literals checked by the unit tests; a failure here is a programming error.
    (void)fw_config_set(cfg, k_keys[i].name, k_keys[i].def, "default", NULL, 0);
  }
}

static char* trim(char* s) {
  while (*s == ' ' || *s == '\t') {
    ++s;
  }
  size_t n = strlen(s);
  while (n > 0 && (s[n - 1] == ' ' || s[n - 1] == '\t' || s[n - 1] == '\r' || s[n - 1] == '\n')) {
    s[--n] = '\0';
  }
  return s;
}

// Splits "key = value  # comment" in place. Returns 0 (blank/comment: *key = NULL), 1 (pair),
// -1 with a message on a syntax error.
static int split_line(char* line, char** key, char** value, char* why, size_t why_cap) {
  *key = NULL;
  *value = NULL;
  // Strip a comment that is not inside double quotes.
  bool quoted = false;
  for (char* p = line; *p != '\0'; ++p) {
    if (*p == '"') {
      quoted = !quoted;
    } else if (*p == '#' && !quoted) {
      *p = '\0';
      break;
    }
  }
  char* s = trim(line);
  if (*s == '\0') {
    return 0;
  }
  char* eq = strchr(s, '=');
  if (eq == NULL) {
    fw_errfmt(why, why_cap, "expected 'key = value', got '%s'", s);
    return -1;
  }
  *eq = '\0';
  char* k = trim(s);
  char* v = trim(eq + 1);
  if (*k == '\0') {
    fw_errfmt(why, why_cap, "missing key before '='");
    return -1;
  }
  const size_t n = strlen(v);
  if (n > 0 && v[0] == '"') {
    if (n < 2 || v[n - 1] != '"') {
      fw_errfmt(why, why_cap, "unterminated quoted value for key '%s'", k);
      return -1;
    }
    v[n - 1] = '\0';
    ++v;
  }
  *key = k;
  *value = v;
  return 1;
}

int fw_config_set_arg(fw_config_t* cfg, const char* key_eq_value, char* err, size_t err_cap) {
  char buf[1024];
  const size_t n = strlen(key_eq_value);
  if (n >= sizeof buf) {
    fw_errfmt(err, err_cap, "--set: argument longer than %zu characters", sizeof buf - 1);
    return -1;
  }
  memcpy(buf, key_eq_value, n + 1);
  char* key = NULL;
  char* value = NULL;
  char why[FW_CONFIG_ERR_MAX];
  const int r = split_line(buf, &key, &value, why, sizeof why);
  if (r <= 0) {
    fw_errfmt(err, err_cap, "--set '%s': %s", key_eq_value, r == 0 ? "expected key=value" : why);
    return -1;
  }
  return fw_config_set(cfg, key, value, "--set", err, err_cap);
}

int fw_config_load_file(fw_config_t* cfg, const char* path, char* err, size_t err_cap) {
  return fw_config_load_file_with(cfg, path, NULL, NULL, err, err_cap);
}

// Extra keys seen in one file, for the once-per-file rule (names are short; a file has few).
#define EXTRA_SEEN_MAX 64
#define EXTRA_KEY_MAX 64

int fw_config_load_file_with(fw_config_t* cfg, const char* path, fw_config_extra_key_fn extra, void* user,
                             char* err, size_t err_cap) {
  FILE* f = fopen(path, "r");
  if (f == NULL) {
    fw_errfmt(err, err_cap, "%s: cannot open config file: %s", path, strerror(errno));
    return -1;
  }
  char line[1024];
  char source[FW_CONFIG_STR_MAX + 32];
  bool seen[N_KEYS];
  memset(seen, 0, sizeof seen);
  char extra_seen[EXTRA_SEEN_MAX][EXTRA_KEY_MAX];
  size_t n_extra = 0;
  int line_no = 0;
  int rc = 0;
  while (fgets(line, sizeof line, f) != NULL) {
    ++line_no;
    snprintf(source, sizeof source, "%s:%d", path, line_no);
    const size_t n = strlen(line);
    if (n == sizeof line - 1 && line[n - 1] != '\n' && !feof(f)) {
      fw_errfmt(err, err_cap, "%s: line longer than %zu characters", source, sizeof line - 2);
      rc = -1;
      break;
    }
    char* key = NULL;
    char* value = NULL;
    char why[FW_CONFIG_ERR_MAX];
    const int r = split_line(line, &key, &value, why, sizeof why);
    if (r < 0) {
      fw_errfmt(err, err_cap, "%s: %s", source, why);
      rc = -1;
      break;
    }
    if (r == 0) {
      continue;
    }
    const key_desc_t* k = find_key(key);
    if (k == NULL && extra != NULL) {
      bool twice = false;
      for (size_t i = 0; i < n_extra; ++i) {
        twice = twice || strcmp(extra_seen[i], key) == 0;
      }
      if (twice) {
        fw_errfmt(err, err_cap, "%s: key '%s' appears twice in this file", source, key);
        rc = -1;
        break;
      }
      const int r_extra = extra(user, key, value, source, err, err_cap);
      if (r_extra < 0) {
        rc = -1;
        break;
      }
      if (r_extra == 0) {
        if (n_extra < EXTRA_SEEN_MAX && strlen(key) < EXTRA_KEY_MAX) {
          strcpy(extra_seen[n_extra++], key);
        }
        continue;
      }
    }
    if (k != NULL && seen[k - k_keys]) {
      fw_errfmt(err, err_cap, "%s: key '%s' appears twice in this file (first on line %u)", source, key,
          (unsigned)cfg->origins.key_line[k - k_keys]);
      rc = -1;
      break;
    }
    if (fw_config_set(cfg, key, value, source, err, err_cap) != 0) {
      rc = -1;
      break;
    }
    seen[k - k_keys] = true;
  }
  if (rc == 0 && ferror(f)) {
    fw_errfmt(err, err_cap, "%s: read error", path);
    rc = -1;
  }
  fclose(f);
  return rc;
}

// "origin: " of key name, for the start of a cross-key message.
typedef struct origin_buf {
  char text[FW_CONFIG_STR_MAX + 16];
} origin_buf_t;

static origin_buf_t origin_of(const fw_config_t* cfg, const char* key) {
  origin_buf_t o;
  fw_config_origin(cfg, key, o.text, sizeof o.text);
  return o;
}

const char* fw_task_name(int32_t task) {
  const tasks_decl_t* d = tasks_by_id(task);
  return d != NULL ? d->name : "unknown";
}

int fw_config_validate_program(const fw_config_t* cfg, char* err, size_t err_cap) {
  if (fw_config_validate(cfg, err, err_cap) != 0) {
    return -1;
  }
  if (cfg->mode == FW_MODE_LEARN && cfg->phase_driver == FW_DRIVER_JOYSTICK && cfg->lockstep) {
    fw_errfmt(err, err_cap,
        "%s: phase_one_driver = joystick needs real time, but lockstep = true (set at %s): the emulator's time "
        "only advances with the loop, so no operator can drive it; set lockstep = false (and run b21r-sim "
        "without --lockstep) or phase_one_driver = example",
        origin_of(cfg, "phase_one_driver").text, origin_of(cfg, "lockstep").text);
    return -1;
  }
  if (cfg->mode == FW_MODE_LEARN && cfg->phase_driver == FW_DRIVER_JOYSTICK && strcmp(cfg->lcm_url, "none") == 0) {
    fw_errfmt(err, err_cap,
        "%s: phase_one_driver = joystick needs B21R_TELEOP over LCM, but lcm_url = none (set at %s); set lcm_url "
        "(\"\" = LCM's default, e.g. udpm://239.255.76.67:7667?ttl=0 for this host only) or "
        "phase_one_driver = example",
        origin_of(cfg, "phase_one_driver").text, origin_of(cfg, "lcm_url").text);
    return -1;
  }
  // What only the operator can say is taken only signed with the operator key (fw/opauth.h): a
  // configuration that waits for it without a key would wait for ever.
  const bool lcm_on = strcmp(cfg->lcm_url, "none") != 0;
  if (lcm_on && cfg->operator_key_file[0] == '\0') {
    const char* needs = NULL;
    const char* key = NULL;
    if (cfg->reposition == FW_REPOSITION_OPERATOR) {
      needs = "reposition = operator waits for the operator's CONFIRM_START_POSE before every run";
      key = "reposition";
    } else if (cfg->mode == FW_MODE_LEARN && cfg->phase_driver == FW_DRIVER_JOYSTICK) {
      needs = "phase_one_driver = joystick drives with the operator's B21R_TELEOP";
      key = "phase_one_driver";
    } else if (cfg->mode == FW_MODE_LEARN && cfg->phase_switch == FW_SWITCH_OPERATOR) {
      needs = "phase_switch = operator waits for the operator's START_PHASE_TWO";
      key = "phase_switch";
    }
    if (needs != NULL) {
      fw_errfmt(err, err_cap,
          "%s: %s, which the controller takes only signed with the operator key, but operator_key_file is not set "
          "(%s); create a key with tools/b21r_key.py create /etc/b21r/operator.key and set operator_key_file to "
          "it (docs/robot.md, \"Network and security\")",
          origin_of(cfg, key).text, needs, origin_of(cfg, "operator_key_file").text);
      return -1;
    }
  }
  return 0;
}

int fw_config_each_task_param(const fw_config_t* cfg, fw_config_task_param_fn fn, void* user, char* err,
                              size_t err_cap) {
  const tasks_decl_t* decl = tasks_by_id(cfg->task);
  char buf[FW_CONFIG_STR_MAX];
  snprintf(buf, sizeof buf, "%s", cfg->task_params);
  char* next = buf;
  while (next != NULL) {
    char* item = next;
    char* comma = strchr(item, ',');
    next = comma != NULL ? comma + 1 : NULL;
    if (comma != NULL) {
      *comma = '\0';
    }
    if (item[strspn(item, " ")] == '\0' && next == NULL && item == buf) {
      break;  // "": the task's defaults
    }
    char* eq = strchr(item, '=');
    char* name = item;
    while (*name == ' ') {
      ++name;
    }
    if (eq == NULL || eq == name) {
      fw_errfmt(err, err_cap, "%s: task_params item '%s': expected name=value", origin_of(cfg, "task_params").text, item);
      return -1;
    }
    *eq = '\0';
    for (char* e = eq - 1; e > name && *e == ' '; --e) {
      *e = '\0';
    }
    char* value = eq + 1;
    while (*value == ' ') {
      ++value;
    }
    for (size_t n = strlen(value); n > 0 && value[n - 1] == ' '; --n) {
      value[n - 1] = '\0';
    }
    const tasks_param_t* p = decl != NULL ? tasks_param_find(decl, name) : NULL;
    double v = 0.0;
    if (p == NULL) {
      char names[FW_CONFIG_STR_MAX] = "";
      size_t used = 0;
      for (uint32_t i = 0; decl != NULL && i < decl->n_params && used < sizeof names; ++i) {
        used += (size_t)snprintf(names + used, sizeof names - used, "%s%s", i == 0 ? "" : ", ", decl->params[i].name);
      }
      fw_errfmt(err, err_cap, "%s: task_params: task %s (set at %s) has no parameter '%s'; its parameters: %s",
          origin_of(cfg, "task_params").text, fw_task_name(cfg->task), origin_of(cfg, "task").text, name, names);
      return -1;
    }
    if (!parse_double(value, &v) || !(v >= p->min && v <= p->max)) {
      fw_errfmt(err, err_cap, "%s: task_params: %s = '%s', expected a number in [%g, %g] (%s)",
          origin_of(cfg, "task_params").text, name, value, p->min, p->max, p->help);
      return -1;
    }
    if (fn != NULL) {
      fn(user, p->name, v);
    }
  }
  return 0;
}

int fw_config_validate(const fw_config_t* cfg, char* err, size_t err_cap) {
  if (tasks_by_id(cfg->task) == NULL) {
    fw_errfmt(err, err_cap, "%s: task id %d is not a declared task", origin_of(cfg, "task").text, (int)cfg->task);
    return -1;
  }
  if (fw_config_each_task_param(cfg, NULL, NULL, err, err_cap) != 0) {
    return -1;
  }
  if (cfg->eval_poses_n > 0 && cfg->eval_poses_n < cfg->eval_starts) {
    fw_errfmt(err, err_cap, "%s: eval_poses gives %d poses, but eval_starts (set at %s) asks for %d; give more poses or "
        "lower eval_starts", origin_of(cfg, "eval_poses").text, (int)cfg->eval_poses_n, origin_of(cfg, "eval_starts").text,
        (int)cfg->eval_starts);
    return -1;
  }
  if (cfg->laser_resolution_cdeg == 25 && cfg->laser_fov_deg != 100) {
    fw_errfmt(err, err_cap,
        "%s: laser_resolution_deg = 0.25 needs laser_fov_deg = 100 (set at %s; the LMS200 has no 180/0.25 variant)",
        origin_of(cfg, "laser_resolution_deg").text, origin_of(cfg, "laser_fov_deg").text);
    return -1;
  }
  if (cfg->hedger_k_min > cfg->hedger_k_max) {
    fw_errfmt(err, err_cap, "%s: hedger_k_min (%d) must not exceed hedger_k_max (%d, set at %s)",
        origin_of(cfg, "hedger_k_min").text, (int)cfg->hedger_k_min, (int)cfg->hedger_k_max,
        origin_of(cfg, "hedger_k_max").text);
    return -1;
  }
  if (cfg->hedger_greedy_reach > 0.0 && cfg->hedger_greedy_reach < 1.0) {
    fw_errfmt(err, err_cap, "%s: hedger_greedy_reach = %g must be 0 (the task's) or at least 1 (1 = no widening)",
        origin_of(cfg, "hedger_greedy_reach").text, cfg->hedger_greedy_reach);
    return -1;
  }
  if (cfg->example_gain_range_n != 0 &&
      (cfg->example_gain_range_n != 2 || cfg->example_gain_range[0] > cfg->example_gain_range[1])) {
    char given[FW_CONFIG_MAX_SCALES * 26];
    size_t used = 0;
    for (int32_t i = 0; i < cfg->example_gain_range_n && used < sizeof given; ++i) {
      used += (size_t)snprintf(given + used, sizeof given - used, "%s%g", i == 0 ? "" : ",",
                               cfg->example_gain_range[i]);
    }
    fw_errfmt(err, err_cap,
        "%s: example_gain_range = \"%s\": it needs two gains [1/s], the lowest first (e.g. \"0.5,2\"), or \"\" "
        "for the task's range",
        origin_of(cfg, "example_gain_range").text, given);
    return -1;
  }
  const tasks_decl_t* decl = tasks_by_id(cfg->task);
  const int32_t dims = (decl != NULL ? (int32_t)decl->state_dim : 0) + (cfg->state_rotation ? 1 : 0) + 1;
  if (cfg->hedger_input_scale_n != 0 && cfg->hedger_input_scale_n != dims) {
    fw_errfmt(err, err_cap,
        "%s: hedger_input_scale has %d values; task %s (set at %s) needs %d (state dimensions%s, then the action)",
        origin_of(cfg, "hedger_input_scale").text, (int)cfg->hedger_input_scale_n,
        fw_task_name(cfg->task), origin_of(cfg, "task").text, (int)dims,
        cfg->state_rotation ? ", the last one the executed rotation of state_rotation" : "");
    return -1;
  }
  if (cfg->learner == FW_LEARNER_TABULAR && cfg->checkpoint_file[0] != '\0') {
    fw_errfmt(err, err_cap,
        "%s: learner = tabular cannot checkpoint (checkpoint_file set at %s); set checkpoint_file = \"\" or use "
        "learner = hedger",
        origin_of(cfg, "learner").text, origin_of(cfg, "checkpoint_file").text);
    return -1;
  }
  if (cfg->policy != FW_POLICY_GREEDY && cfg->actor_queries > cfg->actor_capacity) {
    fw_errfmt(err, err_cap, "%s: actor_queries = %d exceeds actor_capacity = %d (set at %s); the query set is drawn "
        "from the recorded transitions", origin_of(cfg, "actor_queries").text, (int)cfg->actor_queries,
        (int)cfg->actor_capacity, origin_of(cfg, "actor_capacity").text);
    return -1;
  }
  if (cfg->base_protocol == FW_BASE_CANOPEN) {
    // One node id per device: a shared id would mix a drive's TPDO1 with the bump panels'.
    const struct {
      const char* key;
      int32_t node;
    } nodes[3] = {{"can_node_translation", cfg->can_node_translation},
                  {"can_node_rotation", cfg->can_node_rotation},
                  {"can_node_bumpers", cfg->can_node_bumpers}};
    for (int i = 0; i < 3; ++i) {
      for (int j = i + 1; j < 3; ++j) {
        if (nodes[i].node == nodes[j].node) {
          fw_errfmt(err, err_cap, "%s: %s = %d is also %s (set at %s); every CANopen node needs its own id",
              origin_of(cfg, nodes[j].key).text, nodes[j].key, (int)nodes[j].node, nodes[i].key,
              origin_of(cfg, nodes[i].key).text);
          return -1;
        }
      }
    }
  }
  if (cfg->reposition == FW_REPOSITION_EMULATOR && cfg->emulator_control[0] == '\0') {
    fw_errfmt(err, err_cap, "%s: reposition = emulator needs emulator_control = <path of the emulator's control socket>",
        origin_of(cfg, "reposition").text);
    return -1;
  }
  if (cfg->device_reopen_backoff_max_s < cfg->device_reopen_backoff_s) {
    fw_errfmt(err, err_cap, "%s: device_reopen_backoff_max_s (%g) must not be below device_reopen_backoff_s (%g, set at %s)",
        origin_of(cfg, "device_reopen_backoff_max_s").text, cfg->device_reopen_backoff_max_s,
        cfg->device_reopen_backoff_s, origin_of(cfg, "device_reopen_backoff_s").text);
    return -1;
  }
  const int32_t q = cfg->queue_capacity;
  if ((q & (q - 1)) != 0) {
    fw_errfmt(err, err_cap, "%s: queue_capacity = %d: must be a power of two in [16, 65536]",
        origin_of(cfg, "queue_capacity").text, (int)q);
    return -1;
  }
  if (cfg->mode == FW_MODE_LEARN && cfg->phase_one_runs + cfg->phase_two_runs == 0) {
    fw_errfmt(err, err_cap, "%s: phase_one_runs + phase_two_runs is 0 (phase_two_runs set at %s): nothing to learn",
        origin_of(cfg, "phase_one_runs").text, origin_of(cfg, "phase_two_runs").text);
    return -1;
  }
  if (cfg->phase_switch == FW_SWITCH_AUTO && cfg->auto_switch_min_runs > cfg->phase_one_runs) {
    fw_errfmt(err, err_cap, "%s: auto_switch_min_runs (%d) exceeds phase_one_runs (%d, set at %s), the latest switch",
        origin_of(cfg, "auto_switch_min_runs").text, (int)cfg->auto_switch_min_runs, (int)cfg->phase_one_runs,
        origin_of(cfg, "phase_one_runs").text);
    return -1;
  }
  return 0;
}

int fw_config_format_doubles(const double* v, uint32_t n, char* out, size_t cap) {
  if (cap == 0U) {
    return -1;
  }
  out[0] = '\0';
  size_t at = 0;
  for (uint32_t i = 0; i < n; ++i) {
    char one[32];
    snprintf(one, sizeof one, "%.15g", v[i]);
    const double back = strtod(one, NULL);
    if (memcmp(&back, &v[i], sizeof back) != 0) {
      snprintf(one, sizeof one, "%.17g", v[i]);
    }
    const int w = snprintf(out + at, cap - at, "%s%s", i > 0 ? "," : "", one);
    if (w < 0 || (size_t)w >= cap - at) {
      return -1;
    }
    at += (size_t)w;
  }
  return 0;
}

// A file written by --print-config says 0.1, not 0.10000000000000001, and still round-trips
// exactly.
static void print_double(FILE* out, double d) {
  char buf[32];
  (void)fw_config_format_doubles(&d, 1U, buf, sizeof buf);
  fputs(buf, out);
}

static void print_value(const key_desc_t* k, const fw_config_t* cfg, FILE* out) {
  const char* field = (const char*)cfg + k->offset;
  switch (k->kind) {
    case KIND_BOOL: {
      bool b = false;
      memcpy(&b, field, sizeof b);
      fprintf(out, "%s", b ? "true" : "false");
      break;
    }
    case KIND_INT: {
      int32_t i = 0;
      memcpy(&i, field, sizeof i);
      fprintf(out, "%d", (int)i);
      break;
    }
    case KIND_U64: {
      uint64_t u = 0;
      memcpy(&u, field, sizeof u);
      fprintf(out, "%llu", (unsigned long long)u);
      break;
    }
    case KIND_DOUBLE: {
      double d = 0.0;
      memcpy(&d, field, sizeof d);
      print_double(out, d);
      break;
    }
    case KIND_STRING:
      fprintf(out, "\"%s\"", field);
      break;
    case KIND_DLIST: {
      int32_t n = 0;
      memcpy(&n, field + FW_CONFIG_MAX_SCALES * sizeof(double), sizeof n);
      double v[FW_CONFIG_MAX_SCALES];
      memcpy(v, field, sizeof v);
      char list[FW_CONFIG_MAX_SCALES * 26];
      (void)fw_config_format_doubles(v, n > 0 && n <= (int32_t)FW_CONFIG_MAX_SCALES ? (uint32_t)n : 0U, list,
                                     sizeof list);
      fprintf(out, "\"%s\"", list);
      break;
    }
    case KIND_CPUS: {
      uint64_t mask = 0;
      memcpy(&mask, field, sizeof mask);
      char list[4 * FW_CONFIG_MAX_CPUS];
      fw_config_format_cpus(mask, list, sizeof list);
      fprintf(out, "\"%s\"", list);
      break;
    }
    case KIND_ENUM: {
      int32_t v = 0;
      memcpy(&v, field, sizeof v);
      for (const choice_t* c = k->choices; c->name != NULL; ++c) {
        if (c->value == v) {
          fprintf(out, "%s", c->name);
          break;
        }
      }
      break;
    }
    case KIND_TASK: {
      int32_t v = 0;
      memcpy(&v, field, sizeof v);
      fprintf(out, "%s", fw_task_name(v));
      break;
    }
    case KIND_POSES: {
      int32_t n = 0;
      memcpy(&n, field + 3U * FW_CONFIG_MAX_POSES * sizeof(double), sizeof n);
      fputc('"', out);
      for (int32_t i = 0; i < n; ++i) {
        double p[3];
        memcpy(p, field + (size_t)i * 3U * sizeof(double), sizeof p);
        fputs(i == 0 ? "" : "; ", out);
        print_double(out, p[0]);
        fputc(',', out);
        print_double(out, p[1]);
        fputc(',', out);
        print_double(out, p[2]);
      }
      fputc('"', out);
      break;
    }
  }
}

void fw_config_print_reference(FILE* out) {
  for (size_t i = 0; i < N_KEYS; ++i) {
    const key_desc_t* k = &k_keys[i];
    if (k->section != NULL) {
      fprintf(out, "%s# --- %s ---\n", i == 0 ? "" : "\n", k->section);
    }
    char allowed[256];
    describe_allowed(k, allowed, sizeof allowed);
    fprintf(out, "# %s\n#   allowed: %s\n", k->doc, allowed);
    if (k->kind == KIND_STRING || k->kind == KIND_DLIST || k->kind == KIND_CPUS || k->kind == KIND_POSES) {
      fprintf(out, "%s = \"%s\"\n", k->name, k->def);
    } else {
      fprintf(out, "%s = %s\n", k->name, k->def);
    }
  }
}

void fw_config_print(const fw_config_t* cfg, FILE* out) {
  for (size_t i = 0; i < N_KEYS; ++i) {
    fprintf(out, "%s = ", k_keys[i].name);
    print_value(&k_keys[i], cfg, out);
    fputc('\n', out);
  }
}

int64_t fw_config_period_us(const fw_config_t* cfg) { return (int64_t)llround(1e6 / cfg->tick_rate_hz); }

int32_t fw_config_ticks(const fw_config_t* cfg, double seconds) {
  const double t = ceil(seconds * cfg->tick_rate_hz - 1e-9);
  return t < 1.0 ? 1 : (int32_t)t;
}
