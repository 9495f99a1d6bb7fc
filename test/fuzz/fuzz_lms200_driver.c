// SPDX-License-Identifier: MIT
// libFuzzer target: the LMS200 host driver's state machine (drivers/lms200.h), with the fuzzer
// as the scanner on the other end of its line. The input is a sequence of records, op byte
// first: 0 = device bytes (length byte, bytes) sent to the driver; 1 = time advances by a u16
// of milliseconds; 2 = drv_lms_restart; 3 = drv_lms_stop_stream; after each record the driver
// steps. Properties: the state is always one of the documented ones, a returned scan is valid
// (1..LMS_MAX_SCAN_VALUES beams, ranges within [0, max]), counters never decrease, no I/O error
// occurs, and a request is outstanding or the driver streams after every step.
//
// The line is a non-blocking AF_UNIX stream socket pair behind a drv_serial_t filled in directly
// (a terminal's settings fail on it and are ignored, as the driver ignores them): a pseudo-
// terminal made every read and write a context switch (480 inputs/s against 2300). The serial
// line's pacing sleeps (55 µs per byte at 500 kBd, nanosleep) are skipped too: they time the
// wire, not the state machine.
#include <drivers/lms200.h>
#include <drivers/serial.h>

#include "fuzz_util.h"

#include <errno.h>
#include <fcntl.h>
#include <sys/socket.h>
#include <time.h>

int __wrap_nanosleep(const struct timespec* req, struct timespec* rem);
int __wrap_nanosleep(const struct timespec* req, struct timespec* rem) {
  (void)req;
  (void)rem;
  return 0;
}

static int g_master = -1;  // the scanner's end
static int g_slave = -1;   // the driver's end

static void drain(int fd) {
  uint8_t buf[4096];
  while (read(fd, buf, sizeof buf) > 0) {
  }
}

static void check_counters(const drv_lms_counters_t* a, const drv_lms_counters_t* b) {
  FUZZ_CHECK(b->scans >= a->scans && b->scans_superseded >= a->scans_superseded &&
             b->scan_errors >= a->scan_errors && b->timeouts >= a->timeouts && b->naks >= a->naks &&
             b->restarts >= a->restarts && b->connects >= a->connects && b->io_errors >= a->io_errors);
}

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (g_master < 0) {
    int sv[2];
    FUZZ_CHECK(socketpair(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0, sv) == 0);
    g_master = sv[0];
    g_slave = sv[1];
  }
  drain(g_master);
  drain(g_slave);
  static int verbose = -1;  // B21R_FUZZ_VERBOSE set: print each input's end state and counters
  if (verbose < 0) {
    verbose = getenv("B21R_FUZZ_VERBOSE") != NULL;
  }
  drv_serial_t port;
  memset(&port, 0, sizeof port);
  port.fd = g_slave;
  port.baud = 9600U;
  drv_lms_config_t cfg;
  drv_lms_config_default(&cfg);
  static drv_lms_t drv;
  FUZZ_CHECK(drv_lms_init(&drv, &port, &cfg) == 0);
  static lms_scan_t scan;
  uint64_t now_us = 1000000;
  fuzz_in_t in = {data, size};
  while (fuzz_more(&in)) {
    const drv_lms_counters_t before = drv.counters;
    switch (fuzz_u8(&in) % 4U) {
      case 0: {
        uint8_t bytes[256];
        const size_t n = fuzz_bytes(&in, bytes, fuzz_u8(&in));
        if (n > 0) {
          FUZZ_CHECK(write(g_master, bytes, n) == (ssize_t)n);
        }
        break;
      }
      case 1:
        now_us += (uint64_t)fuzz_u16(&in) * 1000U;
        break;
      case 2:
        drv_lms_restart(&drv);
        break;
      default:
        (void)drv_lms_stop_stream(&drv);
        break;
    }
    bool got = false;
    const drv_lms_state_t st = drv_lms_step(&drv, now_us, &scan, &got);
    if (verbose) {
      fprintf(stderr, "  step: %s waiting %d got %d\n", drv_lms_state_name(st), drv.waiting, got);
    }
    FUZZ_CHECK(st == drv.state && st >= DRV_LMS_CONNECT && st <= DRV_LMS_STREAMING);
    FUZZ_CHECK(strcmp(drv_lms_state_name(st), "unknown") != 0);
    FUZZ_CHECK(st == DRV_LMS_STREAMING || drv.waiting);
    check_counters(&before, &drv.counters);
    FUZZ_CHECK(drv.counters.io_errors == 0);
    if (got) {
      FUZZ_CHECK(st == DRV_LMS_STREAMING);
      FUZZ_CHECK(scan.count >= 1U && scan.count <= LMS_MAX_SCAN_VALUES);
      for (unsigned i = 0; i < scan.count; ++i) {
        FUZZ_CHECK(scan.range_m[i] >= 0.0f && scan.range_m[i] <= scan.max_range_m);
      }
    }
    drain(g_master);
  }
  if (verbose) {
    fprintf(stderr, "fuzz_lms200_driver: %s, %llu scans, %llu connects, %llu restarts\n",
            drv_lms_state_name(drv.state), (unsigned long long)drv.counters.scans,
            (unsigned long long)drv.counters.connects, (unsigned long long)drv.counters.restarts);
  }
  return 0;
}
