// SPDX-License-Identifier: MIT
// LMS200 codec: protocols.md B.3 test vectors, encoders, streaming decoder, typed parsers.
#include <proto/lms200.h>

#include "proto_test_util.h"

#include <b21r_test/alloc_counter.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

// The worked vectors of protocols.md B.3, each a complete telegram.
static const char* const k_request_vectors[] = {
    "02 00 02 00 20 24 34 08",        "02 00 02 00 20 25 35 08",
    "02 00 02 00 20 40 50 08",        "02 00 02 00 20 41 51 08",
    "02 00 02 00 20 42 52 08",        "02 00 02 00 20 48 58 08",
    "02 00 01 00 31 15 12",           "02 00 01 00 3a 1e 12",
    "02 00 05 00 3b b4 00 32 00 3b 1f", "02 00 05 00 3b b4 00 64 00 97 49",
    "02 00 05 00 3b 64 00 19 00 e7 72", "02 00 05 00 3b 64 00 64 00 1d 0f",
};
static const char k_scan_vector[] = "02 80 0a 00 b0 03 00 e8 03 ff 1f c4 09 00 90 eb";

static uint8_t g_buf[4096];
static uint8_t g_stream[16384];
static lms_decoder_t g_dec;
static lms_scan_t g_scan;

// Event log entry: what a decoder produced, comparable across chunkings.
typedef struct logged {
  lms_event_kind_t kind;
  uint8_t cmd;
  uint16_t data_len;
  uint8_t status;
  uint16_t data_crc;
} logged_t;

// Feeds `n` bytes in chunks of the given sizes (cycled; 0 = all at once) and logs the events.
static size_t run_stream(lms_decoder_t* dec, const uint8_t* bytes, size_t n, const size_t* chunks,
                         size_t n_chunks, logged_t* log, size_t log_cap) {
  size_t n_log = 0;
  size_t off = 0;
  size_t ci = 0;
  while (off < n) {
    size_t c = n_chunks == 0U ? n - off : chunks[ci++ % n_chunks];
    if (c == 0U || c > n - off) {
      c = n - off;
    }
    const uint8_t* p = bytes + off;
    size_t left = c;
    while (left > 0U) {
      lms_event_t ev;
      const size_t k = lms_decoder_push(dec, p, left, &ev);
      assert_true(k <= left);
      p += k;
      left -= k;
      if (ev.kind != LMS_EVENT_NONE) {
        assert_true(n_log < log_cap);
        log[n_log].kind = ev.kind;
        log[n_log].cmd = ev.telegram.cmd;
        log[n_log].data_len = ev.telegram.data_len;
        log[n_log].status = ev.telegram.status;
        log[n_log].data_crc =
            ev.kind == LMS_EVENT_TELEGRAM ? lms_crc16(ev.telegram.data, ev.telegram.data_len) : 0U;
        n_log++;
      } else {
        assert_true(k > 0U || left == 0U);
      }
    }
    off += c;
  }
  return n_log;
}

// Every CRC vector of protocols.md B.3 checks out with lms_crc16 (low byte first).
static void test_lms_crc16_vectors_match(void** state) {
  (void)state;
  for (size_t i = 0; i < sizeof k_request_vectors / sizeof k_request_vectors[0]; ++i) {
    const size_t n = test_hex(k_request_vectors[i], g_buf, sizeof g_buf);
    const uint16_t crc = lms_crc16(g_buf, n - 2U);
    assert_int_equal(crc & 0xFFU, g_buf[n - 2U]);
    assert_int_equal(crc >> 8, g_buf[n - 1U]);
  }
  const size_t n = test_hex(k_scan_vector, g_buf, sizeof g_buf);
  assert_int_equal(lms_crc16(g_buf, n - 2U), 0xEB90U);
}

// The CRC of nothing is the initial value 0, and one changed bit changes the CRC.
static void test_lms_crc16_empty_and_bitflip_detected(void** state) {
  (void)state;
  assert_int_equal(lms_crc16(NULL, 0), 0);
  const size_t n = test_hex(k_request_vectors[0], g_buf, sizeof g_buf);
  const uint16_t good = lms_crc16(g_buf, n - 2U);
  for (size_t i = 0; i < n - 2U; ++i) {
    for (unsigned b = 0; b < 8U; ++b) {
      g_buf[i] ^= (uint8_t)(1U << b);
      assert_int_not_equal(lms_crc16(g_buf, n - 2U), good);
      g_buf[i] ^= (uint8_t)(1U << b);
    }
  }
}

static void expect_bytes(const char* hex, size_t got_n) {
  uint8_t want[64];
  const size_t n = test_hex(hex, want, sizeof want);
  assert_int_equal(got_n, n);
  assert_memory_equal(g_buf, want, n);
}

// Each host request encoder reproduces its protocols.md telegram byte for byte.
static void test_lms_encode_requests_match_vectors(void** state) {
  (void)state;
  expect_bytes(k_request_vectors[0], lms_encode_start_stream(g_buf, sizeof g_buf));
  expect_bytes(k_request_vectors[1], lms_encode_stop_stream(g_buf, sizeof g_buf));
  expect_bytes(k_request_vectors[2], lms_encode_baud(g_buf, sizeof g_buf, 38400));
  expect_bytes(k_request_vectors[3], lms_encode_baud(g_buf, sizeof g_buf, 19200));
  expect_bytes(k_request_vectors[4], lms_encode_baud(g_buf, sizeof g_buf, 9600));
  expect_bytes(k_request_vectors[5], lms_encode_baud(g_buf, sizeof g_buf, 500000));
  expect_bytes(k_request_vectors[6], lms_encode_status_request(g_buf, sizeof g_buf));
  expect_bytes(k_request_vectors[7], lms_encode_type_request(g_buf, sizeof g_buf));
  expect_bytes(k_request_vectors[8], lms_encode_variant(g_buf, sizeof g_buf, 180, 50));
  expect_bytes(k_request_vectors[9], lms_encode_variant(g_buf, sizeof g_buf, 180, 100));
  expect_bytes(k_request_vectors[10], lms_encode_variant(g_buf, sizeof g_buf, 100, 25));
  expect_bytes(k_request_vectors[11], lms_encode_variant(g_buf, sizeof g_buf, 100, 100));
  expect_bytes("02 00 02 00 20 24 34 08", lms_encode_mode(g_buf, sizeof g_buf, LMS_MODE_STREAM));
}

// Unsupported rates, variants and short buffers are refused without writing past cap.
static void test_lms_encode_invalid_refused(void** state) {
  (void)state;
  assert_int_equal(lms_encode_baud(g_buf, sizeof g_buf, 115200), 0);
  assert_int_equal(lms_encode_variant(g_buf, sizeof g_buf, 180, 25), 0);
  assert_int_equal(lms_encode_variant(g_buf, sizeof g_buf, 90, 100), 0);
  assert_int_equal(lms_baud_mode(57600), 0xFF);
  assert_int_equal(lms_mode_baud(0x24), 0);
  memset(g_buf, 0xAA, sizeof g_buf);
  assert_int_equal(lms_encode_start_stream(g_buf, 7), 0);
  assert_int_equal(g_buf[7], 0xAA);
  assert_int_equal(lms_encode_start_stream(NULL, 64), 0);
  assert_int_equal(lms_encode_telegram(g_buf, sizeof g_buf, 0, 0x20, NULL, 3, false, 0), 0);
  uint8_t big[LMS_MAX_LEN];
  memset(big, 0, sizeof big);
  assert_int_equal(lms_encode_telegram(g_buf, sizeof g_buf, 0, 0x20, big, LMS_MAX_LEN, false, 0),
                   0);
  assert_int_equal(lms_encode_type_reply(g_buf, sizeof g_buf, "", 0), 0);
  const uint16_t raw[1] = {0};
  assert_int_equal(lms_encode_scan_reply(g_buf, sizeof g_buf, raw, 1, LMS_UNIT_CM, 4, NULL, 0), 0);
  assert_int_equal(lms_encode_scan_reply(g_buf, sizeof g_buf, raw, 0, LMS_UNIT_CM, 0, NULL, 0), 0);
}

// The synthetic 0xB0 reply of protocols.md B.3 is what the device encoder writes.
static void test_lms_encode_scan_reply_matches_vector(void** state) {
  (void)state;
  const uint16_t raw[3] = {1000, 8191, 2500};
  const size_t n = lms_encode_scan_reply(g_buf, sizeof g_buf, raw, 3, LMS_UNIT_CM, 0, NULL, 0);
  expect_bytes(k_scan_vector, n);
  assert_int_equal(n, 2U * 3U + 10U);
}

// The vector scan decodes: cm units, 10 m and 25 m, the 8191 beam "no echo" at max range.
static void test_lms_decode_scan_vector_ranges_and_no_return(void** state) {
  (void)state;
  const size_t n = test_hex(k_scan_vector, g_stream, sizeof g_stream);
  assert_int_equal(lms_decoder_init(&g_dec, LMS_ROLE_HOST, 0), PROTO_OK);
  lms_event_t ev;
  assert_int_equal(lms_decoder_push(&g_dec, g_stream, n, &ev), n);
  assert_int_equal(ev.kind, LMS_EVENT_TELEGRAM);
  assert_int_equal(ev.telegram.cmd, LMS_REPLY_VALUES);
  assert_int_equal(ev.telegram.adr, LMS_ADR_HOST);
  assert_int_equal(ev.telegram.status, 0);
  assert_int_equal(lms_parse_scan(&ev.telegram, 0, &g_scan), PROTO_OK);
  assert_int_equal(g_scan.count, 3);
  assert_int_equal(g_scan.unit, LMS_UNIT_CM);
  assert_false(g_scan.geometry_known);
  assert_false(g_scan.has_scan_index);
  assert_float_equal(g_scan.range_m[0], 10.0f, 1e-5f);
  assert_float_equal(g_scan.range_m[2], 25.0f, 1e-5f);
  assert_int_equal(g_scan.beam_status[0], LMS_BEAM_OK);
  assert_int_equal(g_scan.beam_status[1], LMS_BEAM_NO_ECHO);
  assert_float_equal(g_scan.range_m[1], g_scan.max_range_m, 0.0f);
  assert_float_equal(g_scan.max_range_m, 81.82f, 1e-4f);
  assert_int_equal(g_scan.no_return_count, 1);
  assert_int_equal(g_scan.raw[1], 8191);
  assert_int_equal(g_dec.counters.telegrams_ok, 1);
  assert_int_equal(g_dec.counters.bytes_dropped, 0);
}

// Builds a stream with garbage, ACK/NAK bytes, duplicated STX markers, false starts and a
// corrupt telegram around six valid replies; returns its length and the expected log.
static size_t build_mixed_stream(uint8_t* out, logged_t* want, size_t* n_want) {
  size_t n = 0;
  size_t w = 0;
  uint32_t rng = 0x1234567U;
  // Leading garbage without STX/ACK/NAK.
  for (int i = 0; i < 17; ++i) {
    uint8_t b = (uint8_t)test_rand(&rng);
    if (b == LMS_STX || b == LMS_ACK || b == LMS_NAK) {
      b = 0x55;
    }
    out[n++] = b;
  }
  out[n++] = LMS_ACK;
  want[w++] = (logged_t){LMS_EVENT_ACK, 0, 0, 0, 0};
  // A scan reply (mm, 181 values).
  uint16_t raw[181];
  for (unsigned i = 0; i < 181U; ++i) {
    raw[i] = (uint16_t)(i * 37U % 8200U);
  }
  size_t k = lms_encode_scan_reply(out + n, 4096, raw, 181, LMS_UNIT_MM, 0, NULL, 0x10);
  want[w++] = (logged_t){LMS_EVENT_TELEGRAM, LMS_REPLY_VALUES, 2 + 362, 0x10,
                         lms_crc16(out + n + 5, 2 + 362)};
  n += k;
  // Duplicated STX and a false header (wrong ADR), then a mode reply.
  out[n++] = LMS_STX;
  out[n++] = LMS_STX;
  out[n++] = 0x00;  // request ADR: wrong for the host role
  k = lms_encode_mode_reply(out + n, 64, LMS_MODE_OK, 0);
  want[w++] = (logged_t){LMS_EVENT_TELEGRAM, LMS_REPLY_MODE, 1, 0, lms_crc16(out + n + 5, 1)};
  n += k;
  out[n++] = LMS_NAK;
  want[w++] = (logged_t){LMS_EVENT_NAK, 0, 0, 0, 0};
  // A false start with an absurd LEN.
  out[n++] = LMS_STX;
  out[n++] = LMS_ADR_HOST;
  out[n++] = 0xFF;
  out[n++] = 0x7F;
  // A corrupt telegram (CRC broken), then a valid type reply.
  k = lms_encode_type_reply(out + n, 64, "LMS200;30106", 0);
  out[n + k - 1U] ^= 0x01;
  n += k;
  k = lms_encode_type_reply(out + n, 64, "LMS200;30106", 0);
  want[w++] = (logged_t){LMS_EVENT_TELEGRAM, LMS_REPLY_TYPE, 12, 0, lms_crc16(out + n + 5, 12)};
  n += k;
  // A candidate whose LEN swallows a complete valid telegram: found by rescanning.
  out[n++] = LMS_STX;
  out[n++] = LMS_ADR_HOST;
  out[n++] = 40;
  out[n++] = 0;
  k = lms_encode_nak_reply(out + n, 64, 7);
  want[w++] = (logged_t){LMS_EVENT_TELEGRAM, LMS_REPLY_NAK, 0, 7, 0};
  n += k;
  for (int i = 0; i < 40; ++i) {
    out[n++] = 0x33;
  }
  // Finally a status reply.
  lms_device_status_t st;
  memset(&st, 0, sizeof st);
  memcpy(st.version, "V02.10 ", 8);
  st.width_deg = 180;
  st.res_cdeg = 50;
  st.unit = LMS_UNIT_MM;
  k = lms_encode_status_reply(out + n, 256, &st, 0);
  want[w++] = (logged_t){LMS_EVENT_TELEGRAM, LMS_REPLY_STATUS, LMS_STATUS_BLOCK_BYTES, 0,
                         lms_crc16(out + n + 5, LMS_STATUS_BLOCK_BYTES)};
  n += k;
  *n_want = w;
  return n;
}

static void assert_log_equal(const logged_t* got, size_t n_got, const logged_t* want, size_t n_want) {
  assert_int_equal(n_got, n_want);
  for (size_t i = 0; i < n_want; ++i) {
    assert_int_equal(got[i].kind, want[i].kind);
    assert_int_equal(got[i].cmd, want[i].cmd);
    assert_int_equal(got[i].data_len, want[i].data_len);
    assert_int_equal(got[i].status, want[i].status);
    assert_int_equal(got[i].data_crc, want[i].data_crc);
  }
}

// The mixed stream yields the same events however it is split: whole, byte by byte, and cut
// into two chunks at every byte boundary.
static void test_lms_decoder_split_every_boundary_same_events(void** state) {
  (void)state;
  logged_t want[16];
  size_t n_want = 0;
  const size_t n = build_mixed_stream(g_stream, want, &n_want);
  logged_t got[16];
  size_t n_got;

  assert_int_equal(lms_decoder_init(&g_dec, LMS_ROLE_HOST, 0), PROTO_OK);
  n_got = run_stream(&g_dec, g_stream, n, NULL, 0, got, 16);
  assert_log_equal(got, n_got, want, n_want);
  const lms_decoder_counters_t whole = g_dec.counters;
  assert_int_equal(whole.bytes_in, n);
  assert_int_equal(whole.telegrams_ok, 5);
  assert_int_equal(whole.acks, 1);
  assert_int_equal(whole.naks, 1);
  assert_int_equal(whole.bad_crc, 2);   // the corrupt type reply and the swallowing candidate
  assert_int_equal(whole.bad_address, 2);  // both duplicated STX bytes
  assert_int_equal(whole.bad_length, 1);
  assert_true(whole.bytes_garbage >= 17U + 40U);

  const size_t one = 1;
  assert_int_equal(lms_decoder_init(&g_dec, LMS_ROLE_HOST, 0), PROTO_OK);
  n_got = run_stream(&g_dec, g_stream, n, &one, 1, got, 16);
  assert_log_equal(got, n_got, want, n_want);
  assert_memory_equal(&g_dec.counters, &whole, sizeof whole);

  for (size_t cut = 1; cut < n; ++cut) {
    const size_t plan[2] = {cut, n - cut};
    assert_int_equal(lms_decoder_init(&g_dec, LMS_ROLE_HOST, 0), PROTO_OK);
    n_got = run_stream(&g_dec, g_stream, n, plan, 2, got, 16);
    assert_log_equal(got, n_got, want, n_want);
    assert_memory_equal(&g_dec.counters, &whole, sizeof whole);
  }
}

// A tighter max_len rejects longer telegrams as bad_length and keeps decoding after them.
static void test_lms_decoder_max_len_bounds_telegrams(void** state) {
  (void)state;
  assert_int_equal(lms_decoder_init(&g_dec, LMS_ROLE_HOST, 100), PROTO_OK);
  uint16_t raw[181] = {0};
  size_t n = lms_encode_scan_reply(g_stream, sizeof g_stream, raw, 181, LMS_UNIT_CM, 0, NULL, 0);
  n += lms_encode_mode_reply(g_stream + n, 64, LMS_MODE_OK, 0);
  logged_t got[4];
  const size_t n_got = run_stream(&g_dec, g_stream, n, NULL, 0, got, 4);
  assert_int_equal(n_got, 1);
  assert_int_equal(got[0].cmd, LMS_REPLY_MODE);
  assert_int_equal(g_dec.counters.bad_length, 1);
  assert_int_equal(lms_decoder_init(&g_dec, LMS_ROLE_HOST, 1), PROTO_ERR_INVALID_ARG);
  assert_int_equal(lms_decoder_init(&g_dec, LMS_ROLE_HOST, LMS_MAX_LEN + 1U), PROTO_ERR_INVALID_ARG);
  assert_int_equal(lms_decoder_init(NULL, LMS_ROLE_HOST, 0), PROTO_ERR_INVALID_ARG);
}

// Reset drops a partial telegram and counts its bytes; the next telegram decodes.
static void test_lms_decoder_reset_drops_partial(void** state) {
  (void)state;
  assert_int_equal(lms_decoder_init(&g_dec, LMS_ROLE_HOST, 0), PROTO_OK);
  const size_t n = lms_encode_mode_reply(g_stream, 64, LMS_MODE_OK, 0);
  lms_event_t ev;
  assert_int_equal(lms_decoder_push(&g_dec, g_stream, 5, &ev), 5);
  assert_int_equal(ev.kind, LMS_EVENT_NONE);
  lms_decoder_reset(&g_dec);
  assert_int_equal(g_dec.counters.bytes_dropped, 5);
  assert_int_equal(lms_decoder_push(&g_dec, g_stream, n, &ev), n);
  assert_int_equal(ev.kind, LMS_EVENT_TELEGRAM);
}

// In the device role, every host request decodes into the right typed request; ACK bytes and
// reply telegrams (ADR 0x80) are not requests.
static void test_lms_device_role_parses_requests(void** state) {
  (void)state;
  size_t n = 0;
  n += lms_encode_stop_stream(g_stream + n, 64);
  n += lms_encode_baud(g_stream + n, 64, 500000);
  n += lms_encode_type_request(g_stream + n, 64);
  g_stream[n++] = LMS_ACK;
  n += lms_encode_installation_mode(g_stream + n, 64, NULL);
  n += lms_encode_mode_reply(g_stream + n, 64, LMS_MODE_OK, 0);  // wrong direction: dropped
  n += lms_encode_variant(g_stream + n, 64, 100, 25);
  n += lms_encode_config_request(g_stream + n, 64);
  const lms_config_t cfg = {.blanking = 3, .stop_threshold = 4, .peak_threshold = 5,
                            .availability = 6, .measuring_mode = 0, .unit = LMS_UNIT_MM};
  n += lms_encode_config_write(g_stream + n, 64, &cfg);
  n += lms_encode_values_request(g_stream + n, 64);
  n += lms_encode_status_request(g_stream + n, 64);
  n += lms_encode_start_stream(g_stream + n, 64);
  const uint8_t reset = LMS_CMD_RESET;
  n += lms_encode_telegram(g_stream + n, 64, LMS_ADR_DEVICE, reset, NULL, 0, false, 0);
  const uint8_t odd = 0x66;
  n += lms_encode_telegram(g_stream + n, 64, LMS_ADR_DEVICE, odd, NULL, 0, false, 0);

  static const lms_request_kind_t want[] = {
      LMS_REQ_MODE,        LMS_REQ_BAUD,         LMS_REQ_TYPE,   LMS_REQ_INSTALLATION,
      LMS_REQ_VARIANT,     LMS_REQ_CONFIG_READ,  LMS_REQ_CONFIG_WRITE, LMS_REQ_VALUES,
      LMS_REQ_STATUS,      LMS_REQ_MODE,         LMS_REQ_RESET,  LMS_REQ_UNKNOWN};
  assert_int_equal(lms_decoder_init(&g_dec, LMS_ROLE_DEVICE, 0), PROTO_OK);
  const uint8_t* p = g_stream;
  size_t left = n;
  size_t i = 0;
  while (left > 0U) {
    lms_event_t ev;
    const size_t k = lms_decoder_push(&g_dec, p, left, &ev);
    p += k;
    left -= k;
    if (ev.kind == LMS_EVENT_NONE) {
      continue;
    }
    assert_int_equal(ev.kind, LMS_EVENT_TELEGRAM);
    assert_false(ev.telegram.has_status);
    lms_request_t req;
    assert_int_equal(lms_parse_request(&ev.telegram, &req), PROTO_OK);
    assert_true(i < sizeof want / sizeof want[0]);
    assert_int_equal(req.kind, want[i]);
    switch (req.kind) {
      case LMS_REQ_BAUD:
        assert_int_equal(req.baud, 500000);
        break;
      case LMS_REQ_INSTALLATION:
        assert_string_equal(req.password, "SICK_LMS");
        break;
      case LMS_REQ_VARIANT:
        assert_int_equal(req.width_deg, 100);
        assert_int_equal(req.res_cdeg, 25);
        break;
      case LMS_REQ_CONFIG_WRITE:
        assert_int_equal(req.config.blanking, 3);
        assert_int_equal(req.config.availability, 6);
        assert_int_equal(req.config.unit, LMS_UNIT_MM);
        break;
      case LMS_REQ_VALUES:
        assert_int_equal(req.values_mode, 1);
        break;
      case LMS_REQ_MODE:
        assert_true(req.mode == LMS_MODE_STOP_STREAM || req.mode == LMS_MODE_STREAM);
        break;
      case LMS_REQ_UNKNOWN:
        assert_int_equal(req.cmd, 0x66);
        break;
      default:
        break;
    }
    ++i;
  }
  assert_int_equal(i, sizeof want / sizeof want[0]);
  assert_int_equal(g_dec.counters.bad_address, 1);
  assert_int_equal(g_dec.counters.acks, 0);
  assert_int_equal(g_dec.counters.bytes_garbage, 1U + 8U);  // ACK byte + rest of the reply
}

// Truncated known requests are format errors (a device must not act on them).
static void test_lms_parse_request_short_data_format_error(void** state) {
  (void)state;
  const uint8_t data[3] = {0x00, 'S', 'I'};
  lms_telegram_t t = {.adr = 0, .cmd = LMS_CMD_MODE, .data = data, .data_len = 3};
  lms_request_t req;
  assert_int_equal(lms_parse_request(&t, &req), PROTO_ERR_FORMAT);
  t.data_len = 0;
  t.data = NULL;
  assert_int_equal(lms_parse_request(&t, &req), PROTO_ERR_FORMAT);
  t.cmd = LMS_CMD_VARIANT;
  assert_int_equal(lms_parse_request(&t, &req), PROTO_ERR_FORMAT);
  assert_int_equal(lms_parse_request(NULL, &req), PROTO_ERR_INVALID_ARG);
}

// Decodes one telegram from g_buf[0..n) in the host role.
static lms_telegram_t decode_one(size_t n) {
  assert_int_equal(lms_decoder_init(&g_dec, LMS_ROLE_HOST, 0), PROTO_OK);
  lms_event_t ev;
  assert_int_equal(lms_decoder_push(&g_dec, g_buf, n, &ev), n);
  assert_int_equal(ev.kind, LMS_EVENT_TELEGRAM);
  return ev.telegram;
}

// Every device reply survives encode -> decode -> parse with equal fields.
static void test_lms_replies_round_trip(void** state) {
  (void)state;
  lms_telegram_t t;
  for (int r = 0; r <= 3; ++r) {
    t = decode_one(lms_encode_mode_reply(g_buf, sizeof g_buf, (lms_mode_result_t)r, 0x21));
    lms_mode_result_t mr;
    assert_int_equal(lms_parse_mode_reply(&t, &mr), PROTO_OK);
    assert_int_equal(mr, r);
    assert_int_equal(t.status, 0x21);
  }
  const lms_variant_reply_t vr = {.accepted = true, .width_deg = 100, .res_cdeg = 25};
  t = decode_one(lms_encode_variant_reply(g_buf, sizeof g_buf, &vr, 0));
  lms_variant_reply_t vr2;
  assert_int_equal(lms_parse_variant_reply(&t, &vr2), PROTO_OK);
  assert_true(vr2.accepted);
  assert_int_equal(vr2.width_deg, 100);
  assert_int_equal(vr2.res_cdeg, 25);

  lms_device_status_t st;
  memset(&st, 0, sizeof st);
  memcpy(st.version, "V02.30 ", 8);
  st.operating_mode = LMS_MODE_STREAM;
  st.device_status = 0;
  st.unit = LMS_UNIT_MM;
  st.width_deg = 180;
  st.res_cdeg = 50;
  const size_t n = lms_encode_status_reply(g_buf, sizeof g_buf, &st, 0);
  assert_int_equal(n, 160);
  // Player reads width at reply bytes 107-108 and resolution at 109-110 (reply code = byte 0).
  assert_int_equal(g_buf[4 + 107] | (g_buf[4 + 108] << 8), 180);
  assert_int_equal(g_buf[4 + 109] | (g_buf[4 + 110] << 8), 50);
  t = decode_one(n);
  lms_device_status_t st2;
  assert_int_equal(lms_parse_status_reply(&t, &st2), PROTO_OK);
  assert_string_equal(st2.version, "V02.30 ");
  assert_int_equal(st2.operating_mode, LMS_MODE_STREAM);
  assert_int_equal(st2.device_status, 0);
  assert_int_equal(st2.unit, LMS_UNIT_MM);
  assert_int_equal(st2.width_deg, 180);
  assert_int_equal(st2.res_cdeg, 50);

  char type[LMS_TYPE_MAX_CHARS + 1];
  t = decode_one(lms_encode_type_reply(g_buf, sizeof g_buf, "LMS200;30106", 0));
  assert_int_equal(lms_parse_type_reply(&t, type, sizeof type), PROTO_OK);
  assert_string_equal(type, "LMS200;30106");
  char small[4];
  assert_int_equal(lms_parse_type_reply(&t, small, sizeof small), PROTO_ERR_CAPACITY);
  assert_string_equal(small, "LMS");

  const lms_config_t cfg = {.blanking = 0x1234, .stop_threshold = 1, .peak_threshold = 2,
                            .availability = 3, .measuring_mode = 0, .unit = LMS_UNIT_MM};
  assert_int_equal(lms_encode_config_reply(g_buf, sizeof g_buf, &cfg, 0), 40);
  t = decode_one(40);
  lms_config_t cfg2;
  assert_int_equal(lms_parse_config_reply(&t, &cfg2), PROTO_OK);
  assert_int_equal(cfg2.blanking, 0x1234);
  assert_int_equal(cfg2.stop_threshold, 1);
  assert_int_equal(cfg2.peak_threshold, 2);
  assert_int_equal(cfg2.availability, 3);
  assert_int_equal(cfg2.measuring_mode, 0);
  assert_int_equal(cfg2.unit, LMS_UNIT_MM);

  // ACK and NAK bytes are events of their own.
  assert_int_equal(lms_encode_ack(g_buf, sizeof g_buf, true), 1);
  assert_int_equal(lms_encode_ack(g_buf + 1, sizeof g_buf - 1, false), 1);
  assert_int_equal(lms_encode_ack(g_buf, 0, true), 0);
  assert_int_equal(lms_decoder_init(&g_dec, LMS_ROLE_HOST, 0), PROTO_OK);
  lms_event_t ev;
  assert_int_equal(lms_decoder_push(&g_dec, g_buf, 2, &ev), 1);
  assert_int_equal(ev.kind, LMS_EVENT_ACK);
  assert_int_equal(lms_decoder_push(&g_dec, g_buf + 1, 1, &ev), 1);
  assert_int_equal(ev.kind, LMS_EVENT_NAK);
  t = decode_one(lms_encode_nak_reply(g_buf, sizeof g_buf, 0));
  assert_int_equal(t.cmd, LMS_REPLY_NAK);
  assert_int_equal(t.data_len, 0);
  // Parsers refuse the wrong reply code.
  assert_int_equal(lms_parse_config_reply(&t, &cfg2), PROTO_ERR_FORMAT);
  assert_int_equal(lms_parse_variant_reply(&t, &vr2), PROTO_ERR_FORMAT);
  assert_int_equal(lms_parse_status_reply(&t, &st2), PROTO_ERR_FORMAT);
  assert_int_equal(lms_parse_scan(&t, 13, &g_scan), PROTO_ERR_FORMAT);
}

// Scans of every variant, in both units, with and without the scan index byte and with
// partial-scan offsets, come back with the same ranges and the documented beam angles.
static void test_lms_scan_round_trip_all_variants(void** state) {
  (void)state;
  static const struct {
    uint16_t n, width, res;
  } variants[] = {{181, 180, 100}, {361, 180, 50}, {101, 100, 100}, {201, 100, 50}, {401, 100, 25}};
  const float deg = 3.14159265358979f / 180.0f;
  uint32_t rng = 42;
  uint16_t raw[LMS_MAX_SCAN_VALUES];
  float want_m[LMS_MAX_SCAN_VALUES];
  for (size_t v = 0; v < 5; ++v) {
    for (int unit = 0; unit <= 1; ++unit) {
      for (int with_index = 0; with_index <= 1; ++with_index) {
        const uint8_t partial = (uint8_t)((v + (size_t)unit) % 4U);
        const unsigned n = variants[v].n;
        for (unsigned i = 0; i < n; ++i) {
          const float r = (float)(test_rand(&rng) % 9000U) * (unit ? 0.001f : 0.01f);
          raw[i] = lms_range_to_raw(r, (lms_unit_t)unit, 13);
          want_m[i] = r;
        }
        const uint8_t idx = 0x5A;
        const size_t len = lms_encode_scan_reply(g_buf, sizeof g_buf, raw, n, (lms_unit_t)unit,
                                                 partial, with_index ? &idx : NULL, 0x01);
        assert_int_equal(len, 2U * n + 10U + (unsigned)with_index);
        const lms_telegram_t t = decode_one(len);
        assert_int_equal(lms_parse_scan(&t, 13, &g_scan), PROTO_OK);
        assert_int_equal(g_scan.count, n);
        assert_int_equal(g_scan.unit, unit);
        assert_int_equal(g_scan.partial_index, partial);
        assert_int_equal(g_scan.has_scan_index, with_index);
        if (with_index) {
          assert_int_equal(g_scan.scan_index, 0x5A);
        }
        assert_int_equal(g_scan.status, 0x01);
        assert_true(g_scan.geometry_known);
        assert_int_equal(g_scan.width_deg, variants[v].width);
        assert_int_equal(g_scan.res_cdeg, variants[v].res);
        assert_float_equal(g_scan.start_angle_rad,
                           (-0.5f * variants[v].width + 0.25f * partial) * deg, 1e-6f);
        assert_float_equal(g_scan.step_rad, 0.01f * variants[v].res * deg, 1e-7f);
        // The last beam of a full sweep sits at +width/2 (plus the partial offset).
        assert_float_equal(g_scan.start_angle_rad + (float)(n - 1U) * g_scan.step_rad,
                           (0.5f * variants[v].width + 0.25f * partial) * deg, 1e-5f);
        for (unsigned i = 0; i < n; ++i) {
          const lms_beam_status_t bs = (lms_beam_status_t)g_scan.beam_status[i];
          if (bs == LMS_BEAM_OK) {
            assert_float_equal(g_scan.range_m[i], want_m[i], unit ? 0.0006f : 0.006f);
          } else {
            // Only ranges beyond the valid maximum become "no echo".
            assert_true(want_m[i] > g_scan.max_range_m - 0.01f);
            assert_int_equal(bs, LMS_BEAM_NO_ECHO);
          }
        }
      }
    }
  }
}

// Malformed scans are refused with the documented status and leave *out unchanged.
static void test_lms_parse_scan_malformed_refused(void** state) {
  (void)state;
  uint8_t data[2 + 2 * 402 + 1];
  memset(data, 0, sizeof data);
  lms_telegram_t t = {.adr = LMS_ADR_HOST, .cmd = LMS_REPLY_VALUES, .data = data,
                      .has_status = true};
  memset(&g_scan, 0x77, sizeof g_scan);
  data[0] = 3;  // N = 3 but 4 values of data
  t.data_len = 2 + 8;
  assert_int_equal(lms_parse_scan(&t, 13, &g_scan), PROTO_ERR_FORMAT);
  data[0] = 0x92;  // N = 402
  data[1] = 0x01;
  t.data_len = 2 + 2 * 402;
  assert_int_equal(lms_parse_scan(&t, 13, &g_scan), PROTO_ERR_CAPACITY);
  data[0] = 0;
  data[1] = 0;  // N = 0
  t.data_len = 2;
  assert_int_equal(lms_parse_scan(&t, 13, &g_scan), PROTO_ERR_CAPACITY);
  data[0] = 1;
  data[1] = 0x80;  // unit bits = 2
  t.data_len = 4;
  assert_int_equal(lms_parse_scan(&t, 13, &g_scan), PROTO_ERR_FORMAT);
  t.data_len = 1;
  assert_int_equal(lms_parse_scan(&t, 13, &g_scan), PROTO_ERR_FORMAT);
  assert_int_equal(g_scan.count, 0x7777);
  assert_int_equal(lms_parse_scan(NULL, 13, &g_scan), PROTO_ERR_INVALID_ARG);
}

// The error/saturation code band maps to reasons in 13-, 14- and 15-bit modes, flag bits above
// the distance are ignored, and reason -> code -> reason is the identity.
static void test_lms_beam_status_codes_mapped(void** state) {
  (void)state;
  assert_int_equal(lms_raw_beam_status(8191, 13), LMS_BEAM_NO_ECHO);
  assert_int_equal(lms_raw_beam_status(8190, 13), LMS_BEAM_DAZZLED);
  assert_int_equal(lms_raw_beam_status(8189, 13), LMS_BEAM_OVERFLOW);
  assert_int_equal(lms_raw_beam_status(8188, 13), LMS_BEAM_ERROR_OTHER);
  assert_int_equal(lms_raw_beam_status(8187, 13), LMS_BEAM_SNR_LOW);
  assert_int_equal(lms_raw_beam_status(8186, 13), LMS_BEAM_CHANNEL_ERROR);
  assert_int_equal(lms_raw_beam_status(8185, 13), LMS_BEAM_ERROR_OTHER);
  assert_int_equal(lms_raw_beam_status(8184, 13), LMS_BEAM_ERROR_OTHER);
  assert_int_equal(lms_raw_beam_status(8183, 13), LMS_BEAM_OVER_MAX);
  assert_int_equal(lms_raw_beam_status(8182, 13), LMS_BEAM_OK);
  assert_int_equal(lms_raw_beam_status(0, 13), LMS_BEAM_OK);
  assert_int_equal(lms_raw_beam_status((uint16_t)(0xE000U | 1000U), 13), LMS_BEAM_OK);
  assert_int_equal(lms_raw_beam_status((uint16_t)(0xE000U | 8191U), 13), LMS_BEAM_NO_ECHO);
  assert_int_equal(lms_raw_beam_status(16383, 14), LMS_BEAM_NO_ECHO);
  assert_int_equal(lms_raw_beam_status(16378, 14), LMS_BEAM_CHANNEL_ERROR);
  assert_int_equal(lms_raw_beam_status(8191, 14), LMS_BEAM_OK);
  assert_int_equal(lms_raw_beam_status(32759, 15), LMS_BEAM_OVER_MAX);
  assert_int_equal(lms_raw_beam_status(32767, 15), LMS_BEAM_NO_ECHO);
  for (unsigned bits = 13; bits <= 15; ++bits) {
    for (int r = LMS_BEAM_NO_ECHO; r <= LMS_BEAM_ERROR_OTHER; ++r) {
      const uint16_t code = lms_beam_status_raw((lms_beam_status_t)r, bits);
      assert_int_equal(lms_raw_beam_status(code, bits), r);
      assert_string_not_equal(lms_beam_status_name((lms_beam_status_t)r), "unknown");
    }
  }
  assert_int_equal(lms_beam_status_raw(LMS_BEAM_OVER_MAX, 13), 8183);
}

// Range -> raw conversion: rounding, the valid maximum, and "no echo" for what cannot be sent.
static void test_lms_range_to_raw_edges(void** state) {
  (void)state;
  assert_int_equal(lms_range_to_raw(1.2344f, LMS_UNIT_MM, 13), 1234);
  assert_int_equal(lms_range_to_raw(1.2346f, LMS_UNIT_MM, 13), 1235);
  assert_int_equal(lms_range_to_raw(12.34f, LMS_UNIT_CM, 13), 1234);
  assert_int_equal(lms_range_to_raw(8.182f, LMS_UNIT_MM, 13), 8182);
  assert_int_equal(lms_range_to_raw(8.19f, LMS_UNIT_MM, 13), 8191);
  assert_int_equal(lms_range_to_raw(-0.1f, LMS_UNIT_MM, 13), 8191);
  assert_int_equal(lms_range_to_raw(NAN, LMS_UNIT_MM, 13), 8191);
  assert_int_equal(lms_range_to_raw(INFINITY, LMS_UNIT_CM, 13), 8191);
  assert_int_equal(lms_range_to_raw(0.0f, LMS_UNIT_CM, 13), 0);
  assert_int_equal(lms_range_to_raw(16.0f, LMS_UNIT_MM, 14), 16000);
  assert_int_equal(lms_range_to_raw(20.0f, LMS_UNIT_MM, 14), 16383);
}

// Decoding a long stream allocates nothing.
static void test_lms_decoder_no_allocation(void** state) {
  (void)state;
  logged_t want[16];
  size_t n_want = 0;
  const size_t n = build_mixed_stream(g_stream, want, &n_want);
  assert_int_equal(lms_decoder_init(&g_dec, LMS_ROLE_HOST, 0), PROTO_OK);
  alloc_counter_begin();
  for (int rep = 0; rep < 50; ++rep) {
    const uint8_t* p = g_stream;
    size_t left = n;
    while (left > 0U) {
      lms_event_t ev;
      const size_t k = lms_decoder_push(&g_dec, p, left, &ev);
      p += k;
      left -= k;
      if (ev.kind == LMS_EVENT_TELEGRAM && ev.telegram.cmd == LMS_REPLY_VALUES) {
        assert_int_equal(lms_parse_scan(&ev.telegram, 13, &g_scan), PROTO_OK);
      }
    }
  }
  assert_int_equal(alloc_counter_end(), 0);
  assert_int_equal(g_dec.counters.telegrams_ok, 50U * 5U);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_lms_crc16_vectors_match),
      cmocka_unit_test(test_lms_crc16_empty_and_bitflip_detected),
      cmocka_unit_test(test_lms_encode_requests_match_vectors),
      cmocka_unit_test(test_lms_encode_invalid_refused),
      cmocka_unit_test(test_lms_encode_scan_reply_matches_vector),
      cmocka_unit_test(test_lms_decode_scan_vector_ranges_and_no_return),
      cmocka_unit_test(test_lms_decoder_split_every_boundary_same_events),
      cmocka_unit_test(test_lms_decoder_max_len_bounds_telegrams),
      cmocka_unit_test(test_lms_decoder_reset_drops_partial),
      cmocka_unit_test(test_lms_device_role_parses_requests),
      cmocka_unit_test(test_lms_parse_request_short_data_format_error),
      cmocka_unit_test(test_lms_replies_round_trip),
      cmocka_unit_test(test_lms_scan_round_trip_all_variants),
      cmocka_unit_test(test_lms_parse_scan_malformed_refused),
      cmocka_unit_test(test_lms_beam_status_codes_mapped),
      cmocka_unit_test(test_lms_range_to_raw_edges),
      cmocka_unit_test(test_lms_decoder_no_allocation),
  };
  return cmocka_run_group_tests_name("proto.lms200", tests, NULL, NULL);
}
