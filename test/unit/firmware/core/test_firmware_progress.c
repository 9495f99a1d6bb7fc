// SPDX-License-Identifier: MIT
// The checkpoint's controller section: exact round trips, the byte layout of revision 4 (88
// bytes), every field out of its documented range refused with the field named, revision 3 (72
// bytes) read without ranked pairs, revision 2 (56 bytes) read as the greedy policy without an actor, and revision 1 (96 or 104 bytes, with the
// policy shift of older controllers) read with its shift reported.
#include <learn/learn.h>
#include <tasks/decl.h>
#include "fw/config.h"
#include "fw/progress.h"

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

static fw_progress_t sample(void) {
  fw_progress_t p;
  memset(&p, 0, sizeof p);
  p.task = (int32_t)tasks_obstacles_decl.id;
  p.state_dim = 4;
  p.schedule.phase = 2;
  p.schedule.training_runs = 42;
  p.schedule.phase_one_runs = 30;
  p.schedule.phase_two_runs = 12;
  p.schedule.eval_blocks = 9;
  p.schedule.example_runs = 27;
  p.schedule.example_steps_sum = 27.0 * 130.0 + 17.0;
  p.schedule.best_example_steps = 126;
  p.run_id = 130;
  p.policy = LEARN_POLICY_ACTOR;
  p.actor_bytes = 123456;
  p.revision = 4;
  return p;
}

static uint32_t get_u32(const uint8_t* b, size_t off) {
  return (uint32_t)b[off] | (uint32_t)b[off + 1] << 8 | (uint32_t)b[off + 2] << 16 | (uint32_t)b[off + 3] << 24;
}

static void put_u32(uint8_t* b, size_t off, uint32_t v) {
  for (int i = 0; i < 4; ++i) {
    b[off + (size_t)i] = (uint8_t)(v >> (8 * i));
  }
}

static void put_f64(uint8_t* b, size_t off, double v) {
  uint64_t u;
  memcpy(&u, &v, sizeof u);
  for (int i = 0; i < 8; ++i) {
    b[off + (size_t)i] = (uint8_t)(u >> (8 * i));
  }
}

static bool same(const fw_progress_t* a, const fw_progress_t* b) {
  return a->task == b->task && a->state_dim == b->state_dim && a->run_id == b->run_id &&
         a->legacy_shift == b->legacy_shift && a->policy == b->policy && a->actor_bytes == b->actor_bytes &&
         a->revision == b->revision && memcmp(&a->schedule, &b->schedule, sizeof a->schedule) == 0 &&
         memcmp(&a->selection, &b->selection, sizeof a->selection) == 0;
}

// p encoded, with the u32 at off replaced by v, is refused with `what` in the reason; the output
// is left untouched.
static void expect_refused(const fw_progress_t* p, size_t off, uint32_t v, const char* what) {
  uint8_t b[FW_PROGRESS_BYTES];
  const size_t n = fw_progress_encode(p, b);
  put_u32(b, off, v);
  fw_progress_t out = sample();
  out.run_id = 77;
  char why[FW_PROGRESS_WHY_MAX];
  assert_int_equal(fw_progress_decode(b, n, &out, why, sizeof why), -1);
  if (strstr(why, what) == NULL) {
    fail_msg("expected '%s' in '%s'", what, why);
  }
  assert_int_equal(out.run_id, 77);
}

static uint64_t get_u64(const uint8_t* b, size_t off) {
  return (uint64_t)get_u32(b, off) | (uint64_t)get_u32(b, off + 4) << 32;
}

static double get_f64(const uint8_t* b, size_t off) {
  const uint64_t u = get_u64(b, off);
  double d;
  memcpy(&d, &u, sizeof d);
  return d;
}

// Revision 4 round-trips exactly; the layout is the documented one.
static void test_progress_round_trip_and_layout(void** state) {
  (void)state;
  const fw_progress_t p = sample();
  uint8_t b[FW_PROGRESS_BYTES];
  assert_int_equal(fw_progress_encode(&p, b), FW_PROGRESS_BYTES);
  assert_memory_equal(b, "FWMETA04", 8);
  assert_int_equal(get_u32(b, 8), (int32_t)tasks_obstacles_decl.id);
  assert_int_equal(get_u32(b, 12), 4);
  assert_int_equal(get_u32(b, 16), 2);
  assert_int_equal(get_u32(b, 20), 42);
  assert_int_equal(get_u32(b, 24), 30);
  assert_int_equal(get_u32(b, 28), 12);
  assert_int_equal(get_u32(b, 32), 9);
  assert_int_equal(get_u32(b, 36), 27);
  double sum;
  uint64_t u = 0;
  for (int i = 7; i >= 0; --i) {
    u = u << 8 | b[40 + i];
  }
  memcpy(&sum, &u, sizeof sum);
  assert_true(sum == 27.0 * 130.0 + 17.0);
  assert_int_equal(get_u32(b, 48), 126);
  assert_int_equal(get_u32(b, 52), 131);
  assert_int_equal(get_u32(b, 56), LEARN_POLICY_ACTOR);
  assert_int_equal(get_u32(b, 60), 0);
  assert_int_equal(get_u64(b, 64), 123456);
  assert_true(get_f64(b, 72) == 0.0);
  assert_int_equal(get_u32(b, 80), 0);
  assert_int_equal(get_u32(b, 84), 0);
  fw_progress_t q;
  memset(&q, 0xA5, sizeof q);
  assert_int_equal(fw_progress_decode(b, FW_PROGRESS_BYTES, &q, NULL, 0), 0);
  assert_true(same(&p, &q));
  // policy = select: the ranked pairs at 72 and 80.
  fw_progress_t sel = p;
  sel.policy = LEARN_POLICY_SELECT;
  sel.selection.greedy_saved_steps = -1234.0;
  sel.selection.pairs = 6;
  assert_int_equal(fw_progress_encode(&sel, b), FW_PROGRESS_BYTES);
  assert_int_equal(get_u32(b, 56), LEARN_POLICY_SELECT);
  assert_true(get_f64(b, 72) == -1234.0);
  assert_int_equal(get_u32(b, 80), 6);
  memset(&q, 0xA5, sizeof q);
  assert_int_equal(fw_progress_decode(b, FW_PROGRESS_BYTES, &q, NULL, 0), 0);
  assert_true(same(&sel, &q));
  // A fresh start: no run yet, phase 1, nothing counted.
  fw_progress_t fresh;
  memset(&fresh, 0, sizeof fresh);
  fresh.task = (int32_t)tasks_corridor_decl.id;
  fresh.state_dim = 4;
  fresh.schedule.phase = 1;
  fresh.run_id = -1;
  fresh.policy = LEARN_POLICY_GREEDY;
  fresh.revision = 4;
  assert_int_equal(fw_progress_encode(&fresh, b), FW_PROGRESS_BYTES);
  assert_int_equal(get_u32(b, 52), 0);
  assert_int_equal(fw_progress_decode(b, FW_PROGRESS_BYTES, &q, NULL, 0), 0);
  assert_true(same(&fresh, &q));
}

// Every field outside its documented range is refused, with the field in the reason.
static void test_progress_out_of_range_refused(void** state) {
  (void)state;
  const fw_progress_t p = sample();
  assert_null(tasks_by_id(200));  // no task declares it
  expect_refused(&p, 8, 200, "task 200");
  expect_refused(&p, 12, 0, "state dimension 0");
  expect_refused(&p, 12, 9, "state dimension 9");
  expect_refused(&p, 16, 0, "phase 0");
  expect_refused(&p, 16, 3, "phase 3");
  expect_refused(&p, 20, 0x80000000U, "training runs 2147483648");
  expect_refused(&p, 20, 41, "training runs 41 != phase-one runs 30 + phase-two runs 12");
  expect_refused(&p, 32, 0xFFFFFFFFU, "evaluation blocks");
  expect_refused(&p, 36, 31, "successful phase-one runs 31 > phase-one runs 30");
  expect_refused(&p, 48, 200, "phase-one statistics");  // shortest × runs > sum
  expect_refused(&p, 52, 41, "run id 40 below the 42 training runs");
  expect_refused(&p, 56, 3, "policy 3");
  expect_refused(&p, 60, 1, "reserved field 1");
  expect_refused(&p, 68, 1U << 9, "actor section of");  // 2^41 bytes
  fw_progress_t g = p;
  g.policy = LEARN_POLICY_GREEDY;
  expect_refused(&g, 64, 5, "actor section of 5 bytes with the greedy policy");
  expect_refused(&p, 64, 0, "actor section of 0 bytes with the actor policy");
  expect_refused(&p, 80, 1, "ranked pairs inconsistent (1 pairs");  // ranked pairs without policy = select
  expect_refused(&p, 80, 0x80000000U, "ranked pairs 2147483648");
  expect_refused(&p, 84, 1, "reserved field 1");
  fw_progress_t sel = p;
  sel.policy = LEARN_POLICY_SELECT;
  sel.selection.pairs = 2;
  sel.selection.greedy_saved_steps = 2.5;  // not a whole number of steps
  expect_refused(&sel, 8, 1, "ranked pairs inconsistent");
  sel.selection.greedy_saved_steps = NAN;
  expect_refused(&sel, 8, 1, "ranked pairs inconsistent");
  sel.selection.greedy_saved_steps = 3.0 * (double)INT32_MAX;  // more than 2 pairs can save
  expect_refused(&sel, 8, 1, "ranked pairs inconsistent");
  sel.selection.greedy_saved_steps = -10.0;
  expect_refused(&sel, 64, 0, "actor section of 0 bytes with the select policy");
  fw_progress_t q = p;
  q.schedule.phase = 1;
  expect_refused(&q, 16, 1, "phase 1 with 12 phase-two runs");
  q = p;
  q.schedule.example_steps_sum = 3527.5;
  expect_refused(&q, 8, 1, "phase-one statistics");
  q.schedule.example_steps_sum = NAN;
  expect_refused(&q, 8, 1, "phase-one statistics");
  q.schedule.example_steps_sum = INFINITY;
  expect_refused(&q, 8, 1, "phase-one statistics");
  q.schedule.example_steps_sum = -1.0;
  expect_refused(&q, 8, 1, "phase-one statistics");
  q = p;
  q.schedule.example_runs = 0;
  expect_refused(&q, 8, 1, "phase-one statistics");  // no successful run but a sum and a shortest
  // Sizes and magics other than the two revisions'.
  uint8_t b[FW_PROGRESS_READ_MAX];
  memset(b, 0, sizeof b);
  const size_t bn = fw_progress_encode(&p, b);
  fw_progress_t out;
  char why[FW_PROGRESS_WHY_MAX];
  assert_int_equal(fw_progress_decode(b, bn - 1U, &out, why, sizeof why), -1);
  assert_non_null(strstr(why, "unknown format (87 bytes"));
  assert_int_equal(fw_progress_decode(b, 96, &out, why, sizeof why), -1);  // revision 4's magic, revision 1's size
  assert_non_null(strstr(why, "unknown format (96 bytes"));
  assert_int_equal(fw_progress_decode(b, FW_PROGRESS_BYTES_2, &out, why, sizeof why), -1);  // and revision 2's size
  assert_int_equal(fw_progress_decode(b, FW_PROGRESS_BYTES_3, &out, why, sizeof why), -1);  // and revision 3's size
  b[7] = '5';
  assert_int_equal(fw_progress_decode(b, bn, &out, why, sizeof why), -1);
  assert_non_null(strstr(why, "FWMETA04"));
}

// Revision 3 (72 bytes: bytes 0-71 as revision 4, policy 0 or 1) is read without ranked pairs;
// policy 2 (select) did not exist then, and its magic with revision 4's size is refused.
static void test_progress_revision_3_read(void** state) {
  (void)state;
  const fw_progress_t p = sample();
  uint8_t b[FW_PROGRESS_BYTES];
  fw_progress_encode(&p, b);
  memcpy(b, "FWMETA03", 8);
  fw_progress_t q;
  assert_int_equal(fw_progress_decode(b, FW_PROGRESS_BYTES_3, &q, NULL, 0), 0);
  fw_progress_t want = p;
  want.revision = 3;
  assert_true(same(&want, &q));
  char why[FW_PROGRESS_WHY_MAX];
  assert_int_equal(fw_progress_decode(b, FW_PROGRESS_BYTES, &q, why, sizeof why), -1);
  put_u32(b, 56, LEARN_POLICY_SELECT);
  assert_int_equal(fw_progress_decode(b, FW_PROGRESS_BYTES_3, &q, why, sizeof why), -1);
  assert_non_null(strstr(why, "policy 2, expected 0 (actor), 1 (greedy)"));
}

// Revision 2 (56 bytes, bytes 0-55 as revision 4) is read as the greedy policy with no actor: its
// payload is HEDGER's alone. Its magic with revision 4's size is refused.
static void test_progress_revision_2_read(void** state) {
  (void)state;
  const fw_progress_t p = sample();
  uint8_t b[FW_PROGRESS_BYTES];
  (void)fw_progress_encode(&p, b);
  memcpy(b, "FWMETA02", 8);
  fw_progress_t q;
  assert_int_equal(fw_progress_decode(b, FW_PROGRESS_BYTES_2, &q, NULL, 0), 0);
  fw_progress_t want = p;
  want.policy = LEARN_POLICY_GREEDY;
  want.actor_bytes = 0;
  want.revision = 2;
  assert_true(same(&want, &q));
  char why[FW_PROGRESS_WHY_MAX];
  assert_int_equal(fw_progress_decode(b, FW_PROGRESS_BYTES, &q, why, sizeof why), -1);
  assert_non_null(strstr(why, "unknown format (88 bytes"));
  put_u32(b, 16, 7U);
  assert_int_equal(fw_progress_decode(b, FW_PROGRESS_BYTES_2, &q, why, sizeof why), -1);
  assert_non_null(strstr(why, "phase 7"));
}

// Revision 1 (96 bytes, or 104 with the hold past the obstacle) shares bytes 8-55: it is read with
// the same checks, and legacy_shift says whether its policy shift (a at 56, b at 64, the
// imitation's weight at 80) had moved; its other fields are not used.
static void test_progress_revision_1_read(void** state) {
  (void)state;
  const fw_progress_t p = sample();
  const size_t sizes[] = {96, 104};
  for (size_t k = 0; k < 2; ++k) {
    uint8_t b[FW_PROGRESS_READ_MAX];
    memset(b, 0, sizeof b);
    (void)fw_progress_encode(&p, b);
    memcpy(b, "FWMETA01", 8);
    memset(b + 56, 0, sizeof b - 56);  // revision 3's fields from here on are revision 1's shift
    put_u32(b, 76, 1U);     // the shift's terms revision
    put_f64(b, 88, 0.4);    // a clearance
    if (sizes[k] == 104) {
      put_u32(b, 96, 11U);  // a hold of 10 steps
    }
    fw_progress_t q;
    assert_int_equal(fw_progress_decode(b, sizes[k], &q, NULL, 0), 0);
    fw_progress_t want = p;  // no shift: legacy_shift false, like p; no actor
    want.policy = LEARN_POLICY_GREEDY;
    want.actor_bytes = 0;
    want.revision = 1;
    assert_true(same(&want, &q));
    const size_t shift_at[] = {56, 64, 80};
    for (size_t i = 0; i < 3; ++i) {
      uint8_t c[FW_PROGRESS_READ_MAX];
      memcpy(c, b, sizeof c);
      put_f64(c, shift_at[i], -0.25);
      assert_int_equal(fw_progress_decode(c, sizes[k], &q, NULL, 0), 0);
      assert_true(q.legacy_shift);
      assert_int_equal(q.run_id, 130);
    }
    // The common fields are checked as in revision 3.
    put_u32(b, 16, 7U);
    char why[FW_PROGRESS_WHY_MAX];
    assert_int_equal(fw_progress_decode(b, sizes[k], &q, why, sizeof why), -1);
    assert_non_null(strstr(why, "phase 7"));
    // Revision 1's magic with revision 2's size is no section at all.
    assert_int_equal(fw_progress_decode(b, FW_PROGRESS_BYTES, &q, why, sizeof why), -1);
    assert_non_null(strstr(why, "unknown format"));
  }
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_progress_round_trip_and_layout),
      cmocka_unit_test(test_progress_out_of_range_refused),
      cmocka_unit_test(test_progress_revision_3_read),
      cmocka_unit_test(test_progress_revision_2_read),
      cmocka_unit_test(test_progress_revision_1_read),
  };
  return cmocka_run_group_tests_name("firmware.progress", tests, NULL, NULL);
}
