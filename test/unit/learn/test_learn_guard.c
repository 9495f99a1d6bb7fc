// SPDX-License-Identifier: MIT
// The values' guard of the actor (actor_guard_se, actor_guard_range): an actor cloned from a
// teacher that turns too gently acts as the teacher where the guard is off; with it, where
// HEDGER's values put the teacher's action significantly below their greedy action, the greedy
// action acts instead, bit for bit the one hedger_greedy() gives, and the replacement is counted.
// An actor that turns harder than any action the data hold at the state is held to the largest
// of them (the one the values judged) with actor_guard_range.
#include "learn/learn.h"
#include "learn_test_task.h"
#include "learn/learner.h"
#include "actor/actor.h"
#include "hedger_test_util.h"

#include <math.h>
#include <stdbool.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>


// Cloning samples of the policy a = 2 s on a grid of s in [-1, 1].
static int steep_policy(void* user, uint32_t index, double* state, double* action) {
  (void)user;
  state[0] = -1.0 + 2.0 * (double)index / 199.0;
  *action = 2.0 * state[0];
  return 0;
}

typedef struct {
  double greedy;      // hedger_greedy()'s action at s
  double hi;          // the largest action the data hold at s (hedger_judge())
  uint64_t replaced;  // learn_guard_replaced()
} seen_t;

// The actor's action at s after cloning the teacher's stored points (steep: the policy 2 s
// instead), with the guard at se and range.
static double act_at(double s, double se, bool range, bool steep, seen_t* seen) {
  const learn_task_t task = learn_test_line_task();
  learn_config_t cfg = learn_config_default();
  cfg.mode = LEARN_MODE_EVALUATE;
  cfg.policy = LEARN_POLICY_ACTOR;
  cfg.state_last_action = false;
  cfg.k_max = 64;
  cfg.bandwidth = 0.6;
  cfg.merge_radius = 1e-4;
  cfg.capacity = 2000;
  cfg.actor.capacity = 2000;
  cfg.actor.max_queries = 1000;
  cfg.actor_guard_se = se;
  cfg.actor_guard_range = range;
  const size_t bytes = learn_storage_size(&task, &cfg);
  assert_true(bytes > 0);
  void* mem = aligned_alloc(LEARN_STORAGE_ALIGN, (bytes + LEARN_STORAGE_ALIGN - 1) / LEARN_STORAGE_ALIGN *
                                                     LEARN_STORAGE_ALIGN);
  assert_non_null(mem);
  char err[LEARN_ERR_MAX];
  learn_t* a = learn_init(mem, bytes, &task, &cfg, err, sizeof err);
  assert_non_null(a);
  // The teacher turns as 0.5 s (with dither); the values peak at 0.8 s.
  hedger_t* h = learn_get_learner(a)->hedger;
  uint64_t rs = 23;
  ht_insert_gentle_teacher(h, 600, &rs);
  if (steep) {
    assert_int_equal(actor_clone(learn_get_actor(a), 200, steep_policy, NULL), ACTOR_OK);
  } else {
    assert_true(learn_actor_from_values(a) >= 590);
  }
  assert_int_equal(hedger_greedy(h, &s, &seen->greedy, NULL, NULL), HEDGER_OK);
  hedger_judgement_t j;
  assert_int_equal(hedger_judge(h, &s, 0.0, &j), HEDGER_OK);
  assert_int_equal(j.judged, 1);
  seen->hi = j.action_hi;
  learn_begin_run(a);
  assert_true(learn_observe(a, &s, 0.0));
  double act = 0.0;
  int8_t src = -1;
  learn_act(a, 0.0, 0.0, &act, &src);
  assert_int_equal(src, LEARN_SOURCE_GREEDY);
  seen->replaced = learn_guard_replaced(a);
  free(mem);
  return act;
}

static void test_guard_replaces_an_action_the_values_reject(void** state) {
  (void)state;
  const double s = 0.5;
  seen_t seen;
  const double off = act_at(s, 0.0, false, false, &seen);
  assert_true(fabs(off - 0.25) < 0.08);  // the clone of the teacher
  assert_true(fabs(seen.greedy - 0.4) < 0.05);  // the values' peak
  assert_int_equal(seen.replaced, 0);
  const double on = act_at(s, 1.0, true, false, &seen);
  assert_memory_equal(&on, &seen.greedy, sizeof on);
  assert_int_equal(seen.replaced, 1);
  // A guard too lax to be sure (Q(0.4) − Q(0.25) = 0.0225 is tens of standard errors): the
  // actor, inside the data's actions, as it is.
  const double lax = act_at(s, 1e6, true, false, &seen);
  assert_memory_equal(&lax, &off, sizeof lax);
  assert_int_equal(seen.replaced, 0);
}

static void test_guard_keeps_the_actor_within_the_data(void** state) {
  (void)state;
  const double s = 0.5;
  seen_t seen;
  const double free_action = act_at(s, 0.0, false, true, &seen);
  assert_true(free_action > seen.hi + 0.1);  // about 1 (2 s, within the bounds)
  const double held = act_at(s, 0.0, true, true, &seen);
  assert_memory_equal(&held, &seen.hi, sizeof held);
  assert_true(seen.hi > 0.4 && seen.hi < 0.95);
  assert_int_equal(seen.replaced, 0);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_guard_replaces_an_action_the_values_reject),
      cmocka_unit_test(test_guard_keeps_the_actor_within_the_data),
  };
  return cmocka_run_group_tests_name("learn.guard", tests, NULL, NULL);
}
