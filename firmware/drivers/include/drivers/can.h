// SPDX-License-Identifier: MIT
/// drivers/can.h — CAN frame I/O over SocketCAN or over a local SOCK_SEQPACKET socket.
///
/// Two transports, one frame interface (canopen_frame_t from lib/proto):
/// - SocketCAN: a raw CAN_RAW socket bound to an interface name (`can0`, `vcan0`).
/// - Emulated bus: an AF_UNIX SOCK_SEQPACKET socket (named path or inherited descriptor) whose
///   every record is one Linux `struct can_frame` (16 bytes). The emulator serves the bus; the
///   record boundaries of SOCK_SEQPACKET keep frames whole.
/// Only standard 11-bit data frames are passed up; extended and RTR frames are counted and
/// dropped, error frames (SocketCAN: enabled with CAN_RAW_ERR_FILTER) counted apart. On a kernel without CAN support opening an interface fails with a message that
/// says so (and suggests the emulated bus).
///
/// Not thread-safe. No allocation. Negative errno values on failure.
#ifndef DRIVERS_CAN_H
#define DRIVERS_CAN_H

#include <proto/canopen.h>

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

struct can_frame;

typedef enum drv_can_transport {
  DRV_CAN_SOCKETCAN = 0,  ///< PF_CAN / CAN_RAW socket.
  DRV_CAN_SEQPACKET,      ///< AF_UNIX SOCK_SEQPACKET carrying struct can_frame records.
} drv_can_transport_t;

/// Counters of a CAN port. Never decrease.
typedef struct drv_can_counters {
  uint64_t frames_tx;
  uint64_t frames_rx;
  uint64_t rx_dropped_kind;   ///< Extended or RTR frames received and dropped.
  uint64_t rx_error_frames;   ///< Error frames received (failed CRCs, bus errors: the bus resent the frame; bus-off, restart).
  uint64_t bus_off_events;    ///< Times this host's controller reported going bus-off.
  uint64_t rx_bad_size;       ///< Records that were not one struct can_frame (empty ones too), or DLC > 8.
  uint64_t tx_would_block;    ///< Sends refused because the socket buffer was full.
  uint64_t errors;            ///< Other send/receive failures.
} drv_can_counters_t;

/// An open CAN port. Fields are read-only for callers.
typedef struct drv_can {
  int fd;                     ///< -1 when closed.
  bool owns_fd;
  drv_can_transport_t transport;
  drv_can_counters_t counters;
  bool bus_off;               ///< The controller reported bus-off and no restart or frame since.
} drv_can_t;

/// Opens a raw SocketCAN socket bound to `ifname` (non-blocking).
/// @return 0; -EAFNOSUPPORT when the kernel has no CAN support (message says so); -ENODEV when
///         the interface does not exist; other negative errno. Message in err when not NULL.
int drv_can_open_socketcan(drv_can_t* port, const char* ifname, char* err, size_t err_len);

/// Connects to the emulated bus at `path` (AF_UNIX, SOCK_SEQPACKET, non-blocking).
/// @return 0 or a negative errno with a message.
int drv_can_open_seqpacket(drv_can_t* port, const char* path, char* err, size_t err_len);

/// Uses an inherited descriptor (e.g. one end of socketpair(AF_UNIX, SOCK_SEQPACKET)); sets it
/// non-blocking. @return 0 or a negative errno.
int drv_can_attach(drv_can_t* port, int fd, drv_can_transport_t transport, bool take_ownership);

/// Opens a listening SOCK_SEQPACKET socket at `path` (removing a stale socket file first) for
/// a bus server such as the emulator. @return the listening descriptor, or a negative errno.
int drv_can_seqpacket_listen(const char* path, int backlog, char* err, size_t err_len);

/// Sends one frame (non-blocking). @return 0, -EAGAIN when the socket buffer is full (counted),
/// -EINVAL for an invalid frame (id > 0x7FF or dlc > 8), or another negative errno.
int drv_can_send(drv_can_t* port, const canopen_frame_t* frame);

/// Receives one frame if available (non-blocking). Dropped kinds are skipped (counted) and the
/// next record is tried. @return 1 frame written, 0 nothing available, -EPIPE when the peer of
/// an emulated bus has closed, or another negative errno.
int drv_can_recv(drv_can_t* port, canopen_frame_t* frame);

/// Waits until a record is readable or timeout_ms passes (-1 = forever).
/// @return 1 readable, 0 timeout, negative errno.
int drv_can_wait_readable(drv_can_t* port, int timeout_ms);

/// Closes the descriptor if owned. Idempotent.
void drv_can_close(drv_can_t* port);

/// Converts to / from the kernel's frame layout (used on both transports). to_linux returns
/// -EINVAL for an invalid frame; from_linux returns -EINVAL for extended/RTR/error frames or a
/// DLC > 8 and leaves *out unspecified. O(1).
int drv_can_to_linux(const canopen_frame_t* in, struct can_frame* out);
int drv_can_from_linux(const struct can_frame* in, canopen_frame_t* out);

#ifdef __cplusplus
}
#endif

#endif  // DRIVERS_CAN_H
