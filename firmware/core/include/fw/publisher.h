// SPDX-License-Identifier: MIT
/// fw/publisher.h — The thread that drains the publisher queue: encodes each message, publishes
/// it on LCM and appends it to the optional LCM event logs. Everything slow (encoding, sockets,
/// disk) happens here, off the control tick.
///
/// Event logs are written in LCM's own log format (readable by lcm-logplayer, lcm.EventLog in
/// Python and tools/b21r_log.py) with the message's own `utime` as the event timestamp, so in
/// lockstep two identical runs give byte-identical experience logs.
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
  uint64_t lcm_errors;    ///< lcm_publish failures
  uint64_t log_errors;    ///< event-log write failures
} fw_publisher_counters_t;

/// Opens the logs and starts the thread over q (borrowed; q must outlive the publisher).
/// Returns NULL with a message in err on failure (e.g. a log file that cannot be created).
fw_publisher_t* fw_publisher_create(fw_pubq_t* q, const fw_publisher_config_t* cfg, char* err, size_t err_cap);

/// Producer side: wakes the thread after one or more fw_pubq_commit calls. Async-signal-safe,
/// never blocks (a POSIX semaphore post).
void fw_publisher_notify(fw_publisher_t* p);

/// Waits until the queue is empty and everything taken is written and flushed.
void fw_publisher_flush(fw_publisher_t* p);

fw_publisher_counters_t fw_publisher_counters(fw_publisher_t* p);

/// Drains the queue, closes the logs, stops the thread. NULL is ignored.
void fw_publisher_destroy(fw_publisher_t* p);

#ifdef __cplusplus
}
#endif

#endif  // FW_PUBLISHER_H
