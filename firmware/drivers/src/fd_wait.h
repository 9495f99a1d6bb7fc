// SPDX-License-Identifier: MIT
// Internal: waiting for a file descriptor to become readable, shared by the serial and CAN drivers.
#ifndef DRIVERS_FD_WAIT_H
#define DRIVERS_FD_WAIT_H

/// poll() for POLLIN on fd, retrying after EINTR. timeout_ms < 0 waits forever.
/// Returns 1 readable (or hung up: the next read reports it), 0 on timeout, -errno on error.
int drv_fd_wait_readable(int fd, int timeout_ms);

#endif  // DRIVERS_FD_WAIT_H
