// SPDX-License-Identifier: MIT
// The toy task of the actor's tests (actor_test_util.h).
#include "actor_test_util.h"

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdlib.h>

#include <cmocka.h>

actor_config_t toy_config(void) {
  actor_config_t c = actor_config_default();
  c.state_dim = 2;
  c.state_min[0] = 0.0;
  c.state_max[0] = 1.0;
  c.state_min[1] = -1.0;
  c.state_max[1] = 1.0;
  c.state_scale[0] = 0.1;
  c.state_scale[1] = 1.0;
  c.action_min = -1.0;
  c.action_max = 1.0;
  c.action_scale = 0.25;
  c.gamma = 0.99;
  c.capacity = 4000;
  c.max_queries = 1000;
  c.seed = 5;
  return c;
}

actor_t* toy_actor(const actor_config_t* cfg, void** storage) {
  const size_t n = actor_storage_size(cfg);
  assert_true(n > 0);
  *storage = aligned_alloc(ACTOR_STORAGE_ALIGN, n);
  assert_non_null(*storage);
  actor_t* a = NULL;
  assert_int_equal(actor_init(&a, *storage, n, cfg), ACTOR_OK);
  return a;
}

static double clampd(double x) { return x < -1.0 ? -1.0 : (x > 1.0 ? 1.0 : x); }

int toy_run(actor_t* a, toy_driver_t driver, rng_t* rng) { return toy_run_effect(a, driver, rng, 0.02); }

int toy_run_effect(actor_t* a, toy_driver_t driver, rng_t* rng, double effect) {
  double s[2] = {0.1 + 0.05 * rng_uniform(rng), 0.0};
  // Without an action effect x moves exactly and the goal lies 0-0.2 before x = 1, drawn per run:
  // the returns' noise is the run's alone, the dynamics model is exact.
  const double goal_x = effect > 0.0 ? 1.0 : 1.0 - 0.2 * rng_uniform(rng);
  for (int t = 0; t < TOY_STEP_LIMIT; ++t) {
    double act = driver == TOY_FAIL ? -1.0 : 0.0;
    double noise = 0.0;
    if (driver != TOY_FAIL && rng_uniform(rng) < 0.2) {
      noise = (driver == TOY_TEACHER ? 0.3 : 0.1) * rng_normal(rng);
    }
    if (driver == TOY_ACTOR) {
      const actor_status_t st = actor_act(a, s, &act);
      assert_true(st == ACTOR_OK || st == ACTOR_UNTRAINED);
    }
    act = clampd(act + noise);
    const double drift = effect > 0.0 ? effect * (0.5 + act) : 0.01;
    double sn[2] = {s[0] + drift + (effect > 0.0 ? 0.002 * rng_normal(rng) : 0.0), act};
    const int goal = sn[0] >= goal_x;
    const int fail = driver == TOY_FAIL && sn[0] < 0.0;
    assert_int_equal(actor_record(a, s, act, goal ? 1.0 : 0.0, sn, goal || fail), ACTOR_OK);
    if (goal || fail) {
      return t + 1;
    }
    s[0] = sn[0];
    s[1] = sn[1];
  }
  return TOY_STEP_LIMIT;
}

void toy_runs(actor_t* a, toy_driver_t driver, rng_t* rng, int runs) {
  for (int run = 0; run < runs; ++run) {
    toy_run(a, driver, rng);
    toy_end_run(a, 5000);
  }
}

uint64_t toy_end_run(actor_t* a, uint32_t budget) {
  int pending = 0;
  assert_int_equal(actor_end_run_begin(a, &pending), ACTOR_OK);
  uint64_t slices = 0;
  int remaining = pending;
  while (remaining) {
    assert_int_equal(actor_end_run_step(a, budget, &remaining), ACTOR_OK);
    ++slices;
  }
  assert_false(actor_working(a));
  return slices;
}

double toy_mean_action(actor_t* a) {
  double sum = 0.0;
  int n = 0;
  for (double x = 0.05; x < 0.96; x += 0.1) {
    const double s[2] = {x, 0.0};
    double act = 0.0;
    assert_int_equal(actor_act(a, s, &act), ACTOR_OK);
    sum += act;
    ++n;
  }
  return sum / n;
}

uint8_t* toy_save(const actor_t* a, size_t* n) {
  *n = actor_serialized_size(a);
  uint8_t* b = malloc(*n);
  assert_non_null(b);
  size_t w = 0;
  assert_int_equal(actor_save(a, b, *n, &w), ACTOR_OK);
  assert_int_equal(w, *n);
  return b;
}
