// SPDX-License-Identifier: MIT
// rFLEX codec: protocols.md A.4 worked examples, the host's no-raw-ESC rule, device stuffing,
// the streaming decoder, typed messages and odometry integration.
#include <proto/rflex.h>

#include "proto_test_util.h"

#include <b21r_test/alloc_counter.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

static uint8_t g_buf[2048];
static uint8_t g_stream[16384];
static rflex_decoder_t g_dec;

static void expect_encoded(const rflex_packet_t* pkt, const char* hex) {
  uint8_t want[64];
  const size_t n = test_hex(hex, want, sizeof want);
  const size_t got = rflex_encode(g_buf, sizeof g_buf, pkt, RFLEX_HOST_STRICT);
  assert_int_equal(got, n);
  assert_memory_equal(g_buf, want, n);
}

// The worked examples of protocols.md A.4 come out of the typed builders byte for byte.
static void test_rflex_worked_examples_match(void** state) {
  (void)state;
  rflex_b21r_params_t p;
  rflex_b21r_params_default(&p);
  rflex_packet_t pk[2];
  assert_int_equal(rflex_make_velocity(pk, &p, 0.5, 0.3, 0.7), PROTO_OK);
  expect_encoded(&pk[0], "1b 02 02 00 07 0e 00 00 00 c9 2c 00 01 19 a4 00 00 75 30 01 16 1b 03");
  expect_encoded(&pk[1], "1b 02 02 00 07 0e 01 00 00 29 04 00 01 86 a0 00 00 88 b8 01 31 1b 03");
  // The default translational acceleration is the example's 0.7 m/s².
  assert_int_equal(rflex_make_velocity(pk, &p, 0.5, 0.3, 0.0), PROTO_OK);
  expect_encoded(&pk[0], "1b 02 02 00 07 0e 00 00 00 c9 2c 00 01 19 a4 00 00 75 30 01 16 1b 03");
  rflex_packet_t q;
  rflex_make_brake_release(&q);
  expect_encoded(&q, "1b 02 02 00 0c 00 0e 1b 03");
  rflex_make_brake_set(&q);
  expect_encoded(&q, "1b 02 02 00 0b 00 09 1b 03");
  rflex_make_set_defaults(&q);
  expect_encoded(&q, "1b 02 02 00 0a 00 08 1b 03");
  rflex_make_sys_status_request(&q);
  expect_encoded(&q, "1b 02 01 00 01 00 00 1b 03");
  assert_int_equal(rflex_make_odometry_request(&q, 100000, 3), PROTO_OK);
  expect_encoded(&q, "1b 02 02 00 22 08 00 01 86 a0 00 00 00 03 0c 1b 03");
  assert_int_equal(rflex_make_dio_request(&q, 100000), PROTO_OK);
  expect_encoded(&q, "1b 02 05 00 00 04 00 01 86 a0 26 1b 03");
  assert_int_equal(rflex_make_sonar_run(&q, 30000, 0, 0, 2), PROTO_OK);
  expect_encoded(&q, "1b 02 04 04 00 0d 00 00 75 30 00 00 00 00 00 00 00 00 02 4a 1b 03");
}

// Negative velocities send the magnitude with direction 0; stop sends zero with direction 1.
static void test_rflex_velocity_sign_and_stop(void** state) {
  (void)state;
  rflex_b21r_params_t p;
  rflex_b21r_params_default(&p);
  rflex_packet_t pk[2];
  rflex_set_dir_t sd;
  assert_int_equal(rflex_make_velocity(pk, &p, -0.25, -1.0, 1.0), PROTO_OK);
  assert_int_equal(rflex_parse_set_dir(&pk[0], &sd), PROTO_OK);
  assert_int_equal(sd.axis, RFLEX_AXIS_TRANS);
  assert_int_equal(sd.vel_mag, 25750);
  assert_int_equal(sd.dir, 0);
  assert_int_equal(sd.vel_counts, -25750);
  assert_int_equal(sd.acc, 103000);
  assert_int_equal(sd.torque, 30000);
  assert_int_equal(rflex_parse_set_dir(&pk[1], &sd), PROTO_OK);
  assert_int_equal(sd.axis, RFLEX_AXIS_ROT);
  assert_int_equal(sd.vel_counts, -35000);
  assert_int_equal(sd.acc, 100000);
  assert_int_equal(sd.torque, 35000);
  assert_int_equal(rflex_make_velocity(pk, &p, 0.0, 0.0, 0.0), PROTO_OK);
  assert_int_equal(rflex_parse_set_dir(&pk[0], &sd), PROTO_OK);
  assert_int_equal(sd.vel_mag, 0);
  assert_int_equal(sd.dir, 1);
  assert_int_equal(rflex_make_velocity(pk, &p, NAN, 0.0, 0.0), PROTO_ERR_INVALID_ARG);
  p.trans_counts_per_m = 0.0;
  assert_int_equal(rflex_make_velocity(pk, &p, 0.1, 0.0, 0.0), PROTO_ERR_INVALID_ARG);
  // Huge commands saturate instead of wrapping.
  rflex_b21r_params_default(&p);
  assert_int_equal(rflex_make_velocity(pk, &p, 1e9, -1e9, 0.0), PROTO_OK);
  assert_int_equal(rflex_parse_set_dir(&pk[0], &sd), PROTO_OK);
  assert_true(sd.vel_counts >= INT32_MAX - 8);
  assert_int_equal(rflex_parse_set_dir(&pk[1], &sd), PROTO_OK);
  assert_true(sd.vel_counts <= -INT32_MAX + 8);
}

// Sweeping velocities through every byte pattern: the host packet never carries a raw 0x1B
// between the markers (checksum included), the nudge stays within the byte-1 window (128 counts
// plus a few), the sign never changes, and zero stays exactly zero.
static void test_rflex_host_never_emits_raw_esc(void** state) {
  (void)state;
  size_t nudged = 0;
  for (int axis = 0; axis <= 1; ++axis) {
    for (int32_t v = -140000; v <= 140000; v += 1) {
      rflex_packet_t pk;
      int32_t nudge = 99;
      const uint32_t acc = axis == 0 ? 72100U : 100000U;
      const uint32_t torque = axis == 0 ? 30000U : 35000U;
      assert_int_equal(rflex_make_axis_velocity(&pk, (uint8_t)axis, v, acc, torque, &nudge), PROTO_OK);
      const size_t n = rflex_encode(g_buf, sizeof g_buf, &pk, RFLEX_HOST_STRICT);
      assert_int_equal(n, 23);
      assert_null(memchr(g_buf + 2, RFLEX_ESC, n - 4U));
      assert_true(nudge >= -130 && nudge <= 130);
      rflex_set_dir_t sd;
      assert_int_equal(rflex_parse_set_dir(&pk, &sd), PROTO_OK);
      if (v == 0) {
        assert_int_equal(sd.vel_counts, 0);
        assert_int_equal((int64_t)sd.acc - (int64_t)acc, nudge);
      } else {
        // Same sign, magnitude moved by exactly the reported nudge.
        assert_true((sd.vel_counts > 0) == (v > 0));
        const int64_t mag = v > 0 ? v : -(int64_t)v;
        assert_int_equal((int64_t)sd.vel_mag - mag, nudge);
      }
      nudged += nudge != 0 ? 1U : 0U;
    }
  }
  // The sweep crosses 0x1B in bytes 0 and 1 of the magnitude and in the checksum many times.
  assert_true(nudged > 1000U);
  // A stop whose checksum would be 0x1B nudges the acceleration, never the velocity.
  for (uint32_t acc = 0; acc < 70000U; ++acc) {
    rflex_packet_t raw;
    assert_int_equal(rflex_make_set_dir(&raw, 0, 0, acc, 30000, 1), PROTO_OK);
    if (rflex_checksum(&raw) == RFLEX_ESC) {
      rflex_packet_t pk;
      int32_t nudge = 0;
      assert_int_equal(rflex_make_axis_velocity(&pk, 0, 0, acc, 30000, &nudge), PROTO_OK);
      assert_int_not_equal(nudge, 0);
      rflex_set_dir_t sd;
      assert_int_equal(rflex_parse_set_dir(&pk, &sd), PROTO_OK);
      assert_int_equal(sd.vel_mag, 0);
      assert_false(rflex_packet_has_esc(&pk));
      break;
    }
  }
}

// Builders whose caller values contain 0x1B refuse instead of sending them raw; the strict
// encoder refuses such packets while the raw mode writes them as other drivers would.
static void test_rflex_host_strict_refuses_esc(void** state) {
  (void)state;
  rflex_packet_t pk;
  assert_int_equal(rflex_make_odometry_request(&pk, 0x1B00, 3), PROTO_ERR_RANGE);
  assert_int_equal(rflex_make_dio_request(&pk, 0x1B), PROTO_ERR_RANGE);
  assert_int_equal(rflex_encode(g_buf, sizeof g_buf, &pk, RFLEX_HOST_STRICT), 0);
  assert_int_equal(rflex_encode(g_buf, sizeof g_buf, &pk, RFLEX_HOST_RAW), 13);
  assert_int_equal(rflex_make_axis_velocity(&pk, 2, 0, 0, 0, NULL), PROTO_ERR_INVALID_ARG);
  assert_int_equal(rflex_make_set_dir(&pk, 0, 0, 0, 0, 2), PROTO_ERR_INVALID_ARG);
  // Too small a buffer: nothing written past cap.
  rflex_make_brake_set(&pk);
  memset(g_buf, 0xAA, sizeof g_buf);
  assert_int_equal(rflex_encode(g_buf, 8, &pk, RFLEX_HOST_STRICT), 0);
  assert_int_equal(g_buf[8], 0xAA);
  assert_int_equal(rflex_encode(g_buf, 9, &pk, RFLEX_HOST_STRICT), 9);
}

static void assert_motor_equal(const rflex_motor_report_t* a, const rflex_motor_report_t* b) {
  assert_int_equal(a->rv, b->rv);
  assert_int_equal(a->timestamp, b->timestamp);
  assert_int_equal(a->axis, b->axis);
  assert_int_equal(a->position, b->position);
  assert_int_equal(a->velocity, b->velocity);
  assert_int_equal(a->acceleration, b->acceleration);
  assert_int_equal(a->torque, b->torque);
}

// Device output stuffs every 0x1B (data and checksum) as ESC NUL and decodes back unchanged.
static void test_rflex_device_stuffing_round_trip(void** state) {
  (void)state;
  rflex_motor_report_t r = {.rv = 0x1B1B1B1BU, .timestamp = 0x0000001BU, .axis = 1,
                            .position = -0x1B1B, .velocity = 0x1B, .acceleration = 7,
                            .torque = 0x1B000000U};
  rflex_packet_t pk;
  assert_int_equal(rflex_make_motor_report(&pk, 0x1B, &r), PROTO_OK);
  const size_t n = rflex_encode(g_buf, sizeof g_buf, &pk, RFLEX_DEVICE_STUFFED);
  size_t escs = 0;
  for (size_t i = 2; i + 2U < n; ++i) {
    if (g_buf[i] == RFLEX_ESC) {
      assert_int_equal(g_buf[i + 1U], RFLEX_NUL);
      ++escs;
      ++i;
    }
  }
  assert_true(escs >= 8U);
  assert_int_equal(n, RFLEX_PACKET_BYTES(25) + escs);
  rflex_decoder_init(&g_dec);
  rflex_packet_t out;
  bool got = false;
  assert_int_equal(rflex_decoder_push(&g_dec, g_buf, n, &out, &got), n);
  assert_true(got);
  assert_int_equal(out.dlen, 25);
  assert_int_equal(out.id, 0x1B);
  assert_memory_equal(out.data, pk.data, 25);
  rflex_motor_report_t r2;
  assert_int_equal(rflex_parse_motor_report(&out, &r2), PROTO_OK);
  assert_motor_equal(&r, &r2);
  assert_int_equal(g_dec.counters.packets_stuffed, 1);
}

typedef struct want_pkt {
  uint8_t port, opcode, dlen;
  uint8_t chk;
  bool raw_only;  // decodable in the device role only (raw 0x1B framed by DLEN)
} want_pkt_t;

static want_pkt_t summary(const rflex_packet_t* p) {
  return (want_pkt_t){p->port, p->opcode, p->dlen, rflex_checksum(p), false};
}

// Builds a stream with garbage, fillers, duplicated markers, ESC ESC, a corrupt packet, a
// truncated packet and a raw (unstuffed) 0x1B host packet between eight good packets.
static size_t build_mixed_stream(uint8_t* out, want_pkt_t* want, size_t* n_want) {
  size_t n = 0;
  size_t w = 0;
  rflex_packet_t pk;
  // Garbage, including ETX and STX bytes outside any packet.
  static const uint8_t garbage[] = {0x00, 0x03, 0x02, 0x55, 0xFF, 0x1B, 0x1B, 0x1B, 0x07};
  memcpy(out + n, garbage, sizeof garbage);
  n += sizeof garbage;
  // 1: a stuffed motor report.
  const rflex_motor_report_t r = {.rv = 0, .timestamp = 0x1B1B, .axis = 0, .position = 0x001B0000,
                                  .velocity = -27, .acceleration = 0, .torque = 0};
  (void)rflex_make_motor_report(&pk, 3, &r);
  n += rflex_encode(out + n, 512, &pk, RFLEX_DEVICE_STUFFED);
  want[w++] = summary(&pk);
  // 2: duplicated start markers, then a status reply with an ESC SOH filler after DLEN.
  out[n++] = 0x1B;
  out[n++] = 0x02;
  out[n++] = 0x1B;
  out[n++] = 0x02;
  const rflex_sys_status_t s = {.timestamp = 5, .voltage_raw = 2480, .brake = 1};
  (void)rflex_make_sys_status(&pk, 4, &s);
  size_t k = rflex_encode(out + n, 512, &pk, RFLEX_DEVICE_STUFFED);
  memmove(out + n + 8, out + n + 6, k - 6U);
  out[n + 6] = 0x1B;
  out[n + 7] = 0x01;
  n += k + 2U;
  want[w++] = summary(&pk);
  // 3: a DIO report after "ESC ESC STX".
  out[n++] = 0x1B;
  const rflex_dio_report_t d = {.timestamp = 9, .address = 0x45, .value = 0x000B};
  (void)rflex_make_dio_report(&pk, 5, &d);
  n += rflex_encode(out + n, 512, &pk, RFLEX_DEVICE_STUFFED);
  want[w++] = summary(&pk);
  // A corrupt packet (checksum flipped), then 4: the same packet intact.
  k = rflex_encode(out + n, 512, &pk, RFLEX_DEVICE_STUFFED);
  out[n + k - 3U] ^= 0x40;
  n += k;
  n += rflex_encode(out + n, 512, &pk, RFLEX_DEVICE_STUFFED);
  want[w++] = summary(&pk);
  // A truncated packet (cut before its end marker), then 5: a brake-set packet.
  k = rflex_encode(out + n, 512, &pk, RFLEX_DEVICE_STUFFED);
  n += k - 4U;
  rflex_make_brake_set(&pk);
  n += rflex_encode(out + n, 512, &pk, RFLEX_DEVICE_STUFFED);
  want[w++] = summary(&pk);
  // 6: a raw host packet with 0x1B bytes in its data (as Player would send), framed by DLEN.
  (void)rflex_make_set_dir(&pk, 0, 0x00001B1BU, 0x1B, 30000, 1);
  assert_true(rflex_packet_has_esc(&pk));
  n += rflex_encode(out + n, 512, &pk, RFLEX_HOST_RAW);
  want[w] = summary(&pk);
  want[w++].raw_only = true;
  // A packet with an invalid port, then 7: odometry request; 8: a packet with the maximum DLEN.
  out[n++] = 0x1B;
  out[n++] = 0x02;
  out[n++] = 0x09;
  out[n++] = 0x00;
  (void)rflex_make_odometry_request(&pk, 100000, 3);
  n += rflex_encode(out + n, 512, &pk, RFLEX_DEVICE_STUFFED);
  want[w++] = summary(&pk);
  memset(&pk, 0, sizeof pk);
  pk.port = RFLEX_PORT_SYS;
  pk.opcode = RFLEX_OP_SYS_LCD_DUMP;
  pk.dlen = 255;
  for (unsigned i = 0; i < 255U; ++i) {
    pk.data[i] = (uint8_t)(i * 7U);
  }
  n += rflex_encode(out + n, 1024, &pk, RFLEX_DEVICE_STUFFED);
  want[w++] = summary(&pk);
  *n_want = w;
  return n;
}

static size_t run_stream(rflex_decoder_t* dec, const uint8_t* bytes, size_t n, const size_t* plan,
                         size_t n_plan, want_pkt_t* got, size_t cap) {
  size_t n_got = 0;
  size_t off = 0;
  size_t pi = 0;
  while (off < n) {
    size_t c = n_plan == 0U ? n - off : plan[pi++ % n_plan];
    if (c == 0U || c > n - off) {
      c = n - off;
    }
    const uint8_t* p = bytes + off;
    size_t left = c;
    while (left > 0U) {
      rflex_packet_t pk;
      bool have = false;
      const size_t k = rflex_decoder_push(dec, p, left, &pk, &have);
      p += k;
      left -= k;
      if (have) {
        assert_true(n_got < cap);
        got[n_got++] = summary(&pk);
      } else {
        assert_true(k > 0U);
      }
    }
    off += c;
  }
  return n_got;
}

static void assert_pkts_equal(const want_pkt_t* got, size_t n_got, const want_pkt_t* want,
                              size_t n_want) {
  assert_int_equal(n_got, n_want);
  for (size_t i = 0; i < n_want; ++i) {
    assert_int_equal(got[i].port, want[i].port);
    assert_int_equal(got[i].opcode, want[i].opcode);
    assert_int_equal(got[i].dlen, want[i].dlen);
    assert_int_equal(got[i].chk, want[i].chk);
  }
}

// The packets of the mixed stream a decoder of this role must find.
static size_t wanted_for(rflex_role_t role, const want_pkt_t* all, size_t n_all, want_pkt_t* out) {
  size_t n = 0;
  for (size_t i = 0; i < n_all; ++i) {
    if (role == RFLEX_ROLE_DEVICE || !all[i].raw_only) {
      out[n++] = all[i];
    }
  }
  return n;
}

// The mixed stream yields the same packets and counters whole, byte by byte, and cut in two at
// every byte boundary, in both roles; only the device role accepts the raw 0x1B packet.
static void split_every_boundary(rflex_role_t role) {
  want_pkt_t all[16];
  size_t n_all = 0;
  const size_t n = build_mixed_stream(g_stream, all, &n_all);
  want_pkt_t want[16];
  const size_t n_want = wanted_for(role, all, n_all, want);
  want_pkt_t got[16];
  rflex_decoder_init_role(&g_dec, role);
  size_t n_got = run_stream(&g_dec, g_stream, n, NULL, 0, got, 16);
  assert_pkts_equal(got, n_got, want, n_want);
  const rflex_decoder_counters_t whole = g_dec.counters;
  assert_int_equal(whole.bytes_in, n);
  assert_int_equal(whole.packets_ok, role == RFLEX_ROLE_DEVICE ? 8 : 7);
  assert_int_equal(whole.packets_stuffed, 3);  // motor report, status (SOH), LCD dump
  assert_int_equal(whole.packets_raw_esc, role == RFLEX_ROLE_DEVICE ? 1 : 0);
  assert_true(whole.bad_checksum >= 1U);
  assert_true(whole.bad_port >= 1U);
  assert_true(whole.bad_framing >= 1U);
  assert_true(whole.bytes_garbage >= 9U);

  const size_t one = 1;
  rflex_decoder_init_role(&g_dec, role);
  n_got = run_stream(&g_dec, g_stream, n, &one, 1, got, 16);
  assert_pkts_equal(got, n_got, want, n_want);
  assert_memory_equal(&g_dec.counters, &whole, sizeof whole);
  for (size_t cut = 1; cut < n; ++cut) {
    const size_t plan[2] = {cut, n - cut};
    rflex_decoder_init_role(&g_dec, role);
    n_got = run_stream(&g_dec, g_stream, n, plan, 2, got, 16);
    assert_pkts_equal(got, n_got, want, n_want);
    assert_memory_equal(&g_dec.counters, &whole, sizeof whole);
  }
}

static void test_rflex_decoder_split_every_boundary_same_packets(void** state) {
  (void)state;
  split_every_boundary(RFLEX_ROLE_DEVICE);
  split_every_boundary(RFLEX_ROLE_HOST);
  // rflex_decoder_init() is the host role.
  rflex_decoder_init(&g_dec);
  assert_int_equal(g_dec.role, RFLEX_ROLE_HOST);
}

// What the B21r's base sends at 10 Hz (protocols.md A.5, A.6), as the emulator models it: per
// period two MOT_SYSTEM_REPORTs (translation slowing down from 0.5 m/s to a stop, rotation at
// 0.3 rad/s, 4 ms timestamps, running packet ids), a SYS_STATUS reply every 20 periods, a bump
// panel pressed and released. About one in twenty carries a 0x1B byte (an id, a position,
// velocity or timestamp byte, a checksum), stuffed as ESC NUL on the wire.
static size_t realistic_device_packets(rflex_packet_t* pk, size_t cap) {
  size_t n = 0;
  uint8_t id = 0;
  int32_t trans = 1234567;
  int32_t bearing = -32500;
  for (int k = 0; k < 600 && n + 4U <= cap; ++k) {
    const uint32_t ts = 0x00100000U + 25U * (uint32_t)k;
    const int32_t vel = k < 599 ? 51500 - 86 * k : 0;
    trans += vel / 10;
    bearing += 1050;  // 0.3 rad/s × 0.1 s × 35000 counts/rad
    const rflex_motor_report_t rt = {.rv = 0, .timestamp = ts, .axis = 0, .position = trans,
                                     .velocity = vel, .acceleration = 72100, .torque = 30000};
    const rflex_motor_report_t rr = {.rv = 0, .timestamp = ts, .axis = 1, .position = bearing,
                                     .velocity = 10500, .acceleration = 100000, .torque = 35000};
    (void)rflex_make_motor_report(&pk[n++], id++, &rt);
    (void)rflex_make_motor_report(&pk[n++], id++, &rr);
    if (k % 20 == 7) {
      const rflex_sys_status_t st = {.timestamp = ts, .voltage_raw = 2480U - (uint32_t)k / 4U, .brake = 0};
      (void)rflex_make_sys_status(&pk[n++], id++, &st);
    }
    if (k == 90 || k == 95) {
      const rflex_dio_report_t d = {.timestamp = ts, .address = 0x43, .value = k == 90 ? 0x0003 : 0};
      (void)rflex_make_dio_report(&pk[n++], id++, &d);
    }
  }
  return n;
}

// Feeds `bytes` and counts the decoded packets; *sentinel_ok is set when exactly `sentinel` came
// out last and every other decoded packet differs from `original` (a corrupted acceptance).
static void decode_damaged(rflex_role_t role, const uint8_t* bytes, size_t n, const rflex_packet_t* sentinel,
                           int* corrupted, int* sentinels) {
  rflex_decoder_init_role(&g_dec, role);
  const uint8_t* p = bytes;
  size_t left = n;
  while (left > 0U) {
    rflex_packet_t out;
    bool have = false;
    const size_t k = rflex_decoder_push(&g_dec, p, left, &out, &have);
    p += k;
    left -= k;
    if (!have) {
      continue;
    }
    if (out.port == sentinel->port && out.id == sentinel->id && out.opcode == sentinel->opcode &&
        out.dlen == sentinel->dlen && memcmp(out.data, sentinel->data, out.dlen) == 0) {
      ++*sentinels;
    } else {
      ++*corrupted;
    }
  }
}

// A byte lost on the line (UART overrun) never yields a packet with shifted fields, and never
// swallows the genuine packet after it: every single-byte deletion of every realistic device
// packet, followed by the next packet, decodes to exactly that next packet in the host role.
// The device role's raw fallback is what used to accept such packets (printed for comparison).
static void test_rflex_host_rejects_every_single_byte_deletion(void** state) {
  (void)state;
  static rflex_packet_t pk[1300];
  const size_t np = realistic_device_packets(pk, 1300);
  size_t with_esc = 0;
  int deletions = 0;
  int host_corrupted = 0;
  int host_lost = 0;
  int device_corrupted = 0;
  for (size_t i = 0; i + 1U < np; ++i) {
    with_esc += rflex_packet_has_esc(&pk[i]) ? 1U : 0U;
    uint8_t wire[2 * RFLEX_MAX_STUFFED_BYTES];
    const size_t a = rflex_encode(wire, sizeof wire, &pk[i], RFLEX_DEVICE_STUFFED);
    const size_t b = rflex_encode(wire + a, sizeof wire - a, &pk[i + 1U], RFLEX_DEVICE_STUFFED);
    assert_true(a > 0U && b > 0U);
    for (size_t del = 0; del < a; ++del) {
      uint8_t damaged[sizeof wire];
      memcpy(damaged, wire, del);
      memcpy(damaged + del, wire + del + 1U, a + b - del - 1U);
      const size_t n = a + b - 1U;
      int corrupted = 0;
      int sentinels = 0;
      decode_damaged(RFLEX_ROLE_HOST, damaged, n, &pk[i + 1U], &corrupted, &sentinels);
      host_corrupted += corrupted;
      host_lost += sentinels == 1 ? 0 : 1;
      int dev_sentinels = 0;
      decode_damaged(RFLEX_ROLE_DEVICE, damaged, n, &pk[i + 1U], &device_corrupted, &dev_sentinels);
      ++deletions;
    }
  }
  printf("rflex: %zu realistic device packets, %zu with a stuffed 0x1B; %d single-byte deletions: "
         "host role accepted %d corrupted and lost %d genuine packets; device role (raw fallback) "
         "accepted %d corrupted\n",
         np - 1U, with_esc, deletions, host_corrupted, host_lost, device_corrupted);
  assert_true(np > 1200U);
  assert_true(with_esc >= 50U);
  assert_int_equal(host_corrupted, 0);
  assert_int_equal(host_lost, 0);
}

// A candidate padded beyond the buffer with ESC SOH fillers is dropped as too long, and the
// decoder recovers for the next packet.
static void test_rflex_decoder_too_long_recovers(void** state) {
  (void)state;
  size_t n = 0;
  g_stream[n++] = 0x1B;
  g_stream[n++] = 0x02;
  g_stream[n++] = 0x02;
  for (int i = 0; i < 400; ++i) {
    g_stream[n++] = 0x1B;
    g_stream[n++] = 0x01;
  }
  rflex_packet_t pk;
  rflex_make_set_defaults(&pk);
  n += rflex_encode(g_stream + n, 64, &pk, RFLEX_HOST_STRICT);
  rflex_decoder_init(&g_dec);
  want_pkt_t got[4];
  const size_t n_got = run_stream(&g_dec, g_stream, n, NULL, 0, got, 4);
  assert_int_equal(n_got, 1);
  assert_int_equal(got[0].opcode, RFLEX_OP_MOT_SET_DEFAULTS);
  assert_int_equal(g_dec.counters.too_long, 1);
  rflex_decoder_reset(&g_dec);
}

// Reports parse back to their fields; battery volts use raw / 100 + 1.2; bump panels map.
static void test_rflex_reports_round_trip(void** state) {
  (void)state;
  rflex_packet_t pk;
  const rflex_sys_status_t s = {.timestamp = 123456, .voltage_raw = 2480, .brake = 1};
  assert_int_equal(rflex_make_sys_status(&pk, 1, &s), PROTO_OK);
  assert_int_equal(rflex_classify(&pk), RFLEX_MSG_SYS_STATUS);
  rflex_sys_status_t s2;
  assert_int_equal(rflex_parse_sys_status(&pk, &s2), PROTO_OK);
  assert_int_equal(s.timestamp, s2.timestamp);
  assert_int_equal(s.voltage_raw, s2.voltage_raw);
  assert_int_equal(s.brake, s2.brake);
  ASSERT_NEAR(rflex_battery_volts(s2.voltage_raw, 1.2), 26.0, 1e-12);
  const rflex_dio_report_t d = {.timestamp = 77, .address = 0x4D, .value = 0x0005};
  assert_int_equal(rflex_make_dio_report(&pk, 2, &d), PROTO_OK);
  assert_int_equal(rflex_classify(&pk), RFLEX_MSG_DIO_REPORT);
  rflex_dio_report_t d2;
  assert_int_equal(rflex_parse_dio_report(&pk, &d2), PROTO_OK);
  assert_int_equal(d.timestamp, d2.timestamp);
  assert_int_equal(d.address, d2.address);
  assert_int_equal(d.value, d2.value);
  assert_int_equal(rflex_dio_bumper_panel(0x40), 0);
  assert_int_equal(rflex_dio_bumper_panel(0x4D), 13);
  assert_int_equal(rflex_dio_bumper_panel(0x4E), -1);
  assert_int_equal(rflex_dio_bumper_panel(RFLEX_DIO_HEADING_INDEX), -1);
  const rflex_motor_report_t m = {.rv = 1, .timestamp = 2, .axis = 1, .position = INT32_MIN,
                                  .velocity = -1, .acceleration = 3, .torque = 4};
  assert_int_equal(rflex_make_motor_report(&pk, 3, &m), PROTO_OK);
  assert_int_equal(rflex_classify(&pk), RFLEX_MSG_MOTOR_REPORT);
  rflex_motor_report_t m2;
  assert_int_equal(rflex_parse_motor_report(&pk, &m2), PROTO_OK);
  assert_motor_equal(&m, &m2);
  // Wrong packets are refused.
  assert_int_equal(rflex_parse_sys_status(&pk, &s2), PROTO_ERR_FORMAT);
  assert_int_equal(rflex_parse_dio_report(&pk, &d2), PROTO_ERR_FORMAT);
  pk.dlen = 24;
  assert_int_equal(rflex_parse_motor_report(&pk, &m2), PROTO_ERR_FORMAT);
  const rflex_motor_report_t bad = {.axis = 2};
  assert_int_equal(rflex_make_motor_report(&pk, 0, &bad), PROTO_ERR_INVALID_ARG);
}

// Host commands as the device sees them: classification and field parsing of each.
static void test_rflex_device_parses_host_commands(void** state) {
  (void)state;
  rflex_packet_t pk;
  uint32_t a = 0;
  uint32_t b = 0;
  uint32_t c = 0;
  uint8_t mode = 9;
  assert_int_equal(rflex_make_odometry_request(&pk, 100000, 3), PROTO_OK);
  assert_int_equal(rflex_classify(&pk), RFLEX_MSG_ODOMETRY_REQUEST);
  assert_int_equal(rflex_parse_odometry_request(&pk, &a, &b), PROTO_OK);
  assert_int_equal(a, 100000);
  assert_int_equal(b, 3);
  assert_int_equal(rflex_make_dio_request(&pk, 0), PROTO_OK);
  assert_int_equal(rflex_classify(&pk), RFLEX_MSG_DIO_REQUEST);
  assert_int_equal(rflex_parse_dio_request(&pk, &a), PROTO_OK);
  assert_int_equal(a, 0);
  // The legacy "DIO off" on the SONAR port (opcode 0, DLEN 4) parses as a DIO request and is
  // not a sonar run.
  pk.port = RFLEX_PORT_SONAR;
  assert_int_equal(rflex_classify(&pk), RFLEX_MSG_SONAR_RUN);
  assert_int_equal(rflex_parse_dio_request(&pk, &a), PROTO_OK);
  assert_int_equal(rflex_parse_sonar_run(&pk, &a, &b, &c, &mode), PROTO_ERR_FORMAT);
  rflex_make_sonar_off(&pk);
  assert_int_equal(pk.id, 4);
  assert_int_equal(rflex_parse_sonar_run(&pk, &a, &b, &c, &mode), PROTO_OK);
  assert_int_equal(mode, 0);
  const uint32_t ir_on[5] = {0, 70, 10, 20, 150};
  assert_int_equal(rflex_make_ir_run(&pk, ir_on, 2), PROTO_OK);
  assert_int_equal(pk.dlen, 21);
  assert_int_equal(rflex_classify(&pk), RFLEX_MSG_IR_RUN);
  rflex_make_ir_off(&pk);
  assert_int_equal(pk.data[20], 0);
  rflex_make_brake_release(&pk);
  assert_int_equal(rflex_classify(&pk), RFLEX_MSG_BRAKE_RELEASE);
  rflex_make_brake_set(&pk);
  assert_int_equal(rflex_classify(&pk), RFLEX_MSG_BRAKE_SET);
  rflex_make_set_defaults(&pk);
  assert_int_equal(rflex_classify(&pk), RFLEX_MSG_SET_DEFAULTS);
  rflex_make_sys_status_request(&pk);
  assert_int_equal(rflex_classify(&pk), RFLEX_MSG_SYS_STATUS);
  assert_int_equal(pk.dlen, 0);
  (void)rflex_make_set_dir(&pk, 1, 5, 6, 7, 0);
  assert_int_equal(rflex_classify(&pk), RFLEX_MSG_SET_DIR);
  pk.data[0] = 3;
  rflex_set_dir_t sd;
  assert_int_equal(rflex_parse_set_dir(&pk, &sd), PROTO_ERR_RANGE);
  pk.port = 7;
  assert_int_equal(rflex_classify(&pk), RFLEX_MSG_UNKNOWN);
}

// Every builder's packet survives encode -> decoder unchanged: host commands unstuffed
// (strict), device reports stuffed, all in one stream.
static void test_rflex_every_message_round_trips(void** state) {
  (void)state;
  rflex_packet_t pk[24];
  size_t np = 0;
  rflex_b21r_params_t p;
  rflex_b21r_params_default(&p);
  assert_int_equal(rflex_make_velocity(&pk[np], &p, 0.0695, -0.2, 0.5), PROTO_OK);  // 0x1Bxx
  np += 2;
  assert_int_equal(rflex_make_set_dir(&pk[np++], 1, 7, 8, 9, 0), PROTO_OK);
  rflex_make_brake_set(&pk[np++]);
  rflex_make_brake_release(&pk[np++]);
  rflex_make_set_defaults(&pk[np++]);
  rflex_make_sys_status_request(&pk[np++]);
  assert_int_equal(rflex_make_odometry_request(&pk[np++], 100000, 3), PROTO_OK);
  assert_int_equal(rflex_make_odometry_request(&pk[np++], 0, 0), PROTO_OK);
  assert_int_equal(rflex_make_dio_request(&pk[np++], 100000), PROTO_OK);
  assert_int_equal(rflex_make_sonar_run(&pk[np++], 30000, 0, 0, 2), PROTO_OK);
  rflex_make_sonar_off(&pk[np++]);
  const uint32_t ir[5] = {0, 70, 10, 20, 150};
  assert_int_equal(rflex_make_ir_run(&pk[np++], ir, 2), PROTO_OK);
  rflex_make_ir_off(&pk[np++]);
  const size_t n_host = np;
  const rflex_motor_report_t m = {.rv = 0x1B, .timestamp = 1, .axis = 0, .position = 0x1B00,
                                  .velocity = -1, .acceleration = 2, .torque = 3};
  assert_int_equal(rflex_make_motor_report(&pk[np++], 0x1B, &m), PROTO_OK);
  const rflex_sys_status_t st = {.timestamp = 0x1B1B1B1B, .voltage_raw = 2300, .brake = 0};
  assert_int_equal(rflex_make_sys_status(&pk[np++], 2, &st), PROTO_OK);
  const rflex_dio_report_t d = {.timestamp = 3, .address = 0x31, .value = 0x1B};
  assert_int_equal(rflex_make_dio_report(&pk[np++], 3, &d), PROTO_OK);
  size_t n = 0;
  for (size_t i = 0; i < np; ++i) {
    const size_t k = rflex_encode(g_stream + n, sizeof g_stream - n, &pk[i],
                                  i < n_host ? RFLEX_HOST_STRICT : RFLEX_DEVICE_STUFFED);
    assert_true(k >= RFLEX_PACKET_BYTES(pk[i].dlen));
    n += k;
  }
  rflex_decoder_init(&g_dec);
  size_t got = 0;
  const uint8_t* q = g_stream;
  size_t left = n;
  while (left > 0U) {
    rflex_packet_t out;
    bool have = false;
    const size_t k = rflex_decoder_push(&g_dec, q, left, &out, &have);
    q += k;
    left -= k;
    if (have) {
      assert_true(got < np);
      assert_int_equal(out.port, pk[got].port);
      assert_int_equal(out.id, pk[got].id);
      assert_int_equal(out.opcode, pk[got].opcode);
      assert_int_equal(out.dlen, pk[got].dlen);
      assert_memory_equal(out.data, pk[got].data, out.dlen);
      ++got;
    }
  }
  assert_int_equal(got, np);
  assert_int_equal(g_dec.counters.bytes_dropped, 0);
  assert_int_equal(g_dec.counters.packets_stuffed, 3);
}

static rflex_motor_report_t report(uint8_t axis, int32_t pos) {
  return (rflex_motor_report_t){.axis = axis, .position = pos, .velocity = 0};
}

// A follower restarted at (0, 0, 0) integrates only the encoder steps after its restart, from
// the counts its source was fed; the source is only read.
static void test_rflex_odometry_follow(void** state) {
  (void)state;
  rflex_b21r_params_t p;
  rflex_b21r_params_default(&p);
  rflex_odometry_t base;
  assert_int_equal(rflex_odom_init(&base, &p), PROTO_OK);
  rflex_motor_report_t r = report(0, 1000);
  (void)rflex_odom_feed(&base, &r);
  r = report(1, 5000);
  (void)rflex_odom_feed(&base, &r);
  assert_true(rflex_odom_update(&base));
  r = report(0, 1000 + 20600);  // 0.2 m before the restart
  (void)rflex_odom_feed(&base, &r);
  assert_true(rflex_odom_update(&base));
  rflex_odometry_t run = base;
  rflex_odom_set_pose(&run, 0.0, 0.0, 0.0);
  r = report(0, 1000 + 20600 + 51500);  // 0.5 m after it
  (void)rflex_odom_feed(&base, &r);
  assert_true(rflex_odom_update(&base));
  assert_true(rflex_odom_follow(&run, &base));
  ASSERT_NEAR(base.x_m, 0.7, 1e-12);
  ASSERT_NEAR(run.x_m, 0.5, 1e-12);
  ASSERT_NEAR(run.y_m, 0.0, 0.0);
  assert_true(rflex_odom_follow(&run, &base));  // no new counts: no motion
  ASSERT_NEAR(run.x_m, 0.5, 1e-12);
  ASSERT_NEAR(base.x_m, 0.7, 1e-12);  // the source is only read
  assert_false(rflex_odom_follow(NULL, &base));
  assert_false(rflex_odom_follow(&run, NULL));
}

// Odometry: the first update sets the baseline; then heading first, then translation along the
// new heading; int32 wrap-around is a small step; implausible jumps are rejected and counted.
static void test_rflex_odometry_heading_first_wrap_and_rejects(void** state) {
  (void)state;
  rflex_b21r_params_t p;
  rflex_b21r_params_default(&p);
  rflex_odometry_t o;
  assert_int_equal(rflex_odom_init(&o, &p), PROTO_OK);
  rflex_motor_report_t r = report(0, 1000);
  assert_false(rflex_odom_update(&o));  // nothing seen yet
  assert_int_equal(rflex_odom_feed(&o, &r), PROTO_OK);
  assert_false(rflex_odom_update(&o));  // rotation not seen yet
  r = report(1, 5000);
  assert_int_equal(rflex_odom_feed(&o, &r), PROTO_OK);
  assert_true(rflex_odom_update(&o));  // baseline only
  ASSERT_NEAR(o.x_m, 0.0, 0.0);
  ASSERT_NEAR(o.theta_rad, 0.0, 0.0);
  // Quarter turn (pi/2 rad) and 0.5 m in the same update: heading applied first, so the
  // translation goes along +y.
  r = report(1, 5000 + (int32_t)lround(35000.0 * 3.14159265358979 / 2.0));
  (void)rflex_odom_feed(&o, &r);
  r = report(0, 1000 + 51500);
  (void)rflex_odom_feed(&o, &r);
  o.params.odom_max_step_rad = 2.0;
  assert_true(rflex_odom_update(&o));
  ASSERT_NEAR(o.theta_rad, 3.14159265358979 / 2.0, 1e-4);
  ASSERT_NEAR(o.x_m, 0.0, 1e-4);
  ASSERT_NEAR(o.y_m, 0.5, 1e-6);
  // Counters near INT32_MAX wrap to INT32_MIN: a small forward step, not a 4e9-count jump.
  p.odom_max_step_rad = 2.0;
  assert_int_equal(rflex_odom_init(&o, &p), PROTO_OK);
  r = report(1, 0);
  (void)rflex_odom_feed(&o, &r);
  r = report(0, INT32_MAX - 100);
  (void)rflex_odom_feed(&o, &r);
  assert_true(rflex_odom_update(&o));
  r = report(0, INT32_MIN + 10299);  // 10400 counts later
  (void)rflex_odom_feed(&o, &r);
  (void)rflex_odom_update(&o);
  ASSERT_NEAR(o.x_m, 10400.0 / 103000.0, 1e-9);
  assert_int_equal(o.rejected_trans, 0);
  // A corrupt position (jump of 2 m) is rejected; the return to normal is rejected too; then
  // integration continues.
  const double x_before = o.x_m;
  r = report(0, INT32_MIN + 10299 + 206000);
  (void)rflex_odom_feed(&o, &r);
  (void)rflex_odom_update(&o);
  r = report(0, INT32_MIN + 10299 + 1000);
  (void)rflex_odom_feed(&o, &r);
  (void)rflex_odom_update(&o);
  assert_int_equal(o.rejected_trans, 2);
  ASSERT_NEAR(o.x_m, x_before, 0.0);
  r = report(0, INT32_MIN + 10299 + 1000 + 10300);
  (void)rflex_odom_feed(&o, &r);
  (void)rflex_odom_update(&o);
  ASSERT_NEAR(o.x_m, x_before + 0.1, 1e-9);
  // A heading jump beyond the limit is rejected and counted.
  r = report(1, o.rot_latest + 3 * 35000);
  (void)rflex_odom_feed(&o, &r);
  (void)rflex_odom_update(&o);
  assert_int_equal(o.rejected_rot, 1);
  ASSERT_NEAR(o.theta_rad, 0.0, 0.0);
  // Headings stay normalised in (-pi, pi].
  for (int i = 0; i < 20; ++i) {
    r = report(1, o.rot_latest + 35000);
    (void)rflex_odom_feed(&o, &r);
    (void)rflex_odom_update(&o);
    assert_true(o.theta_rad > -3.1415927 && o.theta_rad <= 3.1415927);
  }
  // Velocities are converted with the same factors.
  r = (rflex_motor_report_t){.axis = 0, .position = o.trans_latest, .velocity = -51500};
  (void)rflex_odom_feed(&o, &r);
  ASSERT_NEAR(o.v_mps, -0.5, 1e-12);
  r = (rflex_motor_report_t){.axis = 2};
  assert_int_equal(rflex_odom_feed(&o, &r), PROTO_ERR_RANGE);
  p.rot_counts_per_rad = NAN;
  assert_int_equal(rflex_odom_init(&o, &p), PROTO_ERR_INVALID_ARG);
}

// Decoding and odometry over a long stream allocate nothing.
static void test_rflex_decoder_no_allocation(void** state) {
  (void)state;
  want_pkt_t want[16];
  size_t n_want = 0;
  const size_t n = build_mixed_stream(g_stream, want, &n_want);
  rflex_decoder_init_role(&g_dec, RFLEX_ROLE_DEVICE);
  alloc_counter_begin();
  for (int rep = 0; rep < 100; ++rep) {
    const uint8_t* p = g_stream;
    size_t left = n;
    while (left > 0U) {
      rflex_packet_t pk;
      bool have = false;
      const size_t k = rflex_decoder_push(&g_dec, p, left, &pk, &have);
      p += k;
      left -= k;
    }
  }
  assert_int_equal(alloc_counter_end(), 0);
  assert_int_equal(g_dec.counters.packets_ok, 800);
}

// Encodes pkt as the base sends it (stuffed) into buf; returns the byte count.
static size_t device_bytes(uint8_t* buf, size_t cap, const rflex_packet_t* pkt) {
  const size_t n = rflex_encode(buf, cap, pkt, RFLEX_DEVICE_STUFFED);
  assert_true(n > 0U);
  return n;
}

// The host view takes the base's byte stream: odometry from both axes' reports, bump panels
// pressed and released over DIO, brake and battery from SYS_STATUS; garbage is only counted.
static void test_rflex_host_view_follows_reports(void** state) {
  (void)state;
  rflex_b21r_params_t params;
  rflex_b21r_params_default(&params);
  rflex_host_t host;
  assert_int_equal(rflex_host_init(&host, &params), PROTO_OK);
  assert_int_equal(host.brake, -1);
  static uint8_t buf[4096];
  size_t n = 0;
  rflex_packet_t pk;
  const rflex_motor_report_t trans = {.axis = 0, .position = 103000, .velocity = 0x1B1B};
  const rflex_motor_report_t rot = {.axis = 1, .position = 0};
  assert_int_equal(rflex_make_motor_report(&pk, 0x1B, &trans), PROTO_OK);  // stuffed id and data
  n += device_bytes(buf + n, sizeof buf - n, &pk);
  assert_int_equal(rflex_make_motor_report(&pk, 1, &rot), PROTO_OK);
  n += device_bytes(buf + n, sizeof buf - n, &pk);
  buf[n++] = 0x55;  // line noise between packets
  const rflex_dio_report_t press = {.address = 0x46, .value = 0x0003};
  assert_int_equal(rflex_make_dio_report(&pk, 2, &press), PROTO_OK);
  n += device_bytes(buf + n, sizeof buf - n, &pk);
  const rflex_sys_status_t st = {.voltage_raw = 2480, .brake = 0};
  assert_int_equal(rflex_make_sys_status(&pk, 3, &st), PROTO_OK);
  n += device_bytes(buf + n, sizeof buf - n, &pk);
  assert_int_equal(rflex_host_feed(&host, buf, n), 4U);
  assert_true(host.report_new[0] && host.report_new[1]);
  assert_int_equal(host.bumper_mask, 1U << 6);
  assert_int_equal(host.brake, 0);
  ASSERT_NEAR(host.battery_v, 26.0, 1e-12);
  assert_int_equal(host.packets, 4U);
  assert_int_equal(host.decoder.counters.bytes_garbage, 1U);
  // The first update sets the baseline; the next report pair moves the pose 1 m ahead.
  assert_true(rflex_odom_update(&host.odometry));
  const rflex_motor_report_t trans2 = {.axis = 0, .position = 2 * 103000};
  assert_int_equal(rflex_make_motor_report(&pk, 4, &trans2), PROTO_OK);
  n = device_bytes(buf, sizeof buf, &pk);
  const rflex_dio_report_t release = {.address = 0x46, .value = 0};
  assert_int_equal(rflex_make_dio_report(&pk, 5, &release), PROTO_OK);
  n += device_bytes(buf + n, sizeof buf - n, &pk);
  assert_int_equal(rflex_host_feed(&host, buf, n), 2U);
  assert_true(rflex_odom_update(&host.odometry));
  ASSERT_NEAR(host.odometry.x_m, 1.0, 1e-12);
  assert_int_equal(host.bumper_mask, 0U);
  assert_int_equal(rflex_host_init(&host, NULL), PROTO_ERR_INVALID_ARG);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_rflex_worked_examples_match),
      cmocka_unit_test(test_rflex_velocity_sign_and_stop),
      cmocka_unit_test(test_rflex_host_never_emits_raw_esc),
      cmocka_unit_test(test_rflex_host_strict_refuses_esc),
      cmocka_unit_test(test_rflex_device_stuffing_round_trip),
      cmocka_unit_test(test_rflex_decoder_split_every_boundary_same_packets),
      cmocka_unit_test(test_rflex_host_rejects_every_single_byte_deletion),
      cmocka_unit_test(test_rflex_decoder_too_long_recovers),
      cmocka_unit_test(test_rflex_reports_round_trip),
      cmocka_unit_test(test_rflex_device_parses_host_commands),
      cmocka_unit_test(test_rflex_every_message_round_trips),
      cmocka_unit_test(test_rflex_odometry_heading_first_wrap_and_rejects),
      cmocka_unit_test(test_rflex_odometry_follow),
      cmocka_unit_test(test_rflex_decoder_no_allocation),
      cmocka_unit_test(test_rflex_host_view_follows_reports),
  };
  return cmocka_run_group_tests_name("proto.rflex", tests, NULL, NULL);
}
