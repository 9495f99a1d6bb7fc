// SPDX-License-Identifier: MIT
// learn_learner_config(): the framework's settings reach the value learner it builds, HEDGER's or
// tabular Q's, as one set: the replay's passes, lambda and step go to both, so that the learner
// kinds compared in an ablation replay alike.
#include "learn/learn.h"

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

static learn_task_t corridor_like_task(void) {
  learn_task_t t;
  memset(&t, 0, sizeof t);
  t.state_dim = 3;
  for (uint32_t i = 0; i < t.state_dim; ++i) {
    t.state_scale[i] = 1.0;
    t.state_min[i] = -1.0;
    t.state_max[i] = 1.0;
  }
  t.action_min = -1.0;
  t.action_max = 1.0;
  t.action_scale = 0.25;
  t.gamma = 0.99;
  t.step_limit = 1000;
  t.greedy_reach = 8.0;
  return t;
}

static int same(double a, double b) { return memcmp(&a, &b, sizeof a) == 0; }

// The defaults: 3 passes of the replay's own step 0.7741 (as far as 20 passes of alpha 0.2),
// lambda 0.9, k_max 48.
static void test_learner_config_defaults(void** state) {
  (void)state;
  const learn_task_t task = corridor_like_task();
  const learn_config_t cfg = learn_config_default();
  learn_learner_config_t lc;
  learn_learner_config(&task, &cfg, &lc);
  assert_int_equal(lc.hedger.replay_passes, 3);
  assert_true(same(lc.hedger.replay_alpha, 0.7741));
  assert_true(same(lc.hedger.alpha, 0.2));
  assert_int_equal(lc.hedger.k_max, 48);
  assert_int_equal(lc.tabular.replay_passes, 3);
  assert_true(same(lc.tabular.replay_alpha, 0.7741));
}

// Whatever the settings, HEDGER and tabular Q get the same replay.
static void test_learner_config_replay_reaches_both_learners(void** state) {
  (void)state;
  const learn_task_t task = corridor_like_task();
  learn_config_t cfg = learn_config_default();
  cfg.replay_passes = 7;
  cfg.replay_lambda = 0.5;
  cfg.replay_alpha = 0.35;
  cfg.alpha = 0.1;
  cfg.learner = LEARN_LEARNER_TABULAR;
  learn_learner_config_t lc;
  learn_learner_config(&task, &cfg, &lc);
  assert_int_equal(lc.hedger.replay_passes, 7);
  assert_int_equal(lc.tabular.replay_passes, 7);
  assert_true(same(lc.hedger.replay_lambda, 0.5) && same(lc.tabular.replay_lambda, 0.5));
  assert_true(same(lc.hedger.replay_alpha, 0.35) && same(lc.tabular.replay_alpha, 0.35));
  assert_true(same(lc.hedger.alpha, 0.1) && same(lc.tabular.alpha, 0.1));
  cfg.replay_alpha = 0.0;  // 0: the replay steps by alpha, in both
  learn_learner_config(&task, &cfg, &lc);
  assert_true(same(lc.hedger.replay_alpha, 0.0) && same(lc.tabular.replay_alpha, 0.0));
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_learner_config_defaults),
      cmocka_unit_test(test_learner_config_replay_reaches_both_learners),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
