// SPDX-License-Identifier: MIT
// Readiness and watchdog notifications to the service manager (sd_notify protocol, see notify.h).
#define _GNU_SOURCE
#include <drivers/notify.h>

#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

// A message is a few lines; the manager reads datagrams of up to its own limit (PIPE_BUF-ish).
#define NOTIFY_MESSAGE_MAX 4096U

static void reset(drv_notify_t* n) {
  memset(n, 0, sizeof *n);
  n->fd = -1;
}

// Strict decimal: digits only, no sign, no overflow; 0 when the text is not such a number.
static uint64_t parse_decimal(const char* s) {
  if (s == NULL || *s == '\0') {
    return 0;
  }
  uint64_t v = 0;
  for (; *s != '\0'; ++s) {
    if (*s < '0' || *s > '9' || v > (UINT64_MAX - 9U) / 10U) {
      return 0;
    }
    v = v * 10U + (uint64_t)(*s - '0');
  }
  return v;
}

int drv_notify_open(drv_notify_t* n, const char* notify_socket, const char* watchdog_usec, const char* watchdog_pid,
                    pid_t self, char* err, size_t err_len) {
  if (n == NULL) {
    return -EINVAL;
  }
  reset(n);
  // The watchdog variables are this process's only when WATCHDOG_PID is unset or names it.
  const bool ours = watchdog_pid == NULL || *watchdog_pid == '\0' || parse_decimal(watchdog_pid) == (uint64_t)self;
  int64_t watchdog_us = 0;
  if (ours && watchdog_usec != NULL && *watchdog_usec != '\0') {
    const uint64_t v = parse_decimal(watchdog_usec);
    if (v == 0U || v > (uint64_t)INT64_MAX / 2U) {
      if (err != NULL && err_len > 0U) {
        snprintf(err, err_len,
                 "notify: WATCHDOG_USEC='%s' is not a positive number of microseconds (the service manager sets it "
                 "from the unit's WatchdogSec=; fix that setting or unset the variable)",
                 watchdog_usec);
      }
      return -EINVAL;
    }
    watchdog_us = (int64_t)v;
  }
  if (notify_socket == NULL || *notify_socket == '\0') {
    if (watchdog_us > 0) {
      if (err != NULL && err_len > 0U) {
        snprintf(err, err_len,
                 "notify: WATCHDOG_USEC is set but NOTIFY_SOCKET is not: the watchdog could not be fed (run as a "
                 "Type=notify service, or unset WATCHDOG_USEC)");
      }
      return -EINVAL;
    }
    return 0;
  }
  const size_t len = strlen(notify_socket);
  if ((notify_socket[0] != '/' && notify_socket[0] != '@') || len < 2U || len >= sizeof n->addr.sun_path) {
    if (err != NULL && err_len > 0U) {
      snprintf(err, err_len,
               "notify: NOTIFY_SOCKET='%s' is not an absolute socket path or an abstract name starting with '@' "
               "(at most %zu characters); it is set by the service manager for Type=notify units: unset it to run "
               "without one",
               notify_socket, sizeof n->addr.sun_path - 1U);
    }
    return -EINVAL;
  }
  n->addr.sun_family = AF_UNIX;
  memcpy(n->addr.sun_path, notify_socket, len);
  if (notify_socket[0] == '@') {
    n->addr.sun_path[0] = '\0';  // the abstract namespace; its name is not NUL-terminated
  }
  n->addr_len = (socklen_t)(offsetof(struct sockaddr_un, sun_path) + len + (notify_socket[0] == '/' ? 1U : 0U));
  const int fd = socket(AF_UNIX, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    const int e = errno;
    if (err != NULL && err_len > 0U) {
      snprintf(err, err_len, "notify: cannot make the notification socket: %s", strerror(e));
    }
    return -e;
  }
  n->fd = fd;
  n->watchdog_us = watchdog_us;
  return 0;
}

int drv_notify_send(drv_notify_t* n, const char* message) {
  if (n == NULL || message == NULL) {
    return -EINVAL;
  }
  if (n->fd < 0) {
    return 0;
  }
  const size_t len = strlen(message);
  if (len == 0U || len > NOTIFY_MESSAGE_MAX) {
    return -EINVAL;
  }
  // Unconnected: the path is resolved per message, so a manager that re-made its socket (a
  // re-executed systemd keeps it, a test may not) is still reached.
  const ssize_t r =
      sendto(n->fd, message, len, MSG_DONTWAIT | MSG_NOSIGNAL, (const struct sockaddr*)&n->addr, n->addr_len);
  if (r < 0) {
    const int e = errno;
    if (e == EAGAIN || e == EWOULDBLOCK) {
      n->counters.would_block++;
      return -EAGAIN;
    }
    n->counters.errors++;
    return -e;
  }
  n->counters.sent++;
  return 0;
}

// "<head>" or "<head>\nSTATUS=<status>", cut to the message limit.
static int send_with_status(drv_notify_t* n, const char* head, const char* status) {
  if (status == NULL || *status == '\0') {
    return drv_notify_send(n, head);
  }
  char msg[512];
  snprintf(msg, sizeof msg, "%s\nSTATUS=%s", head, status);
  return drv_notify_send(n, msg);
}

int drv_notify_ready(drv_notify_t* n, int64_t now_us, const char* status) {
  if (n == NULL) {
    return -EINVAL;
  }
  const int r = send_with_status(n, "READY=1", status);
  if (r == 0) {
    n->ready = true;
    n->next_ping_us = now_us + n->watchdog_us / 2;
  }
  return r;
}

int drv_notify_tick(drv_notify_t* n, int64_t now_us) {
  if (n == NULL) {
    return -EINVAL;
  }
  if (n->fd < 0 || !n->ready || n->watchdog_us <= 0 || now_us < n->next_ping_us) {
    return 0;
  }
  const int r = drv_notify_send(n, "WATCHDOG=1");
  if (r < 0) {
    return r;  // still due: the next tick tries again
  }
  n->counters.pings++;
  n->next_ping_us = now_us + n->watchdog_us / 2;
  return 1;
}

int drv_notify_stopping(drv_notify_t* n, const char* status) {
  if (n == NULL) {
    return -EINVAL;
  }
  return send_with_status(n, "STOPPING=1", status);
}

void drv_notify_close(drv_notify_t* n) {
  if (n != NULL && n->fd >= 0) {
    (void)close(n->fd);
    n->fd = -1;
  }
}
