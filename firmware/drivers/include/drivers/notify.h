// SPDX-License-Identifier: MIT
/// drivers/notify.h — Readiness and watchdog notifications to the service manager (systemd's
/// sd_notify protocol: one datagram of "KEY=VALUE" lines to the AF_UNIX socket named by
/// $NOTIFY_SOCKET; the watchdog interval from $WATCHDOG_USEC for the process in $WATCHDOG_PID).
///
/// Why not libsystemd's sd_notify(): it makes a new socket and four socket-option calls per
/// message and then sends with a blocking sendmsg(), which waits as long as the receiver's queue
/// is full. The watchdog ping comes from the tick thread, which must never wait: here the socket
/// is made once, at start-up, non-blocking, and each message is one sendto() with MSG_DONTWAIT
/// (a full queue is counted and the ping is tried again at the next tick). The protocol is the
/// stable, documented one of sd_notify(3) (named and abstract sockets, "@" for the latter).
///
/// Use: drv_notify_open() from the environment at start-up; drv_notify_ready() once the devices
/// are open and the first tick is done; drv_notify_tick() after every tick's command has been
/// sent (pings at half the watchdog interval, as sd_watchdog_enabled(3) recommends);
/// drv_notify_stopping() before the orderly shutdown. Without $NOTIFY_SOCKET every call is a
/// no-op returning 0. Not thread-safe (one thread: the tick's). No allocation. Linux only.
#ifndef DRIVERS_NOTIFY_H
#define DRIVERS_NOTIFY_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/socket.h>
#include <sys/types.h>
#include <sys/un.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Counters; never decrease.
typedef struct drv_notify_counters {
  uint64_t sent;           ///< messages the socket took
  uint64_t pings;          ///< of those, WATCHDOG=1
  uint64_t would_block;    ///< messages refused because the receiver's queue was full (retried)
  uint64_t errors;         ///< other send failures (the receiver is gone, ...)
} drv_notify_counters_t;

/// The notification channel. Fields are read-only for callers.
typedef struct drv_notify {
  int fd;                       ///< -1 when there is no service manager to notify
  struct sockaddr_un addr;      ///< $NOTIFY_SOCKET ('@' turned into the abstract namespace's NUL)
  socklen_t addr_len;
  int64_t watchdog_us;          ///< the manager's watchdog interval [µs]; 0 = no watchdog
  int64_t next_ping_us;         ///< monotonic time of the next ping [µs]
  bool ready;                   ///< READY=1 was sent
  drv_notify_counters_t counters;
} drv_notify_t;

/// Opens the channel from the environment's values (pass getenv("NOTIFY_SOCKET"),
/// getenv("WATCHDOG_USEC"), getenv("WATCHDOG_PID"); NULL = unset) for process `self`:
/// - notify_socket NULL or empty: no manager (fd -1, every call a no-op);
/// - an absolute path or "@name" (abstract): a non-blocking datagram socket is made;
/// - watchdog_usec: a positive decimal count of µs, used when watchdog_pid is unset or equals
///   self (else the variables were meant for another process and are ignored, as
///   sd_watchdog_enabled(3) does). A watchdog without a notification socket is an error.
/// @return 0, or -EINVAL with a message naming the variable, its value and what it must be
///         (nothing is opened then), or another negative errno from socket().
int drv_notify_open(drv_notify_t* n, const char* notify_socket, const char* watchdog_usec, const char* watchdog_pid,
                    pid_t self, char* err, size_t err_len);

/// Sends one message ("KEY=VALUE" lines) without waiting. @return 0 (sent, or no manager),
/// -EAGAIN when the receiver's queue is full, -EINVAL for a message over 4 KiB, or another
/// negative errno (counted). O(message length).
int drv_notify_send(drv_notify_t* n, const char* message);

/// "READY=1" with "STATUS=<status>" (status may be NULL), and starts the watchdog's schedule at
/// now_us (the first ping is due half an interval later). @return as drv_notify_send.
int drv_notify_ready(drv_notify_t* n, int64_t now_us, const char* status);

/// After a tick's command: sends "WATCHDOG=1" when READY=1 was sent, the manager asked for a
/// watchdog and now_us has reached the next ping (then due half an interval after now_us; a
/// refused ping stays due). @return 1 when a ping was sent, 0 when none was due, < 0 as
/// drv_notify_send. One sendto() at most, never blocks. O(1).
int drv_notify_tick(drv_notify_t* n, int64_t now_us);

/// "STOPPING=1" with "STATUS=<status>" (may be NULL): the orderly shutdown begins (the
/// manager stops watching the watchdog). @return as drv_notify_send.
int drv_notify_stopping(drv_notify_t* n, const char* status);

/// Closes the socket. Safe after any drv_notify_open(), whatever it returned, and twice.
void drv_notify_close(drv_notify_t* n);

#ifdef __cplusplus
}
#endif

#endif  // DRIVERS_NOTIFY_H
