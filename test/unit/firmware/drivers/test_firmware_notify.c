// SPDX-License-Identifier: MIT
// Service-manager notifications (sd_notify protocol) against a datagram socket standing in for
// the manager: the environment's checks, READY=1 / STATUS=, WATCHDOG=1 at half the interval and
// only after READY=1, the abstract namespace, and a full queue that refuses without blocking.
#define _GNU_SOURCE
#include <drivers/notify.h>

#include <b21r_test/alloc_counter.h>

#include <errno.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cmocka.h>

typedef struct manager {
  int fd;
  char path[108];  // "@..." for the abstract namespace
} manager_t;

// A datagram socket bound at `name` (a path, or "@name"), as the service manager's.
static void manager_open(manager_t* m, const char* name) {
  memset(m, 0, sizeof *m);
  snprintf(m->path, sizeof m->path, "%s", name);
  m->fd = socket(AF_UNIX, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  assert_true(m->fd >= 0);
  struct sockaddr_un a = {.sun_family = AF_UNIX};
  const size_t len = strlen(name);
  memcpy(a.sun_path, name, len);
  socklen_t alen = (socklen_t)(offsetof(struct sockaddr_un, sun_path) + len);
  if (name[0] == '@') {
    a.sun_path[0] = '\0';
  } else {
    (void)unlink(name);
    alen++;
  }
  assert_int_equal(bind(m->fd, (struct sockaddr*)&a, alen), 0);
}

static void manager_close(manager_t* m) {
  close(m->fd);
  if (m->path[0] == '/') {
    (void)unlink(m->path);
  }
}

// The next datagram as a string, or "" when none is queued.
static const char* manager_recv(manager_t* m) {
  static char buf[1024];
  const ssize_t r = recv(m->fd, buf, sizeof buf - 1U, 0);
  buf[r > 0 ? r : 0] = '\0';
  return buf;
}

static void temp_path(char* out, size_t cap, const char* tag) {
  const char* dir = getenv("TMPDIR");
  snprintf(out, cap, "%s/b21r-notify-%s-%ld", dir != NULL && dir[0] != '\0' ? dir : "/tmp", tag, (long)getpid());
}

// Without NOTIFY_SOCKET there is no manager: every call succeeds and sends nothing.
static void test_notify_without_manager_is_noop(void** state) {
  (void)state;
  drv_notify_t n;
  char err[256] = "";
  assert_int_equal(drv_notify_open(&n, NULL, NULL, NULL, getpid(), err, sizeof err), 0);
  assert_int_equal(n.fd, -1);
  assert_int_equal(drv_notify_ready(&n, 0, "running"), 0);
  assert_int_equal(drv_notify_tick(&n, 10000000), 0);
  assert_int_equal(drv_notify_stopping(&n, NULL), 0);
  assert_int_equal(n.counters.sent, 0);
  drv_notify_close(&n);
  drv_notify_close(&n);
  assert_int_equal(drv_notify_open(&n, "", NULL, "", getpid(), err, sizeof err), 0);
  assert_int_equal(n.fd, -1);
}

// Bad values are refused with a message naming the variable and the fix; nothing is opened.
static void test_notify_bad_environment_refused(void** state) {
  (void)state;
  drv_notify_t n;
  char err[512] = "";
  assert_int_equal(drv_notify_open(&n, "relative/socket", NULL, NULL, getpid(), err, sizeof err), -EINVAL);
  assert_non_null(strstr(err, "NOTIFY_SOCKET='relative/socket'"));
  assert_non_null(strstr(err, "unset it"));
  assert_int_equal(n.fd, -1);
  char longname[200];
  memset(longname, 'x', sizeof longname);
  longname[0] = '/';
  longname[sizeof longname - 1U] = '\0';
  assert_int_equal(drv_notify_open(&n, longname, NULL, NULL, getpid(), err, sizeof err), -EINVAL);
  assert_int_equal(drv_notify_open(&n, "@", NULL, NULL, getpid(), err, sizeof err), -EINVAL);
  const char* bad_usec[] = {"abc", "0", "-5", "12x", "99999999999999999999999"};
  for (size_t i = 0; i < sizeof bad_usec / sizeof bad_usec[0]; ++i) {
    err[0] = '\0';
    assert_int_equal(drv_notify_open(&n, "/run/x", bad_usec[i], NULL, getpid(), err, sizeof err), -EINVAL);
    assert_non_null(strstr(err, "WATCHDOG_USEC"));
    assert_non_null(strstr(err, "WatchdogSec="));
    assert_int_equal(n.fd, -1);
  }
  // A watchdog with nowhere to send the pings would kill the service: refused.
  assert_int_equal(drv_notify_open(&n, NULL, "2000000", NULL, getpid(), err, sizeof err), -EINVAL);
  assert_non_null(strstr(err, "NOTIFY_SOCKET is not"));
}

// WATCHDOG_USEC meant for another process (WATCHDOG_PID) is ignored, as sd_watchdog_enabled does.
static void test_notify_watchdog_of_other_pid_ignored(void** state) {
  (void)state;
  drv_notify_t n;
  char err[256] = "";
  char other[32];
  snprintf(other, sizeof other, "%ld", (long)getpid() + 1L);
  assert_int_equal(drv_notify_open(&n, "/run/x", "2000000", other, getpid(), err, sizeof err), 0);
  assert_int_equal(n.watchdog_us, 0);
  drv_notify_close(&n);
  char self[32];
  snprintf(self, sizeof self, "%ld", (long)getpid());
  assert_int_equal(drv_notify_open(&n, "/run/x", "2000000", self, getpid(), err, sizeof err), 0);
  assert_int_equal(n.watchdog_us, 2000000);
  drv_notify_close(&n);
}

// READY=1 with its status, then WATCHDOG=1 every half interval of the caller's clock, never
// before READY=1 and never more often; STOPPING=1 at the end. No allocation after open.
static void test_notify_ready_then_pings_at_half_interval(void** state) {
  (void)state;
  char path[108];
  temp_path(path, sizeof path, "ready");
  manager_t m;
  manager_open(&m, path);
  drv_notify_t n;
  char err[256] = "";
  assert_int_equal(drv_notify_open(&n, path, "1000000", NULL, getpid(), err, sizeof err), 0);
  assert_int_equal(n.watchdog_us, 1000000);

  alloc_counter_begin();
  // Before READY=1 the watchdog is not the manager's yet: no ping, however late.
  assert_int_equal(drv_notify_tick(&n, 5000000), 0);
  assert_string_equal(manager_recv(&m), "");
  assert_int_equal(drv_notify_ready(&n, 10000000, "laser /dev/ttyUSB0, base rflex"), 0);
  assert_string_equal(manager_recv(&m), "READY=1\nSTATUS=laser /dev/ttyUSB0, base rflex");
  int pings = 0;
  for (int64_t t = 10000000; t <= 12000000; t += 100000) {  // 10 Hz ticks for 2 s
    const int r = drv_notify_tick(&n, t);
    assert_true(r == 0 || r == 1);
    if (r == 1) {
      assert_true(t == 10500000 || t == 11000000 || t == 11500000 || t == 12000000);
      assert_string_equal(manager_recv(&m), "WATCHDOG=1");
      pings++;
    } else {
      assert_string_equal(manager_recv(&m), "");
    }
  }
  assert_int_equal(pings, 4);
  assert_int_equal(n.counters.pings, 4);
  assert_int_equal(drv_notify_stopping(&n, "signal 15"), 0);
  assert_string_equal(manager_recv(&m), "STOPPING=1\nSTATUS=signal 15");
  assert_int_equal(alloc_counter_end(), 0);
  assert_int_equal(n.counters.sent, 6);
  assert_int_equal(n.counters.errors, 0);
  drv_notify_close(&n);
  manager_close(&m);
}

// An abstract-namespace socket ("@name") is reached too.
static void test_notify_abstract_socket(void** state) {
  (void)state;
  char name[64];
  snprintf(name, sizeof name, "@b21r-notify-test-%ld", (long)getpid());
  manager_t m;
  manager_open(&m, name);
  drv_notify_t n;
  char err[256] = "";
  assert_int_equal(drv_notify_open(&n, name, NULL, NULL, getpid(), err, sizeof err), 0);
  assert_int_equal(drv_notify_ready(&n, 0, NULL), 0);
  assert_string_equal(manager_recv(&m), "READY=1");
  assert_int_equal(drv_notify_tick(&n, 100000000), 0);  // no watchdog asked for: no ping
  drv_notify_close(&n);
  manager_close(&m);
}

// A manager that does not read: sends are refused at once (-EAGAIN, counted), never waited for,
// and the ping stays due until the queue has room again.
static void test_notify_full_queue_never_blocks(void** state) {
  (void)state;
  char path[108];
  temp_path(path, sizeof path, "full");
  manager_t m;
  manager_open(&m, path);
  drv_notify_t n;
  char err[256] = "";
  assert_int_equal(drv_notify_open(&n, path, "200000", NULL, getpid(), err, sizeof err), 0);
  assert_int_equal(drv_notify_ready(&n, 0, NULL), 0);
  int refused = 0;
  for (int i = 0; i < 100000 && refused == 0; ++i) {
    const int r = drv_notify_send(&n, "STATUS=filling the queue");
    if (r == -EAGAIN) {
      refused = 1;
    } else {
      assert_int_equal(r, 0);
    }
  }
  assert_int_equal(refused, 1);
  assert_int_equal(n.counters.would_block, 1);
  assert_int_equal(drv_notify_tick(&n, 100000), -EAGAIN);  // due, refused
  assert_int_equal(drv_notify_tick(&n, 200000), -EAGAIN);  // still due
  while (manager_recv(&m)[0] != '\0') {
  }
  assert_int_equal(drv_notify_tick(&n, 300000), 1);  // the queue has room: the ping goes
  assert_string_equal(manager_recv(&m), "WATCHDOG=1");
  assert_int_equal(drv_notify_tick(&n, 350000), 0);  // next one half an interval after it
  assert_int_equal(n.next_ping_us, 400000);
  drv_notify_close(&n);
  manager_close(&m);
}

// A manager that went away: the error is returned and counted, nothing crashes.
static void test_notify_manager_gone_counted(void** state) {
  (void)state;
  char path[108];
  temp_path(path, sizeof path, "gone");
  manager_t m;
  manager_open(&m, path);
  drv_notify_t n;
  char err[256] = "";
  assert_int_equal(drv_notify_open(&n, path, NULL, NULL, getpid(), err, sizeof err), 0);
  manager_close(&m);
  const int r = drv_notify_ready(&n, 0, "x");
  assert_true(r < 0 && r != -EAGAIN);
  assert_false(n.ready);
  assert_int_equal(n.counters.errors, 1);
  assert_int_equal(drv_notify_send(&n, ""), -EINVAL);
  drv_notify_close(&n);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_notify_without_manager_is_noop),
      cmocka_unit_test(test_notify_bad_environment_refused),
      cmocka_unit_test(test_notify_watchdog_of_other_pid_ignored),
      cmocka_unit_test(test_notify_ready_then_pings_at_half_interval),
      cmocka_unit_test(test_notify_abstract_socket),
      cmocka_unit_test(test_notify_full_queue_never_blocks),
      cmocka_unit_test(test_notify_manager_gone_counted),
  };
  return cmocka_run_group_tests_name("firmware.notify", tests, NULL, NULL);
}
