// SPDX-License-Identifier: MIT
/// drivers/serial.h — Raw 8N1 serial port over a file descriptor (termios), with write pacing.
///
/// Works the same on /dev/ttyS*, USB adapters and pseudo-terminals (the emulator's devices):
/// raw mode, 8 data bits, no parity, 1 stop bit, no hardware or software flow control,
/// non-blocking reads. Baud rates: 9600, 19200, 38400, 57600, 115200, 230400, 500000.
///
/// Pacing: some devices lose bytes when fed too fast. The rFLEX wants about 1 ms after each
/// write chunk (drv_serial_set_pacing(p, 0, 1000, 0)); the LMS200 at 500 kBd wants >= 55 µs
/// between bytes (drv_serial_set_pacing(p, 0, 0, 55)). Pacing sleeps, so drv_serial_write()
/// blocks for about n × byte_gap_us + chunk_gap_us.
///
/// Output that must never wait (the base's commands inside a control tick) goes through the
/// port's bounded output queue instead: drv_serial_queue() appends one packet (a pacing chunk)
/// and writes what the line takes at once; drv_serial_flush() writes more when the descriptor
/// polls writable (POLLOUT) and the chunk gap has passed. A packet that does not fit is refused
/// whole and counted (out_overflows): the caller treats it as a fault of the device. The queue
/// honours chunk_gap_us (after each packet), not byte_gap_us.
///
/// Link mode (drivers/serial_link.h): the port's owner, the real-time control thread, makes
/// no system call on the terminal that can wait for the kernel. A terminal's poll() and read()
/// wait, whenever no input is buffered in the line discipline, for the kernel's work item that
/// moves received bytes out of the driver's flip buffer (n_tty_poll / n_tty_read call
/// tty_buffer_flush_work, i.e. flush_work on the port's buffer work). That work item runs on a
/// time-shared kernel worker (system_unbound_wq): on a loaded machine the real-time thread then
/// waits, in state D, for a worker that any time-shared process can hold back for hundreds of
/// milliseconds, and its priority does not help it (priority inversion). tcflush and tcsetattr
/// contend for the same buffer lock. A real UART (its interrupt pushes the flip buffer) and a
/// pseudo-terminal (the writer pushes it) behave alike. In link mode one helper thread per
/// device (drv_serial_link_start) opens and closes the descriptor, waits for input with poll(),
/// reads it into a lock-free ring the owner takes it from, and carries out the rate changes,
/// input flushes and paced request writes (drv_serial_write) in order; the owner still writes
/// its queued packets itself (drv_serial_queue / drv_serial_flush: a write() to a terminal does
/// not wait for that worker) and is told of new input by a callback.
///
/// Not thread-safe (except the link functions marked so). No allocation (except
/// drv_serial_link_create). Errors are returned as negative errno values, with a
/// human-readable message in the caller's buffer where a function takes one.
#ifndef DRIVERS_SERIAL_H
#define DRIVERS_SERIAL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#ifdef __cplusplus
extern "C" {
#endif

/// @name Line settings of the robot's devices (protocols.md A.1, B.1)
/// @{
#define DRV_SERIAL_RFLEX_BAUD 115200U           ///< rFLEX base controller.
#define DRV_SERIAL_RFLEX_CHUNK_GAP_US 1000U     ///< Pause after each write chunk to the rFLEX.
#define DRV_SERIAL_LMS_POWERUP_BAUD 9600U       ///< LMS200 after power-up.
#define DRV_SERIAL_LMS_500K_BYTE_GAP_US 55U     ///< Byte spacing to the LMS200 at 500 kBd.
/// @}

/// Counters of a serial port. Never decrease.
typedef struct drv_serial_counters {
  uint64_t bytes_read;
  uint64_t bytes_written;
  uint64_t read_errors;    ///< read() failures other than EAGAIN/EINTR.
  uint64_t write_errors;   ///< write() failures other than EAGAIN/EINTR, and write timeouts.
  uint64_t baud_changes;
  uint64_t out_overflows;  ///< packets refused by a full output queue.
} drv_serial_counters_t;

/// Capacity of the output queue [bytes] (about 170 ms of output at 115200 Bd) and [packets].
#define DRV_SERIAL_OUT_BYTES 2048U
#define DRV_SERIAL_OUT_PACKETS 64U

/// Bounded output queue: a byte ring and the lengths of its packets (the pacing chunks).
typedef struct drv_serial_out {
  uint8_t bytes[DRV_SERIAL_OUT_BYTES];
  uint32_t head;           ///< first unwritten byte
  uint32_t len;            ///< unwritten bytes
  uint16_t packet_len[DRV_SERIAL_OUT_PACKETS];
  uint32_t packet_head;    ///< first queued packet
  uint32_t packets;        ///< queued packets (the first may be partly written)
  uint32_t first_done;     ///< bytes of the first packet already written
  uint64_t quiet_until_us; ///< chunk gap: no byte before this time (monotonic clock)
} drv_serial_out_t;

/// A device's helper thread and the rings between it and the port's owner (link mode,
/// drivers/serial_link.h).
typedef struct drv_serial_link drv_serial_link_t;

/// What a port in link mode calls instead of the terminal: drv_serial_use_link (drivers/
/// serial_link.h) installs the link's own. take: up to cap input bytes, 0 when none, or the
/// link's error (< 0); *flushes is the port's count of input flushes applied. The rest are
/// requests to the helper thread: a paced write, an input flush, a rate change after the
/// output drained. Each returns 0 or a negative errno.
typedef struct drv_serial_link_ops {
  ssize_t (*take)(drv_serial_link_t* link, uint32_t* flushes, uint8_t* buf, size_t cap);
  int (*write)(drv_serial_link_t* link, const uint8_t* data, size_t n, uint32_t chunk_gap_us,
               uint32_t byte_gap_us);
  int (*flush_input)(drv_serial_link_t* link, uint32_t* flushes);
  int (*set_baud)(drv_serial_link_t* link, uint32_t baud);
} drv_serial_link_ops_t;

/// An open serial port. Fields are read-only for callers.
typedef struct drv_serial {
  int fd;                  ///< -1 when closed.
  bool owns_fd;            ///< drv_serial_close() closes fd.
  uint32_t baud;           ///< Current rate.
  uint32_t chunk_bytes;    ///< Pacing: bytes per chunk (0 = whole write is one chunk).
  uint32_t chunk_gap_us;   ///< Pacing: sleep after each chunk.
  uint32_t byte_gap_us;    ///< Pacing: minimum spacing between bytes (0 = none).
  int last_error;          ///< negative errno of the last failed read or write (0 = none).
  drv_serial_counters_t counters;
  drv_serial_out_t out;
  drv_serial_link_t* link; ///< link mode (NULL: the port calls the terminal itself).
  const drv_serial_link_ops_t* link_ops; ///< link mode: the link's calls.
  uint32_t link_flushes;   ///< link mode: input flushes of the helper thread applied to the ring.
} drv_serial_t;

/// True for the rates listed above. O(1).
bool drv_serial_baud_supported(uint32_t baud);

/// Opens `path` (O_RDWR | O_NOCTTY | O_NONBLOCK), sets raw 8N1 at `baud`, flushes both queues.
/// @return 0, or a negative errno (ENOENT, EACCES, ENOTTY for a non-terminal, EINVAL for an
///         unsupported baud) with a message naming the path and the cause in err (if not NULL).
int drv_serial_open(drv_serial_t* port, const char* path, uint32_t baud, char* err, size_t err_len);

/// Configures an already open terminal descriptor (e.g. a pseudo-terminal inherited from the
/// emulator) exactly as drv_serial_open() does and sets it non-blocking.
/// @param take_ownership if true, drv_serial_close() closes fd.
int drv_serial_attach(drv_serial_t* port, int fd, uint32_t baud, bool take_ownership, char* err,
                      size_t err_len);

/// Changes the line rate after the output queue has drained (tcdrain), as the LMS200 needs
/// after acknowledging a baud-change request. @return 0 or a negative errno.
int drv_serial_set_baud(drv_serial_t* port, uint32_t baud);

/// Sets write pacing (see file comment). O(1).
void drv_serial_set_pacing(drv_serial_t* port, uint32_t chunk_bytes, uint32_t chunk_gap_us,
                           uint32_t byte_gap_us);

/// Non-blocking read. @return bytes read (> 0), 0 when nothing is available, -EPIPE on a
/// hang-up (e.g. the other side of a pseudo-terminal has closed), or another negative errno.
ssize_t drv_serial_read(drv_serial_t* port, uint8_t* buf, size_t cap);

/// Writes all n bytes with pacing, waiting (poll) while the output queue is full, for at most
/// timeout_ms in total. @return 0, -ETIMEDOUT, or another negative errno.
int drv_serial_write(drv_serial_t* port, const uint8_t* data, size_t n, int timeout_ms);

/// Appends one packet to the output queue and writes what the line takes now; never waits.
/// now_us is CLOCK_MONOTONIC [µs]. @return 0, -ENOBUFS when the packet does not fit (nothing
/// queued, counted in out_overflows), -EINVAL, or a negative errno of the write (the device is gone
/// for EIO, EPIPE, ENODEV, ENXIO).
int drv_serial_queue(drv_serial_t* port, const uint8_t* data, size_t n, uint64_t now_us);

/// Writes queued output as far as the line and the chunk gap allow; never waits. Call when the
/// descriptor polls writable or the gap has passed. @return 0 or a negative errno of the write.
int drv_serial_flush(drv_serial_t* port, uint64_t now_us);

/// True while queued output remains. O(1).
bool drv_serial_out_pending(const drv_serial_t* port);

/// Waits until bytes are readable or timeout_ms passes (-1 = forever). @return 1 readable,
/// 0 timeout, negative errno.
int drv_serial_wait_readable(drv_serial_t* port, int timeout_ms);

/// Discards unread input (tcflush TCIFLUSH). @return 0 or a negative errno.
int drv_serial_flush_input(drv_serial_t* port);

/// Closes the descriptor if owned and discards queued output; the struct may be reopened
/// afterwards. Idempotent. In link mode the descriptor is not closed here: the port detaches
/// from the link, and the owner asks the helper thread to close it (drv_serial_link_close).
void drv_serial_close(drv_serial_t* port);


#ifdef __cplusplus
}
#endif

#endif  // DRIVERS_SERIAL_H
