// SPDX-License-Identifier: MIT
// libFuzzer target: the checkpoint's controller section (fw/progress.h). Every accepted section
// satisfies the documented ranges; a revision-4 section re-encodes to the same bytes; revision 3
// re-encodes to revision 4 with the same bytes 8-71 and no ranked pairs; revisions 1 and 2
// re-encode to revision 4 with the same bytes 8-55 as the greedy policy without an actor, and
// legacy_shift says whether a revision-1 shift's doubles (56, 64, 80) were not all zero;
// every refusal has a reason.
#include "fw/config.h"
#include "fw/progress.h"
#include "learn/learn.h"
#include <tasks/decl.h>
#include "fuzz_util.h"

#include <math.h>

static bool zero_at(const uint8_t* b, size_t off) {
  double x;
  memcpy(&x, b + off, sizeof x);  // little-endian host, as the encoding
  return x >= 0.0 && x <= 0.0;
}

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fw_progress_t p;
  memset(&p, 0xA5, sizeof p);
  char why[FW_PROGRESS_WHY_MAX] = "";
  if (fw_progress_decode(data, size, &p, why, sizeof why) != 0) {
    FUZZ_CHECK(why[0] != '\0');
    FUZZ_CHECK(memchr(why, '\0', sizeof why) != NULL);
    return 0;
  }
  const learn_schedule_progress_t* g = &p.schedule;
  const uint32_t rev = size == FW_PROGRESS_BYTES     ? 4U
                       : size == FW_PROGRESS_BYTES_3 ? 3U
                       : size == FW_PROGRESS_BYTES_2 ? 2U
                                                     : 1U;
  const bool rev1 = rev == 1U;
  FUZZ_CHECK(size == FW_PROGRESS_BYTES || size == FW_PROGRESS_BYTES_3 || size == FW_PROGRESS_BYTES_2 || size == 96U ||
             size == 104U);
  FUZZ_CHECK(p.revision == rev);
  FUZZ_CHECK(tasks_by_id(p.task) != NULL);
  FUZZ_CHECK(p.state_dim >= 1U && p.state_dim <= 8U);
  FUZZ_CHECK(g->phase == 1 || g->phase == 2);
  FUZZ_CHECK(g->phase_one_runs >= 0 && g->phase_two_runs >= 0 && g->eval_blocks >= 0);
  FUZZ_CHECK((int64_t)g->phase_one_runs + g->phase_two_runs == g->training_runs);
  FUZZ_CHECK(g->example_runs >= 0 && g->example_runs <= g->phase_one_runs);
  FUZZ_CHECK(isfinite(g->example_steps_sum) && g->example_steps_sum >= 0.0);
  FUZZ_CHECK(g->best_example_steps >= 0);
  FUZZ_CHECK(p.run_id >= -1 && (int64_t)p.run_id + 1 >= g->training_runs);
  FUZZ_CHECK(p.policy == LEARN_POLICY_ACTOR || p.policy == LEARN_POLICY_GREEDY ||
             (rev == 4U && p.policy == LEARN_POLICY_SELECT));
  FUZZ_CHECK((p.policy == LEARN_POLICY_GREEDY) == (p.actor_bytes == 0U));
  FUZZ_CHECK(p.actor_bytes <= (1ULL << 40));
  FUZZ_CHECK(rev >= 3U || (p.policy == LEARN_POLICY_GREEDY && p.actor_bytes == 0U));
  FUZZ_CHECK(p.selection.pairs >= 0 && isfinite(p.selection.greedy_saved_steps));
  FUZZ_CHECK(p.policy == LEARN_POLICY_SELECT ||
             (p.selection.pairs == 0 && p.selection.greedy_saved_steps >= 0.0 && p.selection.greedy_saved_steps <= 0.0));
  FUZZ_CHECK(fabs(p.selection.greedy_saved_steps) <= (double)p.selection.pairs * 2147483647.0);
  FUZZ_CHECK(p.legacy_shift == (rev1 && !(zero_at(data, 56) && zero_at(data, 64) && zero_at(data, 80))));
  uint8_t again[FW_PROGRESS_BYTES];
  FUZZ_CHECK(fw_progress_encode(&p, again) == FW_PROGRESS_BYTES);
  FUZZ_CHECK(memcmp(again + 8, data + 8, FW_PROGRESS_BYTES_2 - 8U) == 0);
  FUZZ_CHECK(rev < 3U || memcmp(again + 8, data + 8, FW_PROGRESS_BYTES_3 - 8U) == 0);
  FUZZ_CHECK(memcmp(again, "FWMETA04", 8) == 0);
  FUZZ_CHECK(rev != 4U || memcmp(again, data, size) == 0);
  return 0;
}
