// SPDX-License-Identifier: MIT
// A one-dimensional task for the learn tests: state in [-1, 1], action in [-1, 1], γ 0.9, a limit
// of 100 steps.
#ifndef LEARN_TEST_TASK_H
#define LEARN_TEST_TASK_H

#include "learn/learn.h"

#include <string.h>

static inline learn_task_t learn_test_line_task(void) {
  learn_task_t t;
  memset(&t, 0, sizeof t);
  t.state_dim = 1;
  t.state_scale[0] = 1.0;
  t.state_min[0] = -1.0;
  t.state_max[0] = 1.0;
  t.action_min = -1.0;
  t.action_max = 1.0;
  t.action_scale = 1.0;
  t.gamma = 0.9;
  t.step_limit = 100;
  t.greedy_reach = 1.0;
  return t;
}

#endif
