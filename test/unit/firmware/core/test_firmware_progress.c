// SPDX-License-Identifier: MIT
// The checkpoint's controller section: exact round trips, the byte layout (96 bytes, or 104 with
// the hold past the obstacle), every field out of its documented range refused with the field
// named, and which clearance and hold a shift resumes with.
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
  p.task = FW_TASK_OBSTACLES;
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
  p.shift.gain = 0.8125;
  p.shift.centring = -1.5;
  p.shift.pairs = 17;
  p.shift.imitation = -0.375;
  p.obstacle_clearance_m = 0.45;
  p.pass_hold_recorded = true;
  p.obstacle_pass_hold_steps = 10;
  return p;
}

static void put_u32(uint8_t* b, size_t off, uint32_t v) {
  for (int i = 0; i < 4; ++i) {
    b[off + (size_t)i] = (uint8_t)(v >> (8 * i));
  }
}

// Encodes p, applies the edit (offset, 32-bit value), decodes: expects a refusal naming `what`.
static void expect_refused(const fw_progress_t* p, size_t off, uint32_t v, const char* what) {
  uint8_t b[FW_PROGRESS_BYTES];
  const size_t n = fw_progress_encode(p, b);
  put_u32(b, off, v);
  fw_progress_t out = sample();
  out.run_id = -77;
  char why[FW_PROGRESS_WHY_MAX];
  assert_int_equal(fw_progress_decode(b, n, &out, why, sizeof why), -1);
  if (strstr(why, what) == NULL) {
    fail_msg("offset %zu value %u: reason '%s' does not name '%s'", off, (unsigned)v, why, what);
  }
  assert_int_equal(out.run_id, -77);  // untouched on failure
}

// Encode then decode gives the same values; the layout matches the header's table; a fresh
// schedule (no run yet: run id -1) round-trips too.
static void test_progress_round_trip_and_layout(void** state) {
  (void)state;
  const fw_progress_t p = sample();
  uint8_t b[FW_PROGRESS_BYTES];
  size_t bn = fw_progress_encode(&p, b);
  assert_int_equal(bn, FW_PROGRESS_BYTES);  // it records the hold: 104 bytes
  assert_memory_equal(b, "FWMETA01", 8);
  assert_int_equal(b[8], 1);    // task
  assert_int_equal(b[12], 4);   // state dimension
  assert_int_equal(b[16], 2);   // phase
  assert_int_equal(b[20], 42);  // training runs
  assert_int_equal(b[52], 131); // run id + 1
  double shift[2];
  memcpy(shift, b + 56, sizeof shift);  // little-endian doubles (the hosts this runs on)
  assert_true(shift[0] == 0.8125 && shift[1] == -1.5);
  assert_int_equal(b[72], 17);  // pairs that moved the shift
  assert_int_equal(b[76], FW_PAIR_TERMS_REVISION);
  double imitation;
  memcpy(&imitation, b + 80, sizeof imitation);
  assert_true(imitation == -0.375);
  double clearance;
  memcpy(&clearance, b + 88, sizeof clearance);
  assert_true(clearance == 0.45);
  assert_int_equal(b[96], 11);  // the hold past the obstacle + 1
  assert_int_equal(b[100] | b[101] | b[102] | b[103], 0);  // reserved
  fw_progress_t q;
  assert_int_equal(fw_progress_decode(b, bn, &q, NULL, 0), 0);
  assert_memory_equal(&q, &p, sizeof p);
  fw_progress_t fresh;
  memset(&fresh, 0, sizeof fresh);
  fresh.task = FW_TASK_CORRIDOR;
  fresh.state_dim = 3;
  fresh.schedule.phase = 1;
  fresh.run_id = -1;
  bn = fw_progress_encode(&fresh, b);
  assert_int_equal(bn, FW_PROGRESS_BYTES_BASE);  // no hold recorded: the 96 bytes older controllers read
  assert_int_equal(fw_progress_decode(b, bn, &q, NULL, 0), 0);
  assert_memory_equal(&q, &fresh, sizeof fresh);
  // An obstacle section without the hold (written before the field) decodes as not recorded.
  fw_progress_t unrecorded = p;
  unrecorded.pass_hold_recorded = false;
  unrecorded.obstacle_pass_hold_steps = 0;
  bn = fw_progress_encode(&unrecorded, b);
  assert_int_equal(bn, FW_PROGRESS_BYTES_BASE);
  assert_int_equal(fw_progress_decode(b, bn, &q, NULL, 0), 0);
  assert_memory_equal(&q, &unrecorded, sizeof unrecorded);
  // A hold of 0 (never hold) is recorded as 1: distinct from "not recorded".
  fw_progress_t never = p;
  never.obstacle_pass_hold_steps = 0;
  bn = fw_progress_encode(&never, b);
  assert_int_equal(bn, FW_PROGRESS_BYTES);
  assert_int_equal(b[96], 1);
  assert_int_equal(fw_progress_decode(b, bn, &q, NULL, 0), 0);
  assert_true(q.pass_hold_recorded && q.obstacle_pass_hold_steps == 0);
}

// Every field outside its documented range is refused, with the field in the reason.
static void test_progress_out_of_range_refused(void** state) {
  (void)state;
  const fw_progress_t p = sample();
  expect_refused(&p, 8, 2, "task 2");
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
  // The learned policy's shift: finite and within +-FW_PAIR_SHIFT_MAX (an older file's zeros are
  // no shift, tested by the fresh round trip above).
  const double bad_shift[] = {NAN, INFINITY, -INFINITY, 4.0000001, -4.5};
  for (size_t i = 0; i < sizeof bad_shift / sizeof bad_shift[0]; ++i) {
    q = p;
    q.shift.gain = bad_shift[i];
    expect_refused(&q, 8, 1, "learned policy shift");
    q = p;
    q.shift.centring = bad_shift[i];
    expect_refused(&q, 8, 1, "learned policy shift");
  }
  expect_refused(&p, 72, 0x80000000U, "pairs that moved the shift");
  // The imitation's weight: finite and within [-1, 1] (an older file's zeros: weight 0).
  const double bad_imitation[] = {NAN, INFINITY, -INFINITY, 1.0000001, -1.5};
  for (size_t i = 0; i < sizeof bad_imitation / sizeof bad_imitation[0]; ++i) {
    q = p;
    q.shift.imitation = bad_imitation[i];
    expect_refused(&q, 8, 1, "learned imitation weight");
  }
  // The obstacle shift's clearance: 0 (not recorded) or within pair_obstacle_clearance_m's
  // range, and 0 in a corridor file.
  const double bad_clearance[] = {NAN, INFINITY, -0.45, 0.29, 1.2000001, 5e-324};
  for (size_t i = 0; i < sizeof bad_clearance / sizeof bad_clearance[0]; ++i) {
    q = p;
    q.obstacle_clearance_m = bad_clearance[i];
    expect_refused(&q, 8, 1, "obstacle pair clearance");
  }
  q = p;
  q.task = FW_TASK_CORRIDOR;
  q.state_dim = 3;
  expect_refused(&q, 8, 0, "obstacle pair clearance 0.45");
  // The hold past the obstacle: 1..FW_PROGRESS_PASS_HOLD_STEPS_MAX + 1 in a 104-byte section, and
  // only in an obstacle file; the reserved word 0.
  expect_refused(&p, 96, 0U, "obstacle pass hold + 1 = 0");
  expect_refused(&p, 96, FW_PROGRESS_PASS_HOLD_STEPS_MAX + 2U, "obstacle pass hold + 1 = 102");
  expect_refused(&p, 96, 0xFFFFFFFFU, "obstacle pass hold");
  expect_refused(&p, 100, 1U, "reserved bytes 100-103");
  q = p;
  q.task = FW_TASK_CORRIDOR;
  q.state_dim = 3;
  q.obstacle_clearance_m = 0.0;
  expect_refused(&q, 8, 0, "obstacle pass hold + 1 = 11, expected (obstacle task)");
  uint8_t b[FW_PROGRESS_BYTES];
  size_t bn = 0;
  bn = fw_progress_encode(&p, b);
  fw_progress_t out;
  char why[FW_PROGRESS_WHY_MAX];
  bn = fw_progress_encode(&p, b);
  assert_int_equal(fw_progress_decode(b, bn - 1U, &out, why, sizeof why), -1);
  assert_non_null(strstr(why, "unknown format (103 bytes"));
  assert_int_equal(fw_progress_decode(b, FW_PROGRESS_BYTES_BASE - 1U, &out, why, sizeof why), -1);
  assert_non_null(strstr(why, "unknown format (95 bytes"));
  assert_int_equal(fw_progress_decode(b, FW_PROGRESS_BYTES_BASE + 4U, &out, why, sizeof why), -1);
  assert_non_null(strstr(why, "expected 96 or 104"));
  b[0] = 'X';
  assert_int_equal(fw_progress_decode(b, bn, &out, why, sizeof why), -1);
  assert_non_null(strstr(why, "other magic"));
  // The edges of the ranges are accepted.
  q = p;
  q.schedule.eval_blocks = INT32_MAX;
  q.run_id = INT32_MAX - 1;
  q.shift.gain = 4.0;
  q.shift.centring = -4.0;
  q.shift.imitation = -1.0;
  bn = fw_progress_encode(&q, b);
  assert_int_equal(fw_progress_decode(b, bn, &out, why, sizeof why), 0);
  assert_int_equal(out.run_id, INT32_MAX - 1);
  q.shift.imitation = 1.0;
  q.obstacle_clearance_m = FW_PAIR_OBSTACLE_CLEARANCE_MIN_M;
  bn = fw_progress_encode(&q, b);
  assert_int_equal(fw_progress_decode(b, bn, &out, why, sizeof why), 0);
  q.obstacle_clearance_m = FW_PAIR_OBSTACLE_CLEARANCE_MAX_M;
  bn = fw_progress_encode(&q, b);
  assert_int_equal(fw_progress_decode(b, bn, &out, why, sizeof why), 0);
  assert_true(out.obstacle_clearance_m == FW_PAIR_OBSTACLE_CLEARANCE_MAX_M);
  q.obstacle_pass_hold_steps = FW_PROGRESS_PASS_HOLD_STEPS_MAX;
  bn = fw_progress_encode(&q, b);
  assert_int_equal(fw_progress_decode(b, bn, &out, why, sizeof why), 0);
  assert_int_equal(out.obstacle_pass_hold_steps, FW_PROGRESS_PASS_HOLD_STEPS_MAX);
}

// Which hold past the obstacle a shift resumes with (fw_progress_pass_hold_fits): the one
// recorded; any where the file records none (written before the field: unknown,
// fw_progress_pass_hold_unknown), for an obstacle shift that never moved and in the corridor; and
// what a writer records (fw_progress_record_pass_hold).
static void test_progress_pass_hold_fits(void** state) {
  (void)state;
  fw_progress_t p = sample();  // obstacles, a 0.8125, b -1.5, w -0.375, learned holding 10 steps
  int32_t learned = -1;
  assert_true(fw_progress_pass_hold_fits(&p, 10, &learned) && learned == 10);
  learned = -1;
  assert_false(fw_progress_pass_hold_fits(&p, 9, &learned));
  assert_int_equal(learned, 10);
  assert_false(fw_progress_pass_hold_fits(&p, 0, NULL));
  assert_false(fw_progress_pass_hold_unknown(&p));
  p.shift.gain = 0.0;
  p.shift.centring = 0.0;
  assert_false(fw_progress_pass_hold_fits(&p, 9, NULL));  // the weight alone was vetted with the hold too
  // Not recorded (a file written before the field): learned with none or with 10, the file cannot
  // say which; it resumes under any hold, and the caller says so.
  p = sample();
  p.pass_hold_recorded = false;
  p.obstacle_pass_hold_steps = 0;
  assert_true(fw_progress_pass_hold_fits(&p, 0, &learned) && learned == -1);
  assert_true(fw_progress_pass_hold_fits(&p, 10, NULL));
  assert_true(fw_progress_pass_hold_unknown(&p));
  p.shift.gain = 0.0;
  p.shift.centring = 0.0;
  assert_true(fw_progress_pass_hold_unknown(&p));  // w alone moved
  p.shift.imitation = 0.0;
  assert_true(fw_progress_pass_hold_fits(&p, 10, NULL));  // a shift that never moved: nothing to know
  assert_false(fw_progress_pass_hold_unknown(&p));
  p = sample();
  p.shift.imitation = 0.0;
  p.shift.gain = 0.0;
  p.shift.centring = 0.0;
  assert_true(fw_progress_pass_hold_fits(&p, 3, NULL));   // recorded, but the shift never moved
  p = sample();
  p.task = FW_TASK_CORRIDOR;
  p.pass_hold_recorded = false;
  assert_true(fw_progress_pass_hold_fits(&p, 10, NULL) && fw_progress_pass_hold_fits(&p, 0, NULL));
  assert_false(fw_progress_pass_hold_unknown(&p));
  // Recording: with an obstacle shift that moved (any of a, b, w), else none.
  p = sample();
  fw_progress_record_pass_hold(&p, 7);
  assert_true(p.pass_hold_recorded && p.obstacle_pass_hold_steps == 7);
  p.shift.gain = 0.0;
  p.shift.centring = 0.0;
  fw_progress_record_pass_hold(&p, 0);
  assert_true(p.pass_hold_recorded && p.obstacle_pass_hold_steps == 0);
  p.shift.imitation = 0.0;
  fw_progress_record_pass_hold(&p, 7);
  assert_true(!p.pass_hold_recorded && p.obstacle_pass_hold_steps == 0);
  p = sample();
  p.task = FW_TASK_CORRIDOR;
  fw_progress_record_pass_hold(&p, 7);
  assert_false(p.pass_hold_recorded);
}

// Which clearance a shift resumes with (fw_progress_clearance_fits): the one recorded, 0.5 m where
// none is (a file written before the field), any for a shift whose terms are 0 or in the corridor.
static void test_progress_clearance_fits(void** state) {
  (void)state;
  fw_progress_t p = sample();  // obstacles, a 0.8125, b -1.5, learned at 0.45 m
  double learned = 0.0;
  assert_true(fw_progress_clearance_fits(&p, 0.45, &learned) && learned == 0.45);
  assert_false(fw_progress_clearance_fits(&p, 0.5, &learned));
  assert_false(fw_progress_clearance_fits(&p, 0.45000000000000007, NULL));
  p.obstacle_clearance_m = 0.0;
  assert_true(fw_progress_clearance_fits(&p, FW_PROGRESS_CLEARANCE_UNRECORDED_M, &learned) && learned == 0.5);
  assert_false(fw_progress_clearance_fits(&p, 0.45, NULL));
  p.shift.gain = 0.0;
  assert_false(fw_progress_clearance_fits(&p, 0.45, NULL));  // the bend's coefficient alone is a policy too
  p.shift.centring = 0.0;
  assert_true(fw_progress_clearance_fits(&p, 0.45, NULL));   // nothing learned on the terms
  p = sample();
  p.task = FW_TASK_CORRIDOR;
  p.obstacle_clearance_m = 0.0;
  assert_true(fw_progress_clearance_fits(&p, 0.45, NULL) && fw_progress_clearance_fits(&p, 0.5, NULL));
  // -0.0 is "not recorded" too, and round-trips as written.
  p = sample();
  p.obstacle_clearance_m = -0.0;
  uint8_t b[FW_PROGRESS_BYTES];
  size_t bn = 0;
  bn = fw_progress_encode(&p, b);
  fw_progress_t q;
  assert_int_equal(fw_progress_decode(b, bn, &q, NULL, 0), 0);
  assert_true(fw_progress_clearance_fits(&q, 0.5, &learned) && learned == 0.5);
  // What a writer records (fw_progress_record_clearance): the clearance with an obstacle shift
  // learned on the terms, else 0 (so a file with nothing learned on them stays readable by a
  // controller older than the field).
  p = sample();
  fw_progress_record_clearance(&p, 0.45);
  assert_true(p.obstacle_clearance_m == 0.45);
  p.shift.gain = 0.0;
  fw_progress_record_clearance(&p, 0.45);
  assert_true(p.obstacle_clearance_m == 0.45);  // b alone is learned too
  p.shift.centring = 0.0;
  p.shift.imitation = -0.5;                     // the weight does not depend on the clearance
  fw_progress_record_clearance(&p, 0.45);
  assert_true(p.obstacle_clearance_m == 0.0);
  p = sample();
  p.task = FW_TASK_CORRIDOR;
  fw_progress_record_clearance(&p, 0.45);
  assert_true(p.obstacle_clearance_m == 0.0);
}

// A file written before the terms revision (byte 76 = 0) keeps the policy it learned: the
// obstacle task's shift a g + b bend becomes a (g + bend) + (b - a) bend, the corridor's stays;
// a conversion out of range and a newer revision are refused.
static void test_progress_terms_revision(void** state) {
  (void)state;
  fw_progress_t p = sample();  // obstacles: a 0.8125, b -1.5
  uint8_t b[FW_PROGRESS_BYTES];
  size_t bn = 0;
  bn = fw_progress_encode(&p, b);
  put_u32(b, 76, 0U);
  fw_progress_t q;
  char why[FW_PROGRESS_WHY_MAX];
  assert_int_equal(fw_progress_decode(b, bn, &q, why, sizeof why), 0);
  assert_true(q.shift.gain == 0.8125 && q.shift.centring == -1.5 - 0.8125);
  p.task = FW_TASK_CORRIDOR;
  p.state_dim = 3;
  p.obstacle_clearance_m = 0.0;
  p.pass_hold_recorded = false;
  p.obstacle_pass_hold_steps = 0;
  bn = fw_progress_encode(&p, b);
  put_u32(b, 76, 0U);
  assert_int_equal(fw_progress_decode(b, bn, &q, why, sizeof why), 0);
  assert_true(q.shift.gain == 0.8125 && q.shift.centring == -1.5);
  p = sample();
  p.shift.gain = 3.0;
  p.shift.centring = -2.0;  // -5 in today's terms: beyond FW_PAIR_SHIFT_MAX
  expect_refused(&p, 76, 0U, "learned policy shift");
  const fw_progress_t newest = sample();
  expect_refused(&newest, 76, FW_PAIR_TERMS_REVISION + 1U, "shift terms revision 2");
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_progress_round_trip_and_layout),
      cmocka_unit_test(test_progress_out_of_range_refused),
      cmocka_unit_test(test_progress_terms_revision),
      cmocka_unit_test(test_progress_clearance_fits),
      cmocka_unit_test(test_progress_pass_hold_fits),
  };
  return cmocka_run_group_tests_name("firmware.progress", tests, NULL, NULL);
}
