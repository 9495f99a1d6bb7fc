// SPDX-License-Identifier: MIT
// The lockstep contract (one scan + odometry per period, advances only on the cycle's last
// command) on both bases, collisions seen by the controller, and bit-for-bit determinism.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#include "sim/emulator.h"
#include "sim/kinematic.h"
#include "sim_test_host.h"

#ifndef SIM_WORLDS_DIR
#error "SIM_WORLDS_DIR must name sim/worlds"
#endif

static const double k_pi = 3.14159265358979323846;
static sim_world_t g_world;
static host_t g_host;

static sim_emu_t* make(const char* world_file, sim_base_kind_t base, uint64_t seed) {
  char path[512];
  (void)snprintf(path, sizeof(path), "%s/%s", SIM_WORLDS_DIR, world_file);
  char err[256];
  assert_int_equal(sim_world_load(path, &g_world, err, sizeof(err)), SIM_WORLD_OK);
  sim_emu_config_t cfg;
  sim_emu_config_default(&cfg);
  cfg.base = base;
  cfg.seed = seed;
  sim_emu_t* e = sim_emu_create(&g_world, &cfg);
  assert_non_null(e);
  host_init(&g_host, e);
  return e;
}

// rFLEX: nothing streams until the laser streams and odometry is on; then t_0 comes at once,
// and every SET_DIR pair yields exactly one scan and one report per axis, 0.1 s later; other
// packets (SYS_STATUS) do not advance time. The controller's own odometry (proto) follows the
// ground truth, and the ground truth follows the kinematic model of the same commands.
static void test_lockstep_rflex_one_scan_and_odometry_per_period(void** state) {
  (void)state;
  sim_emu_t* e = make("corridor10.world", SIM_BASE_RFLEX, 7);
  host_velocity(&g_host, 0.0, 0.0);  // before streaming: no advance
  assert_true(sim_emu_time(e) == 0.0);
  host_rflex_startup(&g_host);
  assert_true(sim_emu_streaming(e));
  host_read(&g_host);
  assert_int_equal(g_host.scans, 1);
  assert_int_equal(g_host.motor_reports, 2);
  assert_true(sim_emu_time(e) == 0.0);
  sim_kin_state_t k;
  sim_kin_reset(&k, 1.0, 0.0, 0.0);  // corridor10's first start pose
  sim_kin_limits_t lim = {0.7, 100000.0 / 35000.0};
  for (int cycle = 1; cycle <= 40; ++cycle) {
    const double v = 0.4, w = 0.25 * sin(0.2 * cycle);
    host_velocity(&g_host, v, w);
    host_read(&g_host);
    assert_int_equal(g_host.scans, 1);
    assert_int_equal(g_host.motor_reports, 2);
    assert_true(fabs(sim_emu_time(e) - 0.1 * cycle) < 1e-9);
    // The base sees whole counts, nudged off 0x1B bytes by proto: the model gets the command
    // the base decoded (within a few hundred counts of the request).
    sim_rflex_command_t c;
    sim_rflex_get_command(sim_emu_rflex(e), sim_emu_time(e), &c);
    assert_true(fabs(c.v_mps - v) < 0.01 && fabs(c.omega_radps - w) < 0.01);
    for (int i = 0; i < 10; ++i) {
      sim_kin_step(&k, &lim, c.v_mps, c.omega_radps, 0.01);
    }
    rflex_packet_t p;
    rflex_make_sys_status_request(&p);
    host_rflex_packet(&g_host, &p);
    host_read(&g_host);
    assert_int_equal(g_host.sys_status, 1);
    assert_int_equal(g_host.scans, 0);
  }
  sim_plant_state_t s;
  sim_emu_state(e, &s);
  assert_int_equal(s.collided, 0);
  assert_true(fabs(s.x_m - k.x_m) < 1e-9 && fabs(s.y_m - k.y_m) < 1e-9);
  assert_true(fabs(s.theta_rad - k.theta_rad) < 1e-12);
  // Odometry (robot frame at start = world pose (1, 0, 0) here): the heading matches to count
  // rounding; the position differs by the controller's coarser integration (one heading-first
  // step per 0.1 s report instead of per 0.01 s substep), a few millimetres over 1.5 m.
  assert_true(fabs(g_host.odo.x_m + 1.0 - s.x_m) < 0.01);
  assert_true(fabs(g_host.odo.y_m - s.y_m) < 0.01);
  assert_true(fabs(g_host.odo.theta_rad - s.theta_rad) < 1e-4);
  // The last scan sees the corridor: some beam near the end wall, none closer than the robot.
  assert_int_equal(g_host.last_scan.count, 181);
  sim_emu_destroy(e);
}

// CANopen: SYNCs before both drives are enabled are answered with TPDOs at t = 0; the first
// SYNC with both enabled (and the laser streaming) brings the t_0 data; each later RPDO pair +
// SYNC advances exactly one period and brings one scan and TPDO1 + TPDO2 of both drives.
static void test_lockstep_canopen_sync_advances_one_period(void** state) {
  (void)state;
  sim_emu_t* e = make("corridor10.world", SIM_BASE_CANOPEN, 7);
  host_read(&g_host);
  assert_int_equal(g_host.heartbeats, 2);  // boot-up
  host_canopen_startup(&g_host);
  assert_true(sim_emu_time(e) == 0.0);
  assert_true(sim_emu_streaming(e));
  host_read(&g_host);
  assert_int_equal(g_host.scans, 1);
  assert_int_equal(g_host.tpdo1, 3 * 2);  // one pair per SYNC, the last one is t_0
  assert_true(cia402_operation_enabled(g_host.last_tpdo1[0].statusword));
  assert_int_equal(g_host.bump_pdos, 1);  // the bump-panel node answered its NMT start
  assert_int_equal(cia401_bumper_mask(&g_host.last_bump), 0);
  for (int cycle = 1; cycle <= 20; ++cycle) {
    host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.5, 0.2);
    host_read(&g_host);
    assert_int_equal(g_host.scans, 1);
    assert_int_equal(g_host.tpdo1, 2);
    assert_int_equal(g_host.tpdo2, 2);
    assert_int_equal(g_host.heartbeats, 2);
    assert_int_equal(g_host.bump_pdos, 1);  // event timer = period: one per period
    assert_int_equal(g_host.bump_heartbeats, 1);
    assert_true(fabs(sim_emu_time(e) - 0.1 * cycle) < 1e-9);
  }
  // After 2 s: the translation axis reached 0.5 m/s (0.7 s ramp at 0.5 m/s^2 + 1.3 s cruise).
  assert_int_equal(g_host.last_tpdo1[0].velocity_actual, 51500);
  const double dist = canopen_si_from_counts(g_host.last_tpdo2[0].position_actual, 103000.0);
  assert_true(fabs(dist - (0.5 * 0.5 * 1.0 * 1.0 + 0.5 * 1.0)) < 0.01);
  sim_emu_destroy(e);
}

// CANopen in the controller's order (drives enabled, then the laser stream): the stream starts at
// the laser's start request with the t_0 scan and no TPDO, without a SYNC; from then on
// every SYNC is answered by exactly one TPDO1 and one TPDO2 per drive, so a host can match each
// answer to its SYNC.
static void test_lockstep_canopen_t0_at_laser_start_tpdos_only_answer_syncs(void** state) {
  (void)state;
  sim_emu_t* e = make("corridor10.world", SIM_BASE_CANOPEN, 7);
  uint8_t req[32];
  canopen_frame_t f;
  (void)canopen_encode_nmt(&f, CANOPEN_NMT_START, 0);
  host_can(&g_host, &f);
  host_can_cycle(&g_host, CIA402_CW_SHUTDOWN, 0.0, 0.0);
  host_can_cycle(&g_host, CIA402_CW_SWITCH_ON, 0.0, 0.0);
  host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.0, 0.0);
  host_read(&g_host);
  assert_int_equal(g_host.scans, 0);
  assert_int_equal(g_host.tpdo1, 3 * 2);
  assert_int_equal(g_host.tpdo2, 3 * 2);
  assert_int_equal(g_host.bump_pdos, 1);  // the node's inputs at its NMT start
  assert_false(sim_emu_streaming(e));
  host_laser(&g_host, req, lms_encode_start_stream(req, sizeof(req)));
  assert_true(sim_emu_streaming(e));
  assert_true(sim_emu_time(e) == 0.0);
  host_read(&g_host);
  assert_int_equal(g_host.scans, 1);
  assert_int_equal(g_host.tpdo1, 0);
  assert_int_equal(g_host.tpdo2, 0);
  for (int cycle = 1; cycle <= 3; ++cycle) {
    host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.2, 0.0);
    host_read(&g_host);
    assert_int_equal(g_host.scans, 1);
    assert_int_equal(g_host.tpdo1, 2);
    assert_int_equal(g_host.tpdo2, 2);
    assert_true(fabs(sim_emu_time(e) - 0.1 * cycle) < 1e-9);
  }
  sim_emu_destroy(e);
}

// Driving into the left wall: the body stops, the controller receives a DIO report of base
// panel 0 (0x46: the skirt's front, the heading at reset) and `pose` reports the collision.
static void test_lockstep_collision_reaches_controller_as_bumper(void** state) {
  (void)state;
  sim_emu_t* e = make("corridor10.world", SIM_BASE_RFLEX, 7);
  char reply[256];
  assert_int_equal(sim_emu_control(e, "reset 3 0 1.5707963267948966", reply, sizeof(reply)),
                   SIM_EMU_CTRL_OK);
  host_rflex_startup(&g_host);
  host_read(&g_host);
  int dio = 0;
  for (int cycle = 0; cycle < 60; ++cycle) {
    host_velocity(&g_host, 0.4, 0.0);
    host_read(&g_host);
    if (g_host.dio_reports > 0) {
      assert_int_equal(g_host.last_dio.address, 0x46);
      assert_true(g_host.last_dio.value != 0);
      ++dio;
    }
  }
  assert_int_equal(dio, 1);
  sim_plant_state_t s;
  sim_emu_state(e, &s);
  assert_true(fabs(s.y_m - (1.0 - SIM_ROBOT_RADIUS_M)) < 0.01);
  assert_int_equal(sim_emu_control(e, "pose", reply, sizeof(reply)), SIM_EMU_CTRL_OK);
  double t, x, y, th;
  int collided = 0;
  assert_int_equal(sscanf(reply, "ok %lf %lf %lf %lf %d", &t, &x, &y, &th, &collided), 5);
  assert_int_equal(collided, 1);
  assert_true(fabs(th - 0.5 * k_pi) < 1e-9);
  // Backing off releases the panel: a DIO report with value 0.
  host_velocity(&g_host, -0.3, 0.0);
  host_read(&g_host);
  host_velocity(&g_host, -0.3, 0.0);
  host_read(&g_host);
  assert_int_equal(g_host.dio_reports, 0);
  sim_emu_destroy(e);
}

// The same wall on the CANopen base: the bump-panel node's TPDO1 carries the same panel (6, the
// skirt's front) and segment bits as the rFLEX DIO report, in the period of the contact, and
// releases it after backing off. `fault bumper 3` presses panel 3 from the next period on.
static void test_lockstep_canopen_collision_and_fault_reach_controller_as_bumper(void** state) {
  (void)state;
  uint16_t rflex_value = 0;
  int rflex_cycle = -1;
  {
    sim_emu_t* e = make("corridor10.world", SIM_BASE_RFLEX, 7);
    char reply[256];
    (void)sim_emu_control(e, "reset 3 0 1.5707963267948966", reply, sizeof(reply));
    host_rflex_startup(&g_host);
    host_read(&g_host);
    for (int cycle = 0; cycle < 60 && rflex_cycle < 0; ++cycle) {
      host_velocity(&g_host, 0.4, 0.0);
      host_read(&g_host);
      if (g_host.dio_reports > 0) {
        rflex_cycle = cycle;
        rflex_value = g_host.last_dio.value;
      }
    }
    sim_emu_destroy(e);
  }
  assert_true(rflex_cycle > 0);
  sim_emu_t* e = make("corridor10.world", SIM_BASE_CANOPEN, 7);
  char reply[256];
  assert_int_equal(sim_emu_control(e, "reset 3 0 1.5707963267948966", reply, sizeof(reply)), SIM_EMU_CTRL_OK);
  host_canopen_startup(&g_host);
  host_read(&g_host);
  int first = -1;
  for (int cycle = 0; cycle < 60 && first < 0; ++cycle) {
    host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.4, 0.0);
    host_read(&g_host);
    assert_int_equal(g_host.bump_pdos, 1);
    if (cia401_bumper_mask(&g_host.last_bump) != 0U) {
      first = cycle;
      assert_int_equal(cia401_bumper_mask(&g_host.last_bump), 1U << 6);
      assert_int_equal(g_host.last_bump.panels[6], rflex_value);
    }
  }
  assert_true(first > 0);
  for (int cycle = 0; cycle < 3; ++cycle) {
    host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, -0.3, 0.0);
    host_read(&g_host);
  }
  assert_int_equal(cia401_bumper_mask(&g_host.last_bump), 0);
  assert_int_equal(sim_emu_control(e, "fault bumper 3", reply, sizeof(reply)), SIM_EMU_CTRL_OK);
  host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.0, 0.0);
  host_read(&g_host);
  assert_int_equal(g_host.bump_pdos, 1);
  assert_int_equal(cia401_bumper_mask(&g_host.last_bump), 1U << 3);
  assert_int_equal(g_host.last_bump.panels[3], 0x0F);
  assert_int_equal(sim_emu_control(e, "fault clear", reply, sizeof(reply)), SIM_EMU_CTRL_OK);
  host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.0, 0.0);
  host_read(&g_host);
  assert_int_equal(cia401_bumper_mask(&g_host.last_bump), 0);
  sim_emu_destroy(e);
}

// Runs a scripted rFLEX session (start-up, 150 cycles of varying commands through a collision,
// a reset, faults) and returns the hashes of everything received.
static uint64_t rflex_session(uint64_t seed, uint64_t* laser_only) {
  sim_emu_t* e = make("obstacle1.world", SIM_BASE_RFLEX, seed);
  char reply[256];
  host_rflex_startup(&g_host);
  host_read(&g_host);
  uint64_t laser_hash = 1469598103934665603ULL;
  for (int cycle = 0; cycle < 150; ++cycle) {
    if (cycle == 80) {
      (void)sim_emu_control(e, "reset -3 0.5 0.1", reply, sizeof(reply));
      (void)sim_emu_control(e, "fault corrupt 0.01", reply, sizeof(reply));
    }
    if (cycle == 120) {
      (void)sim_emu_control(e, "fault clear", reply, sizeof(reply));
    }
    host_velocity(&g_host, 0.5, 0.6 * sin(0.05 * cycle));
    // Hash the laser separately: read it first, before host_read takes both.
    uint8_t b[4096];
    const size_t n = sim_emu_laser_read(e, b, sizeof(b));
    for (size_t i = 0; i < n; ++i) {
      laser_hash = (laser_hash ^ b[i]) * 1099511628211ULL;
    }
    host_hash(&g_host, b, n);
    host_read(&g_host);
  }
  sim_plant_state_t s;
  sim_emu_state(e, &s);
  host_hash(&g_host, (const uint8_t*)&s.x_m, sizeof(s.x_m));
  host_hash(&g_host, (const uint8_t*)&s.contacts_total, sizeof(s.contacts_total));
  sim_emu_destroy(e);
  *laser_only = laser_hash;
  return g_host.hash;
}

// Same seed, same host bytes: identical output streams (hashes equal); another seed changes
// the laser noise.
static void test_lockstep_same_seed_gives_identical_streams(void** state) {
  (void)state;
  uint64_t l1, l2, l3;
  const uint64_t h1 = rflex_session(42, &l1);
  const uint64_t h2 = rflex_session(42, &l2);
  const uint64_t h3 = rflex_session(43, &l3);
  assert_true(h1 == h2);
  assert_true(l1 == l2);
  assert_true(l1 != l3);
  assert_true(h1 != h3);
}

// The same holds on the CANopen base (TPDOs, heartbeats, scans, the bump-panel node's PDOs
// through contacts, an injected bumper and its silence).
static void test_lockstep_canopen_streams_are_reproducible(void** state) {
  (void)state;
  uint64_t h[2];
  int pressed[2] = {0, 0};
  for (int run = 0; run < 2; ++run) {
    sim_emu_t* e = make("corridor10.world", SIM_BASE_CANOPEN, 99);
    char reply[256];
    host_canopen_startup(&g_host);
    for (int cycle = 0; cycle < 100; ++cycle) {
      if (cycle == 30) {
        (void)sim_emu_control(e, "fault bumper 5", reply, sizeof(reply));
      } else if (cycle == 40) {
        (void)sim_emu_control(e, "fault bumper_silent 300", reply, sizeof(reply));
      } else if (cycle == 50) {
        (void)sim_emu_control(e, "fault clear", reply, sizeof(reply));
      }
      host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.6, 0.3 * cos(0.1 * cycle));
      host_read(&g_host);
      pressed[run] += g_host.bump_pdos > 0 && cia401_bumper_mask(&g_host.last_bump) != 0U;
    }
    h[run] = g_host.hash;
    sim_emu_destroy(e);
  }
  assert_true(h[0] == h[1]);
  assert_int_equal(pressed[0], pressed[1]);
  assert_true(pressed[0] >= 10);  // at least cycles 30..39 (the silence hides some of 40..49)
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_lockstep_rflex_one_scan_and_odometry_per_period),
      cmocka_unit_test(test_lockstep_canopen_sync_advances_one_period),
      cmocka_unit_test(test_lockstep_canopen_t0_at_laser_start_tpdos_only_answer_syncs),
      cmocka_unit_test(test_lockstep_collision_reaches_controller_as_bumper),
      cmocka_unit_test(test_lockstep_canopen_collision_and_fault_reach_controller_as_bumper),
      cmocka_unit_test(test_lockstep_same_seed_gives_identical_streams),
      cmocka_unit_test(test_lockstep_canopen_streams_are_reproducible),
  };
  return cmocka_run_group_tests_name("sim.lockstep", tests, NULL, NULL);
}
