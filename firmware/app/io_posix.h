// SPDX-License-Identifier: MIT
/// io_posix.h — The onboard binding of the loop's I/O table: the LMS200 host driver on a serial
/// line, the rFLEX serial line or the CAN bus (SocketCAN or the emulator's seqpacket bus), the
/// emulator's control socket for repositioning, poll() for waiting and CLOCK_MONOTONIC.
/// The same binding drives the real robot and the emulated one (other device paths).
#ifndef B21R_APP_IO_POSIX_H
#define B21R_APP_IO_POSIX_H

#include "fw/config.h"
#include "fw/io.h"

#include <drivers/can.h>
#include <drivers/lms200.h>
#include <drivers/serial.h>

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

typedef struct io_posix {
  drv_serial_t laser_port;
  drv_lms_t lms;
  drv_serial_t base_port;
  drv_can_t can;
  bool use_can;
  int control_fd;                 ///< emulator control socket, -1 when none
  int reset_timeout_ms;
  char control_path[FW_CONFIG_STR_MAX];
} io_posix_t;

/// Opens every device named by cfg. Returns 0, or -1 with a message naming the device and the
/// cause (and, for CAN on a kernel without it, the emulated-bus alternative).
int io_posix_open(io_posix_t* io, const fw_config_t* cfg, char* err, size_t err_cap);

/// The binding for fw_loop_create.
fw_io_t io_posix_binding(io_posix_t* io);

void io_posix_close(io_posix_t* io);

/// Monotonic clock [µs].
int64_t io_posix_now_us(void);

#endif  // B21R_APP_IO_POSIX_H
