// SPDX-License-Identifier: MIT
/// fw/io.h — The only window the loop core has on the world: a const table of platform
/// services plus a `void* user` (libcanard style). Three bindings implement it: the real drivers
/// of the onboard program (firmware/app), the emulator over pseudo-terminals / the seqpacket bus
/// (the same binding, other paths), and test doubles.
///
/// Levels: the laser is seen at the level of decoded scans (the binding runs the LMS200 host
/// driver, drivers/lms200.h, whose start-up state machine owns the serial line and its baud
/// switching); the base is seen at the byte level (rFLEX) or the frame level (CANopen), because
/// the core itself encodes every command and decodes every report, so that a run is a function
/// of (config, seed, input bytes).
///
/// Rules for implementations: every function is non-blocking except `wait`; none may be NULL
/// except where stated; return conventions as documented per member. The core calls them from
/// its single tick thread only.
#ifndef FW_IO_H
#define FW_IO_H

#include <proto/canopen.h>
#include <proto/lms200.h>

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Laser link counters for STATUS (monotonic).
typedef struct fw_laser_stats {
  uint64_t bytes_dropped;   ///< bytes the telegram decoder discarded
  uint64_t crc_errors;      ///< telegrams refused for a CRC mismatch
  uint64_t restarts;        ///< driver start-overs (timeouts, silence)
} fw_laser_stats_t;

/// CAN bus counters for STATUS (monotonic over reopens) and the host controller's state.
typedef struct fw_can_stats {
  uint64_t error_frames;    ///< error frames received: the bus signalled a failed frame and resent it
  bool bus_off;             ///< this host's CAN controller is bus-off (it sends and receives nothing)
} fw_can_stats_t;

/// Devices of fw_io_health_t (bit mask).
#define FW_IO_DEVICE_LASER 1U
#define FW_IO_DEVICE_BASE 2U

/// Capacity of a device-loss message, including the NUL.
#define FW_IO_DETAIL_MAX 160U

/// Health of the devices, reported once per tick.
typedef struct fw_io_health {
  uint32_t lost;           ///< FW_IO_DEVICE_* bits of the devices that are gone now
  uint32_t reopened;       ///< devices that came back since the last call: the core repeats their start-up
  uint32_t output_overflows; ///< commands the base's bounded output buffer refused since the last call
  char detail[FW_IO_DETAIL_MAX]; ///< when lost != 0: the first lost device, e.g. "laser device lost: /dev/ttyUSB0 (hang-up)"
} fw_io_health_t;

typedef struct fw_io_vtable {
  /// Monotonic clock [µs]. The core reads it at tick boundaries only and passes the value down.
  int64_t (*now_us)(void* user);

  /// Blocks until some device input may be readable or the monotonic time deadline_us passes.
  /// Returns 1 (input may be ready), 0 (deadline), < 0 (error). Spurious wake-ups are allowed.
  int (*wait)(void* user, int64_t deadline_us);

  /// Advances the laser driver with the caller's clock and returns the newest complete scan
  /// received since the last call: 1 (scan written to *out), 0 (none), < 0 (device error).
  int (*laser_poll)(void* user, int64_t now_us, lms_scan_t* out);

  /// Laser counters; may be NULL (then reported as 0).
  void (*laser_stats)(void* user, fw_laser_stats_t* out);

  /// Stops the laser stream (shutdown); may be NULL.
  void (*laser_stop)(void* user);

  /// rFLEX: reads up to cap pending bytes from the base: bytes read (≥ 0) or < 0 on error.
  /// NULL when the base speaks CANopen.
  ssize_t (*base_read)(void* user, uint8_t* buf, size_t cap);

  /// rFLEX: sends n bytes (one packet) to the base, paced as the device needs, without waiting:
  /// the binding queues what the line does not take at once. 0, or < 0 (-ENOBUFS: the bounded
  /// queue is full, counted in fw_io_health_t.output_overflows).
  int (*base_write)(void* user, const uint8_t* buf, size_t n);

  /// CANopen: receives one frame: 1 (frame), 0 (none pending), < 0 (error). NULL for rFLEX.
  int (*can_read)(void* user, canopen_frame_t* frame);

  /// CANopen: bus counters; may be NULL (then reported as 0).
  void (*can_stats)(void* user, fw_can_stats_t* out);

  /// CANopen: sends one frame without waiting (queued when the bus is busy): 0, or < 0 (-ENOBUFS:
  /// the bounded queue is full, counted in fw_io_health_t.output_overflows).
  int (*can_write)(void* user, const canopen_frame_t* frame);

  /// Asks for the robot to be placed at a start pose (task frame: metres, radians).
  /// Returns 1 when the pose is in effect now (emulator `reset`), 0 when a person must place the
  /// robot and confirm with B21R_COMMAND CONFIRM_START_POSE, 2 when the request is under way (the
  /// caller asks again, with the same pose, in later ticks until it gets 1 or an error), < 0 on
  /// error (retried later). May be NULL (= always 0, the operator places the robot).
  /// run: the id of the run about to start (B21R_RUN.run_id); an emulator restarts its sensor
  /// noise from it (see sim_emu_reset_run), a person placing the robot ignores it.
  int (*request_start_pose)(void* user, double x_m, double y_m, double theta_rad, uint64_t run);

  /// Device health at now_us, once per tick: lost devices (their descriptors closed, never polled
  /// again), devices reopened, output overflows. The binding reopens lost devices itself, with
  /// back-off, when `reopen` is true. May be NULL (devices are never lost).
  void (*health)(void* user, int64_t now_us, bool reopen, fw_io_health_t* out);
} fw_io_vtable_t;

/// A binding: the table and its context.
typedef struct fw_io {
  const fw_io_vtable_t* vt;
  void* user;
} fw_io_t;

#ifdef __cplusplus
}
#endif

#endif  // FW_IO_H
