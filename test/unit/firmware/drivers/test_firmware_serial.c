// SPDX-License-Identifier: MIT
// Serial driver over pseudo-terminals: raw 8N1 settings, non-blocking reads, baud changes,
// pacing, error messages, and rFLEX packets end to end through a pty.
#define _GNU_SOURCE
#include <drivers/serial.h>
#include <proto/rflex.h>

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include <cmocka.h>

typedef struct fixture {
  int master;
  int slave;
  char path[128];
} fixture_t;

static int setup(void** state) {
  static fixture_t fx;
  if (openpty(&fx.master, &fx.slave, fx.path, NULL, NULL) != 0) {
    return -1;
  }
  *state = &fx;
  return 0;
}

static int teardown(void** state) {
  fixture_t* fx = *state;
  if (fx->master >= 0) {
    close(fx->master);
  }
  if (fx->slave >= 0) {
    close(fx->slave);
  }
  return 0;
}

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

// Reads exactly n bytes from fd within about a second.
static void read_exact(int fd, uint8_t* buf, size_t n) {
  size_t got = 0;
  const double end = now_s() + 2.0;
  while (got < n && now_s() < end) {
    struct pollfd p = {.fd = fd, .events = POLLIN, .revents = 0};
    if (poll(&p, 1, 100) > 0) {
      const ssize_t k = read(fd, buf + got, n - got);
      if (k > 0) {
        got += (size_t)k;
      }
    }
  }
  assert_int_equal(got, n);
}

// Opening the pty by path gives raw 8N1 at the rate, no flow control, non-blocking.
static void test_serial_open_pty_raw_8n1(void** state) {
  fixture_t* fx = *state;
  drv_serial_t port;
  char err[256] = "";
  assert_int_equal(drv_serial_open(&port, fx->path, 115200, err, sizeof err), 0);
  struct termios tio;
  assert_int_equal(tcgetattr(port.fd, &tio), 0);
  assert_int_equal(tio.c_cflag & CSIZE, CS8);
  assert_int_equal(tio.c_cflag & (PARENB | CSTOPB | CRTSCTS), 0);
  assert_int_equal(tio.c_lflag & (ICANON | ECHO | ISIG), 0);
  assert_int_equal(tio.c_iflag & (IXON | IXOFF | ICRNL), 0);
  assert_int_equal(tio.c_oflag & OPOST, 0);
  assert_int_equal(cfgetospeed(&tio), B115200);
  assert_int_equal(cfgetispeed(&tio), B115200);
  assert_true((fcntl(port.fd, F_GETFL) & O_NONBLOCK) != 0);
  assert_int_equal(port.baud, 115200);
  drv_serial_close(&port);
  assert_int_equal(port.fd, -1);
  drv_serial_close(&port);  // idempotent
}

// Bytes flow both ways; an empty line reads as 0 without blocking; 0x00..0xFF pass untouched.
static void test_serial_read_write_all_bytes(void** state) {
  fixture_t* fx = *state;
  drv_serial_t port;
  assert_int_equal(drv_serial_attach(&port, fx->slave, 115200, false, NULL, 0), 0);
  uint8_t buf[512];
  assert_int_equal(drv_serial_read(&port, buf, sizeof buf), 0);
  uint8_t all[256];
  for (int i = 0; i < 256; ++i) {
    all[i] = (uint8_t)i;
  }
  assert_int_equal(drv_serial_write(&port, all, sizeof all, 1000), 0);
  read_exact(fx->master, buf, sizeof all);
  assert_memory_equal(buf, all, sizeof all);
  assert_int_equal(write(fx->master, all, sizeof all), (ssize_t)sizeof all);
  size_t got = 0;
  while (got < sizeof all) {
    assert_int_equal(drv_serial_wait_readable(&port, 1000), 1);
    const ssize_t k = drv_serial_read(&port, buf + got, sizeof buf - got);
    assert_true(k >= 0);
    got += (size_t)k;
  }
  assert_memory_equal(buf, all, sizeof all);
  assert_int_equal(port.counters.bytes_read, 256);
  assert_int_equal(port.counters.bytes_written, 256);
  assert_int_equal(drv_serial_wait_readable(&port, 10), 0);
  drv_serial_close(&port);
  // Not owned: the descriptor is still usable.
  assert_true(fcntl(fx->slave, F_GETFD) >= 0);
}

// The LMS200 rates: 9600 -> 38400 -> 500000 are applied to the line; unsupported rates are refused.
static void test_serial_set_baud_switches_rate(void** state) {
  fixture_t* fx = *state;
  drv_serial_t port;
  assert_int_equal(drv_serial_attach(&port, fx->slave, 9600, false, NULL, 0), 0);
  struct termios tio;
  assert_int_equal(tcgetattr(fx->slave, &tio), 0);
  assert_int_equal(cfgetospeed(&tio), B9600);
  assert_int_equal(drv_serial_set_baud(&port, 38400), 0);
  assert_int_equal(tcgetattr(fx->slave, &tio), 0);
  assert_int_equal(cfgetospeed(&tio), B38400);
  assert_int_equal(drv_serial_set_baud(&port, 500000), 0);
  assert_int_equal(tcgetattr(fx->slave, &tio), 0);
  assert_int_equal(cfgetospeed(&tio), B500000);
  assert_int_equal(port.baud, 500000);
  assert_int_equal(port.counters.baud_changes, 2);
  assert_int_equal(drv_serial_set_baud(&port, 12345), -EINVAL);
  assert_int_equal(port.baud, 500000);
  assert_false(drv_serial_baud_supported(0));
  assert_true(drv_serial_baud_supported(115200));
}

// Pacing: chunk gaps and byte gaps make a write take at least the configured time.
static void test_serial_pacing_spaces_writes(void** state) {
  fixture_t* fx = *state;
  drv_serial_t port;
  assert_int_equal(drv_serial_attach(&port, fx->slave, 115200, false, NULL, 0), 0);
  uint8_t data[40];
  memset(data, 0x5A, sizeof data);
  drv_serial_set_pacing(&port, 8, 1000, 0);  // rFLEX style: 1 ms after each 8-byte chunk
  double t0 = now_s();
  assert_int_equal(drv_serial_write(&port, data, sizeof data, 1000), 0);
  assert_true(now_s() - t0 >= 0.005);
  uint8_t sink[64];
  read_exact(fx->master, sink, sizeof data);
  drv_serial_set_pacing(&port, 0, 0, 100);  // LMS 500 kBd style: spacing between bytes
  t0 = now_s();
  assert_int_equal(drv_serial_write(&port, data, 20, 1000), 0);
  assert_true(now_s() - t0 >= 0.002);
  read_exact(fx->master, sink, 20);
}

// Errors come with a message that names the path and the cause.
static void test_serial_open_errors_have_messages(void** state) {
  (void)state;
  drv_serial_t port;
  char err[256] = "";
  assert_int_equal(drv_serial_open(&port, "/nonexistent/ttyS9", 115200, err, sizeof err), -ENOENT);
  assert_non_null(strstr(err, "/nonexistent/ttyS9"));
  assert_int_equal(drv_serial_open(&port, "/dev/null", 115200, err, sizeof err), -ENOTTY);
  assert_non_null(strstr(err, "not a terminal"));
  assert_non_null(strstr(err, "/dev/null"));
  assert_int_equal(drv_serial_open(&port, "/dev/null", 1234, err, sizeof err), -EINVAL);
  assert_non_null(strstr(err, "baud"));
  assert_int_equal(port.fd, -1);
}

// When the device side of the pty goes away the read reports an error instead of blocking.
static void test_serial_peer_closed_read_fails(void** state) {
  fixture_t* fx = *state;
  drv_serial_t port;
  assert_int_equal(drv_serial_attach(&port, fx->slave, 115200, false, NULL, 0), 0);
  close(fx->master);
  fx->master = -1;
  uint8_t buf[16];
  assert_true(drv_serial_read(&port, buf, sizeof buf) < 0);
  assert_int_equal(drv_serial_wait_readable(&port, 100), 1);
}

// rFLEX end to end through a pty: host packets (unstuffed) and device reports (stuffed) decode.
static void test_serial_rflex_packets_through_pty(void** state) {
  fixture_t* fx = *state;
  drv_serial_t port;
  assert_int_equal(drv_serial_attach(&port, fx->slave, 115200, false, NULL, 0), 0);
  drv_serial_set_pacing(&port, 0, 1000, 0);
  rflex_b21r_params_t p;
  rflex_b21r_params_default(&p);
  rflex_packet_t cmd[2];
  assert_int_equal(rflex_make_velocity(cmd, &p, 0.5, 0.3, 0.7), PROTO_OK);
  uint8_t buf[1024];
  size_t total = 0;
  for (int i = 0; i < 2; ++i) {
    const size_t n = rflex_encode(buf, sizeof buf, &cmd[i], RFLEX_HOST_STRICT);
    assert_int_equal(drv_serial_write(&port, buf, n, 1000), 0);
    total += n;
  }
  uint8_t wire[128];
  read_exact(fx->master, wire, total);
  rflex_decoder_t dec;
  rflex_decoder_init_role(&dec, RFLEX_ROLE_DEVICE);  // reads what the host sent
  int got = 0;
  const uint8_t* q = wire;
  size_t left = total;
  while (left > 0U) {
    rflex_packet_t pk;
    bool have = false;
    const size_t k = rflex_decoder_push(&dec, q, left, &pk, &have);
    q += k;
    left -= k;
    if (have) {
      assert_int_equal(pk.dlen, 14);
      assert_memory_equal(pk.data, cmd[got].data, 14);
      ++got;
    }
  }
  assert_int_equal(got, 2);
  // Device -> host: a stuffed motor report with 0x1B bytes in it.
  const rflex_motor_report_t r = {.axis = 1, .position = 0x1B1B, .velocity = -0x1B};
  rflex_packet_t pk;
  assert_int_equal(rflex_make_motor_report(&pk, 0x1B, &r), PROTO_OK);
  const size_t n = rflex_encode(buf, sizeof buf, &pk, RFLEX_DEVICE_STUFFED);
  assert_int_equal(write(fx->master, buf, n), (ssize_t)n);
  rflex_decoder_init(&dec);
  bool have = false;
  for (int tries = 0; tries < 100 && !have; ++tries) {
    (void)drv_serial_wait_readable(&port, 20);
    uint8_t rx[64];
    const ssize_t k = drv_serial_read(&port, rx, sizeof rx);
    assert_true(k >= 0);
    const uint8_t* s = rx;
    size_t l = (size_t)k;
    while (l > 0U && !have) {
      const size_t used = rflex_decoder_push(&dec, s, l, &pk, &have);
      s += used;
      l -= used;
    }
  }
  assert_true(have);
  rflex_motor_report_t r2;
  assert_int_equal(rflex_parse_motor_report(&pk, &r2), PROTO_OK);
  assert_int_equal(r2.position, 0x1B1B);
  assert_int_equal(r2.velocity, -0x1B);
  assert_int_equal(dec.counters.packets_stuffed, 1);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test_setup_teardown(test_serial_open_pty_raw_8n1, setup, teardown),
      cmocka_unit_test_setup_teardown(test_serial_read_write_all_bytes, setup, teardown),
      cmocka_unit_test_setup_teardown(test_serial_set_baud_switches_rate, setup, teardown),
      cmocka_unit_test_setup_teardown(test_serial_pacing_spaces_writes, setup, teardown),
      cmocka_unit_test(test_serial_open_errors_have_messages),
      cmocka_unit_test_setup_teardown(test_serial_peer_closed_read_fails, setup, teardown),
      cmocka_unit_test_setup_teardown(test_serial_rflex_packets_through_pty, setup, teardown),
  };
  return cmocka_run_group_tests_name("firmware.serial", tests, NULL, NULL);
}
