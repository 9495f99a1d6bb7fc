// SPDX-License-Identifier: MIT
// The checkpoint's controller section: encoding and a validating decoder (fw/progress.h).
#include "fw/progress.h"

#include "le_bytes.h"
#include "fw/errfmt.h"

#include <hedger/hedger.h>
#include <learn/learn.h>
#include <tasks/decl.h>

#include <math.h>
#include <stdbool.h>
#include <stdio.h>
#include <string.h>

#define MAGIC "FWMETA04"
#define MAGIC_3 "FWMETA03"
#define MAGIC_2 "FWMETA02"
#define MAGIC_1 "FWMETA01"
// Revision 1's sizes: without and with the hold past the obstacle.
#define BYTES_1 96U
#define BYTES_1_HOLD 104U

_Static_assert(FW_PROGRESS_BYTES == 88U, "fw_progress_encode fills bytes 0-87");
// The largest actor section a decoder accepts (the payload's own size is checked by the loader).
#define ACTOR_BYTES_MAX ((uint64_t)1 << 40)
_Static_assert(FW_PROGRESS_READ_MAX >= BYTES_1_HOLD, "the largest section read fits the buffer");

size_t fw_progress_encode(const fw_progress_t* p, uint8_t out[FW_PROGRESS_BYTES]) {
  const learn_schedule_progress_t* g = &p->schedule;
  memset(out, 0, FW_PROGRESS_BYTES);
  memcpy(out, MAGIC, 8);
  fw_put_u32(out + 8, (uint32_t)p->task);
  fw_put_u32(out + 12, p->state_dim);
  fw_put_u32(out + 16, (uint32_t)g->phase);
  fw_put_u32(out + 20, (uint32_t)g->training_runs);
  fw_put_u32(out + 24, (uint32_t)g->phase_one_runs);
  fw_put_u32(out + 28, (uint32_t)g->phase_two_runs);
  fw_put_u32(out + 32, (uint32_t)g->eval_blocks);
  fw_put_u32(out + 36, (uint32_t)g->example_runs);
  fw_put_f64(out + 40, g->example_steps_sum);
  fw_put_u32(out + 48, (uint32_t)g->best_example_steps);
  fw_put_u32(out + 52, (uint32_t)p->run_id + 1U);
  fw_put_u32(out + 56, (uint32_t)p->policy);
  fw_put_u32(out + 60, 0U);
  fw_put_u64(out + 64, p->actor_bytes);
  fw_put_f64(out + 72, p->selection.greedy_saved_steps);
  fw_put_u32(out + 80, (uint32_t)p->selection.pairs);
  fw_put_u32(out + 84, 0U);
  return FW_PROGRESS_BYTES;
}

static bool is_zero(double x) { return x >= 0.0 && x <= 0.0; }

// Reads a counter at off into *v; false (with the reason) when it exceeds INT32_MAX.
static bool counter(const uint8_t* b, size_t off, const char* name, int32_t* v, char* why, size_t cap) {
  const uint32_t u = fw_get_u32(b + off);
  if (u > (uint32_t)INT32_MAX) {
    fw_errfmt(why, cap, "%s %u, expected at most %d", name, (unsigned)u, INT32_MAX);
    return false;
  }
  *v = (int32_t)u;
  return true;
}

int fw_progress_decode(const uint8_t* b, size_t n, fw_progress_t* out, char* why, size_t cap) {
  const bool rev4 = n == FW_PROGRESS_BYTES && memcmp(b, MAGIC, 8) == 0;
  const bool rev3 = rev4 || (n == FW_PROGRESS_BYTES_3 && memcmp(b, MAGIC_3, 8) == 0);  // bytes 0-71 alike
  const bool rev2 = n == FW_PROGRESS_BYTES_2 && memcmp(b, MAGIC_2, 8) == 0;
  const bool rev1 = (n == BYTES_1 || n == BYTES_1_HOLD) && memcmp(b, MAGIC_1, 8) == 0;
  if (!rev3 && !rev2 && !rev1) {
    fw_errfmt(why, cap, "unknown format (%zu bytes, expected %u starting with " MAGIC ", %u starting with " MAGIC_3
              ", %u starting with " MAGIC_2 " or %u or %u starting with " MAGIC_1 ")", n, FW_PROGRESS_BYTES,
              FW_PROGRESS_BYTES_3, FW_PROGRESS_BYTES_2, BYTES_1, BYTES_1_HOLD);
    return -1;
  }
  fw_progress_t p;
  memset(&p, 0, sizeof p);
  learn_schedule_progress_t* g = &p.schedule;
  const uint32_t task = fw_get_u32(b + 8);
  if (task > (uint32_t)INT32_MAX || tasks_by_id((int32_t)task) == NULL) {
    fw_errfmt(why, cap, "task %u, expected the id of a declared task", (unsigned)task);
    return -1;
  }
  p.task = (int32_t)task;
  p.state_dim = fw_get_u32(b + 12);
  if (p.state_dim < 1U || p.state_dim > HEDGER_MAX_STATE_DIM) {
    fw_errfmt(why, cap, "state dimension %u, expected 1..%u", (unsigned)p.state_dim, HEDGER_MAX_STATE_DIM);
    return -1;
  }
  const uint32_t phase = fw_get_u32(b + 16);
  if (phase != 1U && phase != 2U) {
    fw_errfmt(why, cap, "phase %u, expected 1 or 2", (unsigned)phase);
    return -1;
  }
  g->phase = (int32_t)phase;
  int32_t run_id_plus_1 = 0;
  if (!counter(b, 20, "training runs", &g->training_runs, why, cap) ||
      !counter(b, 24, "phase-one runs", &g->phase_one_runs, why, cap) ||
      !counter(b, 28, "phase-two runs", &g->phase_two_runs, why, cap) ||
      !counter(b, 32, "evaluation blocks", &g->eval_blocks, why, cap) ||
      !counter(b, 36, "successful phase-one runs", &g->example_runs, why, cap) ||
      !counter(b, 48, "shortest phase-one run", &g->best_example_steps, why, cap) ||
      !counter(b, 52, "run id + 1", &run_id_plus_1, why, cap)) {
    return -1;
  }
  g->example_steps_sum = fw_get_f64(b + 40);
  if ((int64_t)g->phase_one_runs + g->phase_two_runs != g->training_runs) {
    fw_errfmt(why, cap, "training runs %d != phase-one runs %d + phase-two runs %d", (int)g->training_runs,
        (int)g->phase_one_runs, (int)g->phase_two_runs);
    return -1;
  }
  if (g->phase == 1 && g->phase_two_runs != 0) {
    fw_errfmt(why, cap, "phase 1 with %d phase-two runs", (int)g->phase_two_runs);
    return -1;
  }
  if (g->example_runs > g->phase_one_runs) {
    fw_errfmt(why, cap, "successful phase-one runs %d > phase-one runs %d", (int)g->example_runs, (int)g->phase_one_runs);
    return -1;
  }
  const double sum = g->example_steps_sum;
  const double runs = (double)g->example_runs;
  // A sum of whole step counts, each at least the shortest one.
  const bool stats_ok = g->example_runs == 0 ? is_zero(sum) && g->best_example_steps == 0
                                             : isfinite(sum) && !(sum > floor(sum)) &&
                                                   sum >= (double)g->best_example_steps * runs &&
                                                   sum <= runs * (double)INT32_MAX;
  if (!stats_ok) {
    fw_errfmt(why, cap, "phase-one statistics inconsistent (%d successful runs, %.17g steps in total, shortest %d)",
        (int)g->example_runs, sum, (int)g->best_example_steps);
    return -1;
  }
  if (run_id_plus_1 < g->training_runs) {
    fw_errfmt(why, cap, "run id %d below the %d training runs", (int)run_id_plus_1 - 1, (int)g->training_runs);
    return -1;
  }
  p.run_id = run_id_plus_1 - 1;
  p.revision = rev4 ? 4U : (rev3 ? 3U : (rev2 ? 2U : 1U));
  p.policy = LEARN_POLICY_GREEDY;  // revisions 1 and 2: HEDGER's values alone
  if (rev3) {
    const uint32_t policy = fw_get_u32(b + 56);
    const uint64_t actor_bytes = fw_get_u64(b + 64);
    if (policy != (uint32_t)LEARN_POLICY_ACTOR && policy != (uint32_t)LEARN_POLICY_GREEDY &&
        !(rev4 && policy == (uint32_t)LEARN_POLICY_SELECT)) {
      fw_errfmt(why, cap, "policy %u, expected 0 (actor), 1 (greedy)%s", (unsigned)policy,
                rev4 ? " or 2 (select)" : "");
      return -1;
    }
    if (fw_get_u32(b + 60) != 0U) {
      fw_errfmt(why, cap, "reserved field %u, expected 0", (unsigned)fw_get_u32(b + 60));
      return -1;
    }
    if ((policy == (uint32_t)LEARN_POLICY_GREEDY) != (actor_bytes == 0U) || actor_bytes > ACTOR_BYTES_MAX) {
      fw_errfmt(why, cap, "actor section of %llu bytes with the %s policy", (unsigned long long)actor_bytes,
                policy == (uint32_t)LEARN_POLICY_GREEDY ? "greedy" : (policy == 0U ? "actor" : "select"));
      return -1;
    }
    p.policy = (int32_t)policy;
    p.actor_bytes = actor_bytes;
  }
  if (rev4) {
    const double saved = fw_get_f64(b + 72);
    int32_t pairs = 0;
    if (!counter(b, 80, "ranked pairs", &pairs, why, cap)) {
      return -1;
    }
    if (fw_get_u32(b + 84) != 0U) {
      fw_errfmt(why, cap, "reserved field %u, expected 0", (unsigned)fw_get_u32(b + 84));
      return -1;
    }
    const bool select = p.policy == LEARN_POLICY_SELECT;
    const bool ok = select ? isfinite(saved) && !(fabs(saved) > floor(fabs(saved))) &&
                                 fabs(saved) <= (double)pairs * (double)INT32_MAX
                           : pairs == 0 && is_zero(saved);
    if (!ok) {
      fw_errfmt(why, cap, "ranked pairs inconsistent (%d pairs, %.17g steps saved, policy %d)", (int)pairs, saved,
                (int)p.policy);
      return -1;
    }
    p.selection.greedy_saved_steps = saved;
    p.selection.pairs = pairs;
  }
  // Revision 1's policy shift (its a, b and imitation weight as doubles at 56, 64 and 80): not
  // used any more; the operator is told when it had moved.
  p.legacy_shift = rev1 && !(is_zero(fw_get_f64(b + 56)) && is_zero(fw_get_f64(b + 64)) && is_zero(fw_get_f64(b + 80)));
  *out = p;
  return 0;
}
