// SPDX-License-Identifier: MIT
/// fw/checkpoint.h — Crash-safe files for the learned state, and a background writer so that
/// the control tick never waits for the disk.
///
/// File layout (all integers little-endian), format version FW_CHECKPOINT_VERSION:
/// ```
///  0  8  magic "B21RCKPT"
///  8  4  format version
/// 12  4  header size (48)
/// 16  8  meta size   M   (controller state: phase, run counters, the learned policy's shift;
///                         fw_loop's own encoding, fw/progress.h)
/// 24  8  payload size P  (the learner's own versioned, checksummed save format)
/// 32  4  CRC-32 of meta
/// 36  4  CRC-32 of payload
/// 40  4  reserved (0)
/// 44  4  CRC-32 of bytes 0..43
/// 48  M  meta
/// 48+M P payload
/// ```
/// Atomicity: fw_checkpoint_write() writes `<path>.tmp`, fsyncs it, renames it over `<path>`
/// and fsyncs the directory. A process killed at any instant (kill -9) therefore leaves `<path>`
/// holding either the previous or the new complete file; a stale `<path>.tmp` is harmless and is
/// overwritten by the next write. CRC-32 is the IEEE 802.3 polynomial (as zlib's crc32()).
#ifndef FW_CHECKPOINT_H
#define FW_CHECKPOINT_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define FW_CHECKPOINT_VERSION 1U
#define FW_CHECKPOINT_HEADER_SIZE 48U
/// Capacity of the error messages below, including the NUL.
#define FW_CHECKPOINT_ERR_MAX 512U
/// How every refusal of a checkpoint ends: how to start fresh (a printf format taking the path
/// twice).
#define FW_CHECKPOINT_FRESH_HINT \
  "to start fresh with an empty learner, move the file away (e.g. mv '%s' '%s.bad')"

/// CRC-32 (IEEE, reflected, init and final XOR 0xFFFFFFFF) of n bytes, continuing from crc
/// (pass 0 to start). O(n), no allocation.
uint32_t fw_crc32(uint32_t crc, const void* data, size_t n);

/// Writes a checkpoint atomically (see the file comment). meta/payload may be NULL when their
/// size is 0. Blocks on the disk (fsync): never call it from the tick; use fw_ckpt_writer_t.
/// Returns 0, or -1 with a message naming the path and the failing step in err; on failure
/// `<path>` is untouched.
int fw_checkpoint_write(const char* path, const void* meta, size_t meta_size, const void* payload,
                        size_t payload_size, char* err, size_t err_cap);

/// Reads the header and reports the section sizes so the caller can size its buffers.
/// Returns 1 (file present and the header valid), 0 (no file at path), -1 (not a regular file,
/// e.g. a directory; unreadable; or corrupt: err says what and how to fix it or start fresh).
int fw_checkpoint_peek(const char* path, size_t* meta_size, size_t* payload_size, char* err, size_t err_cap);

/// Reads and verifies a whole checkpoint into caller buffers. Returns 1 (loaded; *meta_size and
/// *payload_size set), 0 (no file), -1 (corrupt, truncated, wrong version, too big for the
/// buffers, or unreadable; err names the problem and says how to start fresh: move the file away).
int fw_checkpoint_read(const char* path, void* meta, size_t meta_cap, size_t* meta_size, void* payload,
                       size_t payload_cap, size_t* payload_size, char* err, size_t err_cap);

/// Background checkpoint writer: two buffers of fixed capacity, one thread. The tick fills a
/// buffer (fw_ckpt_writer_acquire → serialise into it → fw_ckpt_writer_submit); the thread
/// writes it with fw_checkpoint_write. When the disk is slower than the submissions, a pending,
/// not yet started checkpoint is replaced by the newer one (the newest state always wins; the
/// replaced one is counted as superseded).
typedef struct fw_ckpt_writer fw_ckpt_writer_t;

/// Counters of a writer; monotonic.
typedef struct fw_ckpt_counters {
  uint64_t written;      ///< checkpoints on disk
  uint64_t failed;       ///< write attempts that failed (message on stderr)
  uint64_t superseded;   ///< submissions replaced by a newer one before being written
  uint64_t busy;         ///< acquire calls that found no free buffer (checkpoint skipped)
  uint64_t journal_written;  ///< journal records on disk (fw/journal.h)
  uint64_t journal_failed;   ///< journal appends that failed (message on stderr)
  uint64_t journal_skipped;  ///< records not journalled: no free slot, too large, or after a failure
} fw_ckpt_counters_t;

/// Creates a writer for path with buffers of meta_cap + payload_cap bytes each (allocated here,
/// once) and starts its thread. Returns NULL with a message on failure.
fw_ckpt_writer_t* fw_ckpt_writer_create(const char* path, size_t meta_cap, size_t payload_cap, char* err,
                                        size_t err_cap);

/// Gives the tick a free buffer to serialise into, or returns -1 when both are in use (counted
/// in `busy`). On success *meta/*payload point into the writer's buffer of the stated capacity
/// and the returned handle must be passed to fw_ckpt_writer_submit. Bounded time (a mutex held
/// only for bookkeeping by the thread), no allocation.
int fw_ckpt_writer_acquire(fw_ckpt_writer_t* w, void** meta, size_t* meta_cap, void** payload,
                           size_t* payload_cap);

/// Queues the buffer of handle (from acquire) with the used sizes for writing. Bounded time.
void fw_ckpt_writer_submit(fw_ckpt_writer_t* w, int handle, size_t meta_size, size_t payload_size);

/// As fw_ckpt_writer_submit, for a checkpoint that holds the learned state and progress after
/// the run covered_run (-1: none): once it is on disk, every run up to it is durable
/// (fw_ckpt_writer_durable_run) and the journal, whose runs it covers, is emptied.
void fw_ckpt_writer_submit_run(fw_ckpt_writer_t* w, int handle, size_t meta_size, size_t payload_size,
                               int32_t covered_run);

/// The journal of finished runs (fw/journal.h) at `<path>.journal`: records appended and synced
/// (fdatasync) by the writer's thread, in the order of submission together with the checkpoints.
/// Sets up `slots` record buffers of record_cap bytes each (allocated here, once), opens the
/// journal (created if absent) keeping its first keep_bytes (the records the caller has resumed
/// from; the rest, a torn or unused tail, is cut) and sets the run that is durable already (the
/// resumed one; -1: none). Start-up only. Returns 0, or -1 with a message naming the file and the
/// cause.
int fw_ckpt_writer_journal_init(fw_ckpt_writer_t* w, size_t record_cap, uint32_t slots, int32_t durable_run,
                                size_t keep_bytes, char* err, size_t err_cap);

/// Copies a finished run's record (fw_journal_finish) for appending. Bounded time (a copy of n
/// bytes), never waits for the disk. Returns 0, or -1 when the journal is not set up, n exceeds
/// record_cap or no slot is free (counted in journal_skipped: the run becomes durable with the
/// next checkpoint that covers it).
int fw_ckpt_writer_journal_submit(fw_ckpt_writer_t* w, const void* record, size_t n, int32_t run_id);

/// The newest run id up to which every run is on disk: appended to the journal in an unbroken
/// sequence of run ids after a checkpoint, or covered by a checkpoint. Lock-free (the tick reads it
/// every tick).
int32_t fw_ckpt_writer_durable_run(fw_ckpt_writer_t* w);

/// Waits until every submitted checkpoint and journal record is on disk (or failed). For
/// shutdown and tests.
void fw_ckpt_writer_flush(fw_ckpt_writer_t* w);

/// Snapshot of the counters (thread-safe).
fw_ckpt_counters_t fw_ckpt_writer_counters(fw_ckpt_writer_t* w);

/// Flushes, stops the thread and frees the buffers. NULL is ignored.
void fw_ckpt_writer_destroy(fw_ckpt_writer_t* w);

/// Maps every page of both buffers now (fw/prefault.h). Start-up only, before the first acquire.
void fw_ckpt_writer_prefault(fw_ckpt_writer_t* w);

#ifdef __cplusplus
}
#endif

#endif  // FW_CHECKPOINT_H
