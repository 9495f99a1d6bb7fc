// SPDX-License-Identifier: MIT
/// fw/publisher.h — The thread that drains the publisher queue: encodes each message, publishes
/// it on LCM and appends it to the optional LCM event logs. Everything slow (encoding, sockets,
/// disk) happens here, off the control tick.
///
/// Event logs are written in LCM's own log format (readable by lcm-logplayer, lcm.EventLog in
/// Python and tools/b21r_log.py). Event timestamps: in the full log (log_file), the wall clock
/// [µs since the Unix epoch] when the event was written, as lcm-logger does (the controller's
/// own time, simulated in lockstep, stays in each message's `utime`); in the experience log, the
/// message's `utime`, so that two identical lockstep runs give byte-identical experience logs.
/// The full log also records what the operator sent (fw_publisher_record), in arrival order.
#ifndef FW_PUBLISHER_H
#define FW_PUBLISHER_H

#include "fw/pubq.h"

#include <lcm/lcm.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct fw_publisher fw_publisher_t;

/// Where messages go. Every field may be NULL / "" to disable that output.
typedef struct fw_publisher_config {
  lcm_t* lcm;                       ///< borrowed; NULL = no LCM publishing
  const char* log_file;             ///< event log of every message
  const char* experience_log_file;  ///< event log of B21R_EXPERIENCE only
} fw_publisher_config_t;

/// Counters of the publisher thread; monotonic.
typedef struct fw_publisher_counters_s {
  uint64_t published;     ///< messages taken from the queue
  uint64_t lcm_errors;    ///< lcm_publish failures and messages that could not be encoded
  uint64_t log_errors;    ///< event-log write failures
  uint64_t recorded;      ///< events written by fw_publisher_record
} fw_publisher_counters_t;

/// Opens the logs and starts the thread over q (borrowed; q must outlive the publisher).
/// Returns NULL with a message in err on failure (e.g. a log file that cannot be created).
fw_publisher_t* fw_publisher_create(fw_pubq_t* q, const fw_publisher_config_t* cfg, char* err, size_t err_cap);

/// Producer side: wakes the thread after one or more fw_pubq_commit calls. Async-signal-safe,
/// never blocks (a POSIX semaphore post).
void fw_publisher_notify(fw_publisher_t* p);

/// Waits until the queue is empty and everything taken is written and flushed.
void fw_publisher_flush(fw_publisher_t* p);

/// Snapshot of the counters; lock-free (relaxed atomic loads), callable from any thread, also
/// from the tick. NULL gives zeros.
fw_publisher_counters_t fw_publisher_counters(const fw_publisher_t* p);

/// Writes one received message (already encoded, e.g. B21R_TELEOP from the LCM receive thread)
/// to the full log with the wall-clock timestamp. Any thread; takes the log's lock and writes to
/// the file (never call it from the tick). Nothing happens without a log_file or when p is NULL.
void fw_publisher_record(fw_publisher_t* p, const char* channel, const void* data, size_t size);

/// Wall clock [µs since the Unix epoch] (CLOCK_REALTIME), the timestamps of the full log.
int64_t fw_publisher_wall_us(void);

/// Drains the queue, closes the logs, stops the thread. NULL is ignored.
void fw_publisher_destroy(fw_publisher_t* p);

#ifdef __cplusplus
}
#endif

#endif  // FW_PUBLISHER_H
