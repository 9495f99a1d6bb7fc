// SPDX-License-Identifier: MIT
/// fw/pubq.h — Bounded single-producer/single-consumer queue of outgoing messages, so that the
/// control tick hands messages to a publisher thread without ever blocking or allocating.
///
/// The tick (producer) reserves a slot, fills the message in place and commits it. When the
/// queue is full, reserve returns NULL and the message is dropped and counted (per kind): a slow
/// network or disk costs messages, never a late command. Because experiences carry a global
/// sequence number assigned by the producer, a recorder sees every drop as a gap.
///
/// Memory: capacity × sizeof(fw_msg_t) bytes allocated once by fw_pubq_create (about 2.5 kB per
/// slot, dominated by the optional scan). Thread-safety: exactly one producer thread and one
/// consumer thread; C11 acquire/release atomics on the two indices, no locks.
#ifndef FW_PUBQ_H
#define FW_PUBQ_H

#include <b21r/b21r_config_t.h>
#include <b21r/b21r_eval_t.h>
#include <b21r/b21r_experience_t.h>
#include <b21r/b21r_pose_t.h>
#include <b21r/b21r_run_t.h>
#include <b21r/b21r_scan_t.h>
#include <b21r/b21r_status_t.h>

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Message kinds, one per B21R_* channel the controller publishes.
typedef enum fw_msg_kind {
  FW_MSG_EXPERIENCE = 0,  ///< B21R_EXPERIENCE
  FW_MSG_STATUS = 1,      ///< B21R_STATUS
  FW_MSG_POSE = 2,        ///< B21R_POSE
  FW_MSG_EVAL = 3,        ///< B21R_EVAL
  FW_MSG_SCAN = 4,        ///< B21R_SCAN
  FW_MSG_TEXT = 5,        ///< a line for stdout (progress) or stderr (log); not on LCM
  FW_MSG_CONFIG = 6,      ///< B21R_CONFIG (its text points at storage that outlives the queue)
  FW_MSG_RUN = 7,         ///< B21R_RUN (its detail points at a static string)
  FW_MSG_KIND_COUNT = 8
} fw_msg_kind_t;

/// Capacity of STATUS's stop_detail text carried in a slot, including the NUL.
#define FW_STATUS_DETAIL_MAX 160U
/// Capacity of a FW_MSG_TEXT line, including the NUL.
#define FW_TEXT_MAX 240U

/// One queued message. For STATUS, msg.stop_detail is set by the consumer to point at `detail`.
typedef struct fw_msg {
  int32_t kind;  ///< fw_msg_kind_t
  union {
    b21r_experience_t experience;
    struct {
      b21r_status_t msg;
      char detail[FW_STATUS_DETAIL_MAX];
    } status;
    b21r_pose_t pose;
    b21r_eval_t eval;
    b21r_scan_t scan;
    b21r_config_t config;
    b21r_run_t run;
    struct {
      int32_t stream;  ///< 1 = stdout, 2 = stderr
      char line[FW_TEXT_MAX];  ///< without the trailing newline
    } text;
  } u;
} fw_msg_t;

/// LCM channel name of a kind ("B21R_EXPERIENCE", ...), or "" for FW_MSG_TEXT and invalid kinds.
const char* fw_msg_channel(int32_t kind);

typedef struct fw_pubq fw_pubq_t;

/// Creates a queue of `capacity` slots (a power of two, ≥ 2). Allocates once; NULL on a bad
/// capacity or out of memory.
fw_pubq_t* fw_pubq_create(uint32_t capacity);
void fw_pubq_destroy(fw_pubq_t* q);

/// Maps every page of the slots now (fw/prefault.h). Start-up only, before the threads use q.
void fw_pubq_prefault(fw_pubq_t* q);

/// Producer: a free slot to fill in place, or NULL when the queue is full (the drop is counted
/// under kind). The slot's `kind` is set. O(1), wait-free, no allocation.
fw_msg_t* fw_pubq_reserve(fw_pubq_t* q, fw_msg_kind_t kind);
/// Producer: publishes the slot returned by the last successful reserve. O(1), wait-free.
void fw_pubq_commit(fw_pubq_t* q);

/// Consumer: the oldest committed message, or NULL when empty. O(1), wait-free.
const fw_msg_t* fw_pubq_peek(fw_pubq_t* q);
/// Consumer: frees the slot returned by the last peek. O(1), wait-free.
void fw_pubq_pop(fw_pubq_t* q);

/// Messages dropped because the queue was full: of one kind, or in total (kind < 0).
/// Monotonic; readable from any thread.
uint64_t fw_pubq_drops(const fw_pubq_t* q, int32_t kind);
/// Messages committed so far (monotonic).
uint64_t fw_pubq_committed(const fw_pubq_t* q);
/// Committed messages not yet popped (a snapshot).
uint32_t fw_pubq_depth(const fw_pubq_t* q);
uint32_t fw_pubq_capacity(const fw_pubq_t* q);

#ifdef __cplusplus
}
#endif

#endif  // FW_PUBQ_H
