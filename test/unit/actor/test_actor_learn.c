// SPDX-License-Identifier: MIT
// The actor learns: cloning reproduces its teacher, the slope of the returns moves it past the
// teacher on the toy task, the trust radius keeps it near the recorded actions while only the
// teacher drives, the significance test stops most steps on noise, the rewarded window keeps a
// slope after a streak of failed runs, the work is bounded per slice and its result does not depend on the
// slicing, nothing is allocated, and a diverging fit is undone.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include <b21r_test/alloc_counter.h>

#include "actor_test_util.h"

// Before any run the actor is untrained (the middle of the bounds); the first run clones the
// teacher, whose action is about 0.
static void test_actor_first_run_clones_teacher(void** state) {
  (void)state;
  const actor_config_t cfg = toy_config();
  void* mem = NULL;
  actor_t* a = toy_actor(&cfg, &mem);
  const double s[2] = {0.5, 0.0};
  double act = 7.0;
  assert_int_equal(actor_act(a, s, &act), ACTOR_UNTRAINED);
  assert_true(act == 0.0);
  rng_t rng;
  rng_seed(&rng, 3);
  toy_run(a, TOY_TEACHER, &rng);
  toy_end_run(a, 1000);
  assert_true(actor_trained(a));
  assert_int_equal(actor_counters(a)->clones, 1);
  assert_int_equal(actor_counters(a)->fits, 0);
  const double m = toy_mean_action(a);
  print_message("after cloning the teacher (action about 0): mean action %.3f, loss %.4f\n", m,
                actor_counters(a)->last_fit_loss);
  assert_true(fabs(m) < 0.1);
  free(mem);
}

// Teacher runs, then the actor drives: its action rises well above the teacher's (about 0)
// towards the best action (+1), one bounded step per run.
static void test_actor_moves_past_teacher(void** state) {
  (void)state;
  const actor_config_t cfg = toy_config();
  void* mem = NULL;
  actor_t* a = toy_actor(&cfg, &mem);
  rng_t rng;
  rng_seed(&rng, 11);
  toy_runs(a, TOY_TEACHER, &rng, 5);
  const double after_teacher = toy_mean_action(a);
  int steps = 0;
  for (int run = 0; run < 15; ++run) {
    steps = toy_run(a, TOY_ACTOR, &rng);
    toy_end_run(a, 5000);
  }
  const double after = toy_mean_action(a);
  const actor_counters_t* c = actor_counters(a);
  print_message("mean action after 5 teacher runs %.3f, after 15 own runs %.3f (last run %d steps); queries with a "
                "slope %llu of %llu, last mean step %.3f\n",
                after_teacher, after, steps, (unsigned long long)c->queries_with_slope,
                (unsigned long long)c->queries, c->last_mean_step);
  assert_true(after > after_teacher + 0.5);
  assert_true(c->queries_with_slope > c->queries / 2);
  assert_int_equal(c->fits, 19);
  free(mem);
}

// While only the teacher drives, its runs never answer the actor's moves: without a bound the
// steps add up run after run (the local models are linear, the slope keeps its sign) and the
// actor's action walks far past anything the runs did; the trust radius keeps it within that
// distance of the recorded actions (about 0, the teacher's noise aside). Same runs both ways.
static void test_actor_trust_radius_bounds_drift_from_data(void** state) {
  (void)state;
  double mean[2] = {0.0, 0.0};
  const double radius[2] = {0.0, 0.125};
  for (int v = 0; v < 2; ++v) {
    actor_config_t cfg = toy_config();
    cfg.trust_radius = radius[v];
    cfg.slope_min_t = 0.0;  // every slope steps: the walk the radius bounds
    void* mem = NULL;
    actor_t* a = toy_actor(&cfg, &mem);
    rng_t rng;
    rng_seed(&rng, 13);
    toy_runs(a, TOY_TEACHER, &rng, 20);
    mean[v] = toy_mean_action(a);
    free(mem);
  }
  print_message("mean action after 20 teacher runs (teacher about 0): no bound %.3f, trust radius 0.125 %.3f\n",
                mean[0], mean[1]);
  assert_true(mean[0] > 0.3);
  assert_true(mean[1] < 0.15);
}

// Where the action changes nothing but the state's last-action entry, every slope of the return
// in the action is the value model's noise (the goal's place is drawn per run, so a run's returns
// share it); while the teacher drives (its runs never answer the actor) the steps add up wherever
// that noise keeps its sign. With the significance test the actor steps only on slopes of at
// least 3 standard errors (clustered by run) and stays at the teacher's action; a real slope (the
// toy task's) still moves it past the teacher.
static void test_actor_slope_test_stops_walk_on_noise(void** state) {
  (void)state;
  double spread[2] = {0.0, 0.0};
  uint64_t stepped[2] = {0, 0};
  uint64_t with_slope[2] = {0, 0};
  const double min_t[2] = {0.0, 3.0};
  for (int v = 0; v < 2; ++v) {
    actor_config_t cfg = toy_config();
    cfg.slope_min_t = min_t[v];
    void* mem = NULL;
    actor_t* a = toy_actor(&cfg, &mem);
    rng_t rng;
    rng_seed(&rng, 17);
    for (int run = 0; run < 20; ++run) {
      toy_run_effect(a, TOY_TEACHER, &rng, 0.0);
      toy_end_run(a, 5000);
    }
    // How far the actor has moved from the teacher (about 0): its largest |action| over the states.
    for (double x = 0.05; x < 0.96; x += 0.05) {
      const double s[2] = {x, 0.0};
      double act = 0.0;
      assert_int_equal(actor_act(a, s, &act), ACTOR_OK);
      if (fabs(act) > spread[v]) spread[v] = fabs(act);
    }
    stepped[v] = actor_counters(a)->queries_stepped;
    with_slope[v] = actor_counters(a)->queries_with_slope;
    free(mem);
  }
  print_message("action without effect, 20 teacher runs: largest |action| with every slope %.3f (%llu of %llu "
                "queries stepped), with the 3-standard-error test %.3f (%llu of %llu)\n",
                spread[0], (unsigned long long)stepped[0], (unsigned long long)with_slope[0], spread[1],
                (unsigned long long)stepped[1], (unsigned long long)with_slope[1]);
  assert_true(spread[0] > 0.5);
  assert_true(spread[1] < 0.15);
  assert_true(stepped[0] == with_slope[0]);
  assert_true(stepped[1] < with_slope[1] / 10u);

  // The toy task's real slope passes the test: teacher runs, then the actor drives and moves up.
  actor_config_t cfg = toy_config();
  cfg.slope_min_t = 3.0;
  void* mem = NULL;
  actor_t* a = toy_actor(&cfg, &mem);
  rng_t rng;
  rng_seed(&rng, 11);
  toy_runs(a, TOY_TEACHER, &rng, 5);
  const double after_teacher = toy_mean_action(a);
  toy_runs(a, TOY_ACTOR, &rng, 15);
  const double after = toy_mean_action(a);
  print_message("real slope, 3-standard-error test: mean action after the teacher %.3f, after 15 own runs %.3f\n",
                after_teacher, after);
  assert_true(after > after_teacher + 0.5);
  free(mem);
}

// Ten runs in a row that fail with reward 0: a window of the last ten runs holds only returns of
// 0, so V is 0 everywhere, no query has a slope and the actor cannot move. The rewarded window
// reaches back to the teacher's rewarded runs, and the failures' states get slopes again.
static void test_actor_rewarded_window_keeps_signal_after_failures(void** state) {
  (void)state;
  double mean_step[2] = {0.0, 0.0};
  uint64_t stepped[2] = {0, 0};
  for (int v = 0; v < 2; ++v) {
    actor_config_t cfg = toy_config();
    cfg.rewarded_window = (uint32_t)v;
    cfg.slope_min_t = 0.0;  // the window alone
    void* mem = NULL;
    actor_t* a = toy_actor(&cfg, &mem);
    rng_t rng;
    rng_seed(&rng, 19);
    toy_runs(a, TOY_TEACHER, &rng, 5);
    toy_runs(a, TOY_FAIL, &rng, 10);
    const uint64_t before = actor_counters(a)->queries_stepped;
    toy_run(a, TOY_FAIL, &rng);
    toy_end_run(a, 5000);
    stepped[v] = actor_counters(a)->queries_stepped - before;
    mean_step[v] = actor_counters(a)->last_mean_step;
    free(mem);
  }
  print_message("after 11 failing runs: last ten runs: mean step %.4f (%llu queries stepped); rewarded window: "
                "%.4f (%llu)\n",
                mean_step[0], (unsigned long long)stepped[0], mean_step[1], (unsigned long long)stepped[1]);
  assert_true(mean_step[0] == 0.0);
  assert_true(mean_step[1] > 0.01);
  assert_true(stepped[1] > 0u);
}

// The same calls with slices of 1, 37 and unbounded work give the same bytes; every slice stays
// within its budget plus one query's work.
static void test_actor_slicing_does_not_change_result(void** state) {
  (void)state;
  const actor_config_t cfg = toy_config();
  const uint32_t budgets[3] = {UINT32_MAX, 37, 1};
  uint8_t* saved[3] = {NULL, NULL, NULL};
  size_t n[3] = {0, 0, 0};
  for (int v = 0; v < 3; ++v) {
    void* mem = NULL;
    actor_t* a = toy_actor(&cfg, &mem);
    rng_t rng;
    rng_seed(&rng, 21);
    uint64_t slices = 0;
    for (int run = 0; run < 4; ++run) {
      toy_run(a, run < 2 ? TOY_TEACHER : TOY_ACTOR, &rng);
      slices += toy_end_run(a, budgets[v]);
    }
    const actor_counters_t* c = actor_counters(a);
    print_message("budget %u: %llu slices, largest %u units\n", budgets[v], (unsigned long long)slices,
                  c->max_slice_work);
    if (budgets[v] != UINT32_MAX) {
      assert_true(c->max_slice_work <= budgets[v] + ACTOR_WORK_QUERY);
      assert_true(slices > 100);
    }
    saved[v] = toy_save(a, &n[v]);
    free(mem);
  }
  for (int v = 1; v < 3; ++v) {
    assert_int_equal(n[v], n[0]);
    assert_memory_equal(saved[v], saved[0], n[0]);
  }
  for (int v = 0; v < 3; ++v) {
    free(saved[v]);
  }
}

// Acting, recording and the between-run work allocate nothing.
static void test_actor_no_allocation(void** state) {
  (void)state;
  const actor_config_t cfg = toy_config();
  void* mem = NULL;
  actor_t* a = toy_actor(&cfg, &mem);
  rng_t rng;
  rng_seed(&rng, 4);
  alloc_counter_begin();
  for (int run = 0; run < 3; ++run) {
    toy_run(a, run == 0 ? TOY_TEACHER : TOY_ACTOR, &rng);
    toy_end_run(a, 500);
  }
  assert_int_equal(alloc_counter_end(), 0);
  assert_int_equal(actor_counters(a)->fits, 2);
  free(mem);
}

// A fit whose steps overflow leaves non-finite parameters: it is undone and counted, and the
// actor keeps acting with its last good parameters.
static void test_actor_diverging_fit_undone(void** state) {
  (void)state;
  actor_config_t cfg = toy_config();
  void* mem = NULL;
  actor_t* a = toy_actor(&cfg, &mem);
  rng_t rng;
  rng_seed(&rng, 8);
  toy_run(a, TOY_TEACHER, &rng);
  toy_end_run(a, 1000);
  const double before = toy_mean_action(a);
  free(mem);
  // Same calls, a learning rate that overflows the parameters in the second run's fit.
  cfg.learning_rate = 1e308;
  a = toy_actor(&cfg, &mem);
  rng_seed(&rng, 8);
  toy_run(a, TOY_TEACHER, &rng);
  toy_end_run(a, 1000);
  assert_int_equal(actor_counters(a)->fits_undone, 1);  // the cloning overflowed: undone
  assert_true(actor_trained(a));
  const double s[2] = {0.5, 0.0};
  double act = 0.0;
  assert_int_equal(actor_act(a, s, &act), ACTOR_OK);
  assert_true(isfinite(act));
  print_message("mean action with a sane cloning %.3f; after an undone one %.3f (the initial weights)\n", before,
                toy_mean_action(a));
  free(mem);
}

// Non-finite inputs are refused and counted; nothing is recorded.
static void test_actor_non_finite_inputs(void** state) {
  (void)state;
  const actor_config_t cfg = toy_config();
  void* mem = NULL;
  actor_t* a = toy_actor(&cfg, &mem);
  const double ok[2] = {0.2, 0.0};
  const double bad[2] = {NAN, 0.0};
  assert_int_equal(actor_record(a, bad, 0.0, 0.0, ok, 0), ACTOR_ERR_NON_FINITE);
  assert_int_equal(actor_record(a, ok, INFINITY, 0.0, ok, 0), ACTOR_ERR_NON_FINITE);
  assert_int_equal(actor_record(a, ok, 0.0, NAN, ok, 0), ACTOR_ERR_NON_FINITE);
  assert_int_equal(actor_record(a, ok, 0.0, 0.0, bad, 0), ACTOR_ERR_NON_FINITE);
  assert_int_equal(actor_record(a, ok, 0.0, 1.0, NULL, 1), ACTOR_OK);  // terminal: s' unused
  assert_int_equal(actor_counters(a)->rejected_non_finite, 4);
  assert_int_equal(actor_counters(a)->recorded, 1);
  double act = 0.0;
  assert_int_equal(actor_act(a, bad, &act), ACTOR_ERR_NON_FINITE);
  int pending = 0;
  assert_int_equal(actor_end_run_begin(a, &pending), ACTOR_OK);
  assert_int_equal(pending, 1);
  // Recording waits for the between-run work.
  assert_int_equal(actor_record(a, ok, 0.0, 0.0, ok, 0), ACTOR_ERR_BUSY);
  int remaining = 1;
  while (remaining) {
    assert_int_equal(actor_end_run_step(a, 100, &remaining), ACTOR_OK);
  }
  // A run without transitions has no work.
  assert_int_equal(actor_end_run_begin(a, &pending), ACTOR_OK);
  assert_int_equal(pending, 0);
  free(mem);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_actor_first_run_clones_teacher),
      cmocka_unit_test(test_actor_moves_past_teacher),
      cmocka_unit_test(test_actor_trust_radius_bounds_drift_from_data),
      cmocka_unit_test(test_actor_slope_test_stops_walk_on_noise),
      cmocka_unit_test(test_actor_rewarded_window_keeps_signal_after_failures),
      cmocka_unit_test(test_actor_slicing_does_not_change_result),
      cmocka_unit_test(test_actor_no_allocation),
      cmocka_unit_test(test_actor_diverging_fit_undone),
      cmocka_unit_test(test_actor_non_finite_inputs),
  };
  return cmocka_run_group_tests_name("actor.learn", tests, NULL, NULL);
}
