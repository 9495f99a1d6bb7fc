// SPDX-License-Identifier: MIT
// Tabular Q-learning: exact values on a chain MDP, the replay's propagation, the greedy tie rule
// and unknown cells, fixed memory (no allocation, nothing written outside the block),
// determinism, bad input refused.
#include <b21r_test/alloc_counter.h>
#include <tabq/tabq.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

// Chain of 5 states 0..4 (state value = index, one bin each); actions -1 (left) and +1 (right);
// stepping right from state 3 reaches 4: reward 1, terminal. Left from 0 stays at 0.
enum { CHAIN_N = 5 };
static const double k_gamma = 0.9;

static tabq_config_t chain_config(void) {
  tabq_config_t c = tabq_config_default();
  c.state_dim = 1;
  c.state_min[0] = 0.0;
  c.state_max[0] = CHAIN_N;
  c.bins[0] = CHAIN_N;
  c.action_min = -1.0;
  c.action_max = 1.0;
  c.n_actions = 2;
  c.alpha = 1.0;
  c.gamma = k_gamma;
  return c;
}

typedef struct inst {
  void* storage;
  tabq_t* t;
} inst_t;

static inst_t make(const tabq_config_t* c) {
  inst_t in;
  const size_t n = tabq_storage_size(c);
  assert_true(n > 0);
  in.storage = aligned_alloc(TABQ_STORAGE_ALIGN, (n + TABQ_STORAGE_ALIGN - 1) & ~(size_t)(TABQ_STORAGE_ALIGN - 1));
  assert_non_null(in.storage);
  assert_int_equal(tabq_init(&in.t, in.storage, n, c), TABQ_OK);
  return in;
}

static void chain_step(double s, double a, double* s_next, double* r, int* terminal) {
  *s_next = a > 0.0 ? s + 1.0 : (s > 0.0 ? s - 1.0 : 0.0);
  *terminal = *s_next >= CHAIN_N - 1 ? 1 : 0;
  *r = *terminal ? 1.0 : 0.0;
}

// Exact equality without -Wfloat-equal's objection (every compared value is exact here).
static int eq(double x, double y) { return !(x < y) && !(x > y); }

static double learn_one(tabq_t* t, double s, double a) {
  double sn = 0.0, r = 0.0;
  int term = 0;
  chain_step(s, a, &sn, &r, &term);
  double qn = 0.0;
  if (!term) {
    (void)tabq_greedy(t, &sn, NULL, &qn);
  }
  double q_old = 0.0;
  assert_int_equal(tabq_learn(t, &s, a, r, term ? NULL : &sn, term, qn, &q_old, NULL), TABQ_OK);
  return q_old;
}

// Q*(s, right) = γ^(3 − s); Q*(s, left) = γ · V*(max(s − 1, 0)).
static double q_star(int s, double a) {
  if (a > 0.0) {
    return pow(k_gamma, 3 - s);
  }
  const int l = s > 0 ? s - 1 : 0;
  return k_gamma * pow(k_gamma, 3 - l);
}

// With α = 1, sweeps over every (s, a) are value iteration: after 5 sweeps the values are exact.
static void test_tabq_chain_learns_exact_values(void** state) {
  (void)state;
  const tabq_config_t c = chain_config();
  inst_t in = make(&c);
  for (int sweep = 0; sweep < 5; ++sweep) {
    for (int s = CHAIN_N - 2; s >= 0; --s) {
      (void)learn_one(in.t, s, 1.0);
      (void)learn_one(in.t, s, -1.0);
    }
  }
  for (int s = 0; s < CHAIN_N - 1; ++s) {
    const double st = s;
    for (int j = 0; j < 2; ++j) {
      const double a = j == 0 ? -1.0 : 1.0;
      double v = -1.0;
      int known = 0;
      assert_int_equal(tabq_predict(in.t, &st, a, &v, &known), TABQ_OK);
      assert_int_equal(known, 1);
      assert_true(fabs(v - q_star(s, a)) <= 1e-12);
    }
    double ga = 0.0, gv = 0.0;
    assert_int_equal(tabq_greedy(in.t, &st, &ga, &gv), TABQ_OK);
    assert_true(eq(ga, 1.0));
    assert_true(fabs(gv - q_star(s, 1.0)) <= 1e-12);
  }
  // The terminal state's bin was never updated: unknown.
  const double s4 = CHAIN_N - 1;
  double v = 5.0, a = 5.0;
  int known = 1;
  assert_int_equal(tabq_predict(in.t, &s4, 1.0, &v, &known), TABQ_OK);
  assert_int_equal(known, 0);
  assert_true(eq(v, 0.0));
  assert_int_equal(tabq_greedy(in.t, &s4, &a, &v), TABQ_NO_KNOWN_ACTION);
  assert_true(eq(v, 0.0));
  assert_int_equal(tabq_counters(in.t)->cells_visited, 8);
  free(in.storage);
}

// One run 0 → 4 to the right. Without replay only the last step learns its reward; with one
// backward pass at λ = 1 every step gets its discounted return at once.
static void test_tabq_replay_propagates_the_reward(void** state) {
  (void)state;
  for (int replay = 0; replay <= 1; ++replay) {
    tabq_config_t c = chain_config();
    c.run_capacity = 16;
    c.replay = (uint32_t)replay;
    c.replay_lambda = 1.0;
    inst_t in = make(&c);
    for (int s = 0; s < CHAIN_N - 1; ++s) {
      (void)learn_one(in.t, s, 1.0);
    }
    uint32_t pending = 99, remaining = 99;
    assert_int_equal(tabq_end_run_begin(in.t, &pending), TABQ_OK);
    assert_int_equal(pending, replay ? 4 : 0);
    assert_int_equal(tabq_end_run_step(in.t, 1, &remaining), TABQ_OK);  // sliced
    assert_int_equal(remaining, replay ? 3 : 0);
    assert_int_equal(tabq_end_run_step(in.t, UINT32_MAX, &remaining), TABQ_OK);
    assert_int_equal(remaining, 0);
    for (int s = 0; s < CHAIN_N - 1; ++s) {
      const double st = s;
      double v = -1.0;
      assert_int_equal(tabq_predict(in.t, &st, 1.0, &v, NULL), TABQ_OK);
      const double want = (replay || s == 3) ? q_star(s, 1.0) : 0.0;
      assert_true(fabs(v - want) <= 1e-12);
    }
    assert_int_equal(tabq_counters(in.t)->replayed_updates, replay ? 4 : 0);
    assert_int_equal(tabq_counters(in.t)->run_fill, 0);
    free(in.storage);
  }
}

// The replay's own step (replay_alpha): online updates keep alpha (0.5), the replay's take
// replay_alpha. One run 0 → 4, one backward pass at λ = 1: with replay_alpha = 1 every step holds its
// return exactly; with 0 (= alpha) the replay moves each value half way (the last step's 0.5 online
// value to 0.75, the others from 0 to half their return).
static void test_tabq_replay_alpha(void** state) {
  (void)state;
  for (int own = 0; own <= 1; ++own) {
    tabq_config_t c = chain_config();
    c.alpha = 0.5;
    c.run_capacity = 16;
    c.replay = 1;
    c.replay_lambda = 1.0;
    c.replay_alpha = own ? 1.0 : 0.0;
    inst_t in = make(&c);
    for (int s = 0; s < CHAIN_N - 1; ++s) {
      (void)learn_one(in.t, s, 1.0);
    }
    double v3 = -1.0;
    const double s3 = 3.0;
    assert_int_equal(tabq_predict(in.t, &s3, 1.0, &v3, NULL), TABQ_OK);
    assert_true(eq(v3, 0.5));  // online: alpha, whatever replay_alpha
    assert_int_equal(tabq_end_run_begin(in.t, NULL), TABQ_OK);
    assert_int_equal(tabq_end_run_step(in.t, UINT32_MAX, NULL), TABQ_OK);
    for (int s = 0; s < CHAIN_N - 1; ++s) {
      const double st = s;
      double v = -1.0;
      assert_int_equal(tabq_predict(in.t, &st, 1.0, &v, NULL), TABQ_OK);
      const double want = own ? q_star(s, 1.0) : (s == 3 ? 0.75 : 0.5 * q_star(s, 1.0));
      assert_true(fabs(v - want) <= 1e-12);
    }
    free(in.storage);
  }
  tabq_config_t c = chain_config();
  c.replay_alpha = 1.5;
  assert_int_equal(tabq_config_validate(&c), TABQ_ERR_INVALID_ARG);
  c.replay_alpha = -0.1;
  assert_int_equal(tabq_config_validate(&c), TABQ_ERR_INVALID_ARG);
}

// Equal values: the smallest |action| wins; unvisited actions never win; an executed action is
// learned at its nearest grid action.
static void test_tabq_greedy_ties_and_unknown(void** state) {
  (void)state;
  tabq_config_t c = chain_config();
  c.n_actions = 9;  // -1, -0.75, ..., 1
  c.alpha = 1.0;
  inst_t in = make(&c);
  const double s = 0.5;
  double a = 7.0, v = 7.0;
  assert_int_equal(tabq_greedy(in.t, &s, &a, &v), TABQ_NO_KNOWN_ACTION);
  assert_true(eq(a, 0.0) && eq(v, 0.0));
  const double sn = 1.5;
  assert_int_equal(tabq_learn(in.t, &s, -0.9, -1.0, &sn, 0, 0.0, NULL, NULL), TABQ_OK);  // cell -1
  assert_int_equal(tabq_greedy(in.t, &s, &a, &v), TABQ_OK);
  assert_true(eq(a, -1.0) && eq(v, -1.0));  // the only known action wins, even with a negative value
  assert_int_equal(tabq_learn(in.t, &s, 0.8, 2.0, &sn, 0, 0.0, NULL, NULL), TABQ_OK);    // cell 0.75
  assert_int_equal(tabq_learn(in.t, &s, -0.3, 2.0, &sn, 0, 0.0, NULL, NULL), TABQ_OK);   // cell -0.25
  assert_int_equal(tabq_greedy(in.t, &s, &a, &v), TABQ_OK);
  assert_true(eq(a, -0.25) && eq(v, 2.0));
  assert_int_equal(tabq_learn(in.t, &s, 0.26, 2.0, &sn, 0, 0.0, NULL, NULL), TABQ_OK);   // cell 0.25
  assert_int_equal(tabq_greedy(in.t, &s, &a, &v), TABQ_OK);
  assert_true(eq(a, -0.25));  // |-0.25| = |0.25|: the lower one
  assert_int_equal(tabq_learn(in.t, &s, 0.01, 2.0, &sn, 0, 0.0, NULL, NULL), TABQ_OK);   // cell 0
  assert_int_equal(tabq_greedy(in.t, &s, &a, &v), TABQ_OK);
  assert_true(eq(a, 0.0));
  // Out-of-range states fall into the edge bins.
  const double far = 1e6, near_edge = 4.9;
  assert_int_equal(tabq_learn(in.t, &far, 0.0, 3.0, NULL, 1, 0.0, NULL, NULL), TABQ_OK);
  assert_int_equal(tabq_predict(in.t, &near_edge, 0.0, &v, NULL), TABQ_OK);
  assert_true(eq(v, 3.0));
  free(in.storage);
}

// Random transitions over a 3-D state with replay, run buffer overflowing: nothing allocated,
// nothing written past the block, two instances bit-identical.
static void test_tabq_fixed_memory_and_determinism(void** state) {
  (void)state;
  tabq_config_t c = tabq_config_default();
  c.state_dim = 3;
  for (int i = 0; i < 3; ++i) {
    c.state_min[i] = -1.0;
    c.state_max[i] = 1.0;
    c.bins[i] = 7;
  }
  c.run_capacity = 32;
  c.replay = 1;
  c.replay_passes = 3;
  c.replay_lambda = 0.5;
  const size_t n = tabq_storage_size(&c);
  const size_t cells = 7U * 7U * 7U * 9U;
  assert_int_equal(tabq_cells(NULL), 0);
  assert_true(n >= cells * 12U + 32U * 9U * 8U && n <= cells * 12U + 32U * 9U * 8U + 1024U);
  enum { CANARY = 256 };
  uint8_t* blocks[2];
  tabq_t* t[2];
  for (int k = 0; k < 2; ++k) {
    blocks[k] = aligned_alloc(TABQ_STORAGE_ALIGN, n + CANARY);
    assert_non_null(blocks[k]);
    memset(blocks[k] + n, 0xA5, CANARY);
    assert_int_equal(tabq_init(&t[k], blocks[k], n, &c), TABQ_OK);
  }
  assert_int_equal(tabq_cells(t[0]), cells);
  double out[2][4];
  alloc_counter_begin();
  for (int k = 0; k < 2; ++k) {
    uint64_t rs = 12345;
    for (int step = 0; step < 5000; ++step) {
      double s[3], sn[3];
      for (int i = 0; i < 3; ++i) {
        rs = rs * 6364136223846793005ULL + 1442695040888963407ULL;
        s[i] = -1.3 + 2.6 * (double)(rs >> 11) / 9007199254740992.0;
        sn[i] = 0.9 * s[i];
      }
      const double a = s[0] * s[1];
      const int term = (rs >> 60) == 0;
      double qn = 0.0;
      (void)tabq_greedy(t[k], sn, NULL, &qn);
      assert_int_equal(tabq_learn(t[k], s, a, s[2], sn, term, qn, NULL, NULL), TABQ_OK);
      if (step % 100 == 99) {
        assert_int_equal(tabq_end_run_begin(t[k], NULL), TABQ_OK);
        assert_int_equal(tabq_end_run_step(t[k], 7, NULL), TABQ_OK);  // the rest finishes in learn
      }
    }
    const double q[3] = {0.1, -0.2, 0.3};
    assert_int_equal(tabq_greedy(t[k], q, &out[k][0], &out[k][1]), TABQ_OK);
    assert_int_equal(tabq_predict(t[k], q, 0.5, &out[k][2], NULL), TABQ_OK);
    out[k][3] = (double)tabq_counters(t[k])->cells_visited;
  }
  assert_int_equal(alloc_counter_end(), 0);
  assert_true(tabq_counters(t[0])->run_overflows > 0);
  assert_true(tabq_counters(t[0])->replayed_updates > 0);
  assert_memory_equal(out[0], out[1], sizeof out[0]);
  for (int k = 0; k < 2; ++k) {
    for (size_t i = 0; i < CANARY; ++i) {
      assert_int_equal(blocks[k][n + i], 0xA5);
    }
  }
  free(blocks[0]);
  free(blocks[1]);
}

static void test_tabq_bad_input(void** state) {
  (void)state;
  tabq_config_t c = chain_config();
  c.bins[0] = 0;
  assert_int_equal(tabq_storage_size(&c), 0);
  c = chain_config();
  c.replay = 1;  // without a run buffer
  assert_int_equal(tabq_config_validate(&c), TABQ_ERR_INVALID_ARG);
  c = chain_config();
  c.state_dim = 4;
  for (int i = 0; i < 4; ++i) {
    c.bins[i] = 1024;  // 2^40 cells
    c.state_max[i] = 1.0;
  }
  assert_int_equal(tabq_config_validate(&c), TABQ_ERR_INVALID_ARG);
  c = chain_config();
  inst_t in = make(&c);
  const double s = 1.0, bad = NAN;
  assert_int_equal(tabq_learn(in.t, &bad, 1.0, 0.0, &s, 0, 0.0, NULL, NULL), TABQ_ERR_NON_FINITE);
  assert_int_equal(tabq_learn(in.t, &s, 1.0, 0.0, &bad, 0, 0.0, NULL, NULL), TABQ_ERR_NON_FINITE);
  assert_int_equal(tabq_learn(in.t, &s, 1.0, 0.0, &s, 0, INFINITY, NULL, NULL), TABQ_ERR_NON_FINITE);
  assert_int_equal(tabq_counters(in.t)->updates, 0);
  assert_int_equal(tabq_counters(in.t)->rejected_non_finite, 3);
  free(in.storage);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_tabq_chain_learns_exact_values),
      cmocka_unit_test(test_tabq_replay_propagates_the_reward),
      cmocka_unit_test(test_tabq_replay_alpha),
      cmocka_unit_test(test_tabq_greedy_ties_and_unknown),
      cmocka_unit_test(test_tabq_fixed_memory_and_determinism),
      cmocka_unit_test(test_tabq_bad_input),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
