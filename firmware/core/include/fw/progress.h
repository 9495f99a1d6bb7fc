// SPDX-License-Identifier: MIT
/// fw/progress.h — The controller's section of a checkpoint (fw/checkpoint.h, "meta"): which
/// task the learned state belongs to, how far the schedule got, so that a restart resumes, and
/// which learned policy the payload holds.
///
/// Byte layout of revision 4 (FW_PROGRESS_BYTES, integers little-endian):
/// ```
///  0  8  magic "FWMETA04"
///  8  4  task (its declaration's id)        12  4  state dimension
/// 16  4  phase                               20  4  training runs (both phases)
/// 24  4  phase-one runs                      28  4  phase-two runs
/// 32  4  evaluation blocks                   36  4  successful phase-one runs
/// 40  8  their summed steps (IEEE-754 double) 48  4  shortest of them (0 = none)
/// 52  4  run id + 1 (0 = no run started)
/// 56  4  policy (learn_policy_t: 0 actor, 1 greedy, 2 select) 60  4  reserved (0)
/// 64  8  actor section bytes A (0 with the greedy policy)
/// 72  8  policy = select: steps the greedy policy saved over the actor in the ranked pairs (double)
/// 80  4  policy = select: ranked pairs           84  4  reserved (0)
/// ```
/// The payload (the checkpoint's learned state) is HEDGER's save (hedger_save, which declares
/// its own length) followed, with the actor policy, by the actor's (actor_save: its parameters
/// and optimiser moments, the ring of recorded transitions with their returns and run ids, the
/// query generator): its last A bytes. Restarting from it, the actor learns on exactly as if
/// the controller had not stopped (the between-run work is always complete in a checkpoint).
///
/// Revision 3 ("FWMETA03", 72 bytes: bytes 0-71 as above, policy 0 or 1) has no ranked pairs:
/// it decodes with none (a controller with policy = select starts its ranking afresh).
/// Revision 2 ("FWMETA02", 56 bytes: bytes 0-55 as above) has no policy fields: its payload is
/// HEDGER's alone (decoded as the greedy policy, revision 2). The controller keeps its values
/// and starts the actor from them (learn_actor_from_values) with a note.
/// Revision 1 ("FWMETA01", 96 or 104 bytes) has the same bytes 8-55 and, after them, a policy
/// shift that the controllers of that revision added to the greedy action (learned by ranking
/// pairs of runs in the reference controllers' coordinates, and among obstacles with a hold past
/// the obstacle copied from the reference law). The learner no longer has either: such a file is
/// read, its learned values and progress are kept, and where its shift had moved the decoder says
/// so (legacy_shift), so that the controller can tell the operator that the policy it resumes is
/// the values' alone.
/// Decoding validates every field against the ranges below, so a section with a valid CRC but
/// impossible contents (a bug, or bytes written by something else) is refused like a corrupt
/// file instead of steering the schedule. Ranges (fw_progress_decode):
/// - task: the id of a declared task (tasks/decl.h); state dimension 1..HEDGER_MAX_STATE_DIM;
/// - phase 1 or 2; every counter and the run id + 1 in [0, INT32_MAX];
/// - training runs = phase-one runs + phase-two runs; phase-two runs = 0 in phase 1;
/// - successful phase-one runs <= phase-one runs; with none, their sum and shortest are 0;
///   otherwise the sum is a whole number with shortest × runs <= sum <= runs × INT32_MAX;
/// - run id + 1 >= training runs (every training run started as a run);
/// - policy 0, 1 or 2 (0 or 1 in revision 3), reserved 0, actor section bytes 0 exactly with the
///   greedy policy and at most 2^40 (the payload's size is checked against it by the loader);
/// - ranked pairs: 0 pairs and 0 steps unless policy = select; the steps a whole number of at
///   most pairs × INT32_MAX in magnitude.
/// A later field needs a new magic (older decoders refuse it as an unknown format).
///
/// Pure functions: no I/O, no allocation, O(1).
#ifndef FW_PROGRESS_H
#define FW_PROGRESS_H

#include "learn/learn.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Size of an encoded section (revision 4).
#define FW_PROGRESS_BYTES 88U
/// Size of a revision-3 section.
#define FW_PROGRESS_BYTES_3 72U
/// Size of a revision-2 section.
#define FW_PROGRESS_BYTES_2 56U
/// Largest section the decoder reads (revision 1 with the hold past the obstacle); a buffer this
/// large holds any section.
#define FW_PROGRESS_READ_MAX 104U
/// Capacity of fw_progress_decode()'s reason text, including the NUL.
#define FW_PROGRESS_WHY_MAX 160U

/// What a checkpoint records besides the learned state.
typedef struct fw_progress {
  int32_t task;                     ///< the declared task's id the learned state belongs to
  uint32_t state_dim;               ///< its state dimension
  learn_schedule_progress_t schedule;  ///< schedule progress (fw/schedule.h)
  int32_t run_id;                   ///< last run started, -1 = none
  int32_t policy;                   ///< learn_policy_t the payload was written with
  uint64_t actor_bytes;             ///< the actor's section at the payload's end (0: none)
  learn_selection_t selection;      ///< policy = select: the ranked pairs (zero otherwise)
  /// decoded only: a revision-1 file whose policy shift had moved (not used by this controller)
  bool legacy_shift;
  uint32_t revision;                ///< decoded only: 1, 2, 3 or 4
} fw_progress_t;

/// Writes p into out[0..FW_PROGRESS_BYTES) (revision 4) and returns FW_PROGRESS_BYTES. Does not
/// validate: a value outside the ranges above is written as is (and refused by the decoder).
size_t fw_progress_encode(const fw_progress_t* p, uint8_t out[FW_PROGRESS_BYTES]);

/// Decodes and validates n bytes (revision 4: FW_PROGRESS_BYTES; revision 3: FW_PROGRESS_BYTES_3;
/// revision 2: FW_PROGRESS_BYTES_2;
/// revision 1: 96 or 104; revisions 1 and 2 decode as the greedy policy without an actor). Returns
/// 0 with *out filled, or -1 with a one-line reason in why (e.g. "phase 7, expected 1 or 2";
/// capacity why_cap, may be 0) and *out untouched.
int fw_progress_decode(const uint8_t* bytes, size_t n, fw_progress_t* out, char* why, size_t why_cap);

#ifdef __cplusplus
}
#endif

#endif  // FW_PROGRESS_H
