// SPDX-License-Identifier: MIT
/// drivers/lms200.h — SICK LMS200 host driver: connect, baud switch, variant, streaming scans.
///
/// A non-blocking state machine over a drv_serial_t, advanced by drv_lms_step() once per loop
/// iteration with the caller's clock (it reads no clock itself). Sequence (after Player's
/// sicklms200 start-up, protocols.md B.4), each request answered by a reply telegram (an ACK
/// byte before it is accepted and ignored):
///  1. CONNECT: for each probe rate (9600, then the target rate, then the others) set the local
///     rate, flush input, send "stop streaming" `20 25`, wait for reply 0xA0.
///  2. BAUD (only if not already at the target): send `20 40|41|42|48`, wait for 0xA0, then
///     switch the local rate (the reply comes at the old rate).
///  3. TYPE: `3A` -> 0xBA (the type string is kept).
///  4. INSTALL: `20 00 SICK_LMS` -> 0xA0 result 0.
///  5. VARIANT: `3B width res` -> 0xBB accepted = 1.
///  6. CONFIG: `74` -> 0xF4; if a unit is requested and differs, `77 ...` -> 0xF7.
///  7. START: `20 24` -> 0xA0; then STREAMING: every 0xB0 telegram becomes a scan.
/// A timeout or NAK retries the request (max_retries), then starts over at CONNECT; silence
/// while streaming longer than stream_timeout_us starts over too. The driver never gives up:
/// the control loop sees "no scan" and applies its own laser-silence safety rule.
///
/// Memory: one lms_decoder_t inside (about 850 bytes); the caller owns the scan buffer.
/// No allocation. Not thread-safe.
#ifndef DRIVERS_LMS200_H
#define DRIVERS_LMS200_H

#include <drivers/serial.h>
#include <proto/lms200.h>

#include <stdbool.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Driver configuration; drv_lms_config_default() gives the values in brackets.
typedef struct drv_lms_config {
  uint32_t target_baud;        ///< 9600, 19200, 38400 or 500000 [38400].
  uint16_t width_deg;          ///< 180 or 100 [180].
  uint16_t res_cdeg;           ///< 100, 50 or 25 (0.01°) [100 = 1°, 181 beams, about 10 Hz at 38400].
  int unit;                    ///< LMS_UNIT_CM, LMS_UNIT_MM, or -1 to keep the device's [-1].
  unsigned distance_bits;      ///< Distance bits of the measuring mode: 13, 14 or 15 [13].
  char password[LMS_PASSWORD_BYTES + 1];  ///< Installation password ["SICK_LMS"].
  uint32_t reply_timeout_us;   ///< Wait for an ordinary reply [1 000 000].
  uint32_t mode_timeout_us;    ///< Wait for a mode-change reply [3 000 000].
  uint32_t stream_timeout_us;  ///< Silence while streaming before starting over [1 000 000].
  uint8_t max_retries;         ///< Retries of one request before starting over [2].
} drv_lms_config_t;

typedef enum drv_lms_state {
  DRV_LMS_CONNECT = 0,
  DRV_LMS_BAUD,
  DRV_LMS_TYPE,
  DRV_LMS_INSTALL,
  DRV_LMS_VARIANT,
  DRV_LMS_CONFIG_READ,
  DRV_LMS_CONFIG_WRITE,
  DRV_LMS_START,
  DRV_LMS_STREAMING,
} drv_lms_state_t;

/// Counters. Never decrease.
typedef struct drv_lms_counters {
  uint64_t scans;              ///< Scans returned to the caller.
  uint64_t scans_superseded;   ///< Scans replaced by a newer one within the same step.
  uint64_t scan_errors;        ///< 0xB0 telegrams that did not parse (counted, skipped).
  uint64_t timeouts;           ///< Requests that timed out.
  uint64_t naks;               ///< NAK bytes or 0x92 replies.
  uint64_t restarts;           ///< Returns to CONNECT (after retries or stream silence).
  uint64_t connects;           ///< Successful CONNECT steps.
  uint64_t io_errors;          ///< Serial read/write failures.
} drv_lms_counters_t;

/// Driver state. Read-only for callers except through the functions below.
typedef struct drv_lms {
  drv_lms_config_t config;
  drv_serial_t* port;          ///< Not owned.
  lms_decoder_t decoder;
  drv_lms_state_t state;
  bool waiting;                ///< A request is outstanding.
  uint64_t deadline_us;        ///< When the outstanding request (or the stream) times out.
  uint8_t retries;
  uint8_t probe_index;
  uint32_t line_baud;          ///< Rate both sides use now.
  char type[LMS_TYPE_MAX_CHARS + 1];  ///< Type string from 0xBA ("" until read).
  lms_config_t device_config;  ///< Last configuration read.
  drv_lms_counters_t counters;
} drv_lms_t;

/// Fills the defaults listed in drv_lms_config_t. O(1).
void drv_lms_config_default(drv_lms_config_t* cfg);

/// Binds the driver to an open port (any rate; the driver sets rates itself) and starts at
/// CONNECT. @return 0, or -EINVAL for NULL pointers, an unsupported target rate, variant,
/// unit or distance bits.
int drv_lms_init(drv_lms_t* drv, drv_serial_t* port, const drv_lms_config_t* cfg);

/// Advances the state machine: reads every available byte (bounded by 64 KiB per call), handles
/// replies, sends the next request when due, applies timeouts. When one or more scans arrived,
/// the newest is written to *scan and *got_scan is set. Never blocks longer than writing one
/// short request (< 20 bytes). @return the state after the step.
drv_lms_state_t drv_lms_step(drv_lms_t* drv, uint64_t now_us, lms_scan_t* scan, bool* got_scan);

/// Forces a start-over at CONNECT (e.g. after the caller detected laser silence). O(1).
void drv_lms_restart(drv_lms_t* drv);

/// Sends "stop streaming" (for shutdown). @return 0 or a negative errno.
int drv_lms_stop_stream(drv_lms_t* drv);

/// Short state name ("streaming", ...), never NULL.
const char* drv_lms_state_name(drv_lms_state_t state);

#ifdef __cplusplus
}
#endif

#endif  // DRIVERS_LMS200_H
