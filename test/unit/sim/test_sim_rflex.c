// SPDX-License-Identifier: MIT
// The emulated rFLEX base answers the controller's packets (hand-written vectors of
// protocols.md A.4 and lib/proto's builders), stuffs its output, reports odometry and bump
// panels, and stops on its watchdog.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>
#include <proto/rflex.h>

#include "sim/rflex_dev.h"

static uint8_t g_buf[16384];
static rflex_decoder_t g_dec;  // host-side decoder of the device's output, one per test

// protocols.md A.4 worked examples (B21r factors).
static const uint8_t k_trans[] = {0x1b, 0x02, 0x02, 0x00, 0x07, 0x0e, 0x00, 0x00, 0x00, 0xc9, 0x2c, 0x00,
                                  0x01, 0x19, 0xa4, 0x00, 0x00, 0x75, 0x30, 0x01, 0x16, 0x1b, 0x03};
static const uint8_t k_rot[] = {0x1b, 0x02, 0x02, 0x00, 0x07, 0x0e, 0x01, 0x00, 0x00, 0x29, 0x04, 0x00,
                                0x01, 0x86, 0xa0, 0x00, 0x00, 0x88, 0xb8, 0x01, 0x31, 0x1b, 0x03};
static const uint8_t k_brake_release[] = {0x1b, 0x02, 0x02, 0x00, 0x0c, 0x00, 0x0e, 0x1b, 0x03};
static const uint8_t k_brake_set[] = {0x1b, 0x02, 0x02, 0x00, 0x0b, 0x00, 0x09, 0x1b, 0x03};
static const uint8_t k_set_defaults[] = {0x1b, 0x02, 0x02, 0x00, 0x0a, 0x00, 0x08, 0x1b, 0x03};
static const uint8_t k_sys_status[] = {0x1b, 0x02, 0x01, 0x00, 0x01, 0x00, 0x00, 0x1b, 0x03};
static const uint8_t k_odometry_on[] = {0x1b, 0x02, 0x02, 0x00, 0x22, 0x08, 0x00, 0x01, 0x86,
                                        0xa0, 0x00, 0x00, 0x00, 0x03, 0x0c, 0x1b, 0x03};
static const uint8_t k_dio_on[] = {0x1b, 0x02, 0x05, 0x00, 0x00, 0x04, 0x00,
                                   0x01, 0x86, 0xa0, 0x26, 0x1b, 0x03};
static const uint8_t k_sonar_on[] = {0x1b, 0x02, 0x04, 0x04, 0x00, 0x0d, 0x00, 0x00, 0x75, 0x30, 0x00,
                                     0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0x4a, 0x1b, 0x03};

static sim_rflex_t* make(bool paced) {
  sim_rflex_config_t cfg;
  sim_rflex_config_default(&cfg);
  cfg.paced = paced;
  sim_rflex_t* d = sim_rflex_create(&cfg);
  assert_non_null(d);
  rflex_decoder_init(&g_dec);
  return d;
}

static int feed(sim_rflex_t* d, const uint8_t* b, size_t n, double t_s) {
  int end = 0;
  assert_int_equal(sim_rflex_feed(d, b, n, t_s, &end), n);
  return end;
}

// Decodes all queued output with proto's decoder into packets[]; returns the count.
static size_t collect(sim_rflex_t* d, double t_s, rflex_packet_t* packets, size_t cap) {
  const size_t n = sim_rflex_drain(d, g_buf, sizeof(g_buf), t_s);
  size_t used = 0, got_n = 0;
  while (used < n) {
    bool got = false;
    rflex_packet_t pkt;
    used += rflex_decoder_push(&g_dec, g_buf + used, n - used, &pkt, &got);
    if (got && got_n < cap) {
      packets[got_n++] = pkt;
    }
  }
  assert_int_equal(g_dec.counters.bad_checksum + g_dec.counters.bad_framing, 0);
  return got_n;
}

// The hand-written SET_DIR pair sets v = 51500 / 103000 = 0.5 m/s at 72100 / 103000 = 0.7 m/s^2
// and w = 10500 / 35000 = 0.3 rad/s at 100000 / 35000 rad/s^2; the rotation packet ends the
// cycle; nothing moves while the brake (engaged at power-up) is on.
static void test_rflex_handwritten_set_dir_pair_sets_commands(void** state) {
  (void)state;
  sim_rflex_t* d = make(false);
  assert_int_equal(feed(d, k_trans, sizeof(k_trans), 0.0), 0);
  assert_int_equal(feed(d, k_rot, sizeof(k_rot), 0.0), 1);
  sim_rflex_command_t c;
  sim_rflex_get_command(d, 0.0, &c);
  assert_true(c.v_mps == 0.0 && c.omega_radps == 0.0);  // brake engaged
  assert_int_equal(feed(d, k_brake_release, sizeof(k_brake_release), 0.0), 0);
  sim_rflex_get_command(d, 0.0, &c);
  assert_true(fabs(c.v_mps - 0.5) < 1e-12);
  assert_true(fabs(c.omega_radps - 0.3) < 1e-12);
  assert_true(fabs(c.accel_trans_mps2 - 0.7) < 1e-12);
  assert_true(fabs(c.accel_rot_radps2 - 100000.0 / 35000.0) < 1e-12);
  assert_false(sim_rflex_brake(d));
  assert_int_equal(feed(d, k_brake_set, sizeof(k_brake_set), 0.0), 0);
  sim_rflex_get_command(d, 0.0, &c);
  assert_true(c.v_mps == 0.0 && c.omega_radps == 0.0);
  assert_true(sim_rflex_brake(d));
  // No packet of these gets an answer.
  assert_int_equal(sim_rflex_drain(d, g_buf, sizeof(g_buf), 0.0), 0);
  sim_rflex_destroy(d);
}

// A feed holding two command cycles stops after the first rotation SET_DIR (lockstep advance
// point) and the rest is consumed by the next call.
static void test_rflex_feed_stops_after_rotation_set_dir(void** state) {
  (void)state;
  sim_rflex_t* d = make(false);
  uint8_t stream[2 * (sizeof(k_trans) + sizeof(k_rot))];
  size_t n = 0;
  for (int i = 0; i < 2; ++i) {
    memcpy(stream + n, k_trans, sizeof(k_trans));
    n += sizeof(k_trans);
    memcpy(stream + n, k_rot, sizeof(k_rot));
    n += sizeof(k_rot);
  }
  int end = 0;
  const size_t first = sim_rflex_feed(d, stream, n, 0.0, &end);
  assert_int_equal(end, 1);
  assert_int_equal(first, sizeof(k_trans) + sizeof(k_rot));
  const size_t second = sim_rflex_feed(d, stream + first, n - first, 0.0, &end);
  assert_int_equal(end, 1);
  assert_int_equal(first + second, n);
  assert_int_equal(sim_rflex_get_counters(d)->set_dir, 4);
  sim_rflex_destroy(d);
}

// SYS_STATUS (hand-written request) is answered with the exact packet: port 1, id 0, opcode 1,
// DLEN 9, timestamp 0, voltage raw (24.6 - 1.2) * 100 = 2340 = 0x0924, brake 0, XOR 0x24.
static void test_rflex_sys_status_reply_is_exact(void** state) {
  (void)state;
  sim_rflex_t* d = make(false);
  feed(d, k_brake_release, sizeof(k_brake_release), 0.0);
  feed(d, k_sys_status, sizeof(k_sys_status), 0.0);
  const size_t n = sim_rflex_drain(d, g_buf, sizeof(g_buf), 0.0);
  static const uint8_t expected[] = {0x1b, 0x02, 0x01, 0x00, 0x01, 0x09, 0x00, 0x00, 0x00,
                                     0x00, 0x00, 0x00, 0x09, 0x24, 0x00, 0x24, 0x1b, 0x03};
  assert_int_equal(n, sizeof(expected));
  assert_memory_equal(g_buf, expected, sizeof(expected));
  // Through proto: the brake byte follows BRAKE_SET.
  rflex_packet_t pkt;
  rflex_make_brake_set(&pkt);
  size_t k = rflex_encode(g_buf, sizeof(g_buf), &pkt, RFLEX_HOST_STRICT);
  feed(d, g_buf, k, 0.0);
  rflex_make_sys_status_request(&pkt);
  k = rflex_encode(g_buf, sizeof(g_buf), &pkt, RFLEX_HOST_STRICT);
  feed(d, g_buf, k, 0.0);
  rflex_packet_t out[4];
  assert_int_equal(collect(d, 0.0, out, 4), 1);
  rflex_sys_status_t st;
  assert_int_equal(rflex_parse_sys_status(&out[0], &st), PROTO_OK);
  assert_int_equal(st.brake, 1);
  assert_true(fabs(rflex_battery_volts(st.voltage_raw, 1.2) - 24.6) < 1e-9);
  sim_rflex_destroy(d);
}

// Odometry on (hand-written, period 100000 µs, mask 3): each emission gives one report per
// axis with positions round(odo * K) and velocities round(v * K); proto's odometry integrates
// them back to the distance driven.
static void test_rflex_odometry_reports_encode_positions(void** state) {
  (void)state;
  sim_rflex_t* d = make(false);
  assert_false(sim_rflex_odometry_on(d));
  feed(d, k_odometry_on, sizeof(k_odometry_on), 0.0);
  assert_true(sim_rflex_odometry_on(d));
  sim_rflex_sample_t s;
  memset(&s, 0, sizeof(s));
  s.odo_trans_m = 1.25;
  s.odo_rot_rad = -0.5;
  s.v_mps = 0.4;
  s.omega_radps = -0.2;
  sim_rflex_emit_odometry(d, &s, 0.1);
  rflex_packet_t out[8];
  assert_int_equal(collect(d, 0.1, out, 8), 2);
  rflex_motor_report_t r[2];
  for (int i = 0; i < 2; ++i) {
    assert_int_equal(rflex_parse_motor_report(&out[i], &r[i]), PROTO_OK);
    assert_int_equal(out[i].id, i);  // ids count up
  }
  assert_int_equal(r[0].axis, RFLEX_AXIS_TRANS);
  assert_int_equal(r[0].position, 128750);
  assert_int_equal(r[0].velocity, 41200);
  assert_int_equal(r[1].axis, RFLEX_AXIS_ROT);
  assert_int_equal(r[1].position, -17500);
  assert_int_equal(r[1].velocity, -7000);
  assert_int_equal(r[0].timestamp, 25);  // 0.1 s in 4 ms ticks
  sim_rflex_destroy(d);
}

// A 0x1B byte inside a report leaves as ESC NUL (device stuffing) and decodes back.
static void test_rflex_reports_stuff_escape_bytes(void** state) {
  (void)state;
  sim_rflex_t* d = make(false);
  feed(d, k_odometry_on, sizeof(k_odometry_on), 0.0);
  sim_rflex_sample_t s;
  memset(&s, 0, sizeof(s));
  s.odo_trans_m = 27.0 / 103000.0;  // position 0x0000001B
  sim_rflex_emit_odometry(d, &s, 0.0);
  const size_t n = sim_rflex_drain(d, g_buf, sizeof(g_buf), 0.0);
  // Translation report data: rv 0, timestamp 0, axis 0, then position 00 00 00 1B -> 1B 00.
  static const uint8_t stuffed[] = {0x00, 0x00, 0x00, 0x1b, 0x00, 0x00, 0x00, 0x00, 0x00};
  int found = 0;
  for (size_t i = 0; i + sizeof(stuffed) <= n; ++i) {
    if (memcmp(g_buf + i, stuffed, sizeof(stuffed)) == 0) {
      found = 1;
    }
  }
  assert_true(found);
  static rflex_decoder_t dec;
  rflex_decoder_init(&dec);
  size_t used = 0;
  rflex_motor_report_t r;
  int reports = 0;
  while (used < n) {
    bool got = false;
    rflex_packet_t pkt;
    used += rflex_decoder_push(&dec, g_buf + used, n - used, &pkt, &got);
    if (got && rflex_parse_motor_report(&pkt, &r) == PROTO_OK && r.axis == RFLEX_AXIS_TRANS) {
      assert_int_equal(r.position, 27);
      ++reports;
    }
  }
  assert_int_equal(reports, 1);
  assert_true(dec.counters.packets_stuffed >= 1);
  sim_rflex_destroy(d);
}

// Bump panels: with DIO on (hand-written request) a press of base panel 2 (address 0x48) is
// reported once with its segment bits, and its release with value 0; with DIO off nothing.
static void test_rflex_bumper_changes_send_dio_reports(void** state) {
  (void)state;
  sim_rflex_t* d = make(false);
  sim_rflex_sample_t s;
  memset(&s, 0, sizeof(s));
  s.panels[8] = 0x04;
  sim_rflex_emit_dio(d, &s, 0.0);
  assert_int_equal(sim_rflex_drain(d, g_buf, sizeof(g_buf), 0.0), 0);  // DIO off
  feed(d, k_dio_on, sizeof(k_dio_on), 0.0);
  sim_rflex_emit_dio(d, &s, 0.1);
  sim_rflex_emit_dio(d, &s, 0.2);  // unchanged: no second report
  rflex_packet_t out[4];
  assert_int_equal(collect(d, 0.2, out, 4), 1);
  rflex_dio_report_t r;
  assert_int_equal(rflex_parse_dio_report(&out[0], &r), PROTO_OK);
  assert_int_equal(r.address, 0x48);
  assert_int_equal(r.value, 0x04);
  assert_int_equal(rflex_dio_bumper_panel(r.address), 8);
  s.panels[8] = 0;
  sim_rflex_emit_dio(d, &s, 0.3);
  assert_int_equal(collect(d, 0.3, out, 4), 1);
  assert_int_equal(rflex_parse_dio_report(&out[0], &r), PROTO_OK);
  assert_int_equal(r.value, 0);
  // Older drivers' "DIO off" on the SONAR port (opcode 0, DLEN 4) is ignored (protocols.md A.2):
  // DIO stays on.
  static const uint8_t sonar_dio_off[] = {0x1b, 0x02, 0x04, 0x00, 0x00, 0x04, 0x00,
                                          0x00, 0x00, 0x00, 0x00, 0x1b, 0x03};
  feed(d, sonar_dio_off, sizeof(sonar_dio_off), 0.4);
  s.panels[13] = 0x01;
  sim_rflex_emit_dio(d, &s, 0.5);
  assert_int_equal(collect(d, 0.5, out, 4), 1);
  assert_int_equal(rflex_parse_dio_report(&out[0], &r), PROTO_OK);
  assert_int_equal(r.address, 0x4D);
  sim_rflex_destroy(d);
}

// Watchdog: commands hold for 1 s after the last SET_DIR, then both axes stop (counted once);
// the next SET_DIR restores motion.
static void test_rflex_watchdog_stops_base_after_silence(void** state) {
  (void)state;
  sim_rflex_t* d = make(false);
  feed(d, k_brake_release, sizeof(k_brake_release), 0.0);
  feed(d, k_trans, sizeof(k_trans), 0.0);
  feed(d, k_rot, sizeof(k_rot), 0.0);
  sim_rflex_command_t c;
  sim_rflex_get_command(d, 0.9, &c);
  assert_true(c.v_mps > 0.0);
  sim_rflex_get_command(d, 1.05, &c);
  assert_true(c.v_mps == 0.0 && c.omega_radps == 0.0);
  sim_rflex_get_command(d, 2.0, &c);
  assert_int_equal(sim_rflex_get_counters(d)->watchdog_trips, 1);
  feed(d, k_trans, sizeof(k_trans), 2.0);
  sim_rflex_get_command(d, 2.0, &c);
  assert_true(fabs(c.v_mps - 0.5) < 1e-12);
  sim_rflex_destroy(d);
}

// SET_DEFAULTS stops both axes and restores the default accelerations; sonar commands (also
// the hand-written one with id 4) and proto-built IR commands are consumed silently.
static void test_rflex_defaults_and_unanswered_packets(void** state) {
  (void)state;
  sim_rflex_t* d = make(false);
  feed(d, k_brake_release, sizeof(k_brake_release), 0.0);
  feed(d, k_trans, sizeof(k_trans), 0.0);
  feed(d, k_set_defaults, sizeof(k_set_defaults), 0.0);
  sim_rflex_command_t c;
  sim_rflex_get_command(d, 0.0, &c);
  assert_true(c.v_mps == 0.0);
  assert_true(fabs(c.accel_trans_mps2 - 0.7) < 1e-12);  // rflex_b21r_params_default
  feed(d, k_sonar_on, sizeof(k_sonar_on), 0.0);
  rflex_packet_t pkt;
  rflex_make_ir_off(&pkt);
  const size_t k = rflex_encode(g_buf, sizeof(g_buf), &pkt, RFLEX_HOST_STRICT);
  feed(d, g_buf, k, 0.0);
  assert_int_equal(sim_rflex_get_counters(d)->unanswered, 2);
  assert_int_equal(sim_rflex_drain(d, g_buf, sizeof(g_buf), 0.0), 0);
  sim_rflex_destroy(d);
}

// proto's velocity builder (with its 0x1B nudging) drives the same commands; odometry through
// proto's builder switches reports off again with period 0.
static void test_rflex_proto_built_commands_round_trip(void** state) {
  (void)state;
  sim_rflex_t* d = make(false);
  rflex_b21r_params_t params;
  rflex_b21r_params_default(&params);
  rflex_packet_t pkts[2];
  assert_int_equal(rflex_make_velocity(pkts, &params, -0.35, 0.8, 0.0), PROTO_OK);
  rflex_packet_t rel;
  rflex_make_brake_release(&rel);
  size_t k = rflex_encode(g_buf, sizeof(g_buf), &rel, RFLEX_HOST_STRICT);
  feed(d, g_buf, k, 0.0);
  for (int i = 0; i < 2; ++i) {
    k = rflex_encode(g_buf, sizeof(g_buf), &pkts[i], RFLEX_HOST_STRICT);
    assert_true(k > 0);
    assert_int_equal(feed(d, g_buf, k, 0.0), i);
  }
  sim_rflex_command_t c;
  sim_rflex_get_command(d, 0.0, &c);
  assert_true(fabs(c.v_mps + 0.35) < 1e-4);  // within the nudge of a few counts
  assert_true(fabs(c.omega_radps - 0.8) < 1e-4);
  rflex_packet_t odo;
  assert_int_equal(rflex_make_odometry_request(&odo, 100000, 3), PROTO_OK);
  k = rflex_encode(g_buf, sizeof(g_buf), &odo, RFLEX_HOST_STRICT);
  feed(d, g_buf, k, 0.0);
  assert_true(sim_rflex_odometry_on(d));
  assert_int_equal(rflex_make_odometry_request(&odo, 0, 0), PROTO_OK);
  k = rflex_encode(g_buf, sizeof(g_buf), &odo, RFLEX_HOST_STRICT);
  feed(d, g_buf, k, 0.0);
  assert_false(sim_rflex_odometry_on(d));
  sim_rflex_destroy(d);
}

// Paced: reports follow the requested period (10 Hz per axis over 2 s) and bytes leave at
// 115200 Bd; silence suppresses everything.
static void test_rflex_paced_reports_follow_period(void** state) {
  (void)state;
  sim_rflex_t* d = make(true);
  feed(d, k_odometry_on, sizeof(k_odometry_on), 0.0);
  sim_rflex_sample_t s;
  memset(&s, 0, sizeof(s));
  size_t packets = 0;
  rflex_packet_t out[64];
  for (int ms = 0; ms <= 2000; ++ms) {
    sim_rflex_poll(d, &s, ms * 1e-3);
    packets += collect(d, ms * 1e-3, out, 64);
  }
  assert_true(packets >= 40 && packets <= 42);
  sim_rflex_set_silent_until(d, 3.0);
  size_t silent_packets = 0;
  for (int ms = 2001; ms < 3000; ++ms) {
    sim_rflex_poll(d, &s, ms * 1e-3);
    silent_packets += collect(d, ms * 1e-3, out, 64);
  }
  assert_int_equal(silent_packets, 0);
  sim_rflex_destroy(d);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_rflex_handwritten_set_dir_pair_sets_commands),
      cmocka_unit_test(test_rflex_feed_stops_after_rotation_set_dir),
      cmocka_unit_test(test_rflex_sys_status_reply_is_exact),
      cmocka_unit_test(test_rflex_odometry_reports_encode_positions),
      cmocka_unit_test(test_rflex_reports_stuff_escape_bytes),
      cmocka_unit_test(test_rflex_bumper_changes_send_dio_reports),
      cmocka_unit_test(test_rflex_watchdog_stops_base_after_silence),
      cmocka_unit_test(test_rflex_defaults_and_unanswered_packets),
      cmocka_unit_test(test_rflex_proto_built_commands_round_trip),
      cmocka_unit_test(test_rflex_paced_reports_follow_period),
  };
  return cmocka_run_group_tests_name("sim.rflex", tests, NULL, NULL);
}
