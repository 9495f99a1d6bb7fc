// SPDX-License-Identifier: MIT
/// io_posix.h — The onboard binding of the loop's I/O table: the LMS200 host driver on a serial
/// line, the rFLEX serial line or the CAN bus (SocketCAN or the emulator's seqpacket bus), the
/// emulator's control socket for repositioning, poll() for waiting and CLOCK_MONOTONIC.
/// The same binding drives the real robot and the emulated one (other device paths).
///
/// Nothing here waits inside a tick, and the tick thread makes no system call on a terminal that
/// can wait for the kernel's tty worker (drivers/serial.h, link mode): each serial device (the
/// laser, the rFLEX base) has a helper thread that opens and closes it, reads its input into a
/// ring, and carries out the laser driver's rate changes, input flushes and paced requests; it
/// wakes the tick thread through an eventfd. The tick writes the base's commands itself (a
/// write() to a terminal does not wait for that worker) from a bounded queue paced by timers,
/// never by poll(); CAN frames go through a frame ring drained when the socket polls POLLOUT (a
/// socket's poll does not involve the tty worker). A start-pose request is sent and its answer
/// collected in later ticks (lockstep excepted: there the tick waits for the emulator anyway).
/// A device that reports end of file, EIO, ENODEV or a hang-up is lost: its descriptor is
/// closed at once (by its helper thread; nothing polls a dead line), the loss is reported
/// through `health`, and the device is reopened after a back-off that doubles up to a limit
/// (the helper opens it; the tick sees the result in a later tick).
#ifndef B21R_APP_IO_POSIX_H
#define B21R_APP_IO_POSIX_H

#include "fw/config.h"
#include "fw/io.h"

#include <drivers/can.h>
#include <drivers/lms200.h>
#include <drivers/serial_link.h>

#include <signal.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/// Frames waiting for room in the CAN socket (about 5 ticks of the cyclic traffic).
#define IO_POSIX_CAN_OUT 32U

/// Loss and reopening of one device.
typedef struct io_posix_device {
  const char* what;               ///< "laser", "base", "CAN bus"
  const char* path;               ///< in the configuration (borrowed)
  bool lost;
  bool opening;                   ///< a reopen is under way (serial: the helper thread opens it)
  bool reopened;                  ///< since the last health report
  int64_t retry_at_us;            ///< next reopen attempt
  int64_t backoff_us;             ///< wait after the next failed attempt
  uint64_t losses;
  uint64_t reopens;
  char cause[64];                 ///< of the loss ("hang-up", "EIO", ...)
} io_posix_device_t;

typedef struct io_posix {
  const fw_config_t* cfg;         ///< borrowed; outlives the binding
  int tick_fd;                    ///< eventfd: a helper thread has news for the tick (-1: none)
  drv_serial_link_t* laser_link;  ///< the laser line's helper thread
  drv_serial_link_t* base_link;   ///< the rFLEX line's helper thread (NULL on CANopen)
  drv_serial_t laser_port;
  drv_lms_config_t lms_config;
  drv_lms_t lms;
  // The laser driver's counters of its earlier opens: a reopen starts a new driver, and the
  // status counters built on them never go back (status_t: monotonic while the process runs).
  fw_laser_stats_t laser_before;
  fw_can_stats_t can_before;      ///< the CAN port's counters of its earlier opens (same reason)
  drv_serial_t base_port;
  drv_can_t can;
  bool use_can;
  io_posix_device_t laser;
  io_posix_device_t base;
  canopen_frame_t can_out[IO_POSIX_CAN_OUT];  ///< frames the socket did not take yet (ring)
  uint32_t can_out_head;
  uint32_t can_out_n;
  uint64_t overflows;             ///< packets or frames the full output queues refused
  uint64_t overflows_reported;
  int control_fd;                 ///< emulator control socket, -1 when none
  bool request_pending;           ///< a `reset` was sent, its answer not yet read
  double request_pose[3];
  int64_t request_sent_us;
  uint32_t stale_replies;         ///< answers of timed-out requests still to be discarded
  volatile sig_atomic_t woken;    ///< io_posix_wake() came (a stop signal): waits end, for good
  bool tick_note_taken;           ///< a wait other than v_wait read a helper's notification: the
                                  ///< next v_wait returns at once instead of sleeping on it
} io_posix_t;

/// Prepares the binding for cfg (borrowed: it must outlive io) without touching any device.
void io_posix_init(io_posix_t* io, const fw_config_t* cfg);

/// Opens every device named by the configuration. Returns 0, or -1 with a message naming the
/// device and the cause (and, for CAN on a kernel without it, the emulated-bus alternative).
int io_posix_open(io_posix_t* io, char* err, size_t err_cap);

/// The binding for fw_loop_create.
fw_io_t io_posix_binding(io_posix_t* io);

/// Real-time scheduling for the helper threads: policy (SCHED_FIFO, SCHED_RR) at priority, one
/// below the tick thread's. Returns 0, or -1 with a message.
int io_posix_realtime(io_posix_t* io, int policy, int priority, char* err, size_t err_cap);

void io_posix_close(io_posix_t* io);

/// A stop signal came: the tick thread's waits end now and for the rest of the process (the
/// binding's wait() returns; a lockstep start-pose request stops awaiting its answer and reports
/// it under way). Async-signal-safe (a flag and one write to an eventfd), for a signal handler on
/// any thread; the eventfd write is skipped before io_posix_open. Not concurrently with
/// io_posix_close (the handler's caller clears its pointer first).
void io_posix_wake(io_posix_t* io);

/// Monotonic clock [µs].
int64_t io_posix_now_us(void);

#endif  // B21R_APP_IO_POSIX_H
