// SPDX-License-Identifier: MIT
// Training update (hand-computed, step by step, including the neighbour pull) and greedy search.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

#include <cmocka.h>

#include "hedger_test_util.h"

// 1-D state; actions {-1, 0, 1} scanned, no refinement; h = 1, α = 0.5, γ = 0.5, k_min = 1.
static hedger_config_t hand_config(void) {
  hedger_config_t c = hedger_config_default();
  c.state_dim = 1;
  c.capacity = 16;
  c.k_min = 1;
  c.k_max = 4;
  c.bandwidth = 1.0;
  c.weight_epsilon = 0.01;  // usable radius sqrt(ln 100) = 2.146
  c.alpha = 0.5;
  c.gamma = 0.5;
  c.greedy_coarse_actions = 3;
  c.greedy_refine_iters = 0;
  c.merge_radius = 0.01;
  return c;
}

// The update of a hand-worked example equals the formulas of hedger.md, step by step.
//   Store: P0 = (s 0, a 0, q 1), P1 = (s 0, a 1, q 3). Two points < D + 1 = 3: every prediction
//   is LWA (singular normal equations), so everything below is a weighted average.
//   Experience: s = 0, a = 0.5, r = 1, s' = 0, not terminal.
static void test_update_hand_example_matches_steps(void** state) {
  (void)state;
  const hedger_config_t c = hand_config();
  hedger_t* h = ht_create(&c);
  const double s0[1] = {0.0};
  hedger_store_op_t op;
  assert_int_equal(hedger_insert(h, s0, 0.0, 1.0, 0, &op), HEDGER_OK);
  assert_int_equal(op, HEDGER_STORE_INSERTED);
  assert_int_equal(hedger_insert(h, s0, 1.0, 3.0, 0, &op), HEDGER_OK);
  const double e1 = exp(-1.0), e025 = exp(-0.25);
  // Step 1: greedy at s' = 0 over a ∈ {-1, 0, 1}:
  //   Q(0,-1) = (e^-1·1 + e^-4·3)/(e^-1 + e^-4) = 1.0993…
  //   Q(0, 0) = (1·1 + e^-1·3)/(1 + e^-1)       = 1.5379…
  //   Q(0, 1) = (e^-1·1 + 1·3)/(e^-1 + 1)       = 2.4621…  → a' = 1, q' = 2.4621…
  const double q_next = (e1 * 1.0 + 3.0) / (e1 + 1.0);
  // Step 2: q = Q(0, 0.5): both points at d² = 0.25 (weight e^-0.25): q = (1 + 3)/2 = 2.
  const double q = (e025 * 1.0 + e025 * 3.0) / (e025 + e025);
  // Step 3: target = r + γ q' = 1 + 0.5·2.4621… = 2.2311…; q_new = q + α (target − q) = 2.1155…
  const double target = 1.0 + 0.5 * q_next;
  const double q_new = q + 0.5 * (target - q);
  // Step 5: pull P0 and P1 toward q_new by α κ = 0.5 e^-0.25.
  const double p0 = 1.0 + 0.5 * e025 * (q_new - 1.0);
  const double p1 = 3.0 + 0.5 * e025 * (q_new - 3.0);

  const double s[1] = {0.0}, sn[1] = {0.0};
  hedger_update_info_t info;
  assert_int_equal(hedger_update(h, s, 0.5, 1.0, sn, 0, &info), HEDGER_OK);
  assert_int_equal(info.next_status, HEDGER_OK);
  assert_true(info.next_action == 1.0);
  assert_int_equal(info.next_kind, HEDGER_KIND_LWA);
  assert_true(fabs(info.next_value - q_next) < 1e-12);
  assert_true(fabs(info.q_next - q_next) < 1e-12);
  assert_int_equal(info.kind, HEDGER_KIND_LWA);
  assert_true(fabs(info.q_old - 2.0) < 1e-12);
  assert_true(fabs(info.q_old - q) < 1e-12);
  assert_true(fabs(info.target - target) < 1e-12);
  assert_true(fabs(info.q_new - q_new) < 1e-12);
  assert_int_equal(info.store_op, HEDGER_STORE_INSERTED);  // d² = 0.25 > merge radius²
  assert_int_equal(info.n_pulled, 2);
  // Step 4 stored the point; step 5 pulled the neighbours.
  assert_int_equal(hedger_size(h), 3);
  hedger_point_t pt;
  hedger_get_point(h, 2, &pt);
  assert_true(pt.state[0] == 0.0 && pt.action == 0.5);
  assert_true(fabs(pt.value - q_new) < 1e-12);
  assert_int_equal(pt.flags, HEDGER_POINT_PROTECTED);  // r ≠ 0: reward-bearing
  hedger_get_point(h, 0, &pt);
  assert_true(fabs(pt.value - p0) < 1e-12);
  hedger_get_point(h, 1, &pt);
  assert_true(fabs(pt.value - p1) < 1e-12);
  // Step 6: rewards seen.
  assert_true(hedger_counters(h)->reward_max == 1.0);
  assert_true(hedger_counters(h)->reward_min == 0.0);
  hedger_destroy(h);
}

// A terminal transition: q' = 0 (no greedy search), the point is protected, r_min tracked.
static void test_update_terminal_uses_zero_next_value(void** state) {
  (void)state;
  const hedger_config_t c = hand_config();
  hedger_t* h = ht_create(&c);
  const double s0[1] = {0.0};
  hedger_insert(h, s0, 0.0, 1.0, 0, NULL);
  const double s[1] = {0.0};
  hedger_update_info_t info;
  const uint64_t greedy_before = hedger_counters(h)->greedy_calls;
  assert_int_equal(hedger_update(h, s, 0.2, -1.0, NULL, 1, &info), HEDGER_OK);
  assert_int_equal(hedger_counters(h)->greedy_calls, greedy_before);
  assert_int_equal(info.next_status, HEDGER_NO_KNOWN_ACTION);
  assert_int_equal(info.next_kind, HEDGER_KIND_UNKNOWN);
  assert_true(info.q_next == 0.0);
  // q = Q(0, 0.2) = 1 (one neighbour, LWA); target = -1; q_new = 1 + 0.5 (-1 - 1) = 0.
  assert_true(fabs(info.q_old - 1.0) < 1e-15);
  assert_true(info.target == -1.0);
  assert_true(fabs(info.q_new - 0.0) < 1e-15);
  hedger_point_t pt;
  hedger_get_point(h, 1, &pt);
  assert_int_equal(pt.flags, HEDGER_POINT_PROTECTED);
  // Pull: 1 + 0.5 e^-0.04 (0 - 1).
  hedger_get_point(h, 0, &pt);
  assert_true(fabs(pt.value - (1.0 - 0.5 * exp(-0.04))) < 1e-12);
  assert_true(hedger_counters(h)->reward_min == -1.0);
  assert_int_equal(hedger_counters(h)->store_protected, 1);
  hedger_destroy(h);
}

// An update with an unknown Q(s, a) starts from the default value; an unknown s' gives q' =
// default and next_status NO_KNOWN_ACTION.
static void test_update_unknown_everywhere_uses_default(void** state) {
  (void)state;
  hedger_config_t c = hand_config();
  c.default_value = 0.5;
  hedger_t* h = ht_create(&c);
  const double s[1] = {0.0}, sn[1] = {0.1};
  hedger_update_info_t info;
  assert_int_equal(hedger_update(h, s, 0.0, 0.0, sn, 0, &info), HEDGER_OK);
  assert_int_equal(info.next_status, HEDGER_NO_KNOWN_ACTION);
  assert_true(info.next_action == 0.0);
  assert_true(info.q_next == 0.5);
  assert_int_equal(info.kind, HEDGER_KIND_UNKNOWN);
  assert_true(info.q_old == 0.5);
  // target = 0 + 0.5·0.5 = 0.25; q_new = 0.5 + 0.5 (0.25 − 0.5) = 0.375
  assert_true(fabs(info.q_new - 0.375) < 1e-15);
  assert_int_equal(info.n_pulled, 0);
  assert_int_equal(hedger_size(h), 1);
  hedger_destroy(h);
}

// A new point within merge_radius of a stored one is merged: no new slot, value moved by κ.
static void test_update_close_point_merged(void** state) {
  (void)state;
  const hedger_config_t c = hand_config();
  hedger_t* h = ht_create(&c);
  const double s0[1] = {0.0};
  hedger_insert(h, s0, 0.0, 1.0, 0, NULL);
  const double s1[1] = {0.005};
  hedger_store_op_t op;
  assert_int_equal(hedger_insert(h, s1, 0.0, 3.0, HEDGER_POINT_PROTECTED, &op), HEDGER_OK);
  assert_int_equal(op, HEDGER_STORE_MERGED);
  assert_int_equal(hedger_size(h), 1);
  hedger_point_t pt;
  hedger_get_point(h, 0, &pt);
  assert_true(fabs(pt.value - (1.0 + exp(-0.005 * 0.005) * 2.0)) < 1e-12);
  assert_int_equal(pt.flags, HEDGER_POINT_PROTECTED);  // protection carried over
  assert_int_equal(hedger_counters(h)->merges, 1);
  hedger_destroy(h);
}

// Greedy: unknown actions never win over known ones, even with a higher default value.
static void test_greedy_unknown_never_beats_known(void** state) {
  (void)state;
  hedger_config_t c = hand_config();
  c.default_value = 100.0;
  c.greedy_coarse_actions = 5;
  hedger_t* h = ht_create(&c);
  const double s[1] = {0.0};
  hedger_insert(h, s, 1.0, -5.0, 0, NULL);  // known only near a = 1 (radius 2.1 reaches a = -1!)
  double a = 0.0, v = 0.0;
  hedger_kind_t k;
  // With h = 1 every action sees the point: all known, all -5: ties → the smallest action.
  assert_int_equal(hedger_greedy(h, s, &a, &v, &k), HEDGER_OK);
  assert_true(a == -1.0);
  assert_true(v == -5.0);
  hedger_destroy(h);
  c.bandwidth = 0.25;  // radius 0.54: only a ∈ {0.5, 1} see the point
  h = ht_create(&c);
  hedger_insert(h, s, 1.0, -5.0, 0, NULL);
  assert_int_equal(hedger_greedy(h, s, &a, &v, &k), HEDGER_OK);
  assert_true(a == 0.5);  // tie between 0.5 and 1 (both -5): the smaller action
  assert_true(v == -5.0);
  assert_int_equal(k, HEDGER_KIND_LWA);
  hedger_destroy(h);
}

// Greedy with nothing known: a distinct status, midpoint action, default value.
static void test_greedy_all_unknown_distinct_status(void** state) {
  (void)state;
  hedger_config_t c = hand_config();
  c.action_min = -0.5;
  c.action_max = 1.5;
  c.default_value = 2.0;
  hedger_t* h = ht_create(&c);
  const double s[1] = {3.0};
  double a = 0.0, v = 0.0;
  hedger_kind_t k = HEDGER_KIND_LWR;
  assert_int_equal(hedger_greedy(h, s, &a, &v, &k), HEDGER_NO_KNOWN_ACTION);
  assert_true(a == 0.5);
  assert_true(v == 2.0);
  assert_int_equal(k, HEDGER_KIND_UNKNOWN);
  assert_int_equal(hedger_counters(h)->greedy_all_unknown, 1);
  hedger_destroy(h);
}

// Greedy refinement finds an interior maximum between grid actions.
static void test_greedy_refines_interior_maximum(void** state) {
  (void)state;
  hedger_config_t c = hedger_config_default();
  c.state_dim = 1;
  c.capacity = 4000;
  c.k_min = 3;
  c.k_max = 24;
  c.bandwidth = 0.15;
  c.greedy_coarse_actions = 5;  // grid step 0.5: the optimum 0.3 is not on it
  c.greedy_refine_iters = 10;
  c.merge_radius = 0.0;
  hedger_t* h = ht_create(&c);
  hedger_observe_reward(h, 1.0);
  hedger_observe_reward(h, -1.0);
  for (int i = 0; i <= 20; ++i) {
    for (int j = 0; j <= 80; ++j) {
      const double s[1] = {-0.5 + 0.05 * i};
      const double a = -1.0 + 0.025 * j;
      hedger_insert(h, s, a, 1.0 - (a - 0.3) * (a - 0.3), 0, NULL);
    }
  }
  const double s[1] = {0.0};
  double a = 0.0, v = 0.0;
  hedger_kind_t k;
  assert_int_equal(hedger_greedy(h, s, &a, &v, &k), HEDGER_OK);
  assert_true(fabs(a - 0.3) < 0.03);
  assert_true(v > 0.99 && v <= 1.0 + 1e-3);
  assert_int_equal(hedger_counters(h)->greedy_calls, 1);
  const hedger_counters_t* n = hedger_counters(h);
  assert_int_equal(n->predictions_lwr + n->predictions_lwa + n->predictions_unknown, 5 + 10);
  hedger_destroy(h);
}

// Non-finite inputs are refused with their own code, counted, and nothing is stored.
static void test_update_non_finite_rejected(void** state) {
  (void)state;
  const hedger_config_t c = hand_config();
  hedger_t* h = ht_create(&c);
  const double ok[1] = {0.0}, bad[1] = {NAN}, inf[1] = {INFINITY};
  hedger_update_info_t info;
  hedger_prediction_t p;
  assert_int_equal(hedger_update(h, bad, 0.0, 0.0, ok, 0, &info), HEDGER_ERR_NON_FINITE);
  assert_int_equal(hedger_update(h, ok, NAN, 0.0, ok, 0, &info), HEDGER_ERR_NON_FINITE);
  assert_int_equal(hedger_update(h, ok, 0.0, INFINITY, ok, 0, &info), HEDGER_ERR_NON_FINITE);
  assert_int_equal(hedger_update(h, ok, 0.0, 0.0, inf, 0, &info), HEDGER_ERR_NON_FINITE);
  assert_int_equal(hedger_update(h, ok, 0.0, 0.0, bad, 1, &info), HEDGER_OK);  // s' ignored if terminal
  assert_int_equal(hedger_predict(h, bad, 0.0, &p), HEDGER_ERR_NON_FINITE);
  assert_int_equal(hedger_predict(h, ok, -INFINITY, &p), HEDGER_ERR_NON_FINITE);
  assert_int_equal(hedger_greedy(h, inf, NULL, NULL, NULL), HEDGER_ERR_NON_FINITE);
  assert_int_equal(hedger_insert(h, ok, 0.0, NAN, 0, NULL), HEDGER_ERR_NON_FINITE);
  assert_int_equal(hedger_observe_reward(h, NAN), HEDGER_ERR_NON_FINITE);
  assert_int_equal(hedger_counters(h)->rejected_non_finite, 9);
  assert_int_equal(hedger_size(h), 1);
  assert_int_equal(hedger_counters(h)->updates, 1);
  // Invalid arguments are refused too.
  assert_int_equal(hedger_update(NULL, ok, 0.0, 0.0, ok, 0, &info), HEDGER_ERR_INVALID_ARG);
  assert_int_equal(hedger_update(h, ok, 0.0, 0.0, NULL, 0, &info), HEDGER_ERR_INVALID_ARG);
  assert_int_equal(hedger_predict(h, ok, 0.0, NULL), HEDGER_ERR_INVALID_ARG);
  assert_int_equal(hedger_insert(h, ok, 0.0, 0.0, 0x80, NULL), HEDGER_ERR_INVALID_ARG);
  hedger_destroy(h);
}

// The replay tests' chain: s = 0, 1, 2, 3 (far apart: no neighbour sharing, each state its own
// stored point), action 0, reward 1 at the terminal end; alpha 0.5 online, the replay's step
// replay_alpha (0 = alpha).
static hedger_config_t chain_config(double replay_alpha) {
  hedger_config_t c = hand_config();
  c.run_capacity = 8;
  c.replay = 1;
  c.gamma = 0.9;
  c.alpha = 0.5;
  c.replay_alpha = replay_alpha;
  c.greedy_coarse_actions = 3;
  c.bandwidth = 0.1;
  return c;
}

static void drive_chain(hedger_t* h) {
  for (int t = 0; t < 3; ++t) {
    const double s[1] = {(double)t}, sn[1] = {(double)t + 1.0};
    hedger_update(h, s, 0.0, 0.0, sn, 0, NULL);
  }
  const double s3[1] = {3.0};
  hedger_update(h, s3, 0.0, 1.0, NULL, 1, NULL);
}

// Backward replay re-applies the run newest first and propagates a final reward back.
static void test_end_run_replay_propagates_reward(void** state) {
  (void)state;
  const hedger_config_t c = chain_config(0.0);
  hedger_t* h = ht_create(&c);
  drive_chain(h);
  assert_int_equal(hedger_counters(h)->run_fill, 4);
  uint32_t replayed = 0;
  assert_int_equal(hedger_end_run(h, &replayed), HEDGER_OK);
  assert_int_equal(replayed, 4);
  assert_int_equal(hedger_counters(h)->replayed_updates, 4);
  assert_int_equal(hedger_counters(h)->run_fill, 0);
  // After replay, the value reached s = 2 (one step before the reward) in the same run.
  hedger_prediction_t p;
  const double s2[1] = {2.0};
  hedger_predict(h, s2, 0.0, &p);
  assert_true(p.kind != HEDGER_KIND_UNKNOWN);
  assert_true(p.value > 0.0);
  hedger_destroy(h);
}

// The replay's own learning rate (cfg.replay_alpha): the online update keeps alpha, the replay's
// updates take replay_alpha; 0 means alpha, bit for bit. On the chain the terminal state's value
// after one replayed update is known exactly: alpha 0.5 online gives 0.5, the replay's step 0.5
// then 0.75, a replay step of 1 the reward.
static hedger_t* replay_chain(double replay_alpha, double* v_before, double* v_after) {
  const hedger_config_t c = chain_config(replay_alpha);
  hedger_t* h = ht_create(&c);
  drive_chain(h);
  const double s3[1] = {3.0};
  hedger_prediction_t p;
  hedger_predict(h, s3, 0.0, &p);
  *v_before = p.value;
  assert_int_equal(hedger_end_run(h, NULL), HEDGER_OK);
  hedger_predict(h, s3, 0.0, &p);
  *v_after = p.value;
  return h;
}

static void test_end_run_replay_alpha(void** state) {
  (void)state;
  double before[3], after[3];
  hedger_t* h_default = replay_chain(0.0, &before[0], &after[0]);
  hedger_t* h_same = replay_chain(0.5, &before[1], &after[1]);
  hedger_t* h_full = replay_chain(1.0, &before[2], &after[2]);
  for (int i = 0; i < 3; ++i) assert_float_equal(before[i], 0.5, 1e-12);
  assert_float_equal(after[0], 0.75, 1e-12);
  assert_float_equal(after[2], 1.0, 1e-12);
  // replay_alpha = alpha is the default's learned state, byte for byte.
  assert_true(ht_same_saved(h_default, h_same));
  hedger_destroy(h_default);
  hedger_destroy(h_same);
  hedger_destroy(h_full);
  // Outside [0, 1]: refused.
  hedger_config_t c = chain_config(1.5);
  hedger_t* bad = NULL;
  assert_int_equal(hedger_create(&bad, &c), HEDGER_ERR_INVALID_ARG);
  c.replay_alpha = -0.1;
  assert_int_equal(hedger_create(&bad, &c), HEDGER_ERR_INVALID_ARG);
  assert_null(bad);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_update_hand_example_matches_steps),
      cmocka_unit_test(test_update_terminal_uses_zero_next_value),
      cmocka_unit_test(test_update_unknown_everywhere_uses_default),
      cmocka_unit_test(test_update_close_point_merged),
      cmocka_unit_test(test_greedy_unknown_never_beats_known),
      cmocka_unit_test(test_greedy_all_unknown_distinct_status),
      cmocka_unit_test(test_greedy_refines_interior_maximum),
      cmocka_unit_test(test_update_non_finite_rejected),
      cmocka_unit_test(test_end_run_replay_propagates_reward),
      cmocka_unit_test(test_end_run_replay_alpha),
  };
  return cmocka_run_group_tests_name("hedger.update", tests, NULL, NULL);
}
