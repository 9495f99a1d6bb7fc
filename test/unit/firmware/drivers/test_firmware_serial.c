// SPDX-License-Identifier: MIT
// Serial driver over pseudo-terminals: raw 8N1 settings, non-blocking reads, baud changes,
// pacing, error messages, rFLEX packets end to end through a pty, and link mode (a helper
// thread makes the terminal calls; the owner never waits for them).
#define _GNU_SOURCE
#include <drivers/serial_link.h>
#include <proto/rflex.h>

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <stdatomic.h>
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

// ---- link mode --------------------------------------------------------------------------------

static atomic_int g_notified;

static void on_news(void* user) {
  (void)user;
  atomic_fetch_add(&g_notified, 1);
}

// A link opened on the pty's path, its helper running, the port in link mode on it.
static drv_serial_link_t* open_link(fixture_t* fx, drv_serial_t* port, uint32_t baud) {
  drv_serial_link_t* link = drv_serial_link_create(on_news, NULL);
  assert_non_null(link);
  assert_int_equal(drv_serial_link_start(link), 0);
  drv_serial_link_open(link, fx->path, baud);
  const double end = now_s() + 2.0;
  int fd = -1;
  while (drv_serial_link_state(link, &fd, NULL, NULL, 0) != DRV_SERIAL_LINK_OPEN && now_s() < end) {
    usleep(1000);
  }
  assert_true(fd >= 0);
  assert_int_equal(drv_serial_use_link(port, link), 0);
  assert_ptr_equal(port->link, link);
  assert_int_equal(port->baud, baud);
  return link;
}

// Reads through the link until n bytes arrived (about a second at most).
static void link_read_exact(drv_serial_t* port, uint8_t* buf, size_t n) {
  size_t got = 0;
  const double end = now_s() + 2.0;
  while (got < n && now_s() < end) {
    const ssize_t k = drv_serial_read(port, buf + got, n - got);
    assert_true(k >= 0);
    got += (size_t)k;
    if (k == 0) {
      usleep(500);
    }
  }
  assert_int_equal(got, n);
}

// Input reaches the owner through the helper (which tells it so); the owner's queued packets
// and its paced requests reach the device; nothing is lost or reordered.
static void test_serial_link_bytes_both_ways(void** state) {
  fixture_t* fx = *state;
  drv_serial_t port;
  atomic_store(&g_notified, 0);
  drv_serial_link_t* link = open_link(fx, &port, 115200);
  uint8_t all[256];
  for (int i = 0; i < 256; ++i) {
    all[i] = (uint8_t)i;
  }
  uint8_t buf[512];
  assert_int_equal(drv_serial_read(&port, buf, sizeof buf), 0);
  assert_int_equal(write(fx->master, all, sizeof all), (ssize_t)sizeof all);
  link_read_exact(&port, buf, sizeof all);
  assert_memory_equal(buf, all, sizeof all);
  assert_true(atomic_load(&g_notified) > 0);
  assert_int_equal(drv_serial_link_counters(link).bytes_in, 256);
  // A request written by the helper, then a packet the owner writes itself.
  assert_int_equal(drv_serial_write(&port, all, 100, 1000), 0);
  while (drv_serial_link_busy(link)) {
    usleep(500);
  }
  assert_int_equal(drv_serial_queue(&port, all + 100, 50, 0), 0);
  read_exact(fx->master, buf, 150);
  assert_memory_equal(buf, all, 150);
  // A request longer than a slot is refused, not cut.
  uint8_t big[DRV_SERIAL_LINK_OP_BYTES + 1];
  memset(big, 0, sizeof big);
  assert_int_equal(drv_serial_write(&port, big, sizeof big, 1000), -EMSGSIZE);
  drv_serial_close(&port);
  assert_null(port.link);
  drv_serial_link_close(link);
  drv_serial_link_destroy(link);
}

// Rate changes and input flushes are carried out by the helper, in order with the requests.
static void test_serial_link_baud_and_flush(void** state) {
  fixture_t* fx = *state;
  drv_serial_t port;
  drv_serial_link_t* link = open_link(fx, &port, 9600);
  assert_int_equal(drv_serial_set_baud(&port, 38400), 0);
  assert_int_equal(port.baud, 38400);
  while (drv_serial_link_busy(link)) {
    usleep(500);
  }
  struct termios tio;
  assert_int_equal(tcgetattr(fx->slave, &tio), 0);
  assert_int_equal(cfgetospeed(&tio), B38400);
  // Input that arrived before a flush is gone, input after it comes through.
  const uint8_t old_bytes[4] = {1, 2, 3, 4};
  assert_int_equal(write(fx->master, old_bytes, sizeof old_bytes), 4);
  const double end = now_s() + 2.0;
  while (drv_serial_link_counters(link).bytes_in < 4 && now_s() < end) {
    usleep(500);
  }
  assert_int_equal(drv_serial_flush_input(&port), 0);
  while (drv_serial_link_busy(link)) {
    usleep(500);
  }
  const uint8_t new_bytes[3] = {7, 8, 9};
  assert_int_equal(write(fx->master, new_bytes, sizeof new_bytes), 3);
  uint8_t buf[8];
  link_read_exact(&port, buf, 3);
  assert_memory_equal(buf, new_bytes, 3);
  assert_int_equal(drv_serial_set_baud(&port, 12345), -EINVAL);
  drv_serial_close(&port);
  drv_serial_link_destroy(link);
}

// The owner never waits for the helper's terminal calls: while the helper is busy for about half
// a second with a paced request, reads, rate changes, flushes and queued packets return at once.
static void test_serial_link_owner_never_waits(void** state) {
  fixture_t* fx = *state;
  drv_serial_t port;
  drv_serial_link_t* link = open_link(fx, &port, 115200);
  drv_serial_set_pacing(&port, 0, 0, 5000);  // 5 ms between bytes: 100 bytes keep the helper ~0.5 s
  uint8_t data[100];
  memset(data, 0x33, sizeof data);
  assert_int_equal(drv_serial_write(&port, data, sizeof data, 1000), 0);
  usleep(20000);  // the helper is inside the request now
  assert_true(drv_serial_link_busy(link));
  double worst = 0.0;
  for (int i = 0; i < 20; ++i) {
    uint8_t buf[64];
    const double t0 = now_s();
    assert_true(drv_serial_read(&port, buf, sizeof buf) >= 0);
    (void)drv_serial_set_baud(&port, i % 2 == 0 ? 38400 : 115200);
    (void)drv_serial_flush_input(&port);
    assert_int_equal(drv_serial_queue(&port, data, 8, 0), 0);
    const double dt = now_s() - t0;
    worst = dt > worst ? dt : worst;
    usleep(5000);
  }
  assert_true(drv_serial_link_busy(link));  // the helper is still writing
  print_message("owner calls while the helper was busy: worst %.0f us\n", worst * 1e6);
  assert_true(worst < 0.01);
  drv_serial_close(&port);
  drv_serial_link_destroy(link);  // stops the helper mid-request
}

// A hang-up of the line is the link's error (-EPIPE or -EIO) for the owner's reads; the helper
// then waits instead of spinning on the dead line; the link reopens on request.
static void test_serial_link_hangup_is_an_error(void** state) {
  fixture_t* fx = *state;
  drv_serial_t port;
  atomic_store(&g_notified, 0);
  drv_serial_link_t* link = open_link(fx, &port, 115200);
  close(fx->master);
  fx->master = -1;
  uint8_t buf[16];
  ssize_t r = 0;
  const double end = now_s() + 2.0;
  while ((r = drv_serial_read(&port, buf, sizeof buf)) == 0 && now_s() < end) {
    usleep(1000);
  }
  assert_true(r == -EPIPE || r == -EIO);
  assert_int_equal(port.last_error, (int)r);
  const int news = atomic_load(&g_notified);
  usleep(100000);
  assert_int_equal(atomic_load(&g_notified), news);  // nothing more happens: no spinning
  drv_serial_close(&port);
  drv_serial_link_close(link);
  // The line comes back (a new pty at a new path): the same link opens it.
  int master = -1;
  int slave = -1;
  char path[128];
  assert_int_equal(openpty(&master, &slave, path, NULL, NULL), 0);
  drv_serial_link_open(link, path, 115200);
  const double end2 = now_s() + 2.0;
  while (drv_serial_link_state(link, NULL, NULL, NULL, 0) != DRV_SERIAL_LINK_OPEN && now_s() < end2) {
    usleep(1000);
  }
  assert_int_equal(drv_serial_use_link(&port, link), 0);
  assert_int_equal(write(master, "ok", 2), 2);
  link_read_exact(&port, buf, 2);
  assert_memory_equal(buf, "ok", 2);
  // An open that fails is reported with the reason.
  drv_serial_close(&port);
  drv_serial_link_open(link, "/nonexistent/ttyS9", 115200);
  char msg[256];
  int e = 0;
  drv_serial_link_state_t st = DRV_SERIAL_LINK_OPENING;
  const double end3 = now_s() + 2.0;
  while ((st = drv_serial_link_state(link, NULL, &e, msg, sizeof msg)) == DRV_SERIAL_LINK_OPENING && now_s() < end3) {
    usleep(1000);
  }
  assert_int_equal(st, DRV_SERIAL_LINK_FAILED);
  assert_int_equal(e, -ENOENT);
  assert_non_null(strstr(msg, "/nonexistent/ttyS9"));
  assert_int_equal(drv_serial_use_link(&port, link), -ENOTCONN);
  drv_serial_link_destroy(link);
  close(master);
  close(slave);
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
      cmocka_unit_test_setup_teardown(test_serial_link_bytes_both_ways, setup, teardown),
      cmocka_unit_test_setup_teardown(test_serial_link_baud_and_flush, setup, teardown),
      cmocka_unit_test_setup_teardown(test_serial_link_owner_never_waits, setup, teardown),
      cmocka_unit_test_setup_teardown(test_serial_link_hangup_is_an_error, setup, teardown),
  };
  return cmocka_run_group_tests_name("firmware.serial", tests, NULL, NULL);
}
