// SPDX-License-Identifier: MIT
// The emulator's control text, fault injection, SVG trace and real-time mode.
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "sim/emulator.h"
#include "sim_test_host.h"

#ifndef SIM_WORLDS_DIR
#error "SIM_WORLDS_DIR must name sim/worlds"
#endif

static sim_world_t g_world;
static host_t g_host;
static char g_reply[512];

static sim_emu_t* make(const char* world_file, sim_base_kind_t base, sim_mode_t mode) {
  char path[512];
  (void)snprintf(path, sizeof(path), "%s/%s", SIM_WORLDS_DIR, world_file);
  char err[256];
  assert_int_equal(sim_world_load(path, &g_world, err, sizeof(err)), SIM_WORLD_OK);
  sim_emu_config_t cfg;
  sim_emu_config_default(&cfg);
  cfg.base = base;
  cfg.mode = mode;
  sim_emu_t* e = sim_emu_create(&g_world, &cfg);
  assert_non_null(e);
  host_init(&g_host, e);
  return e;
}

static sim_emu_ctrl_t ctl(sim_emu_t* e, const char* line) {
  return sim_emu_control(e, line, g_reply, sizeof(g_reply));
}

// reset/pose round trip, with the documented reply format; malformed commands are errors that
// name the problem; quit says bye.
static void test_emu_control_reset_pose_and_errors(void** state) {
  (void)state;
  sim_emu_t* e = make("open.world", SIM_BASE_RFLEX, SIM_MODE_LOCKSTEP);
  assert_int_equal(ctl(e, "reset 1.5 -2 0.25"), SIM_EMU_CTRL_OK);
  assert_string_equal(g_reply, "ok");
  assert_int_equal(ctl(e, "pose"), SIM_EMU_CTRL_OK);
  double t, x, y, th;
  int c;
  assert_int_equal(sscanf(g_reply, "ok %lf %lf %lf %lf %d", &t, &x, &y, &th, &c), 5);
  assert_true(t == 0.0 && x == 1.5 && y == -2.0 && th == 0.25 && c == 0);
  assert_int_equal(ctl(e, "reset 1 2"), SIM_EMU_CTRL_ERROR);
  assert_non_null(strstr(g_reply, "usage: reset"));
  assert_int_equal(ctl(e, "reset a b c"), SIM_EMU_CTRL_ERROR);
  // Beyond the coordinates a world may use: refused (found by fuzz_emu_control: a reset to
  // x = 1e300 went into ODE). The robot stays where it was.
  assert_int_equal(ctl(e, "reset 1e300 0 0"), SIM_EMU_CTRL_ERROR);
  assert_non_null(strstr(g_reply, "must lie within +-1e+06"));
  assert_int_equal(ctl(e, "reset 0 -1000000.5 0"), SIM_EMU_CTRL_ERROR);
  assert_int_equal(ctl(e, "reset 0 0 2e6"), SIM_EMU_CTRL_ERROR);
  sim_plant_state_t st;
  sim_emu_state(e, &st);
  assert_true(st.x_m == 1.5 && st.y_m == -2.0);
  assert_int_equal(ctl(e, "jump"), SIM_EMU_CTRL_ERROR);
  assert_int_equal(strncmp(g_reply, "error ", 6), 0);
  assert_int_equal(ctl(e, ""), SIM_EMU_CTRL_ERROR);
  assert_int_equal(ctl(e, "fault bumper 14"), SIM_EMU_CTRL_ERROR);
  assert_int_equal(ctl(e, "fault corrupt 2"), SIM_EMU_CTRL_ERROR);
  assert_int_equal(ctl(e, "fault drive_fault 1"), SIM_EMU_CTRL_ERROR);  // rFLEX base
  assert_non_null(strstr(g_reply, "canopen"));
  assert_int_equal(ctl(e, "fault teleport 3"), SIM_EMU_CTRL_ERROR);
  assert_int_equal(ctl(e, "fault latency 25"), SIM_EMU_CTRL_OK);
  assert_true(fabs(sim_emu_latency_s(e) - 0.025) < 1e-12);
  assert_int_equal(ctl(e, "status"), SIM_EMU_CTRL_OK);
  assert_non_null(strstr(g_reply, "streaming=0"));
  assert_int_equal(ctl(e, "quit"), SIM_EMU_CTRL_QUIT);
  assert_string_equal(g_reply, "ok bye");
  sim_emu_destroy(e);
}

// laser_drop 300 ms: the next three periods bring odometry but no scan; then scans resume.
static void test_emu_fault_laser_drop_silences_laser(void** state) {
  (void)state;
  sim_emu_t* e = make("corridor10.world", SIM_BASE_RFLEX, SIM_MODE_LOCKSTEP);
  host_rflex_startup(&g_host);
  host_read(&g_host);
  assert_int_equal(ctl(e, "fault laser_drop 300"), SIM_EMU_CTRL_OK);
  int scans[5];
  for (int i = 0; i < 5; ++i) {
    host_velocity(&g_host, 0.2, 0.0);
    host_read(&g_host);
    scans[i] = g_host.scans;
    assert_int_equal(g_host.motor_reports, 2);
  }
  assert_int_equal(scans[0] + scans[1], 0);
  assert_int_equal(scans[3], 1);
  assert_int_equal(scans[4], 1);
  sim_emu_destroy(e);
}

// base_silent 200 ms: no odometry for two periods, scans continue; `fault clear` ends it early.
static void test_emu_fault_base_silent_and_clear(void** state) {
  (void)state;
  sim_emu_t* e = make("corridor10.world", SIM_BASE_RFLEX, SIM_MODE_LOCKSTEP);
  host_rflex_startup(&g_host);
  host_read(&g_host);
  assert_int_equal(ctl(e, "fault base_silent 1000"), SIM_EMU_CTRL_OK);
  host_velocity(&g_host, 0.2, 0.0);  // ignored by the silent base, so time does not advance
  host_read(&g_host);
  assert_int_equal(g_host.motor_reports, 0);
  assert_int_equal(g_host.scans, 0);
  assert_true(sim_emu_time(e) == 0.0);
  assert_int_equal(ctl(e, "fault clear"), SIM_EMU_CTRL_OK);
  host_velocity(&g_host, 0.2, 0.0);
  host_read(&g_host);
  assert_int_equal(g_host.motor_reports, 2);
  assert_int_equal(g_host.scans, 1);
  sim_emu_destroy(e);
}

// corrupt 0.5: about half of the bytes read differ from an identical run without the fault.
static void test_emu_fault_corrupt_changes_bytes(void** state) {
  (void)state;
  static uint8_t clean[8192], dirty[8192];
  size_t n[2] = {0, 0};
  for (int run = 0; run < 2; ++run) {
    sim_emu_t* e = make("corridor10.world", SIM_BASE_RFLEX, SIM_MODE_LOCKSTEP);
    if (run == 1) {
      assert_int_equal(ctl(e, "fault corrupt 0.5"), SIM_EMU_CTRL_OK);
    }
    host_rflex_startup(&g_host);
    n[run] = sim_emu_laser_read(e, run == 0 ? clean : dirty, sizeof(clean));
    sim_emu_destroy(e);
  }
  assert_int_equal(n[0], n[1]);
  size_t diff = 0;
  for (size_t i = 0; i < n[0]; ++i) {
    diff += clean[i] != dirty[i];
  }
  assert_true(diff > n[0] * 4 / 10 && diff < n[0] * 6 / 10);
}

// laser_stuck: the scans keep coming (valid telegrams) with the same distances bit for bit while
// the robot drives; after the fault ends they change again.
static void test_emu_fault_laser_stuck_repeats_scan(void** state) {
  (void)state;
  sim_emu_t* e = make("corridor10.world", SIM_BASE_RFLEX, SIM_MODE_LOCKSTEP);
  host_rflex_startup(&g_host);
  host_read(&g_host);
  static uint16_t first[LMS_MAX_SCAN_VALUES];
  memcpy(first, g_host.last_scan.raw, sizeof first);  // the last scan before the fault
  assert_int_equal(ctl(e, "fault laser_stuck 500"), SIM_EMU_CTRL_OK);
  for (int k = 0; k < 4; ++k) {
    host_velocity(&g_host, 0.3, 0.0);
    host_read(&g_host);
    assert_int_equal(g_host.scans, 1);
    assert_memory_equal(first, g_host.last_scan.raw, sizeof first);
  }
  assert_int_equal(sim_lms_get_counters(sim_emu_laser(e))->repeated_scans, 4);
  for (int k = 0; k < 3; ++k) {  // past 0.5 s of simulated time
    host_velocity(&g_host, 0.3, 0.0);
    host_read(&g_host);
  }
  assert_int_equal(g_host.scans, 1);
  assert_memory_not_equal(first, g_host.last_scan.raw, sizeof first);
  sim_emu_destroy(e);
}

// Runs a CANopen emulator for `cycles` SYNC cycles driving forward, after `fault` (NULL = none);
// returns the hash of every frame received and the error frames signalled.
static uint64_t can_run(const char* fault, int cycles, uint32_t* error_frames, int* tpdo2) {
  sim_emu_t* e = make("corridor10.world", SIM_BASE_CANOPEN, SIM_MODE_LOCKSTEP);
  host_canopen_startup(&g_host);
  host_read(&g_host);
  if (fault != NULL) {
    assert_int_equal(ctl(e, fault), SIM_EMU_CTRL_OK);
  }
  *error_frames = 0;
  *tpdo2 = 0;
  g_host.hash = 1469598103934665603ULL;
  for (int k = 0; k < cycles; ++k) {
    host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.3, 0.0);
    host_read(&g_host);
    *error_frames += sim_emu_can_take_error_frames(e);
    *tpdo2 += g_host.tpdo2;
  }
  const uint64_t h = g_host.hash;
  sim_emu_destroy(e);
  return h;
}

// can_errors: failed CRCs are signalled as error frames and the frames resent, so the host
// receives exactly the frames of a clean run (never a damaged payload); can_drop loses frames.
static void test_emu_fault_can_errors_resend_and_drop_loses(void** state) {
  (void)state;
  uint32_t err0 = 0, err1 = 0, err2 = 0;
  int n0 = 0, n1 = 0, n2 = 0;
  const uint64_t clean = can_run(NULL, 30, &err0, &n0);
  const uint64_t errors = can_run("fault can_errors 0.3", 30, &err1, &n1);
  (void)can_run("fault can_drop 0.3", 30, &err2, &n2);
  assert_int_equal(err0, 0);
  assert_true(err1 > 10);
  assert_true(clean == errors);
  assert_int_equal(n1, n0);
  assert_int_equal(err2, 0);
  assert_true(n2 < n0 * 9 / 10 && n2 > n0 / 2);
}

// node_stuck: the drive's PDOs keep answering each SYNC with the values it had (its position
// stands still while the robot drives), its heartbeats stop; babble floods the bus from COB-ID
// 0x001, at most a bounded burst per read, and keeps the other nodes' frames off it.
static void test_emu_fault_node_stuck_and_babble(void** state) {
  (void)state;
  sim_emu_t* e = make("corridor10.world", SIM_BASE_CANOPEN, SIM_MODE_LOCKSTEP);
  host_canopen_startup(&g_host);
  host_read(&g_host);
  for (int k = 0; k < 5; ++k) {
    host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.3, 0.0);
    host_read(&g_host);
  }
  assert_int_equal(ctl(e, "fault node_stuck 1 1000"), SIM_EMU_CTRL_OK);
  int heartbeats = 0;
  int32_t pos = 0;
  for (int k = 0; k < 8; ++k) {
    host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.3, 0.0);
    host_read(&g_host);
    assert_int_equal(g_host.tpdo2, 2);
    if (k == 0) {
      pos = g_host.last_tpdo2[0].position_actual;
    }
    assert_int_equal(g_host.last_tpdo2[0].position_actual, pos);
    assert_true(g_host.last_tpdo1[0].velocity_actual != 0);
    heartbeats += g_host.heartbeats;
  }
  assert_true(heartbeats <= 8);  // the rotation drive's only (one per 0.1 s)
  assert_int_equal(ctl(e, "fault clear"), SIM_EMU_CTRL_OK);
  host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.3, 0.0);
  host_read(&g_host);
  assert_true(g_host.last_tpdo2[0].position_actual != pos);

  assert_int_equal(ctl(e, "fault babble 5 1000"), SIM_EMU_CTRL_OK);
  assert_int_equal(ctl(e, "fault babble 0 1000"), SIM_EMU_CTRL_ERROR);
  for (int k = 0; k < 3; ++k) {
    host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.3, 0.0);
    host_read(&g_host);
    assert_int_equal(g_host.tpdo1 + g_host.tpdo2 + g_host.bump_pdos, 0);
    assert_true(g_host.other > 0 && g_host.other <= 64);
  }
  sim_emu_destroy(e);
}

// bus_off: the host's controller goes off the bus: a bus-off event, then nothing is received (and
// what the host sends is lost) until its restart, in real time after the fault's duration, in
// lockstep (where the host's periods cannot pass without answers) at `fault clear`; a restart
// event, and frames again. rFLEX refuses it.
static void test_emu_fault_bus_off_and_restart(void** state) {
  (void)state;
  sim_emu_t* e = make("corridor10.world", SIM_BASE_CANOPEN, SIM_MODE_LOCKSTEP);
  host_canopen_startup(&g_host);
  host_read(&g_host);
  assert_int_equal(sim_emu_can_take_bus_event(e), SIM_EMU_BUS_NONE);
  assert_int_equal(ctl(e, "fault bus_off 300"), SIM_EMU_CTRL_OK);
  assert_int_equal(sim_emu_can_take_bus_event(e), SIM_EMU_BUS_OFF);
  for (int k = 0; k < 3; ++k) {
    host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.3, 0.0);
    host_read(&g_host);
    assert_int_equal(g_host.tpdo1 + g_host.tpdo2 + g_host.bump_pdos + g_host.heartbeats, 0);
  }
  assert_int_equal(sim_emu_can_take_bus_event(e), SIM_EMU_BUS_NONE);
  assert_int_equal(ctl(e, "fault clear"), SIM_EMU_CTRL_OK);
  assert_int_equal(sim_emu_can_take_bus_event(e), SIM_EMU_BUS_RESTARTED);
  host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.3, 0.0);
  host_read(&g_host);
  assert_int_equal(g_host.tpdo2, 2);
  sim_emu_destroy(e);

  e = make("corridor10.world", SIM_BASE_CANOPEN, SIM_MODE_REALTIME);
  host_canopen_startup(&g_host);
  assert_int_equal(ctl(e, "fault bus_off 300"), SIM_EMU_CTRL_OK);
  int heard = 0;
  for (int ms = 1; ms <= 290; ++ms) {
    sim_emu_run_until(e, ms * 1e-3);
    host_read(&g_host);
    heard += g_host.heartbeats + g_host.tpdo1 + g_host.bump_pdos;
  }
  assert_int_equal(heard, 0);
  assert_int_equal(sim_emu_can_take_bus_event(e), SIM_EMU_BUS_OFF);
  for (int ms = 291; ms <= 600; ++ms) {
    sim_emu_run_until(e, ms * 1e-3);
    host_read(&g_host);
    heard += g_host.heartbeats;
  }
  assert_int_equal(sim_emu_can_take_bus_event(e), SIM_EMU_BUS_RESTARTED);
  assert_true(heard > 0);  // the nodes' heartbeats are heard again
  sim_emu_destroy(e);

  e = make("corridor10.world", SIM_BASE_RFLEX, SIM_MODE_LOCKSTEP);
  assert_int_equal(ctl(e, "fault bus_off 300"), SIM_EMU_CTRL_ERROR);
  sim_emu_destroy(e);
}

// bumper 3 presses enclosure panel 3 (DIO 0x43, bits 0x0F) from the next period until cleared.
static void test_emu_fault_bumper_reports_panel(void** state) {
  (void)state;
  sim_emu_t* e = make("corridor10.world", SIM_BASE_RFLEX, SIM_MODE_LOCKSTEP);
  host_rflex_startup(&g_host);
  host_read(&g_host);
  assert_int_equal(ctl(e, "fault bumper 0x43"), SIM_EMU_CTRL_OK);
  host_velocity(&g_host, 0.0, 0.0);
  host_read(&g_host);
  assert_int_equal(g_host.dio_reports, 1);
  assert_int_equal(g_host.last_dio.address, 0x43);
  assert_int_equal(g_host.last_dio.value, 0x0F);
  host_velocity(&g_host, 0.0, 0.0);
  host_read(&g_host);
  assert_int_equal(g_host.dio_reports, 0);
  assert_int_equal(ctl(e, "fault clear"), SIM_EMU_CTRL_OK);
  host_velocity(&g_host, 0.0, 0.0);
  host_read(&g_host);
  assert_int_equal(g_host.dio_reports, 1);
  assert_int_equal(g_host.last_dio.value, 0);
  sim_emu_destroy(e);
}

// drive_fault on CANopen: EMCY from the node, its statusword shows the fault in the TPDO.
static void test_emu_fault_drive_fault_on_canopen(void** state) {
  (void)state;
  sim_emu_t* e = make("corridor10.world", SIM_BASE_CANOPEN, SIM_MODE_LOCKSTEP);
  host_canopen_startup(&g_host);
  host_read(&g_host);
  assert_int_equal(ctl(e, "fault drive_fault 2"), SIM_EMU_CTRL_OK);
  assert_int_equal(ctl(e, "fault drive_fault 7"), SIM_EMU_CTRL_ERROR);
  host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.3, 0.3);
  host_read(&g_host);
  assert_int_equal(g_host.emcy, 1);
  assert_true(cia402_fault(g_host.last_tpdo1[1].statusword));
  assert_true(g_host.last_tpdo1[1].velocity_actual == 0);
  sim_emu_destroy(e);
}

// bumper_silent on CANopen: the bump-panel node sends nothing for that long (its PDO and its
// heartbeat), the drives go on; afterwards its PDO comes back at once. rFLEX refuses it.
static void test_emu_fault_bumper_silent_on_canopen(void** state) {
  (void)state;
  sim_emu_t* e = make("corridor10.world", SIM_BASE_CANOPEN, SIM_MODE_LOCKSTEP);
  host_canopen_startup(&g_host);
  host_read(&g_host);
  assert_int_equal(ctl(e, "fault bumper_silent 500"), SIM_EMU_CTRL_OK);
  for (int cycle = 0; cycle < 4; ++cycle) {
    host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.0, 0.0);
    host_read(&g_host);
    assert_int_equal(g_host.bump_pdos, 0);
    assert_int_equal(g_host.bump_heartbeats, 0);
    assert_int_equal(g_host.tpdo1, 2);
  }
  assert_int_equal(ctl(e, "fault clear"), SIM_EMU_CTRL_OK);
  host_can_cycle(&g_host, CIA402_CW_ENABLE_OPERATION, 0.0, 0.0);
  host_read(&g_host);
  assert_int_equal(g_host.bump_pdos, 1);
  sim_emu_destroy(e);
  e = make("corridor10.world", SIM_BASE_RFLEX, SIM_MODE_LOCKSTEP);
  assert_int_equal(ctl(e, "fault bumper_silent 500"), SIM_EMU_CTRL_ERROR);
  sim_emu_destroy(e);
}

// The trace picture: an SVG with the world, one polyline per run coloured in run order on the
// viridis scale of tools/b21r_trajectories.py, a legend naming the runs and the symbols, written
// atomically.
static void test_emu_svg_shows_runs(void** state) {
  (void)state;
  sim_emu_t* e = make("obstacle1.world", SIM_BASE_RFLEX, SIM_MODE_LOCKSTEP);
  host_rflex_startup(&g_host);
  for (int i = 0; i < 30; ++i) {
    host_velocity(&g_host, 0.5, 0.1);
    host_read(&g_host);
  }
  assert_int_equal(ctl(e, "reset -3 1 0"), SIM_EMU_CTRL_OK);
  for (int i = 0; i < 30; ++i) {
    host_velocity(&g_host, 0.5, -0.1);
    host_read(&g_host);
  }
  char path[] = "/tmp/test_sim_emulator_XXXXXX";
  const int fd = mkstemp(path);
  assert_true(fd >= 0);
  close(fd);
  char cmd[600];
  (void)snprintf(cmd, sizeof(cmd), "svg %s", path);
  assert_int_equal(ctl(e, cmd), SIM_EMU_CTRL_OK);
  FILE* f = fopen(path, "r");
  assert_non_null(f);
  static char text[1 << 20];
  const size_t n = fread(text, 1, sizeof(text) - 1, f);
  text[n] = '\0';
  fclose(f);
  unlink(path);
  assert_non_null(strstr(text, "<svg"));
  assert_non_null(strstr(text, "</svg>"));
  assert_non_null(strstr(text, "obstacle1"));
  int polylines = 0;
  for (const char* p = text; (p = strstr(p, "<polyline")) != NULL; ++p) {
    ++polylines;
  }
  assert_int_equal(polylines, 2);
  assert_non_null(strstr(text, "<polyline fill=\"none\" stroke=\"#440154\""));  // the first run
  assert_non_null(strstr(text, "<polyline fill=\"none\" stroke=\"#bddf26\""));  // the last run
  assert_non_null(strstr(text, ">run 0</text>"));
  assert_non_null(strstr(text, ">run 1</text>"));
  assert_non_null(strstr(text, ">start of a run</text>"));
  assert_non_null(strstr(text, ">collision</text>"));
  assert_non_null(strstr(text, ">goal</text>"));
  assert_int_equal(ctl(e, "svg /nonexistent-dir/x.svg"), SIM_EMU_CTRL_ERROR);
  sim_emu_destroy(e);
}

// Real time: the laser streams at its baud rate (9600 Bd: about 2.6 scans/s), odometry at the
// requested 10 Hz, and the watchdog stops the robot 1 s after the last command.
static void test_emu_realtime_rates_and_watchdog(void** state) {
  (void)state;
  sim_emu_t* e = make("corridor10.world", SIM_BASE_RFLEX, SIM_MODE_REALTIME);
  host_rflex_startup(&g_host);
  host_velocity(&g_host, 0.3, 0.0);
  int scans = 0, reports = 0;
  for (int ms = 1; ms <= 3000; ++ms) {
    sim_emu_run_until(e, ms * 1e-3);
    host_read(&g_host);
    scans += g_host.scans;
    reports += g_host.motor_reports;
  }
  assert_true(scans >= 6 && scans <= 8);
  assert_true(reports >= 58 && reports <= 62);
  sim_plant_state_t s;
  sim_emu_state(e, &s);
  assert_true(s.v_mps == 0.0);  // stopped by the watchdog
  // 0.6 s ramp at 0.5 m/s^2 ... the robot moved about 0.3 m/s for ~1 s, then stopped.
  assert_true(s.x_m > 1.2 && s.x_m < 1.45);
  assert_int_equal(sim_rflex_get_counters(sim_emu_rflex(e))->watchdog_trips, 1);
  assert_int_equal(ctl(e, "status"), SIM_EMU_CTRL_OK);  // the control socket reports the trip
  assert_non_null(strstr(g_reply, " watchdog_trips=1"));
  sim_emu_destroy(e);
}

// Invalid configurations are refused.
static void test_emu_create_rejects_bad_period(void** state) {
  (void)state;
  sim_world_clear(&g_world);
  sim_emu_config_t cfg;
  sim_emu_config_default(&cfg);
  cfg.period_s = 0.105;  // not a multiple of dt = 0.01
  assert_null(sim_emu_create(&g_world, &cfg));
  cfg.period_s = 0.0;
  assert_null(sim_emu_create(&g_world, &cfg));
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_emu_control_reset_pose_and_errors),
      cmocka_unit_test(test_emu_fault_laser_drop_silences_laser),
      cmocka_unit_test(test_emu_fault_base_silent_and_clear),
      cmocka_unit_test(test_emu_fault_corrupt_changes_bytes),
      cmocka_unit_test(test_emu_fault_laser_stuck_repeats_scan),
      cmocka_unit_test(test_emu_fault_can_errors_resend_and_drop_loses),
      cmocka_unit_test(test_emu_fault_node_stuck_and_babble),
      cmocka_unit_test(test_emu_fault_bus_off_and_restart),
      cmocka_unit_test(test_emu_fault_bumper_reports_panel),
      cmocka_unit_test(test_emu_fault_drive_fault_on_canopen),
      cmocka_unit_test(test_emu_fault_bumper_silent_on_canopen),
      cmocka_unit_test(test_emu_svg_shows_runs),
      cmocka_unit_test(test_emu_realtime_rates_and_watchdog),
      cmocka_unit_test(test_emu_create_rejects_bad_period),
  };
  return cmocka_run_group_tests_name("sim.emulator", tests, NULL, NULL);
}
