// SPDX-License-Identifier: MIT
// The loop's safety reactions over the fake robot: every cause commands zero in the very tick the
// stop begins and reports its reason on STATUS; bad teleop and command messages are rejected and
// counted; operator commands act.
#define _POSIX_C_SOURCE 200809L
#include "loop_harness.h"

#include "fw/safety.h"

#include <math.h>
#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

static harness_t g_h;

// A run under way on a fresh fake robot (CANopen with its frames can_lag_us behind the laser).
static void open_running_lag(bool canopen, int64_t can_lag_us, void (*tweak)(fw_config_t*)) {
  fw_config_t c;
  harness_config(&c);
  c.phase_one_runs = 50;
  c.eval_every_runs = 50;
  c.safety_clear_ticks = 3;
  if (tweak != NULL) {
    tweak(&c);
  }
  assert_int_equal(canopen ? harness_open_can_lag(&g_h, &c, 9, can_lag_us) : harness_open(&g_h, &c, false, 9), 0);
  harness_run(&g_h, 40);  // a run is under way, the robot moves
}

static void open_running(bool canopen, void (*tweak)(fw_config_t*)) { open_running_lag(canopen, 0, tweak); }

static int run_source_sum(const b21r_run_t* r) {
  int n = 0;
  for (int k = 0; k < 5; ++k) {
    n += r->steps_by_source[k];
  }
  return n;
}

// Silence and corrupt data are faults of time: they are tested in real time (in lockstep a tick
// never runs without the period's data, see test_loop_lockstep_silence_ends_loop).
static void real_time(fw_config_t* c) { c->lockstep = false; }

// Lockstep with the product's patience for the emulator (lockstep_timeout_s 30 s).
static void lockstep_patient(fw_config_t* c) { c->lockstep_timeout_s = 30.0; }

static double fake_v(void) {
  if (!g_h.fake.canopen) {
    return g_h.fake.v_cmd;
  }
  return (double)g_h.fake.drive_target[0] / g_h.fake.k_d;
}

// Runs tick by tick until the stop reason appears; asserts the robot was commanded to move the
// tick before and to stand still in the tick the stop began. Returns the ticks it took.
static int expect_stop_within(int reason, int max_ticks) {
  fw_loop_stats_t st;
  for (int i = 1; i <= max_ticks; ++i) {
    const double v_before = fake_v();
    harness_run(&g_h, 1);
    fw_loop_get_stats(g_h.loop, &st);
    if (st.stop_reason == reason) {
      assert_true(fabs(v_before) > 0.05);
      assert_true(fabs(fake_v()) < 1e-9);
      assert_true(fabs(g_h.fake.canopen ? (double)g_h.fake.drive_target[1] : g_h.fake.w_cmd) < 1e-9);
      assert_true((g_h.stop_reasons_seen & (1U << reason)) != 0);  // on STATUS in that tick
      assert_true(g_h.last_status_detail[0] != '\0');
      return i;
    }
  }
  fail_msg("stop reason %d (%s) not seen within %d ticks", reason, fw_stop_reason_name(reason), max_ticks);
  return -1;
}

// Between runs the learner replays the aborted run in slices before the next run starts: up to
// replay_passes x the run's steps / learn_updates_per_tick ticks (runs here are under 100 steps;
// the harness keeps the default 3 passes and 4 updates per tick).
#define REPLAY_TICKS (3 * 100 / 4)

static void expect_resume(int max_ticks) {
  fw_loop_stats_t st;
  for (int i = 0; i < max_ticks; ++i) {
    harness_run(&g_h, 1);
    fw_loop_get_stats(g_h.loop, &st);
    if (st.stop_reason == FW_STOP_NONE && st.mode == B21R_STATUS_T_MODE_RUNNING) {
      return;
    }
  }
  fail_msg("the loop did not resume within %d ticks", max_ticks);
}

// Laser silence for the limit (4 ticks at 0.35 s) stops the robot in that tick (the 5th tick
// after the fault: the scan of the period under way was already sent); it resumes with a new run
// once scans are back.
static void test_loop_laser_silence_stops_within_one_tick(void** state) {
  (void)state;
  open_running(false, real_time);
  g_h.fake.laser_drop_ticks = 8;
  const int ticks = expect_stop_within(FW_STOP_LASER_SILENT, 20);
  // laser_timeout_s = 0.35: the tick 0.4 s after the last scan stops.
  assert_true(ticks >= 4 && ticks <= 5);
  assert_non_null(strstr(g_h.last_status_detail, "laser silent for 4"));
  expect_resume(60 + REPLAY_TICKS);
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.runs_aborted, 1);
  harness_close(&g_h);
}

// A stuck laser (valid telegrams repeating the same distances) is no source of new scans: the
// command is held, the repeats are counted, and after the laser's limit the robot stops with
// the detail "laser stuck", in real time and in lockstep (where the repeats still pace the ticks:
// no lockstep timeout); it resumes once the scans change again.
static void expect_stuck_laser_stops(void (*tweak)(fw_config_t*)) {
  open_running(false, tweak);
  g_h.fake.laser_stuck_ticks = 8;
  const int ticks = expect_stop_within(FW_STOP_LASER_SILENT, 20);
  assert_true(ticks >= 4 && ticks <= 5);
  assert_non_null(strstr(g_h.last_status_detail, "laser stuck: the same scan"));
  expect_resume(60 + REPLAY_TICKS);
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.runs_aborted, 1);
  assert_true(st.stop_reason != FW_STOP_DEVICE_LOST);
  harness_close(&g_h);
}

static void test_loop_stuck_laser_stops_real_time(void** state) {
  (void)state;
  expect_stuck_laser_stops(real_time);
}

static void test_loop_stuck_laser_stops_lockstep(void** state) {
  (void)state;
  expect_stuck_laser_stops(NULL);
}

// Between scans: a period without a new scan holds the command in force and learns nothing, in
// phase one (the example's run) and in phase two (the learned policy's). Silences shorter than
// the laser's limit, so the runs go on.
static void real_time_two_phases(fw_config_t* c) {
  c->lockstep = false;
  c->phase_one_runs = 4;
  c->phase_two_runs = 20;
}

static void expect_held_through_two_silent_periods(void) {
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  const int64_t steps0 = st.steps;
  const int64_t ticks_held0 = st.held_ticks;
  const double w_held = g_h.fake.w_cmd;
  g_h.fake.laser_drop_ticks = 2;
  harness_run(&g_h, 1);
  assert_true(g_h.fake.w_cmd == w_held);
  harness_run(&g_h, 1);
  assert_true(g_h.fake.w_cmd == w_held);
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.held_ticks - ticks_held0, 2);
  assert_int_equal(st.steps, steps0);
  assert_int_equal(st.stop_reason, FW_STOP_NONE);
}

static void test_loop_between_scans_command_held(void** state) {
  (void)state;
  open_running(false, real_time_two_phases);
  expect_held_through_two_silent_periods();
  // Into the first phase-two run, 30 steps on.
  fw_loop_stats_t st;
  int guard = 0;
  do {
    harness_run(&g_h, 1);
    fw_loop_get_stats(g_h.loop, &st);
    assert_true(++guard < 200000);
  } while (!(st.training_runs >= 4 && st.mode == B21R_STATUS_T_MODE_RUNNING));
  const int32_t runs0 = st.runs_finished;
  const int64_t steps0 = st.steps;
  while (st.steps - steps0 < 30) {
    harness_run(&g_h, 1);
    fw_loop_get_stats(g_h.loop, &st);
  }
  assert_int_equal(st.runs_finished, runs0);  // the same run
  assert_int_equal(st.phase, 2);
  expect_held_through_two_silent_periods();
  harness_run(&g_h, 20);
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.stop_reason, FW_STOP_NONE);
  harness_close(&g_h);
}

// In lockstep a tick never runs without the period's data: a laser that stays silent for
// lockstep_timeout_s (the emulator died) stops the robot and ends the loop, naming the device.
static void test_loop_lockstep_silence_ends_loop(void** state) {
  (void)state;
  open_running(false, NULL);
  g_h.fake.laser_drop_ticks = 1000000;
  const int64_t ticks = harness_run(&g_h, 10);
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  assert_true(ticks <= 2);
  assert_true(st.done);
  assert_int_equal(st.stop_reason, FW_STOP_DEVICE_LOST);
  assert_int_equal(st.exit_status, FW_EXIT_LOCKSTEP_TIMEOUT);
  assert_true(fabs(g_h.fake.v_cmd) < 1e-9 && fabs(g_h.fake.w_cmd) < 1e-9);
  assert_non_null(strstr(g_h.last_status_detail, "no laser data"));
  harness_close(&g_h);
}

// Base silence stops the robot.
static void test_loop_base_silence_stops_within_one_tick(void** state) {
  (void)state;
  open_running(false, real_time);
  g_h.fake.base_silent_ticks = 8;
  expect_stop_within(FW_STOP_BASE_SILENT, 20);
  expect_resume(60 + REPLAY_TICKS);
  harness_close(&g_h);
}

// A bumper hit ends the run as a collision (the last transition is learned, not aborted) and
// stops the robot; the emulator binding repositions it, the bumper clears, the loop resumes.
static void test_loop_bumper_stops_and_ends_run_as_collision(void** state) {
  (void)state;
  open_running(false, NULL);
  g_h.fake.bumper_ticks = 3;
  expect_stop_within(FW_STOP_BUMPER, 5);
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.runs_aborted, 0);
  assert_int_equal(st.runs_finished, 1);
  assert_false(st.last_run_goal);
  expect_resume(60 + REPLAY_TICKS);
  harness_close(&g_h);
}

static void push_can(const canopen_frame_t* fr) {
  assert_true(g_h.fake.n_frames < FAKE_FRAMES);
  g_h.fake.frames[g_h.fake.n_frames++] = *fr;
}

// CANopen: the bump-panel node's TPDO1 sets the same bumper mask as the rFLEX DIO reports: a
// contact ends the run as a collision and stops the robot in that tick, exactly like rFLEX.
// Bump-like frames of another node and a short TPDO1 of the node itself change nothing.
static void test_loop_canopen_bumper_stops_and_ends_run_as_collision(void** state) {
  (void)state;
  open_running(true, NULL);
  canopen_frame_t fr;
  uint8_t all[CIA401_BUMP_PANELS];
  memset(all, CIA401_BUMP_SEGMENTS, sizeof all);
  (void)cia401_encode_bumpers(&fr, CANOPEN_NODE_BUMPERS_DEFAULT + 1, all);  // node 17: not the bumpers
  push_can(&fr);
  (void)cia401_encode_bumpers(&fr, CANOPEN_NODE_BUMPERS_DEFAULT, all);
  fr.dlc = 6;  // shorter than the mapping
  push_can(&fr);
  harness_run(&g_h, 3);
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.stop_reason, FW_STOP_NONE);
  assert_int_equal(st.safety_stops, 0);
  const int64_t pdos = g_h.fake.bump_pdos;
  assert_true(pdos >= 40);  // one per period since the NMT start
  g_h.fake.bumper_ticks = 3;
  expect_stop_within(FW_STOP_BUMPER, 5);
  assert_non_null(strstr(g_h.last_status_detail, "bump panel 6 pressed (mask 0x0040)"));
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.runs_aborted, 0);
  assert_int_equal(st.runs_finished, 1);
  assert_false(st.last_run_goal);
  expect_resume(60 + REPLAY_TICKS);
  harness_close(&g_h);
}

// The bump-panel node's silence for can_bumper_timeout_s (0.35 s: 4 ticks in lockstep) is a base
// fault naming the node, not a bumper stop: the run is aborted, not ended as a collision. It
// clears once the node sends again.
static void bump_node_silence(bool lockstep) {
  open_running(true, lockstep ? NULL : real_time);
  g_h.fake.bump_silent_ticks = 8;
  const int ticks = expect_stop_within(FW_STOP_BASE_FAULT, 10);
  assert_true(ticks >= 4 && ticks <= 5);
  assert_non_null(strstr(g_h.last_status_detail, "bump-panel node 16 (CiA 401): no TPDO1 0x190"));
  assert_non_null(strstr(g_h.last_status_detail, lockstep ? "for 4 ticks (limit 4)" : "(limit 350 ms)"));
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.runs_aborted, 1);
  assert_int_equal(st.stops_by_reason[FW_STOP_BUMPER], 0);
  expect_resume(60 + REPLAY_TICKS);
  harness_close(&g_h);
}

// In lockstep the nodes' heartbeats are judged on the tick's time (tick x period, as the emulator
// produces them), not on the wall clock: a bump-panel node whose heartbeat stops while its PDOs go
// on is a base fault on the 6th tick after its last heartbeat (0.6 s > can_heartbeat_timeout_s
// 0.5 s; the 7th after it falls silent: the period under way had sent its heartbeat), the same
// tick however late the bus's frames reach the controller.
static void test_loop_canopen_heartbeat_loss_lockstep_on_tick_time(void** state) {
  (void)state;
  const int64_t lags_us[3] = {0, 150000, 450000};
  for (int i = 0; i < 3; ++i) {
    open_running_lag(true, lags_us[i], lockstep_patient);
    assert_true(g_h.cfg.can_heartbeat_timeout_s == 0.5);
    g_h.fake.bump_hb_silent_ticks = 12;
    const int ticks = expect_stop_within(FW_STOP_BASE_FAULT, 12);
    print_message("CAN answers %3lld ms late: heartbeat lost on tick %d\n", (long long)(lags_us[i] / 1000), ticks);
    assert_int_equal(ticks, 7);
    assert_non_null(
        strstr(g_h.last_status_detail, "bump-panel node 16 (CiA 401): heartbeat lost (none for 500 ms), its PDOs still arrive"));
    fw_loop_stats_t st;
    fw_loop_get_stats(g_h.loop, &st);
    assert_int_equal(st.runs_aborted, 1);
    assert_int_equal(st.stops_by_reason[FW_STOP_BUMPER], 0);
    expect_resume(60 + REPLAY_TICKS);  // its heartbeats are back
    harness_close(&g_h);
  }
}

static void test_loop_canopen_bumper_node_silence_is_base_fault_lockstep(void** state) {
  (void)state;
  bump_node_silence(true);
}

static void test_loop_canopen_bumper_node_silence_is_base_fault_real_time(void** state) {
  (void)state;
  bump_node_silence(false);
}

// A node that restarts (boot-up heartbeat, pre-operational: no PDOs) is started again by the
// controller, and its PDOs resume before its silence becomes a fault.
static void test_loop_canopen_bumper_node_restart_is_started_again(void** state) {
  (void)state;
  open_running(true, NULL);
  g_h.fake.bump_operational = false;
  canopen_frame_t fr;
  (void)canopen_encode_heartbeat(&fr, CANOPEN_NODE_BUMPERS_DEFAULT, CANOPEN_NMT_STATE_BOOTUP);
  push_can(&fr);
  harness_run(&g_h, 1);
  assert_true(g_h.fake.bump_operational);
  harness_run(&g_h, 10);
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.safety_stops, 0);
  harness_close(&g_h);
}

// Starts a loop with c on g_h.fake (initialised by the caller, faults set), expecting the start to
// fail: returns its error in err; the loop is gone, the fake kept for the caller's checks.
static void start_refused(const fw_config_t* c, char* err, size_t err_cap) {
  const fw_io_t io = fake_robot_io(&g_h.fake);
  fw_pubq_t* q = fw_pubq_create(256);
  assert_non_null(q);
  const fw_loop_outputs_t out = {.queue = q, .notify = NULL, .notify_user = NULL, .checkpoints = NULL};
  fw_loop_t* loop = fw_loop_create(c, &io, &out, err, err_cap);
  assert_non_null(loop);
  const int rc = fw_loop_start(loop, err, err_cap);
  fw_loop_destroy(loop);
  fw_pubq_destroy(q);
  assert_int_not_equal(rc, 0);
}

// A CANopen base whose bump-panel node never answers does not start: the error names the node,
// its COB-ID and the key. A drive id shared with the node is refused by the configuration.
static void test_loop_canopen_bumper_node_missing_refuses_start(void** state) {
  (void)state;
  fw_config_t c;
  harness_config(&c);
  c.base_protocol = FW_BASE_CANOPEN;
  fake_robot_t* fake = &g_h.fake;
  fake_robot_init(fake, true, 1.0 / c.tick_rate_hz, 9);
  fake->bump_absent = true;
  char err[FW_LOOP_ERR_MAX];
  start_refused(&c, err, sizeof err);
  assert_non_null(strstr(err, "bump-panel node 16 (CiA 401 digital inputs, TPDO1 COB-ID 0x190)"));
  assert_non_null(strstr(err, "nothing at all from that id"));
  assert_non_null(strstr(err, "can_node_bumpers"));
  assert_true(fake->drive[0].state == CIA402_OPERATION_ENABLED);  // the drives themselves came up
  c.can_node_bumpers = c.can_node_rotation;
  assert_int_not_equal(fw_config_validate(&c, err, sizeof err), 0);
  assert_non_null(strstr(err, "can_node_bumpers = 2 is also can_node_rotation"));
}

// Lockstep: a drive that does not answer the start's SYNC (a node id the emulator does not have)
// ends the start after lockstep_timeout_s, the error naming the node, the key and the emulator. In
// lockstep each enable cycle waits for its answer (a cycle cut short by a stalled emulator would
// send one SYNC more: firmware.loop's answer-lag test), so a missing one is an error, not a retry.
static void test_loop_canopen_lockstep_drive_missing_refuses_start(void** state) {
  (void)state;
  fw_config_t c;
  harness_config(&c);
  c.base_protocol = FW_BASE_CANOPEN;
  c.can_node_rotation = 5;  // the fake's drives are nodes 1 and 2
  fake_robot_t* fake = &g_h.fake;
  fake_robot_init(fake, true, 1.0 / c.tick_rate_hz, 9);
  const int64_t t0 = fake->clock_us;
  char err[FW_LOOP_ERR_MAX];
  start_refused(&c, err, sizeof err);
  print_message("%s (after %.2f s)\n", err, (double)(fake->clock_us - t0) / 1e6);
  assert_non_null(strstr(err, "SYNC 1 of the start unanswered for 1 s (lockstep_timeout_s) by drive node 5 "
                              "(rotation, can_node_rotation; nothing from that id)"));
  assert_non_null(strstr(err, "from ids no can_node_* key names (the last COB-ID 0x"));
  assert_null(strstr(err, "translation"));  // the drive that answered is not named
  assert_true(fake->clock_us - t0 >= 1000000 && fake->clock_us - t0 <= 1100000);
  assert_int_equal(fake->commands, 1);  // one SYNC: not 40 cycles of retries
}

// Lockstep: the start waits for the first scan at least as long as a tick waits for the period's
// data (lockstep_timeout_s, here 30 s; real time and shorter timeouts 20 s), then names the device.
static void test_loop_lockstep_start_waits_lockstep_timeout_for_first_scan(void** state) {
  (void)state;
  const double timeouts_s[2] = {30.0, 1.0};
  const double expect_s[2] = {30.0, 20.0};
  for (int k = 0; k < 2; ++k) {
    fw_config_t c;
    harness_config(&c);
    c.lockstep_timeout_s = timeouts_s[k];
    fake_robot_init(&g_h.fake, false, 1.0 / c.tick_rate_hz, 9);
    g_h.fake.laser_drop_ticks = 1;  // the t_0 scan is lost; in lockstep no period follows
    const int64_t t0 = g_h.fake.clock_us;
    char err[FW_LOOP_ERR_MAX];
    start_refused(&c, err, sizeof err);
    const double waited_s = (double)(g_h.fake.clock_us - t0) / 1e6;
    print_message("lockstep_timeout_s %g: %s (after %.2f s)\n", timeouts_s[k], err, waited_s);
    char want[64];
    snprintf(want, sizeof want, "laser: no scan within %g s", expect_s[k]);
    assert_non_null(strstr(err, want));
    assert_true(waited_s >= expect_s[k] && waited_s < expect_s[k] + 0.1);
  }
}

// The controller's signal handler: records the signal in the loop (and wakes its wait).
static void raise_sigterm(void* user) { fw_loop_signal((fw_loop_t*)user, SIGTERM); }

// SIGTERM during a lockstep start that waits for a stalled or missing device (up to
// lockstep_timeout_s per wait, here 30 s) ends the start at once: FW_LOOP_START_SIGNALLED, the
// error naming the signal and the step it ended, the fake's clock 0.4 s on (not 30 s). One that
// came before the start (during the real-time set-up) starts no device at all.
static void test_loop_signal_ends_the_lockstep_start(void** state) {
  (void)state;
  for (int k = 0; k < 3; ++k) {
    const bool canopen = k == 1;
    const bool before = k == 2;
    fw_config_t c;
    harness_config(&c);
    c.lockstep_timeout_s = 30.0;
    fake_robot_t* fake = &g_h.fake;
    fake_robot_init(fake, canopen, 1.0 / c.tick_rate_hz, 9);
    if (canopen) {
      c.base_protocol = FW_BASE_CANOPEN;
      c.can_node_rotation = 5;  // a drive that never answers: the enable cycle waits
    } else {
      fake->laser_drop_ticks = 1;  // the t_0 scan is lost: the first-scan wait
    }
    const fw_io_t io = fake_robot_io(fake);
    fw_pubq_t* q = fw_pubq_create(256);
    assert_non_null(q);
    const fw_loop_outputs_t out = {.queue = q, .notify = NULL, .notify_user = NULL, .checkpoints = NULL};
    char err[FW_LOOP_ERR_MAX];
    fw_loop_t* loop = fw_loop_create(&c, &io, &out, err, sizeof err);
    assert_non_null(loop);
    const int64_t t0 = fake->clock_us;
    if (before) {
      fw_loop_signal(loop, SIGTERM);
    } else {
      fake->wake = raise_sigterm;
      fake->wake_user = loop;
      fake->wake_at_us = t0 + 400000;
    }
    const int rc = fw_loop_start(loop, err, sizeof err);
    const double waited_s = (double)(fake->clock_us - t0) / 1e6;
    print_message("%s: rc %d, %s (after %.2f s)\n", before ? "before" : canopen ? "canopen" : "rflex", rc, err,
                  waited_s);
    assert_int_equal(rc, FW_LOOP_START_SIGNALLED);
    fw_loop_stats_t st;
    fw_loop_get_stats(loop, &st);
    assert_int_equal(st.exit_status, 128 + SIGTERM);  // the caller's exit status
    assert_non_null(strstr(err, "stopped by signal 15 (SIGTERM) during the "));
    assert_non_null(strstr(err, before    ? "start (before any device was started)"
                                : canopen ? "CANopen start (enabling the drives)"
                                          : "laser's first scan"));
    if (before) {
      assert_true(fake->clock_us == t0);
      assert_false(fake->streaming);  // no odometry request: the base was not started
    } else {
      assert_true(waited_s >= 0.4 && waited_s < 0.5);
    }
    assert_int_equal(fw_loop_shutdown(loop), 0);
    fw_loop_destroy(loop);
    fw_pubq_destroy(q);
  }
}

// SIGTERM while a lockstep tick waits for a stalled emulator's data ends the loop at once (128 +
// 15, the robot commanded to stand), not after lockstep_timeout_s (30 s) as a silent device would.
static void test_loop_signal_ends_a_lockstep_wait(void** state) {
  (void)state;
  open_running(false, lockstep_patient);
  g_h.fake.laser_drop_ticks = 1000000;  // the emulator sends nothing more
  const int64_t t0 = g_h.fake.clock_us;
  g_h.fake.wake = raise_sigterm;
  g_h.fake.wake_user = g_h.loop;
  g_h.fake.wake_at_us = t0 + 500000;
  const int64_t ticks = harness_run(&g_h, 10);
  const double waited_s = (double)(g_h.fake.clock_us - t0) / 1e6;
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  print_message("%lld ticks, ended after %.3f s, exit status %d\n", (long long)ticks, waited_s, st.exit_status);
  assert_true(st.done);
  assert_int_equal(st.stop_reason, FW_STOP_SIGNAL);
  assert_int_equal(st.exit_status, 128 + SIGTERM);
  // The stop tick's zero command moves the fake on one period (0.1 s) after the signal's 0.5 s.
  assert_true(waited_s >= 0.5 && waited_s < 0.61);
  assert_true(fabs(g_h.fake.v_cmd) < 1e-9 && fabs(g_h.fake.w_cmd) < 1e-9);
  harness_close(&g_h);
}

// A CiA 402 drive fault (EMCY + statusword) stops the robot; after the fault condition clears,
// the loop's fault-reset edge recovers the drive and the loop resumes.
static void test_loop_drive_fault_stops_and_recovers(void** state) {
  (void)state;
  open_running(true, NULL);
  cia402_drive_set_fault(&g_h.fake.drive[1], 0x2310);
  canopen_frame_t emcy;
  (void)canopen_encode_emcy(&emcy, 2, 0x2310, 0x01, NULL);
  g_h.fake.frames[g_h.fake.n_frames++] = emcy;
  expect_stop_within(FW_STOP_BASE_FAULT, 3);
  assert_non_null(strstr(g_h.last_status_detail, "EMCY 0x2310"));
  harness_run(&g_h, 5);
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.stop_reason, FW_STOP_BASE_FAULT);  // still faulted: no recovery by itself
  cia402_drive_set_fault(&g_h.fake.drive[1], 0);            // the cause is gone
  expect_resume(80 + REPLAY_TICKS);
  harness_close(&g_h);
}

// SIGTERM: zero command in the same tick, the loop ends with 128 + 15.
static void test_loop_signal_stops_and_ends(void** state) {
  (void)state;
  open_running(false, NULL);
  const int runs_before = g_h.runs;
  fw_loop_signal(g_h.loop, SIGTERM);
  expect_stop_within(FW_STOP_SIGNAL, 1);
  // The run cut short has its end record: a safety stop, reason signal.
  assert_int_equal(g_h.runs, runs_before + 1);
  assert_int_equal(g_h.run[runs_before].end_reason, B21R_RUN_T_END_SAFETY_STOP);
  assert_int_equal(g_h.run[runs_before].stop_reason, B21R_STATUS_T_STOP_SIGNAL);
  assert_int_equal(run_source_sum(&g_h.run[runs_before]), g_h.run[runs_before].steps);
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  assert_true(st.done);
  assert_int_equal(fw_loop_shutdown(g_h.loop), 0);
  assert_true(g_h.fake.brake);
  assert_false(g_h.fake.streaming);  // odometry reports switched off
  harness_close(&g_h);
}

static void joystick(fw_config_t* c) {
  c->phase_driver = FW_DRIVER_JOYSTICK;
  c->teleop_timeout_s = 0.3;
}

static b21r_teleop_t teleop(int64_t seq, double rot) {
  b21r_teleop_t t;
  memset(&t, 0, sizeof t);
  t.seq = seq;
  t.deadman = 1;
  t.rotation_radps = rot;
  return t;
}

// Joystick driving: the robot moves only while fresh, valid deadman messages arrive; NaN, out of
// range, repeated and stale messages are rejected and counted; losing the deadman stops it.
static void test_loop_teleop_deadman_and_validation(void** state) {
  (void)state;
  fw_config_t c;
  harness_config(&c);
  joystick(&c);
  c.phase_one_runs = 50;
  c.eval_every_runs = 50;
  assert_int_equal(harness_open(&g_h, &c, false, 4), 0);
  // No teleop at all: the first run does not start, the robot never moves, the stop says why.
  fw_loop_stats_t st;
  for (int i = 0; i < 5; ++i) {
    harness_run(&g_h, 1);
    assert_true(fabs(g_h.fake.v_cmd) < 1e-9);
  }
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.stop_reason, FW_STOP_DEADMAN);
  // Valid, fresh messages: the stop clears and the operator's rotation is executed.
  int64_t seq = 1;
  int running = 0;
  for (int i = 0; i < 60 && running < 3; ++i) {
    fw_loop_post_teleop(g_h.loop, &(b21r_teleop_t){.seq = seq++, .deadman = 1, .rotation_radps = 0.25},
                        g_h.fake.clock_us);
    harness_run(&g_h, 1);
    fw_loop_get_stats(g_h.loop, &st);
    running = st.mode == B21R_STATUS_T_MODE_RUNNING ? running + 1 : 0;
  }
  assert_int_equal(running, 3);
  assert_int_equal(st.stop_reason, FW_STOP_NONE);
  assert_true(g_h.fake.v_cmd > 0.05);
  assert_true(fabs(g_h.fake.w_cmd - 0.25) < 1e-6);  // 8750 counts: no 0x1B byte to nudge
  const int64_t accepted = st.teleop_accepted;
  // Bad messages: NaN, out of range, a repeated seq, a stale one.
  b21r_teleop_t bad = teleop(seq++, NAN);
  fw_loop_post_teleop(g_h.loop, &bad, g_h.fake.clock_us);
  bad = teleop(seq++, 5.0);
  fw_loop_post_teleop(g_h.loop, &bad, g_h.fake.clock_us);
  bad = teleop(seq - 5, 0.1);
  fw_loop_post_teleop(g_h.loop, &bad, g_h.fake.clock_us);
  bad = teleop(seq++, 0.1);
  fw_loop_post_teleop(g_h.loop, &bad, g_h.fake.clock_us - 2000000);
  harness_run(&g_h, 1);
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.teleop_rejected, 4);
  assert_int_equal(st.teleop_accepted, accepted);
  // Deadman released (messages stop): stop within the timeout, zero in that tick.
  expect_stop_within(FW_STOP_DEADMAN, 6);
  harness_close(&g_h);
}

// A teleop request over the rotation limit, deadman held, is refused and reported as what it
// is: STOP_TELEOP_RANGE with the value and the limit, a counter and one stderr line, not as a
// released deadman. The aborted run's end record names the stop.
static void test_loop_teleop_out_of_range_reported(void** state) {
  (void)state;
  fw_config_t c;
  harness_config(&c);
  joystick(&c);
  c.phase_one_runs = 50;
  c.eval_every_runs = 50;
  assert_int_equal(harness_open(&g_h, &c, false, 4), 0);
  int64_t seq = 1;
  fw_loop_stats_t st;
  for (int i = 0; i < 60; ++i) {
    fw_loop_post_teleop(g_h.loop, &(b21r_teleop_t){.seq = seq++, .deadman = 1, .rotation_radps = 0.25},
                        g_h.fake.clock_us);
    harness_run(&g_h, 1);
  }
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.mode, B21R_STATUS_T_MODE_RUNNING);
  const int runs_before = g_h.runs;
  int i = 0;
  for (; i < 10 && st.stop_reason == FW_STOP_NONE; ++i) {
    const b21r_teleop_t over = teleop(seq++, 2.0 * c.max_rotation_radps);
    fw_loop_post_teleop(g_h.loop, &over, g_h.fake.clock_us);
    harness_run(&g_h, 1);
    fw_loop_get_stats(g_h.loop, &st);
  }
  assert_int_equal(st.stop_reason, FW_STOP_TELEOP_RANGE);
  assert_true(fabs(g_h.fake.w_cmd) < 1e-9);
  assert_non_null(strstr(g_h.last_status_detail, "rotation"));
  assert_non_null(strstr(g_h.last_status_detail, "max_rotation_radps"));
  assert_int_equal(g_h.last_status.stop_reason, B21R_STATUS_T_STOP_TELEOP_RANGE);
  assert_int_equal(g_h.last_status.teleop_rejected_range, i);
  assert_int_equal(g_h.runs, runs_before + 1);
  const b21r_run_t* r = &g_h.run[runs_before];
  assert_int_equal(r->end_reason, B21R_RUN_T_END_SAFETY_STOP);
  assert_int_equal(r->stop_reason, FW_STOP_TELEOP_RANGE);
  assert_int_equal(r->steps_by_source[B21R_EXPERIENCE_T_SOURCE_JOYSTICK], r->steps);
  harness_close(&g_h);
}

// B21R_CONFIG comes first, with the limits and every key; every run, also one that ends without
// a terminal state (step limit, safety stop, shutdown), has a B21R_RUN end record after its last
// experience, with its steps by driver and its experiences' seq range.
static void step_limit_40(fw_config_t* c) { c->max_steps_per_run = 40; }

static void test_loop_config_and_run_records(void** state) {
  (void)state;
  open_running(false, step_limit_40);
  assert_int_equal(g_h.configs, 1);
  assert_int_equal(g_h.config_before_exp, 0);
  assert_true(g_h.config.max_rotation_radps == g_h.cfg.max_rotation_radps);
  assert_true(g_h.config.max_translation_mps == g_h.cfg.max_translation_mps);
  assert_true(g_h.config.teleop_timeout_s == g_h.cfg.teleop_timeout_s);
  assert_int_equal(g_h.config.step_limit, 40);
  assert_true(g_h.config.lockstep);
  assert_non_null(strstr(g_h.config_text, "max_steps_per_run = 40\n"));
  assert_non_null(strstr(g_h.config_text, "lockstep_realtime_factor = 0\n"));
  harness_run(&g_h, 1000);  // a 40-step run and its replay between runs: about 70 ticks
  assert_true(g_h.runs >= 3);
  int64_t next_first = 0;
  for (int k = 0; k < g_h.runs && k < 64; ++k) {
    const b21r_run_t* r = &g_h.run[k];
    assert_int_equal(r->run_id, k);
    assert_int_equal(r->end_reason, B21R_RUN_T_END_STEP_LIMIT);  // the corridor is longer than 40 steps
    assert_string_equal(r->detail, "step limit");
    assert_int_equal(r->steps, 40);
    assert_int_equal(run_source_sum(r), r->steps);
    assert_int_equal(r->kind, B21R_RUN_T_KIND_TRAINING);
    assert_int_equal(r->training_index, k);
    assert_int_equal(r->first_seq, next_first);
    // One experience per decision (decision_ticks steps; a run's last may end early).
    const int32_t ticks = g_h.cfg.decision_ticks > 1 ? g_h.cfg.decision_ticks : 1;
    assert_int_equal(r->experiences, (r->steps + ticks - 1) / ticks);
    assert_int_equal(g_h.run_exp_next_seq[k], r->first_seq + r->experiences);  // after its last experience
    assert_true(fabs(r->total_reward) < 1e-12);  // the corridor pays only at the goal
    next_first = r->first_seq + r->experiences;
  }
  // Shutdown mid-run: an end record with END_SHUTDOWN and the steps taken so far.
  fw_loop_stats_t st;
  for (int i = 0; i < 1000; ++i) {  // past the between-run slices, into the next run
    fw_loop_get_stats(g_h.loop, &st);
    if (st.mode == B21R_STATUS_T_MODE_RUNNING) {
      break;
    }
    harness_run(&g_h, 1);
  }
  assert_int_equal(st.mode, B21R_STATUS_T_MODE_RUNNING);
  const int before = g_h.runs;
  harness_run(&g_h, 5);
  b21r_command_t cmd = {.seq = 1, .command = B21R_COMMAND_T_SHUTDOWN};
  fw_loop_post_command(g_h.loop, &cmd, 0);
  harness_run(&g_h, 2);
  harness_drain(&g_h);
  assert_int_equal(g_h.runs, before + 1);
  const b21r_run_t* r = &g_h.run[before];
  assert_int_equal(r->end_reason, B21R_RUN_T_END_SHUTDOWN);
  assert_true(r->steps > 0 && r->steps < 40);
  assert_int_equal(run_source_sum(r), r->steps);
  assert_int_equal(g_h.run_exp_next_seq[before], r->first_seq + r->experiences);
  assert_int_equal(fw_loop_shutdown(g_h.loop), 0);
  harness_drain(&g_h);
  assert_int_equal(g_h.runs, before + 1);  // no second record for the same run
  harness_close(&g_h);
}

// Operator commands: PAUSE stops (reported as paused) until RESUME; unknown commands and commands
// older than the newest taken are rejected, except stops: a PAUSE or SHUTDOWN is obeyed whatever
// came before it; START_PHASE_TWO switches after the current run; SHUTDOWN ends the loop.
static void test_loop_operator_commands(void** state) {
  (void)state;
  open_running(false, NULL);
  b21r_command_t cmd;
  memset(&cmd, 0, sizeof cmd);
  cmd.seq = 1;
  cmd.command = B21R_COMMAND_T_PAUSE;
  fw_loop_post_command(g_h.loop, &cmd, 0);
  expect_stop_within(FW_STOP_OPERATOR, 2);
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.mode, B21R_STATUS_T_MODE_PAUSED);
  harness_run(&g_h, 20);
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.stop_reason, FW_STOP_OPERATOR);
  cmd.seq = 2;
  cmd.command = 42;  // unknown
  fw_loop_post_command(g_h.loop, &cmd, 0);
  cmd.seq = 0;
  cmd.command = B21R_COMMAND_T_RESUME;  // older than the PAUSE: overtaken by it, rejected
  fw_loop_post_command(g_h.loop, &cmd, 0);
  harness_run(&g_h, 20);
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.mode, B21R_STATUS_T_MODE_PAUSED);
  assert_int_equal(st.commands_rejected, 2);
  cmd.seq = 3;
  fw_loop_post_command(g_h.loop, &cmd, 0);
  expect_resume(20 + REPLAY_TICKS);
  cmd.seq = 4;
  cmd.command = B21R_COMMAND_T_START_PHASE_TWO;
  fw_loop_post_command(g_h.loop, &cmd, 0);
  for (int i = 0; i < 3000 && st.phase == 1; ++i) {
    harness_run(&g_h, 1);
    fw_loop_get_stats(g_h.loop, &st);
  }
  assert_int_equal(st.phase, 2);
  // Stop wins: a PAUSE older than the newest command taken is obeyed all the same (once a run of
  // phase two is under way).
  for (int i = 0; i < 3000 && !(st.mode == B21R_STATUS_T_MODE_RUNNING && fabs(fake_v()) > 0.05); ++i) {
    harness_run(&g_h, 1);
    fw_loop_get_stats(g_h.loop, &st);
  }
  cmd.seq = 1;
  cmd.command = B21R_COMMAND_T_PAUSE;
  fw_loop_post_command(g_h.loop, &cmd, 0);
  expect_stop_within(FW_STOP_OPERATOR, 2);
  cmd.seq = 6;
  cmd.command = B21R_COMMAND_T_RESUME;
  fw_loop_post_command(g_h.loop, &cmd, 0);
  expect_resume(20 + REPLAY_TICKS);
  cmd.seq = 5;  // older than the RESUME, and obeyed: a stop
  cmd.command = B21R_COMMAND_T_SHUTDOWN;
  fw_loop_post_command(g_h.loop, &cmd, 0);
  harness_run(&g_h, 2);
  fw_loop_get_stats(g_h.loop, &st);
  assert_true(st.done);
  assert_int_equal(st.commands_rejected, 2);
  harness_close(&g_h);
}

// A full command mailbox makes room for a stop: eight commands wait, then a PAUSE comes; the
// oldest waiting command that is not a stop gives way (counted as rejected), and the PAUSE stops.
static void test_loop_mailbox_full_keeps_the_stop(void** state) {
  (void)state;
  open_running(false, NULL);
  b21r_command_t cmd;
  memset(&cmd, 0, sizeof cmd);
  cmd.command = B21R_COMMAND_T_CONFIRM_START_POSE;
  for (int i = 0; i < 8; ++i) {
    cmd.seq = i + 1;
    fw_loop_post_command(g_h.loop, &cmd, 0);
  }
  cmd.seq = 9;
  cmd.command = B21R_COMMAND_T_PAUSE;
  fw_loop_post_command(g_h.loop, &cmd, 0);
  expect_stop_within(FW_STOP_OPERATOR, 2);
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.commands_accepted, 8);
  assert_int_equal(st.commands_rejected, 1);
  harness_close(&g_h);
}

// Corrupted laser bytes are dropped by the CRC and counted, never crash the loop.
static void test_loop_corrupt_bytes_counted(void** state) {
  (void)state;
  open_running(false, real_time);
  g_h.fake.corrupt_fraction = 0.0005;
  harness_run(&g_h, 200);
  g_h.fake.corrupt_fraction = 0.0;
  harness_run(&g_h, 20);
  harness_drain(&g_h);
  assert_true(g_h.last_status.laser_crc_errors > 0);
  assert_true(g_h.last_status.laser_scans > 100);
  harness_close(&g_h);
}

// Deadline accounting of the loop in real time (fake clock): a tick whose thread wakes 61 ms
// after its scheduled start is a late start on STATUS although its own work is short; one that
// starts 250 ms late has skipped two scheduled ticks; the loop then returns to its schedule.
static void test_loop_late_start_and_missed_periods_counted(void** state) {
  (void)state;
  open_running(false, real_time);
  fw_loop_stats_t st0;
  fw_loop_get_stats(g_h.loop, &st0);
  assert_int_equal(st0.late_starts, 0);
  assert_int_equal(st0.missed_periods, 0);
  const int64_t delays_us[2] = {61000, 250000};
  for (int i = 0; i < 2; ++i) {
    const int64_t t = fw_loop_wait(g_h.loop);
    g_h.fake.clock_us += delays_us[i];  // the thread got the CPU late
    assert_true(fw_loop_tick(g_h.loop, t + delays_us[i]));
    harness_drain(&g_h);
    fw_loop_stats_t st;
    fw_loop_get_stats(g_h.loop, &st);
    assert_int_equal(st.late_starts, i + 1);
    assert_true(st.late_max_ever_us >= delays_us[i] && st.late_max_ever_us < delays_us[i] + 1000);
    assert_int_equal(st.missed_periods, i == 0 ? 0 : 2);
    assert_true(st.gap_max_ever_us >= 100000 + delays_us[i]);
    harness_run(&g_h, 5);  // back on schedule: nothing more counted
    fw_loop_get_stats(g_h.loop, &st);
    assert_int_equal(st.late_starts, i + 1);
    assert_int_equal(st.stop_reason, FW_STOP_NONE);
  }
  harness_run(&g_h, g_h.cfg.status_period_ticks);  // a STATUS after both
  assert_int_equal(g_h.last_status.late_starts, 2);
  assert_int_equal(g_h.last_status.missed_periods, 2);
  assert_true(g_h.last_status.late_max_ever_us >= 250000);
  assert_true(g_h.last_status.gap_max_ever_us >= 350000);
  harness_close(&g_h);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_loop_laser_silence_stops_within_one_tick),
      cmocka_unit_test(test_loop_stuck_laser_stops_real_time),
      cmocka_unit_test(test_loop_stuck_laser_stops_lockstep),
      cmocka_unit_test(test_loop_between_scans_command_held),
      cmocka_unit_test(test_loop_lockstep_silence_ends_loop),
      cmocka_unit_test(test_loop_base_silence_stops_within_one_tick),
      cmocka_unit_test(test_loop_bumper_stops_and_ends_run_as_collision),
      cmocka_unit_test(test_loop_canopen_bumper_stops_and_ends_run_as_collision),
      cmocka_unit_test(test_loop_canopen_bumper_node_silence_is_base_fault_lockstep),
      cmocka_unit_test(test_loop_canopen_heartbeat_loss_lockstep_on_tick_time),
      cmocka_unit_test(test_loop_canopen_bumper_node_silence_is_base_fault_real_time),
      cmocka_unit_test(test_loop_canopen_bumper_node_restart_is_started_again),
      cmocka_unit_test(test_loop_canopen_bumper_node_missing_refuses_start),
      cmocka_unit_test(test_loop_canopen_lockstep_drive_missing_refuses_start),
      cmocka_unit_test(test_loop_lockstep_start_waits_lockstep_timeout_for_first_scan),
      cmocka_unit_test(test_loop_signal_ends_the_lockstep_start),
      cmocka_unit_test(test_loop_signal_ends_a_lockstep_wait),
      cmocka_unit_test(test_loop_drive_fault_stops_and_recovers),
      cmocka_unit_test(test_loop_signal_stops_and_ends),
      cmocka_unit_test(test_loop_teleop_deadman_and_validation),
      cmocka_unit_test(test_loop_teleop_out_of_range_reported),
      cmocka_unit_test(test_loop_config_and_run_records),
      cmocka_unit_test(test_loop_operator_commands),
      cmocka_unit_test(test_loop_mailbox_full_keeps_the_stop),
      cmocka_unit_test(test_loop_corrupt_bytes_counted),
      cmocka_unit_test(test_loop_late_start_and_missed_periods_counted),
  };
  return cmocka_run_group_tests_name("firmware.loop_safety", tests, NULL, NULL);
}
