// SPDX-License-Identifier: MIT
// Run tags and anchor weights: the greedy state model's neighbours' policy (the anchor) follows
// the runs weighted up, fades old runs with anchor_recency_runs, and the values never see
// either; tags and weights obey their contracts. hedger_judge(): the same model judges another
// policy's action against the greedy one, within the actions the data hold at the state.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

#include <cmocka.h>

#include "hedger_test_util.h"

// One state dimension; a pessimism so large that the greedy choice is the anchor itself.
static hedger_config_t anchor_config(void) {
  hedger_config_t c = hedger_config_default();
  c.state_dim = 1;
  c.capacity = 2000;
  c.k_max = 64;
  c.bandwidth = 0.6;
  c.merge_radius = 1e-4;
  c.greedy_method = HEDGER_GREEDY_STATE_MODEL;
  c.greedy_pessimism = 100.0;
  c.seed = 5;
  return c;
}

// Two runs with opposite habits at the same states: run `tag_up` turns 0.3 above the common
// law a = 0.5 s, run `tag_down` 0.3 below it. The values do not depend on the action.
static void store_two_runs(hedger_t* h, uint32_t tag_up, uint32_t tag_down, uint64_t* rs) {
  for (int run = 0; run < 2; ++run) {
    assert_int_equal(hedger_set_run_tag(h, run == 0 ? tag_up : tag_down), HEDGER_OK);
    const double offset = run == 0 ? 0.3 : -0.3;
    for (int i = 0; i < 300; ++i) {
      const double s = ht_uniform(rs, -1.0, 1.0);
      const double a = 0.5 * s + offset + 0.05 * ht_normal(rs);
      const double q = 2.0 + 0.2 * s + 0.01 * ht_normal(rs);
      assert_int_equal(hedger_insert(h, &s, a, q, 0, NULL), HEDGER_OK);
    }
  }
  assert_int_equal(hedger_observe_reward(h, 1.0), HEDGER_OK);
}

static double greedy_at(hedger_t* h, double s) {
  double a = 0.0;
  assert_int_equal(hedger_greedy(h, &s, &a, NULL, NULL), HEDGER_OK);
  return a;
}

// With equal weights the anchor lies between the two habits; weighting one run up and the other
// down moves it to the favoured habit; weighting them back to 1 restores the choice bit for bit.
static void test_anchor_follows_weighted_run(void** state) {
  (void)state;
  const hedger_config_t c = anchor_config();
  hedger_t* h = ht_create(&c);
  uint64_t rs = 11;
  store_two_runs(h, 1u, 2u, &rs);
  const double s = 0.2;
  const double neutral = greedy_at(h, s);
  assert_true(fabs(neutral - 0.1) < 0.1);  // the law's 0.5 s, between the habits
  uint32_t up = 0, down = 0;
  assert_int_equal(hedger_weight_run(h, 1u, 1.9, &up), HEDGER_OK);
  assert_int_equal(hedger_weight_run(h, 2u, 0.1, &down), HEDGER_OK);
  assert_true(up > 250 && down > 250);  // nearly every point of each run (a few merged)
  const double favoured = greedy_at(h, s);
  assert_true(favoured > neutral + 0.2);
  assert_true(fabs(favoured - (0.1 + 0.9 * 0.3)) < 0.1);  // weights 1.9 : 0.1 → 0.9 of the offset
  // The values are not weighted: the greedy value is the same model's at the chosen action.
  hedger_prediction_t p;
  assert_int_equal(hedger_predict(h, &s, favoured, &p), HEDGER_OK);
  assert_true(fabs(p.value - (2.0 + 0.2 * s)) < 0.05);
  // The other way round.
  assert_int_equal(hedger_weight_run(h, 1u, 0.1, NULL), HEDGER_OK);
  assert_int_equal(hedger_weight_run(h, 2u, 1.9, NULL), HEDGER_OK);
  assert_true(greedy_at(h, s) < neutral - 0.2);
  assert_int_equal(hedger_weight_run(h, 1u, 1.0, NULL), HEDGER_OK);
  assert_int_equal(hedger_weight_run(h, 2u, 1.0, NULL), HEDGER_OK);
  const double back = greedy_at(h, s);
  assert_memory_equal(&back, &neutral, sizeof back);
  hedger_destroy(h);
}

// The weights are relative: scaling every weight of a neighbourhood by the same factor (here
// 1e-6, where the ridge would otherwise dominate and flatten the fit) leaves the choice as it is.
static void test_anchor_weights_are_relative(void** state) {
  (void)state;
  const hedger_config_t c = anchor_config();
  hedger_t* h = ht_create(&c);
  uint64_t rs = 14;
  store_two_runs(h, 1u, 2u, &rs);
  const double s = 0.6;
  assert_int_equal(hedger_weight_run(h, 1u, 1.5, NULL), HEDGER_OK);
  assert_int_equal(hedger_weight_run(h, 2u, 0.5, NULL), HEDGER_OK);
  const double big = greedy_at(h, s);
  assert_int_equal(hedger_weight_run(h, 1u, 1.5e-6, NULL), HEDGER_OK);
  assert_int_equal(hedger_weight_run(h, 2u, 0.5e-6, NULL), HEDGER_OK);
  const double small = greedy_at(h, s);
  assert_true(fabs(big - small) < 1e-6);
  assert_true(big > 0.3 + 0.05);  // 0.5 s + half the offset: the up-weighted habit
  hedger_destroy(h);
}

// anchor_recency_runs fades older runs: with the newer run 10 tags later and a recency of 2 run
// tags, the anchor is the newer run's habit; without recency it lies between them.
static void test_anchor_recency_fades_old_runs(void** state) {
  (void)state;
  hedger_config_t c = anchor_config();
  c.anchor_recency_runs = 2.0;
  hedger_t* h = ht_create(&c);
  uint64_t rs = 12;
  store_two_runs(h, 5u, 15u, &rs);  // the "down" run is the newer
  const double s = -0.4;
  const double recent = greedy_at(h, s);
  assert_true(fabs(recent - (-0.2 - 0.3)) < 0.1);
  c.anchor_recency_runs = 0.0;
  hedger_t* flat = ht_create(&c);
  rs = 12;
  store_two_runs(flat, 5u, 15u, &rs);
  assert_true(fabs(greedy_at(flat, s) - (-0.2)) < 0.1);
  hedger_destroy(flat);
  hedger_destroy(h);
}

// When the caller weights every neighbour to zero, the anchor falls back to the plain kernel
// weights instead of a regression on nothing.
static void test_anchor_all_zero_weights_fall_back(void** state) {
  (void)state;
  const hedger_config_t c = anchor_config();
  hedger_t* h = ht_create(&c);
  uint64_t rs = 13;
  store_two_runs(h, 1u, 2u, &rs);
  const double neutral = greedy_at(h, 0.5);
  assert_int_equal(hedger_weight_run(h, 1u, 0.0, NULL), HEDGER_OK);
  assert_int_equal(hedger_weight_run(h, 2u, 0.0, NULL), HEDGER_OK);
  const double a = greedy_at(h, 0.5);
  assert_memory_equal(&a, &neutral, sizeof a);
  hedger_destroy(h);
}

// Contracts: new points carry the current tag and weight 1; a merge keeps the tag of the point
// merged into; tags never decrease; weights outside [0, 16] or not finite are refused and change
// nothing; a weight counts as a change of the learned state (a sliced save must restart).
static void test_anchor_tag_and_weight_contracts(void** state) {
  (void)state;
  hedger_config_t c = anchor_config();
  c.merge_radius = 0.05;
  hedger_t* h = ht_create(&c);
  const double s = 0.3;
  assert_int_equal(hedger_run_tag(h), 0);
  assert_int_equal(hedger_set_run_tag(h, 7u), HEDGER_OK);
  assert_int_equal(hedger_run_tag(h), 7);
  hedger_store_op_t op;
  assert_int_equal(hedger_insert(h, &s, 0.1, 1.0, 0, &op), HEDGER_OK);
  assert_int_equal(op, HEDGER_STORE_INSERTED);
  hedger_point_t pt;
  assert_int_equal(hedger_get_point(h, 0, &pt), HEDGER_OK);
  assert_int_equal(pt.run_tag, 7);
  assert_true(pt.anchor_weight == 1.0);
  assert_int_equal(hedger_set_run_tag(h, 6u), HEDGER_ERR_INVALID_ARG);
  assert_int_equal(hedger_set_run_tag(h, 9u), HEDGER_OK);
  assert_int_equal(hedger_insert(h, &s, 0.1, 1.5, 0, &op), HEDGER_OK);
  assert_int_equal(op, HEDGER_STORE_MERGED);
  assert_int_equal(hedger_get_point(h, 0, &pt), HEDGER_OK);
  assert_int_equal(pt.run_tag, 7);
  const double bad[4] = {-0.5, 16.5, NAN, INFINITY};
  for (int i = 0; i < 4; ++i) {
    uint32_t n = 99;
    assert_int_equal(hedger_weight_run(h, 7u, bad[i], &n), HEDGER_ERR_INVALID_ARG);
    assert_int_equal(n, 99);
  }
  assert_int_equal(hedger_get_point(h, 0, &pt), HEDGER_OK);
  assert_true(pt.anchor_weight == 1.0);
  uint8_t buf[512];
  hedger_save_cursor_t cur;
  assert_int_equal(hedger_save_begin(h, buf, sizeof buf, &cur), HEDGER_OK);
  uint32_t n = 0;
  assert_int_equal(hedger_weight_run(h, 7u, 16.0, &n), HEDGER_OK);
  assert_int_equal(n, 1);
  assert_int_equal(hedger_save_step(h, &cur, 10, NULL), HEDGER_ERR_CHANGED);
  assert_int_equal(hedger_weight_run(h, 8u, 2.0, &n), HEDGER_OK);
  assert_int_equal(n, 0);
  hedger_destroy(h);
  c.anchor_recency_runs = -1.0;
  assert_int_equal(hedger_config_validate(&c), HEDGER_ERR_INVALID_ARG);
  c.anchor_recency_runs = NAN;
  assert_int_equal(hedger_config_validate(&c), HEDGER_ERR_INVALID_ARG);
}

// A teacher that turns too gently: actions a = 0.5 s + dither, values peaked at a = 0.8 s.
// hedger_judge() returns hedger_greedy()'s answer, puts the teacher's action significantly below
// the greedy one, clamps an action beyond the data into their range at the state, and judges
// nothing without a state model.
static void test_judge_against_greedy(void** state) {
  (void)state;
  hedger_config_t c = anchor_config();
  c.greedy_pessimism = 4.0;
  hedger_t* h = ht_create(&c);
  uint64_t rs = 23;
  ht_insert_gentle_teacher(h, 600, &rs);
  const double s = 0.5;
  double ga = 0.0, gv = 0.0;
  hedger_kind_t gk = HEDGER_KIND_UNKNOWN;
  assert_int_equal(hedger_greedy(h, &s, &ga, &gv, &gk), HEDGER_OK);
  hedger_judgement_t j;
  assert_int_equal(hedger_judge(h, &s, 0.25, &j), HEDGER_OK);
  assert_true(j.greedy_action == ga && j.greedy_value == gv && j.greedy_kind == gk);
  assert_int_equal(j.judged, 1);
  assert_true(fabs(ga - 0.4) < 0.05);  // the values' peak, not the teacher's 0.25
  assert_true(j.action_lo < 0.25 && 0.25 < ga && ga < j.action_hi);
  assert_true(j.kept_action == 0.25);
  // Q(0.4) − Q(0.25) = 0.15² = 0.0225, many standard errors from 0.
  assert_true(fabs(j.gap - 0.0225) < 0.005);
  assert_true(j.gap > 4.0 * j.gap_se && j.gap_se > 0.0);
  // The greedy action itself: no gap (up to rounding: a fused multiply-add may differ from u²).
  assert_int_equal(hedger_judge(h, &s, ga, &j), HEDGER_OK);
  assert_true(fabs(j.gap) < 1e-12 && j.gap_se < 1e-9 && j.kept_action == ga);
  // Beyond the data's actions at the state: judged at the largest they hold.
  assert_int_equal(hedger_judge(h, &s, 5.0, &j), HEDGER_OK);
  assert_true(j.action_hi < 1.5 && j.kept_action == j.action_hi);
  assert_true(j.gap > 4.0 * j.gap_se);  // the edge of the data turns too hard
  // Contracts.
  assert_int_equal(hedger_judge(h, NULL, 0.0, &j), HEDGER_ERR_INVALID_ARG);
  assert_int_equal(hedger_judge(h, &s, 0.0, NULL), HEDGER_ERR_INVALID_ARG);
  assert_int_equal(hedger_judge(h, &s, NAN, &j), HEDGER_ERR_NON_FINITE);
  hedger_destroy(h);
  // The per-action search has no state model: nothing judged, the action kept as given.
  c.greedy_method = HEDGER_GREEDY_PER_ACTION;
  h = ht_create(&c);
  rs = 23;
  for (int i = 0; i < 600; ++i) {
    const double x = ht_uniform(&rs, -1.0, 1.0);
    const double a = 0.5 * x + 0.2 * ht_normal(&rs);
    assert_int_equal(hedger_insert(h, &x, a, 1.0 - a * a, 0, NULL), HEDGER_OK);
  }
  assert_int_equal(hedger_observe_reward(h, 1.0), HEDGER_OK);
  assert_int_equal(hedger_judge(h, &s, 0.3, &j), HEDGER_OK);
  assert_int_equal(j.judged, 0);
  assert_true(j.kept_action == 0.3 && j.gap == 0.0 && j.gap_se == 0.0);
  hedger_destroy(h);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_anchor_follows_weighted_run),
      cmocka_unit_test(test_anchor_weights_are_relative),
      cmocka_unit_test(test_anchor_recency_fades_old_runs),
      cmocka_unit_test(test_anchor_all_zero_weights_fall_back),
      cmocka_unit_test(test_anchor_tag_and_weight_contracts),
      cmocka_unit_test(test_judge_against_greedy),
  };
  return cmocka_run_group_tests_name("hedger.anchor", tests, NULL, NULL);
}
