// SPDX-License-Identifier: MIT
// The emulated LMS200 answers real encoded requests (lib/proto and the hand-written telegrams of
// protocols.md), streams scans with the right codes, noise and pacing.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>
#include <proto/lms200.h>

#include "sim/lms200_dev.h"

static const double k_pi = 3.14159265358979323846;

// Scan provider: fixed pattern or constant range.
typedef struct provider {
  double pattern[4];
  int use_pattern;
  double constant_m;
  size_t calls;
} provider_t;

static void provide(void* user, double angle_min_rad, double increment_rad, size_t n, double* out) {
  provider_t* p = user;
  (void)angle_min_rad;
  (void)increment_rad;
  ++p->calls;
  for (size_t i = 0; i < n; ++i) {
    out[i] = p->use_pattern ? p->pattern[i % 4] : p->constant_m;
  }
}

static provider_t g_provider;
static uint8_t g_buf[65536];
static lms_decoder_t g_host;

static sim_lms_t* make(double noise, uint32_t baud, bool paced) {
  sim_lms_config_t cfg;
  sim_lms_config_default(&cfg);
  cfg.noise_sigma_m = noise;
  cfg.power_up_baud = baud;
  cfg.paced = paced;
  memset(&g_provider, 0, sizeof(g_provider));
  g_provider.constant_m = 2.0;
  sim_lms_t* d = sim_lms_create(&cfg, provide, &g_provider);
  assert_non_null(d);
  assert_int_equal(lms_decoder_init(&g_host, LMS_ROLE_HOST, 0), PROTO_OK);
  return d;
}

static void send(sim_lms_t* d, const uint8_t* bytes, size_t n) { sim_lms_feed(d, bytes, n, 0.0); }

// Decodes everything the device has queued; returns the number of events, copies the last
// telegram's data into *data (if any) and counts ACKs/NAKs.
typedef struct reply {
  int acks, naks, telegrams;
  uint8_t cmd;
  uint8_t data[1024];
  size_t data_len;
  lms_telegram_t last;  // data pointer invalid after the call
  lms_scan_t scan;
  int scans;
} reply_t;

static reply_t g_reply;

static void collect(sim_lms_t* d, double t_s) {
  memset(&g_reply, 0, sizeof(g_reply));
  const size_t n = sim_lms_drain(d, g_buf, sizeof(g_buf), t_s);
  const uint8_t* p = g_buf;
  size_t len = n;
  while (len > 0) {
    lms_event_t ev;
    const size_t k = lms_decoder_push(&g_host, p, len, &ev);
    p += k;
    len -= k;
    if (ev.kind == LMS_EVENT_ACK) {
      ++g_reply.acks;
    } else if (ev.kind == LMS_EVENT_NAK) {
      ++g_reply.naks;
    } else if (ev.kind == LMS_EVENT_TELEGRAM) {
      ++g_reply.telegrams;
      g_reply.cmd = ev.telegram.cmd;
      g_reply.data_len = ev.telegram.data_len;
      if (ev.telegram.data_len > 0) {
        memcpy(g_reply.data, ev.telegram.data, ev.telegram.data_len);
      }
      if (ev.telegram.cmd == LMS_REPLY_VALUES) {
        assert_int_equal(lms_parse_scan(&ev.telegram, 13, &g_reply.scan), PROTO_OK);
        ++g_reply.scans;
      }
      g_reply.last = ev.telegram;
      g_reply.last.data = NULL;
    }
  }
}

// Start/stop stream through lib/proto's encoders: ACK + 0xA0 "ok", streaming toggles.
static void test_lms_stream_commands_via_proto_are_acknowledged(void** state) {
  (void)state;
  sim_lms_t* d = make(0.0, 9600, false);
  uint8_t req[32];
  send(d, req, lms_encode_start_stream(req, sizeof(req)));
  collect(d, 0.0);
  assert_int_equal(g_reply.acks, 1);
  assert_int_equal(g_reply.telegrams, 1);
  assert_int_equal(g_reply.cmd, LMS_REPLY_MODE);
  assert_int_equal(g_reply.data[0], LMS_MODE_OK);
  assert_true(sim_lms_streaming(d));
  send(d, req, lms_encode_stop_stream(req, sizeof(req)));
  collect(d, 0.0);
  assert_int_equal(g_reply.cmd, LMS_REPLY_MODE);
  assert_false(sim_lms_streaming(d));
  sim_lms_destroy(d);
}

// The hand-written telegrams of protocols.md B.3: start stream and status request give the
// exact reply frames (ACK, STX, ADR 0x80, LEN, code, data, STATUS, CRC low-high).
static void test_lms_handwritten_telegrams_get_exact_replies(void** state) {
  (void)state;
  sim_lms_t* d = make(0.0, 9600, false);
  static const uint8_t start[] = {0x02, 0x00, 0x02, 0x00, 0x20, 0x24, 0x34, 0x08};
  send(d, start, sizeof(start));
  const size_t n = sim_lms_drain(d, g_buf, sizeof(g_buf), 0.0);
  // ACK, then 02 80 03 00 A0 00 00 + CRC16 (the mode reply with result 0 and status 0).
  assert_int_equal(n, 1 + 9);
  static const uint8_t head[] = {0x06, 0x02, 0x80, 0x03, 0x00, 0xA0, 0x00, 0x00};
  assert_memory_equal(g_buf, head, sizeof(head));
  const uint16_t crc = lms_crc16(g_buf + 1, 7);
  assert_int_equal(g_buf[8], crc & 0xFFU);
  assert_int_equal(g_buf[9], crc >> 8);
  assert_true(sim_lms_streaming(d));
  // Status request `02 00 01 00 31 15 12`: ACK + a 0xB1 reply whose width/resolution sit at
  // bytes 107..110 (counting the reply code as 0), as Player reads them.
  static const uint8_t status[] = {0x02, 0x00, 0x01, 0x00, 0x31, 0x15, 0x12};
  send(d, status, sizeof(status));
  const size_t m = sim_lms_drain(d, g_buf, sizeof(g_buf), 0.0);
  assert_int_equal(g_buf[0], 0x06);
  assert_int_equal(g_buf[1], 0x02);
  assert_int_equal(g_buf[2], 0x80);
  assert_int_equal(g_buf[5], 0xB1);
  const uint8_t* code = &g_buf[5];
  assert_int_equal(code[107] | (code[108] << 8), 180);
  assert_int_equal(code[109] | (code[110] << 8), 100);
  const size_t len = (size_t)(g_buf[3] | (g_buf[4] << 8));
  assert_int_equal(m, 1 + 4 + len + 2);
  const uint16_t crc2 = lms_crc16(g_buf + 1, 4 + len);
  assert_int_equal(g_buf[m - 2], crc2 & 0xFFU);
  assert_int_equal(g_buf[m - 1], crc2 >> 8);
  // Type request `02 00 01 00 3a 1e 12` -> "LMS200;30106".
  static const uint8_t type[] = {0x02, 0x00, 0x01, 0x00, 0x3a, 0x1e, 0x12};
  send(d, type, sizeof(type));
  collect(d, 0.0);
  assert_int_equal(g_reply.cmd, LMS_REPLY_TYPE);
  assert_int_equal(g_reply.data_len, strlen("LMS200;30106"));
  assert_memory_equal(g_reply.data, "LMS200;30106", g_reply.data_len);
  sim_lms_destroy(d);
}

// Variant changes (hand-written 180°/0.5° and 100°/0.25° telegrams): accepted, beam count and
// angles follow; an impossible variant (180°/0.25°) is rejected with the current one.
static void test_lms_variant_change_sets_beam_geometry(void** state) {
  (void)state;
  sim_lms_t* d = make(0.0, 9600, false);
  double a0, inc;
  assert_int_equal(sim_lms_beams(d, &a0, &inc), 181);
  static const uint8_t v180_05[] = {0x02, 0x00, 0x05, 0x00, 0x3b, 0xb4, 0x00, 0x32, 0x00, 0x3b, 0x1f};
  send(d, v180_05, sizeof(v180_05));
  collect(d, 0.0);
  assert_int_equal(g_reply.cmd, LMS_REPLY_VARIANT);
  assert_int_equal(g_reply.data[0], 1);
  assert_int_equal(sim_lms_beams(d, &a0, &inc), 361);
  assert_true(fabs(a0 + 0.5 * k_pi) < 1e-12 && fabs(inc - k_pi / 360.0) < 1e-12);
  static const uint8_t v100_025[] = {0x02, 0x00, 0x05, 0x00, 0x3b, 0x64, 0x00, 0x19, 0x00, 0xe7, 0x72};
  send(d, v100_025, sizeof(v100_025));
  collect(d, 0.0);
  assert_int_equal(g_reply.data[0], 1);
  assert_int_equal(sim_lms_beams(d, &a0, &inc), 401);
  assert_true(fabs(a0 + 50.0 * k_pi / 180.0) < 1e-12);
  // 180° at 0.25° does not exist: built by hand (proto's encoder refuses it).
  const uint8_t bad_data[] = {0xb4, 0x00, 0x19, 0x00};
  uint8_t req[32];
  const size_t n = lms_encode_telegram(req, sizeof(req), LMS_ADR_DEVICE, LMS_CMD_VARIANT, bad_data,
                                       sizeof(bad_data), false, 0);
  send(d, req, n);
  collect(d, 0.0);
  assert_int_equal(g_reply.cmd, LMS_REPLY_VARIANT);
  assert_int_equal(g_reply.data[0], 0);
  assert_int_equal(sim_lms_beams(d, NULL, NULL), 401);
  sim_lms_destroy(d);
}

// Scan values: 1 m -> 1000 mm; nothing hit -> 8191 (no echo); 9 m (beyond the 8.182 m of mm
// mode) -> 8183 (measured value > maximum); beyond max_range_m -> 8191.
static void test_lms_scan_values_use_sensor_error_codes(void** state) {
  (void)state;
  sim_lms_t* d = make(0.0, 9600, false);
  g_provider.use_pattern = 1;
  g_provider.pattern[0] = 1.0;
  g_provider.pattern[1] = INFINITY;
  g_provider.pattern[2] = 9.0;
  g_provider.pattern[3] = 31.0;
  sim_lms_emit_scan(d, 0.0);
  collect(d, 0.0);
  assert_int_equal(g_reply.scans, 1);
  const lms_scan_t* s = &g_reply.scan;
  assert_int_equal(s->count, 181);
  assert_int_equal(s->unit, LMS_UNIT_MM);
  assert_int_equal(s->raw[0] & 0x1FFF, 1000);
  assert_int_equal(s->raw[1] & 0x1FFF, 8191);
  assert_int_equal(s->raw[2] & 0x1FFF, 8183);
  assert_int_equal(s->raw[3] & 0x1FFF, 8191);
  assert_int_equal(s->beam_status[1], LMS_BEAM_NO_ECHO);
  assert_int_equal(s->beam_status[2], LMS_BEAM_OVER_MAX);
  assert_true(fabs((double)s->start_angle_rad + 0.5 * k_pi) < 1e-6);
  // One-shot request 0x30 also answers with a scan.
  uint8_t req[16];
  send(d, req, lms_encode_values_request(req, sizeof(req)));
  collect(d, 0.0);
  assert_int_equal(g_reply.acks, 1);
  assert_int_equal(g_reply.scans, 1);
  sim_lms_destroy(d);
}

// Range noise is Gaussian with the configured sigma and reproducible from the seed.
static void test_lms_noise_has_configured_sigma_and_is_seeded(void** state) {
  (void)state;
  double sum = 0.0, sum2 = 0.0;
  int n = 0;
  uint16_t first_run[181];
  for (int run = 0; run < 2; ++run) {
    sim_lms_t* d = make(0.01, 9600, false);
    g_provider.constant_m = 3.0;
    for (int k = 0; k < 40; ++k) {
      sim_lms_emit_scan(d, 0.0);
      collect(d, 0.0);
      for (int i = 0; i < g_reply.scan.count; ++i) {
        if (run == 0) {
          const double e = (double)g_reply.scan.range_m[i] - 3.0;
          sum += e;
          sum2 += e * e;
          ++n;
        }
      }
      if (k == 0) {
        if (run == 0) {
          memcpy(first_run, g_reply.scan.raw, sizeof(first_run));
        } else {
          assert_memory_equal(first_run, g_reply.scan.raw, sizeof(first_run));
        }
      }
    }
    sim_lms_destroy(d);
  }
  const double mean = sum / n;
  const double sd = sqrt(sum2 / n - mean * mean);
  assert_true(fabs(mean) < 0.001);
  assert_true(fabs(sd - 0.01) < 0.001);
}

// Baud change (hand-written 38400 telegram): the reply leaves at the old rate, later bytes at
// the new one; installation mode checks the password; config writes need installation mode
// and switch the unit (cm then shows in the scan's count word).
static void test_lms_baud_password_and_config(void** state) {
  (void)state;
  sim_lms_t* d = make(0.0, 9600, false);
  static const uint8_t b38400[] = {0x02, 0x00, 0x02, 0x00, 0x20, 0x40, 0x50, 0x08};
  send(d, b38400, sizeof(b38400));
  collect(d, 0.0);
  assert_int_equal(g_reply.data[0], LMS_MODE_OK);
  assert_int_equal(sim_lms_baud(d), 38400);
  uint8_t req[64];
  lms_config_t cfg = {0};
  cfg.unit = LMS_UNIT_CM;
  send(d, req, lms_encode_config_write(req, sizeof(req), &cfg));
  collect(d, 0.0);
  assert_int_equal(g_reply.cmd, LMS_REPLY_CONFIG_WRITE);
  assert_int_equal(g_reply.data[0], 0);  // refused outside installation mode
  send(d, req, lms_encode_installation_mode(req, sizeof(req), "WRONG_PW"));
  collect(d, 0.0);
  assert_int_equal(g_reply.data[0], LMS_MODE_BAD_PASSWORD);
  send(d, req, lms_encode_installation_mode(req, sizeof(req), NULL));
  collect(d, 0.0);
  assert_int_equal(g_reply.data[0], LMS_MODE_OK);
  send(d, req, lms_encode_config_write(req, sizeof(req), &cfg));
  collect(d, 0.0);
  assert_int_equal(g_reply.data[0], 1);
  send(d, req, lms_encode_config_request(req, sizeof(req)));
  collect(d, 0.0);
  assert_int_equal(g_reply.cmd, LMS_REPLY_CONFIG_READ);
  g_provider.constant_m = 2.5;
  sim_lms_emit_scan(d, 0.0);
  collect(d, 0.0);
  assert_int_equal(g_reply.scan.unit, LMS_UNIT_CM);
  assert_int_equal(g_reply.scan.raw[0] & 0x1FFF, 250);
  sim_lms_destroy(d);
}

// Unknown codes and malformed requests are refused with NAK; garbage bytes are skipped.
static void test_lms_unknown_request_gets_nak(void** state) {
  (void)state;
  sim_lms_t* d = make(0.0, 9600, false);
  uint8_t req[32];
  const uint8_t data[] = {0x01};
  size_t n = lms_encode_telegram(req, sizeof(req), LMS_ADR_DEVICE, 0x55, data, 1, false, 0);
  send(d, req, n);
  collect(d, 0.0);
  assert_int_equal(g_reply.naks, 1);
  assert_int_equal(g_reply.telegrams, 0);
  static const uint8_t garbage[] = {0xFF, 0x13, 0x37, 0x00};
  send(d, garbage, sizeof(garbage));
  send(d, req, lms_encode_type_request(req, sizeof(req)));
  collect(d, 0.0);
  assert_int_equal(g_reply.cmd, LMS_REPLY_TYPE);
  sim_lms_destroy(d);
}

// Paced streaming: a 181-value telegram (372 bytes) takes 387.5 ms at 9600 Bd and 96.9 ms at
// 38400 Bd (link-limited: at most 5.2 and 20.6 scans in 2 s); at 500 kBd the 75 Hz mirror
// limits (150 in 2 s). Each sweep waits for the mirror's phase, so the count lies between 85 %
// and 100 % of that bound. Bytes never arrive faster than the line rate.
static void test_lms_paced_stream_rate_follows_baud(void** state) {
  (void)state;
  const uint32_t bauds[3] = {9600, 38400, 500000};
  for (int b = 0; b < 3; ++b) {
    sim_lms_t* d = make(0.0, bauds[b], true);
    uint8_t req[16];
    sim_lms_feed(d, req, lms_encode_start_stream(req, sizeof(req)), 0.0);
    int scans = 0;
    size_t bytes = 0;
    for (int ms = 1; ms <= 2000; ++ms) {
      const double t = ms * 1e-3;
      sim_lms_poll(d, t);
      const size_t n = sim_lms_drain(d, g_buf, sizeof(g_buf), t);
      bytes += n;
      assert_true((double)bytes <= t * bauds[b] / 10.0 + 1.0);
      const uint8_t* p = g_buf;
      size_t len = n;
      while (len > 0) {
        lms_event_t ev;
        const size_t k = lms_decoder_push(&g_host, p, len, &ev);
        p += k;
        len -= k;
        if (ev.kind == LMS_EVENT_TELEGRAM && ev.telegram.cmd == LMS_REPLY_VALUES) {
          ++scans;
        }
      }
    }
    const double bound = 2.0 * fmin((double)bauds[b] / 10.0 / 372.0, 75.0);
    assert_true(scans <= (int)bound + 1 && scans >= (int)(0.85 * bound) - 1);
    sim_lms_destroy(d);
  }
}

// While silent (laser dropped) the device ignores requests and sends nothing; then recovers.
static void test_lms_silence_drops_everything_until_it_ends(void** state) {
  (void)state;
  sim_lms_t* d = make(0.0, 9600, false);
  sim_lms_set_silent_until(d, 1.0);
  uint8_t req[16];
  sim_lms_feed(d, req, lms_encode_type_request(req, sizeof(req)), 0.5);
  sim_lms_emit_scan(d, 0.5);
  assert_int_equal(sim_lms_drain(d, g_buf, sizeof(g_buf), 0.5), 0);
  assert_int_equal(sim_lms_get_counters(d)->ignored_silent, 1);
  sim_lms_feed(d, req, lms_encode_type_request(req, sizeof(req)), 1.0);
  collect(d, 1.0);
  assert_int_equal(g_reply.cmd, LMS_REPLY_TYPE);
  sim_lms_destroy(d);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_lms_stream_commands_via_proto_are_acknowledged),
      cmocka_unit_test(test_lms_handwritten_telegrams_get_exact_replies),
      cmocka_unit_test(test_lms_variant_change_sets_beam_geometry),
      cmocka_unit_test(test_lms_scan_values_use_sensor_error_codes),
      cmocka_unit_test(test_lms_noise_has_configured_sigma_and_is_seeded),
      cmocka_unit_test(test_lms_baud_password_and_config),
      cmocka_unit_test(test_lms_unknown_request_gets_nak),
      cmocka_unit_test(test_lms_paced_stream_rate_follows_baud),
      cmocka_unit_test(test_lms_silence_drops_everything_until_it_ends),
  };
  return cmocka_run_group_tests_name("sim.lms200", tests, NULL, NULL);
}
