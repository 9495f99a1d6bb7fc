// SPDX-License-Identifier: MIT
// LMS200 host driver against a scripted LMS on the other side of a pseudo-terminal: power-up
// at 9600 and switch to 38400, reconnect to a scanner already at the target rate, unit change,
// NAK retries and restart after stream silence. Time is simulated (the driver reads no clock).
#define _GNU_SOURCE
#include <drivers/lms200.h>
#include <drivers/serial.h>
#include <proto/lms200.h>

#include <errno.h>
#include <fcntl.h>
#include <pty.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

// The scripted scanner. It hears the host only when both sides use the same rate (a pty has no
// real line rate, so the mismatch is emulated by comparing with the host port's rate).
typedef struct fake_lms {
  int fd;                       // pty master
  const drv_serial_t* host;     // to emulate rate mismatches
  uint32_t baud;
  bool streaming;
  bool installation;
  lms_unit_t unit;
  uint16_t width_deg;
  uint16_t res_cdeg;
  int nak_variant_times;        // NAK this many variant requests first
  bool silent;                  // stop answering and streaming
  lms_decoder_t dec;
  int requests[256];            // count per command code
  uint32_t pending_baud;        // applied after the reply has been written
  uint16_t scan_seed;
} fake_lms_t;

static void fake_init(fake_lms_t* f, int fd, const drv_serial_t* host, uint32_t baud) {
  memset(f, 0, sizeof *f);
  f->fd = fd;
  f->host = host;
  f->baud = baud;
  f->unit = LMS_UNIT_CM;
  f->width_deg = 180;
  f->res_cdeg = 50;
  (void)lms_decoder_init(&f->dec, LMS_ROLE_DEVICE, 0);
}

static void fake_write(fake_lms_t* f, const uint8_t* b, size_t n) {
  assert_int_equal(write(f->fd, b, n), (ssize_t)n);
}

static void fake_reply(fake_lms_t* f, const uint8_t* b, size_t n) {
  const uint8_t ack = LMS_ACK;
  fake_write(f, &ack, 1);
  fake_write(f, b, n);
}

static void fake_handle(fake_lms_t* f, const lms_request_t* req) {
  uint8_t out[1024];
  size_t n = 0;
  f->requests[req->cmd]++;
  switch (req->kind) {
    case LMS_REQ_MODE:
      f->streaming = req->mode == LMS_MODE_STREAM;
      n = lms_encode_mode_reply(out, sizeof out, LMS_MODE_OK, 0);
      break;
    case LMS_REQ_BAUD:
      n = lms_encode_mode_reply(out, sizeof out, LMS_MODE_OK, 0);
      f->pending_baud = req->baud;
      break;
    case LMS_REQ_INSTALLATION:
      f->installation = strcmp(req->password, "SICK_LMS") == 0;
      n = lms_encode_mode_reply(out, sizeof out,
                                f->installation ? LMS_MODE_OK : LMS_MODE_BAD_PASSWORD, 0);
      break;
    case LMS_REQ_TYPE:
      n = lms_encode_type_reply(out, sizeof out, "LMS200;30106", 0);
      break;
    case LMS_REQ_VARIANT: {
      if (f->nak_variant_times > 0) {
        f->nak_variant_times--;
        const uint8_t nak = LMS_NAK;
        fake_write(f, &nak, 1);
        return;
      }
      const bool ok = lms_variant_valid(req->width_deg, req->res_cdeg);
      if (ok) {
        f->width_deg = req->width_deg;
        f->res_cdeg = req->res_cdeg;
      }
      const lms_variant_reply_t vr = {ok, f->width_deg, f->res_cdeg};
      n = lms_encode_variant_reply(out, sizeof out, &vr, 0);
      break;
    }
    case LMS_REQ_CONFIG_READ: {
      const lms_config_t c = {.unit = f->unit};
      n = lms_encode_config_reply(out, sizeof out, &c, 0);
      break;
    }
    case LMS_REQ_CONFIG_WRITE: {
      f->unit = req->config.unit;
      const uint8_t ok = 1;
      n = lms_encode_telegram(out, sizeof out, LMS_ADR_HOST, LMS_REPLY_CONFIG_WRITE, &ok, 1, true, 0);
      break;
    }
    default:
      n = lms_encode_nak_reply(out, sizeof out, 0);
      break;
  }
  fake_reply(f, out, n);
  if (f->pending_baud != 0U) {
    f->baud = f->pending_baud;
    f->pending_baud = 0;
  }
}

// Serves requests that arrived and, when streaming, sends one scan.
static void fake_service(fake_lms_t* f) {
  uint8_t buf[512];
  for (;;) {
    const ssize_t n = read(f->fd, buf, sizeof buf);
    if (n <= 0) {
      break;
    }
    if (f->silent || f->host->baud != f->baud) {
      continue;  // garbled at the wrong rate: the scanner hears nothing
    }
    const uint8_t* p = buf;
    size_t left = (size_t)n;
    while (left > 0U) {
      lms_event_t ev;
      const size_t k = lms_decoder_push(&f->dec, p, left, &ev);
      p += k;
      left -= k;
      if (ev.kind == LMS_EVENT_TELEGRAM) {
        lms_request_t req;
        assert_int_equal(lms_parse_request(&ev.telegram, &req), PROTO_OK);
        fake_handle(f, &req);
      }
    }
  }
  if (f->streaming && !f->silent && f->host->baud == f->baud) {
    const uint16_t n = (uint16_t)(f->width_deg * 100U / f->res_cdeg + 1U);
    uint16_t raw[LMS_MAX_SCAN_VALUES];
    for (uint16_t i = 0; i < n; ++i) {
      raw[i] = (uint16_t)(100U + (uint16_t)(f->scan_seed + i) % 1000U);
    }
    f->scan_seed++;
    uint8_t out[1024];
    const size_t k = lms_encode_scan_reply(out, sizeof out, raw, n, f->unit, 0, NULL, 0);
    fake_write(f, out, k);
  }
}

typedef struct fixture {
  int master;
  int slave;
  drv_serial_t port;
  drv_lms_t drv;
  fake_lms_t lms;
  lms_scan_t scan;
  uint64_t now_us;
} fixture_t;

static int setup(void** state) {
  static fixture_t fx;
  memset(&fx, 0, sizeof fx);
  if (openpty(&fx.master, &fx.slave, NULL, NULL, NULL) != 0) {
    return -1;
  }
  const int flags = fcntl(fx.master, F_GETFL);
  (void)fcntl(fx.master, F_SETFL, flags | O_NONBLOCK);
  if (drv_serial_attach(&fx.port, fx.slave, 9600, true, NULL, 0) != 0) {
    return -1;
  }
  *state = &fx;
  return 0;
}

static int teardown(void** state) {
  fixture_t* fx = *state;
  drv_serial_close(&fx->port);
  close(fx->master);
  return 0;
}

// Runs the loop for `steps` 10 ms ticks; returns the number of scans delivered.
static int run(fixture_t* fx, int steps) {
  int scans = 0;
  for (int i = 0; i < steps; ++i) {
    bool got = false;
    (void)drv_lms_step(&fx->drv, fx->now_us, &fx->scan, &got);
    usleep(300);  // let the pty carry the bytes
    fake_service(&fx->lms);
    usleep(300);
    scans += got ? 1 : 0;
    fx->now_us += 10000U;
  }
  return scans;
}

// From power-up at 9600 the driver switches to 38400, sets the variant and streams scans.
static void test_lms_driver_powerup_switches_baud_and_streams(void** state) {
  fixture_t* fx = *state;
  fake_init(&fx->lms, fx->master, &fx->port, 9600);
  drv_lms_config_t cfg;
  drv_lms_config_default(&cfg);
  cfg.target_baud = 38400;
  cfg.width_deg = 180;
  cfg.res_cdeg = 100;
  assert_int_equal(drv_lms_init(&fx->drv, &fx->port, &cfg), 0);
  const int scans = run(fx, 60);
  assert_int_equal(fx->drv.state, DRV_LMS_STREAMING);
  assert_true(scans >= 20);
  assert_int_equal(fx->port.baud, 38400);
  assert_int_equal(fx->lms.baud, 38400);
  assert_int_equal(fx->lms.width_deg, 180);
  assert_int_equal(fx->lms.res_cdeg, 100);
  assert_string_equal(fx->drv.type, "LMS200;30106");
  assert_int_equal(fx->scan.count, 181);
  assert_true(fx->scan.geometry_known);
  assert_int_equal(fx->scan.unit, LMS_UNIT_CM);
  assert_int_equal(fx->lms.requests[LMS_CMD_CONFIG_WRITE], 0);  // unit kept
  assert_int_equal(fx->drv.counters.connects, 1);
  assert_int_equal(fx->drv.counters.timeouts, 0);
  assert_int_equal(fx->drv.counters.scans, (uint64_t)scans);
  assert_string_equal(drv_lms_state_name(fx->drv.state), "streaming");
}

// A scanner already at the target rate and streaming (controller restart): the 9600 probe
// times out, the 38400 probe connects, no baud change is sent.
static void test_lms_driver_reconnects_at_target_rate(void** state) {
  fixture_t* fx = *state;
  fake_init(&fx->lms, fx->master, &fx->port, 38400);
  fx->lms.streaming = true;
  drv_lms_config_t cfg;
  drv_lms_config_default(&cfg);
  assert_int_equal(drv_lms_init(&fx->drv, &fx->port, &cfg), 0);
  const int scans = run(fx, 400);  // > 3 s of simulated time for the first probe
  assert_int_equal(fx->drv.state, DRV_LMS_STREAMING);
  assert_true(scans > 0);
  assert_int_equal(fx->drv.counters.timeouts, 1);
  assert_int_equal(fx->lms.requests[LMS_CMD_MODE] >= 2, 1);  // stop + start streaming
  assert_int_equal(fx->port.baud, 38400);
}

// A requested unit that differs from the scanner's is written in installation mode; a NAK on
// the variant request is retried.
static void test_lms_driver_unit_change_and_nak_retry(void** state) {
  fixture_t* fx = *state;
  fake_init(&fx->lms, fx->master, &fx->port, 9600);
  fx->lms.nak_variant_times = 1;
  drv_lms_config_t cfg;
  drv_lms_config_default(&cfg);
  cfg.target_baud = 9600;
  cfg.unit = LMS_UNIT_MM;
  cfg.width_deg = 100;
  cfg.res_cdeg = 25;
  assert_int_equal(drv_lms_init(&fx->drv, &fx->port, &cfg), 0);
  const int scans = run(fx, 60);
  assert_int_equal(fx->drv.state, DRV_LMS_STREAMING);
  assert_true(scans > 0);
  assert_int_equal(fx->lms.unit, LMS_UNIT_MM);
  assert_true(fx->lms.installation);
  assert_int_equal(fx->lms.requests[LMS_CMD_CONFIG_WRITE], 1);
  assert_int_equal(fx->lms.requests[LMS_CMD_VARIANT], 2);
  assert_true(fx->drv.counters.naks >= 1U);
  assert_int_equal(fx->scan.count, 401);
  assert_int_equal(fx->scan.unit, LMS_UNIT_MM);
  assert_int_equal(fx->drv.counters.restarts, 0);
}

// Silence while streaming starts the driver over; it reconnects when the scanner answers again.
static void test_lms_driver_stream_silence_restarts(void** state) {
  fixture_t* fx = *state;
  fake_init(&fx->lms, fx->master, &fx->port, 9600);
  drv_lms_config_t cfg;
  drv_lms_config_default(&cfg);
  cfg.mode_timeout_us = 300000;  // probes cycle through all rates within 1.5 s
  cfg.reply_timeout_us = 200000;
  assert_int_equal(drv_lms_init(&fx->drv, &fx->port, &cfg), 0);
  (void)run(fx, 40);
  assert_int_equal(fx->drv.state, DRV_LMS_STREAMING);
  fx->lms.silent = true;
  (void)run(fx, 150);  // 1.5 s of silence
  assert_int_not_equal(fx->drv.state, DRV_LMS_STREAMING);
  assert_true(fx->drv.counters.restarts >= 1U);
  fx->lms.silent = false;
  const int scans = run(fx, 400);  // probes time out until the scanner's rate comes round
  assert_int_equal(fx->drv.state, DRV_LMS_STREAMING);
  assert_true(scans > 0);
  assert_true(fx->drv.counters.connects >= 2U);
}

// Invalid configurations are refused.
static void test_lms_driver_invalid_config_refused(void** state) {
  fixture_t* fx = *state;
  drv_lms_config_t cfg;
  drv_lms_config_default(&cfg);
  cfg.target_baud = 115200;
  assert_int_equal(drv_lms_init(&fx->drv, &fx->port, &cfg), -EINVAL);
  drv_lms_config_default(&cfg);
  cfg.res_cdeg = 25;  // with 180°
  assert_int_equal(drv_lms_init(&fx->drv, &fx->port, &cfg), -EINVAL);
  drv_lms_config_default(&cfg);
  cfg.unit = 2;
  assert_int_equal(drv_lms_init(&fx->drv, &fx->port, &cfg), -EINVAL);
  assert_int_equal(drv_lms_init(&fx->drv, NULL, &cfg), -EINVAL);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test_setup_teardown(test_lms_driver_powerup_switches_baud_and_streams, setup,
                                      teardown),
      cmocka_unit_test_setup_teardown(test_lms_driver_reconnects_at_target_rate, setup, teardown),
      cmocka_unit_test_setup_teardown(test_lms_driver_unit_change_and_nak_retry, setup, teardown),
      cmocka_unit_test_setup_teardown(test_lms_driver_stream_silence_restarts, setup, teardown),
      cmocka_unit_test_setup_teardown(test_lms_driver_invalid_config_refused, setup, teardown),
  };
  return cmocka_run_group_tests_name("firmware.lms200_driver", tests, NULL, NULL);
}
