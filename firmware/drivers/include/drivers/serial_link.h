// SPDX-License-Identifier: MIT
/// drivers/serial_link.h — Link mode of a serial port: one helper thread per device owns the
/// terminal's descriptor (why: drivers/serial.h, "Link mode"), and the port's owner, the
/// real-time control thread, takes the input from a lock-free ring and hands the writes that
/// may wait to the helper as requests.
///
/// Built on the plain port (drivers/serial.h): the helper thread opens, writes and changes the
/// rate through it; a port in link mode calls the link through the drv_serial_link_ops_t that
/// drv_serial_use_link installs. Not thread-safe except where a function says so. Allocates
/// only in drv_serial_link_create.
#ifndef DRIVERS_SERIAL_LINK_H
#define DRIVERS_SERIAL_LINK_H

#include <drivers/serial.h>

#ifdef __cplusplus
extern "C" {
#endif

/// @name Link mode
/// The owner (one thread) calls drv_serial_link_open / _close / _state and the drv_serial_*
/// functions of a port in link mode; the helper thread (drv_serial_link_start) runs the rest;
/// nothing else touches the link. Sizes: input ring DRV_SERIAL_LINK_RX_BYTES, DRV_SERIAL_LINK_OPS requests of
/// at most DRV_SERIAL_LINK_OP_BYTES bytes each.
/// @{
#define DRV_SERIAL_LINK_RX_BYTES 65536U  ///< about 1.3 s of input at 500 kBd
#define DRV_SERIAL_LINK_OPS 16U
#define DRV_SERIAL_LINK_OP_BYTES 128U

/// State of a link's descriptor (drv_serial_link_state).
typedef enum drv_serial_link_state {
  DRV_SERIAL_LINK_CLOSED = 0,   ///< no descriptor
  DRV_SERIAL_LINK_OPENING = 1,  ///< an open request is under way
  DRV_SERIAL_LINK_OPEN = 2,     ///< open (a hang-up or I/O error shows as the link's error)
  DRV_SERIAL_LINK_FAILED = 3,   ///< the last open failed (drv_serial_link_state's *error and message)
} drv_serial_link_state_t;

/// Creates a link (the input ring and the request slots, allocated here once) whose helper
/// thread calls notify(user) after input arrived, an error appeared, the state changed or a
/// request finished (from the helper thread; it must not block, e.g. an eventfd write).
/// NULL when out of memory or the wake-up descriptor cannot be made.
drv_serial_link_t* drv_serial_link_create(void (*notify)(void* user), void* user);

/// Stops the helper thread (drv_serial_link_stop), then frees. NULL is ignored.
void drv_serial_link_destroy(drv_serial_link_t* link);

/// Starts the helper thread (time-shared; drv_serial_link_set_scheduler changes that).
/// @return 0 or a negative errno.
int drv_serial_link_start(drv_serial_link_t* link);

/// Gives the helper thread a scheduling policy (SCHED_FIFO, SCHED_RR, SCHED_OTHER) and priority.
/// @return 0 or a negative errno (EPERM without the privilege).
int drv_serial_link_set_scheduler(drv_serial_link_t* link, int policy, int priority);

/// Ends the helper thread (it closes the descriptor) and waits for it. Idempotent.
void drv_serial_link_stop(drv_serial_link_t* link);

/// Owner: asks the helper thread to open path at baud (raw 8N1, as drv_serial_open), closing a
/// descriptor it still holds first. Never waits; the result shows in drv_serial_link_state.
void drv_serial_link_open(drv_serial_link_t* link, const char* path, uint32_t baud);

/// Owner: asks the helper thread to close the descriptor. Never waits. The owner must not use
/// the descriptor (its port) any more: detach the port first (drv_serial_close).
void drv_serial_link_close(drv_serial_link_t* link);

/// Owner: the link's state; with DRV_SERIAL_LINK_OPEN *fd receives the descriptor (for the
/// owner's own writes), with DRV_SERIAL_LINK_FAILED *error the open's negative errno and msg (if
/// not NULL, capacity msg_cap) its message. O(1), a short lock.
drv_serial_link_state_t drv_serial_link_state(drv_serial_link_t* link, int* fd, int* error, char* msg,
                                              size_t msg_cap);

/// Owner: puts port in link mode on link's open descriptor (as drv_serial_attach would set it up,
/// at the rate of the open): reads take the input ring, drv_serial_write / _set_baud /
/// _flush_input become requests to the helper thread, drv_serial_queue / _flush write the
/// descriptor directly. Input that arrived before is dropped. @return 0, or -ENOTCONN when the
/// link is not open.
int drv_serial_use_link(drv_serial_t* port, drv_serial_link_t* link);

/// Owner: true while requests (writes, rate changes, flushes) wait for the helper thread.
bool drv_serial_link_busy(drv_serial_link_t* link);

/// Counters of the helper thread's side (never decrease; a short lock).
typedef struct drv_serial_link_counters_s {
  uint64_t bytes_in;        ///< bytes read into the input ring
  uint64_t rx_full;         ///< times the input ring was full (input left in the kernel meanwhile)
  uint64_t requests;        ///< requests carried out
  uint64_t requests_refused;///< requests refused: no free slot, too long, or the link not open
  uint64_t opens;           ///< successful opens
  uint64_t open_failures;
} drv_serial_link_counters_t;
drv_serial_link_counters_t drv_serial_link_counters(drv_serial_link_t* link);
/// @}

#ifdef __cplusplus
}
#endif

#endif  // DRIVERS_SERIAL_LINK_H
