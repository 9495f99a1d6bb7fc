// SPDX-License-Identifier: MIT
// libFuzzer target: the checkpoint's controller section (fw/progress.h). Every accepted section
// satisfies the documented ranges and re-encodes to the same bytes (a section of pair terms
// revision 0 to today's revision, with the obstacle shift converted, and those bytes decode to the
// same values), at its own size (the hold past the obstacle recorded or not); every refusal has a
// reason.
#include "fw/config.h"
#include "fw/progress.h"
#include "fuzz_util.h"

#include <math.h>

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fw_progress_t p;
  memset(&p, 0xA5, sizeof p);
  char why[FW_PROGRESS_WHY_MAX] = "";
  if (fw_progress_decode(data, size, &p, why, sizeof why) != 0) {
    FUZZ_CHECK(why[0] != '\0');
    FUZZ_CHECK(memchr(why, '\0', sizeof why) != NULL);
    return 0;
  }
  const fw_schedule_progress_t* g = &p.schedule;
  FUZZ_CHECK(size == FW_PROGRESS_BYTES_BASE || size == FW_PROGRESS_BYTES);
  FUZZ_CHECK(p.pass_hold_recorded == (size == FW_PROGRESS_BYTES));
  FUZZ_CHECK(p.pass_hold_recorded ? p.task == FW_TASK_OBSTACLES && p.obstacle_pass_hold_steps >= 0 &&
                                        p.obstacle_pass_hold_steps <= FW_PROGRESS_PASS_HOLD_STEPS_MAX
                                  : p.obstacle_pass_hold_steps == 0);
  FUZZ_CHECK(p.task == FW_TASK_CORRIDOR || p.task == FW_TASK_OBSTACLES);
  FUZZ_CHECK(p.state_dim >= 1U && p.state_dim <= 8U);
  FUZZ_CHECK(g->phase == 1 || g->phase == 2);
  FUZZ_CHECK(g->phase_one_runs >= 0 && g->phase_two_runs >= 0 && g->eval_blocks >= 0);
  FUZZ_CHECK((int64_t)g->phase_one_runs + g->phase_two_runs == g->training_runs);
  FUZZ_CHECK(g->example_runs >= 0 && g->example_runs <= g->phase_one_runs);
  FUZZ_CHECK(isfinite(g->example_steps_sum) && g->example_steps_sum >= 0.0);
  FUZZ_CHECK(g->best_example_steps >= 0);
  FUZZ_CHECK(p.run_id >= -1 && (int64_t)p.run_id + 1 >= g->training_runs);
  FUZZ_CHECK(isfinite(p.shift.gain) && fabs(p.shift.gain) <= FW_PAIR_SHIFT_MAX);
  FUZZ_CHECK(isfinite(p.shift.centring) && fabs(p.shift.centring) <= FW_PAIR_SHIFT_MAX);
  FUZZ_CHECK(p.shift.pairs <= (uint32_t)INT32_MAX);
  FUZZ_CHECK(p.shift.imitation >= FW_PAIR_IMITATION_MIN && p.shift.imitation <= FW_PAIR_IMITATION_MAX);
  FUZZ_CHECK(p.obstacle_clearance_m == 0.0 ||
             (p.task == FW_TASK_OBSTACLES && p.obstacle_clearance_m >= FW_PAIR_OBSTACLE_CLEARANCE_MIN_M &&
              p.obstacle_clearance_m <= FW_PAIR_OBSTACLE_CLEARANCE_MAX_M));
  uint8_t again[FW_PROGRESS_BYTES];
  FUZZ_CHECK(fw_progress_encode(&p, again) == size);
  const uint32_t terms = (uint32_t)data[76] | (uint32_t)data[77] << 8 | (uint32_t)data[78] << 16 |
                         (uint32_t)data[79] << 24;
  FUZZ_CHECK(terms <= FW_PAIR_TERMS_REVISION);
  if (terms == FW_PAIR_TERMS_REVISION) {
    FUZZ_CHECK(memcmp(again, data, size) == 0);
    return 0;
  }
  // Revision 0: only the shift's b (converted among obstacles) and the revision differ.
  FUZZ_CHECK(memcmp(again, data, 64) == 0 && memcmp(again + 72, data + 72, 4) == 0 &&
             memcmp(again + 80, data + 80, size - 80U) == 0);
  FUZZ_CHECK(p.task == FW_TASK_OBSTACLES || memcmp(again + 64, data + 64, 8) == 0);
  // Today's bytes decode to the same values: they re-encode to themselves.
  fw_progress_t q;
  FUZZ_CHECK(fw_progress_decode(again, size, &q, why, sizeof why) == 0);
  uint8_t twice[FW_PROGRESS_BYTES];
  FUZZ_CHECK(fw_progress_encode(&q, twice) == size);
  FUZZ_CHECK(memcmp(twice, again, size) == 0);
  return 0;
}
