// SPDX-License-Identifier: MIT
// Run schedule: the paper's 30 + 35 runs with a block every 5, aborted runs repeated, the three
// phase-switch modes, evaluate-only, resume from saved progress, and the 95 % interval.

#include "learn/schedule.h"

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

static learn_schedule_config_t paper(void) {
  const learn_schedule_config_t c = {.eval_every = 5,
                                   .eval_starts = 10,
                                   .eval_at_start = false,
                                   .phase_one_runs = 30,
                                   .phase_two_runs = 35,
                                   .switch_mode = LEARN_SWITCH_RUNS,
                                   .auto_min_runs = 5,
                                   .auto_ratio = 1.0,
                                   .evaluate_only = false};
  return c;
}

// The paper's schedule: 65 training runs, 13 blocks after runs 5..65, blocks 0..5 in phase one,
// 6..12 in phase two, then done.
static void test_schedule_paper_runs_and_blocks(void** state) {
  (void)state;
  learn_schedule_t s;
  const learn_schedule_config_t c = paper();
  learn_schedule_init(&s, &c, NULL);
  int training = 0;
  int evals = 0;
  int blocks = 0;
  for (int guard = 0; guard < 1000 && !learn_schedule_done(&s); ++guard) {
    const learn_plan_t plan = learn_schedule_next(&s);
    learn_eval_block_t b;
    if (plan.kind == LEARN_RUN_TRAINING) {
      assert_int_equal(plan.training_index, training);
      assert_int_equal(plan.phase, training < 30 ? 1 : 2);
      training++;
      assert_false(learn_schedule_finish_run(&s, 100, true, false, &b));
    } else {
      assert_int_equal(plan.kind, LEARN_RUN_EVAL);
      assert_int_equal(plan.eval_index, evals % 10);
      evals++;
      if (learn_schedule_finish_run(&s, 50 + plan.eval_index, true, false, &b)) {
        assert_int_equal(b.block, blocks);
        assert_int_equal(b.training_runs, 5 * (blocks + 1));
        assert_int_equal(b.phase, blocks < 6 ? 1 : 2);
        assert_int_equal(b.successes, 10);
        assert_true(fabs(b.mean_steps - 54.5) < 1e-12);
        blocks++;
      }
    }
  }
  assert_true(learn_schedule_done(&s));
  assert_int_equal(training, 65);
  assert_int_equal(evals, 130);
  assert_int_equal(blocks, 13);
  assert_int_equal(learn_schedule_next(&s).kind, LEARN_RUN_NONE);
}

// Aborted training runs do not count; an aborted evaluation run repeats the same start pose.
static void test_schedule_aborted_runs_repeat(void** state) {
  (void)state;
  learn_schedule_t s;
  learn_schedule_config_t c = paper();
  c.eval_every = 2;
  c.eval_starts = 3;
  learn_schedule_init(&s, &c, NULL);
  learn_schedule_finish_run(&s, 10, true, true, NULL);  // aborted
  assert_int_equal(learn_schedule_next(&s).training_index, 0);
  learn_schedule_finish_run(&s, 10, true, false, NULL);
  learn_schedule_finish_run(&s, 10, true, false, NULL);
  assert_int_equal(learn_schedule_next(&s).kind, LEARN_RUN_EVAL);
  learn_schedule_finish_run(&s, 10, true, false, NULL);
  assert_int_equal(learn_schedule_next(&s).eval_index, 1);
  learn_schedule_finish_run(&s, 10, true, true, NULL);  // aborted: same pose again
  assert_int_equal(learn_schedule_next(&s).eval_index, 1);
  learn_schedule_finish_run(&s, 20, false, false, NULL);
  learn_eval_block_t b;
  assert_true(learn_schedule_finish_run(&s, 30, true, false, &b));
  assert_int_equal(b.successes, 2);
  assert_int_equal(b.steps[1], 20);
  assert_false(b.success[1]);
  assert_true(fabs(b.mean_steps - 20.0) < 1e-12);
  assert_int_equal(s.p.training_runs, 2);
}

// Operator mode: phase one continues past phase_one_runs until START_PHASE_TWO; a request
// during a block switches after the block, which still counts as phase one.
static void test_schedule_operator_switch(void** state) {
  (void)state;
  learn_schedule_t s;
  learn_schedule_config_t c = paper();
  c.switch_mode = LEARN_SWITCH_OPERATOR;
  c.phase_one_runs = 2;
  c.phase_two_runs = 3;
  c.eval_every = 4;
  c.eval_starts = 2;
  learn_schedule_init(&s, &c, NULL);
  for (int i = 0; i < 4; ++i) {
    assert_int_equal(learn_schedule_next(&s).phase, 1);
    learn_schedule_finish_run(&s, 10, true, false, NULL);
  }
  assert_int_equal(learn_schedule_next(&s).kind, LEARN_RUN_EVAL);
  learn_schedule_request_phase_two(&s);
  learn_schedule_finish_run(&s, 10, true, false, NULL);
  learn_eval_block_t b;
  assert_true(learn_schedule_finish_run(&s, 10, true, false, &b));
  assert_int_equal(b.phase, 1);
  assert_int_equal(learn_schedule_next(&s).phase, 2);
  assert_int_equal(learn_schedule_next(&s).kind, LEARN_RUN_TRAINING);
  // Three phase-two runs, then the final block (even though 7 is not a multiple of 4).
  for (int i = 0; i < 3; ++i) {
    learn_schedule_finish_run(&s, 10, true, false, NULL);
  }
  assert_int_equal(learn_schedule_next(&s).kind, LEARN_RUN_EVAL);
  learn_schedule_finish_run(&s, 10, true, false, NULL);
  assert_true(learn_schedule_finish_run(&s, 10, true, false, &b));
  assert_int_equal(b.phase, 2);
  assert_true(learn_schedule_done(&s));
}

static void run_block(learn_schedule_t* s, int32_t steps, bool success, learn_eval_block_t* b) {
  for (int i = 0; i < s->cfg.eval_starts; ++i) {
    assert_int_equal(learn_schedule_next(s).kind, LEARN_RUN_EVAL);
    learn_schedule_finish_run(s, steps, success, false, b);
  }
}

// Auto mode: switches after the first block that reaches the goal from every start at most as
// slowly as the examples, not before auto_min_runs, and at the latest after phase_one_runs.
static void test_schedule_auto_switch_when_ready(void** state) {
  (void)state;
  learn_schedule_t s;
  learn_schedule_config_t c = paper();
  c.switch_mode = LEARN_SWITCH_AUTO;
  c.auto_min_runs = 10;
  c.eval_starts = 3;
  learn_schedule_init(&s, &c, NULL);
  learn_eval_block_t b;
  // Examples average 100 steps.
  for (int i = 0; i < 5; ++i) {
    learn_schedule_finish_run(&s, i % 2 == 0 ? 90 : 110, true, false, NULL);
  }
  run_block(&s, 50, true, &b);  // good, but only 5 runs: too early
  assert_int_equal(s.p.phase, 1);
  for (int i = 0; i < 5; ++i) {
    learn_schedule_finish_run(&s, 100, true, false, NULL);
  }
  run_block(&s, 101, true, &b);  // slower than the examples: not ready
  assert_int_equal(s.p.phase, 1);
  for (int i = 0; i < 5; ++i) {
    learn_schedule_finish_run(&s, 100, true, false, NULL);
  }
  run_block(&s, 99, false, &b);  // a start failed: not ready
  assert_int_equal(s.p.phase, 1);
  for (int i = 0; i < 5; ++i) {
    learn_schedule_finish_run(&s, 100, true, false, NULL);
  }
  run_block(&s, 99, true, &b);
  assert_int_equal(b.phase, 1);
  assert_int_equal(s.p.phase, 2);
  assert_int_equal(s.p.phase_one_runs, 20);
  assert_int_equal(s.p.best_example_steps, 90);

  // Never ready: the switch comes after phase_one_runs.
  c.phase_one_runs = 10;
  learn_schedule_init(&s, &c, NULL);
  for (int k = 0; k < 2; ++k) {
    for (int i = 0; i < 5; ++i) {
      learn_schedule_finish_run(&s, 100, true, false, NULL);
    }
    run_block(&s, 500, false, &b);
  }
  assert_int_equal(s.p.phase, 2);
}

// Evaluate-only: one block from the fixed poses, then done.
static void test_schedule_evaluate_only_one_block(void** state) {
  (void)state;
  learn_schedule_t s;
  learn_schedule_config_t c = paper();
  c.evaluate_only = true;
  learn_schedule_init(&s, &c, NULL);
  learn_eval_block_t b;
  run_block(&s, 42, true, &b);
  assert_true(learn_schedule_done(&s));
  assert_int_equal(b.n_starts, 10);
  assert_true(fabs(b.ci95_halfwidth) < 1e-12);
}

// Resuming from saved progress continues the counts, the phase and the block cadence.
static void test_schedule_resume_continues(void** state) {
  (void)state;
  learn_schedule_t s;
  const learn_schedule_config_t c = paper();
  learn_schedule_progress_t p;
  memset(&p, 0, sizeof p);
  p.phase = 2;
  p.training_runs = 42;
  p.phase_one_runs = 30;
  p.phase_two_runs = 12;
  p.eval_blocks = 8;
  learn_schedule_init(&s, &c, &p);
  assert_int_equal(learn_schedule_next(&s).training_index, 42);
  assert_int_equal(learn_schedule_next(&s).phase, 2);
  for (int i = 0; i < 3; ++i) {
    learn_schedule_finish_run(&s, 10, true, false, NULL);
  }
  learn_eval_block_t b;
  run_block(&s, 10, true, &b);
  assert_int_equal(b.block, 8);
  assert_int_equal(b.training_runs, 45);
  // Saved after the training run that made a block due: the block comes first (it was not run).
  p.training_runs = 45;
  p.phase_two_runs = 15;
  learn_schedule_init(&s, &c, &p);
  assert_int_equal(learn_schedule_next(&s).kind, LEARN_RUN_EVAL);
  run_block(&s, 10, true, &b);
  assert_int_equal(b.block, 8);
  assert_int_equal(b.training_runs, 45);
  assert_int_equal(learn_schedule_next(&s).kind, LEARN_RUN_TRAINING);
  // ... at the end of phase one too: the block in phase one, then the switch.
  memset(&p, 0, sizeof p);
  p.phase = 1;
  p.training_runs = 30;
  p.phase_one_runs = 30;
  p.eval_blocks = 5;
  learn_schedule_init(&s, &c, &p);
  assert_int_equal(learn_schedule_next(&s).kind, LEARN_RUN_EVAL);
  assert_int_equal(learn_schedule_next(&s).phase, 1);
  run_block(&s, 10, true, &b);
  assert_int_equal(b.phase, 1);
  assert_int_equal(learn_schedule_next(&s).phase, 2);
  assert_int_equal(learn_schedule_next(&s).kind, LEARN_RUN_TRAINING);
  // Its block done, the same boundary resumes into training (phase two).
  p.eval_blocks = 6;
  learn_schedule_init(&s, &c, &p);
  assert_int_equal(learn_schedule_next(&s).kind, LEARN_RUN_TRAINING);
  // An ended schedule resumes into one final block.
  p.phase_two_runs = 35;
  p.training_runs = 65;
  learn_schedule_init(&s, &c, &p);
  run_block(&s, 10, true, &b);
  assert_true(learn_schedule_done(&s));
}

// Mean and 95 % half-width against a hand computation; fewer than two values give 0 width.
static void test_schedule_mean_ci95_hand_computed(void** state) {
  (void)state;
  const double v[3] = {10.0, 12.0, 14.0};
  double m = 0.0;
  double h = 0.0;
  learn_mean_ci95(v, 3, &m, &h);
  assert_true(fabs(m - 12.0) < 1e-12);
  assert_true(fabs(h - 4.303 * 2.0 / sqrt(3.0)) < 1e-9);
  learn_mean_ci95(v, 1, &m, &h);
  assert_true(fabs(m - 10.0) < 1e-12 && fabs(h) < 1e-12);
  learn_mean_ci95(v, 0, &m, &h);
  assert_true(fabs(m) < 1e-12);
  assert_true(fabs(learn_student_t975(9) - 2.262) < 1e-12);
  assert_true(learn_student_t975(100) < 2.0 && learn_student_t975(100) > 1.96);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_schedule_paper_runs_and_blocks),
      cmocka_unit_test(test_schedule_aborted_runs_repeat),
      cmocka_unit_test(test_schedule_operator_switch),
      cmocka_unit_test(test_schedule_auto_switch_when_ready),
      cmocka_unit_test(test_schedule_evaluate_only_one_block),
      cmocka_unit_test(test_schedule_resume_continues),
      cmocka_unit_test(test_schedule_mean_ci95_hand_computed),
  };
  return cmocka_run_group_tests_name("learn.schedule", tests, NULL, NULL);
}
