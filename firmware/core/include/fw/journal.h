// SPDX-License-Identifier: MIT
/// fw/journal.h — The journal of finished runs: a run is on disk before the controller reports
/// it done, without waiting for the next checkpoint.
///
/// A checkpoint (fw/checkpoint.h) holds the learned state after a training run's between-run
/// work (the backward replay), which takes minutes on the robot; a kill meanwhile would lose a run
/// already reported done. So every run that ends (training or evaluation, finished or aborted) is
/// appended to `<checkpoint_file>.journal` and the file synced before the run's record, its
/// progress lines and its evaluation block are published: the run's outcome, and for a training
/// run every transition it learned, in order. On resume the controller loads the checkpoint and
/// then the journal's runs that follow it (consecutive run ids, each the run the schedule plans
/// next): each training run's transitions are learned again through the learning framework's
/// offline calls, which do exactly the updates the run did online, then its between-run work,
/// and the schedule counts every run as it did. A checkpoint that covers the journal's runs
/// empties the journal.
///
/// Record layout (integers little-endian, doubles IEEE-754 binary64):
/// ```
///  0  4  magic "B21J"            4  4  format version (1)
///  8  4  body size B             12  4  CRC-32 of the body (fw_crc32)
/// 16  B  body:
///      0  4  run id              4  4  kind (learn_run_kind_t)
///      8  4  phase              12  4  training index      16  4  evaluation index
///     20  4  steps (actions executed)
///     24  1  goal  25  1  aborted  26  1  learned (transitions follow)  27  1  reserved (0)
///     28  4  state dimension D  32  4  transitions N
///     36  N × (8·(2D + 2) + 8): s[D], a, r, s'[D], terminal (8 bytes, 0 or 1)
/// ```
/// A record cut short or with a wrong CRC ends the journal (a kill while it was written: the run
/// was not reported).
///
/// Pure functions: no I/O, no allocation.
#ifndef FW_JOURNAL_H
#define FW_JOURNAL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define FW_JOURNAL_VERSION 1U
#define FW_JOURNAL_HEADER_BYTES 16U
#define FW_JOURNAL_RUN_BYTES 36U
/// Largest state dimension a record holds.
#define FW_JOURNAL_MAX_DIM 16U

/// One run of the journal (the body's fields before the transitions).
typedef struct fw_journal_run {
  int32_t run_id;
  int32_t kind;            ///< learn_run_kind_t
  int32_t phase;
  int32_t training_index;
  int32_t eval_index;
  int32_t steps;           ///< actions executed
  bool goal;
  bool aborted;
  bool learned;            ///< a training run whose transitions were learned (they follow)
  uint32_t state_dim;
  uint32_t n;              ///< transitions
} fw_journal_run_t;

/// One learned transition.
typedef struct fw_journal_transition {
  double s[FW_JOURNAL_MAX_DIM];
  double a;
  double r;
  double s_next[FW_JOURNAL_MAX_DIM];
  bool terminal;
} fw_journal_transition_t;

/// Bytes of one transition / of a whole record of n transitions at state_dim. O(1).
size_t fw_journal_transition_bytes(uint32_t state_dim);
size_t fw_journal_record_bytes(uint32_t state_dim, uint32_t n);

/// Writes transition i of a record being built in rec (capacity cap) at state_dim. Returns false
/// when it does not fit (nothing written). O(state_dim).
bool fw_journal_put_transition(uint8_t* rec, size_t cap, uint32_t state_dim, uint32_t i,
                               const fw_journal_transition_t* t);

/// Completes the record in rec: the header and run fields (run->n transitions already put).
/// Returns the record's size, or 0 when it does not fit in cap or run is invalid. O(record).
size_t fw_journal_finish(uint8_t* rec, size_t cap, const fw_journal_run_t* run);

/// Reads the record at p (len bytes available): 1 (a valid record: *run filled, *size its bytes,
/// *transitions its first transition), 0 (nothing more: end of data, or a record cut short), -1
/// (not a valid record: wrong magic, version, size or CRC; a torn write). O(record).
int fw_journal_next(const uint8_t* p, size_t len, fw_journal_run_t* run, const uint8_t** transitions, size_t* size);

/// Transition i of a record read by fw_journal_next. O(state_dim).
void fw_journal_get_transition(const uint8_t* transitions, uint32_t state_dim, uint32_t i,
                               fw_journal_transition_t* out);

#ifdef __cplusplus
}
#endif

#endif  // FW_JOURNAL_H
