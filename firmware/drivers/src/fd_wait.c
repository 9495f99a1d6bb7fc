// SPDX-License-Identifier: MIT
// Waiting for a file descriptor to become readable, shared by the serial and CAN drivers.
#define _GNU_SOURCE
#include "fd_wait.h"

#include <errno.h>
#include <poll.h>

int drv_fd_wait_readable(int fd, int timeout_ms) {
  struct pollfd pfd = {.fd = fd, .events = POLLIN, .revents = 0};
  for (;;) {
    const int rc = poll(&pfd, 1, timeout_ms);
    if (rc >= 0) {
      // POLLHUP (e.g. a pseudo-terminal whose other side closed) counts as readable so that the
      // next read returns the error.
      return rc > 0 ? 1 : 0;
    }
    if (errno != EINTR) {
      return -errno;
    }
  }
}
