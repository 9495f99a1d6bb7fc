// SPDX-License-Identifier: MIT
// Prediction: LWR reproduces linear data, the IVH test, the plausibility bounds, unknown.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>

#include "hedger_test_util.h"

// q(s, a) = 1 + 2 s0 − 3 s1 + 0.5 a: a known linear function.
static double lin(const double* s, double a) { return 1.0 + 2.0 * s[0] - 3.0 * s[1] + 0.5 * a; }

static hedger_config_t lin_config(void) {
  hedger_config_t c = hedger_config_default();
  c.state_dim = 2;
  c.capacity = 2000;
  c.k_min = 4;
  c.k_max = 32;
  c.bandwidth = 0.3;
  c.ridge = 0.0;
  c.gamma = 0.9;
  c.merge_radius = 0.0;
  return c;
}

// Fills [0,1]^2 × [-1,1] with a grid of points valued by lin(); rewards seen [-1, 1] so that
// the plausible range is [-10, 10].
static hedger_t* make_linear(void) {
  const hedger_config_t c = lin_config();
  hedger_t* h = ht_create(&c);
  for (int i = 0; i <= 10; ++i) {
    for (int j = 0; j <= 10; ++j) {
      for (int k = 0; k <= 8; ++k) {
        const double s[2] = {0.1 * i, 0.1 * j};
        const double a = -1.0 + 0.25 * k;
        assert_int_equal(hedger_insert(h, s, a, lin(s, a), 0, NULL), HEDGER_OK);
      }
    }
  }
  assert_int_equal(hedger_observe_reward(h, -1.0), HEDGER_OK);
  assert_int_equal(hedger_observe_reward(h, 1.0), HEDGER_OK);
  return h;
}

// Inside the data, LWR reproduces the linear function to rounding.
static void test_predict_linear_data_lwr_exact(void** state) {
  (void)state;
  hedger_t* h = make_linear();
  uint64_t rs = 42;
  for (int i = 0; i < 200; ++i) {
    const double s[2] = {ht_uniform(&rs, 0.1, 0.9), ht_uniform(&rs, 0.1, 0.9)};
    const double a = ht_uniform(&rs, -0.8, 0.8);
    hedger_prediction_t p;
    assert_int_equal(hedger_predict(h, s, a, &p), HEDGER_OK);
    assert_int_equal(p.kind, HEDGER_KIND_LWR);
    assert_int_equal(p.fallback, HEDGER_FALLBACK_NONE);
    assert_true(p.n_neighbours >= 4 && p.n_neighbours <= 32);
    assert_true(fabs(p.value - lin(s, a)) < 1e-9);
  }
  assert_int_equal(hedger_counters(h)->predictions_lwr, 200);
  hedger_destroy(h);
}

// The IVH test accepts a query inside the data and rejects a far extrapolation (LWA instead).
static void test_predict_far_extrapolation_outside_hull_lwa(void** state) {
  (void)state;
  hedger_config_t c = lin_config();
  c.bandwidth = 1.0;  // neighbours reach 2.1 scaled units: far queries still have neighbours
  hedger_t* h = ht_create(&c);
  for (int i = 0; i <= 4; ++i) {
    for (int j = 0; j <= 4; ++j) {
      for (int k = 0; k <= 4; ++k) {
        const double s[2] = {0.25 * i, 0.25 * j};
        const double a = -0.5 + 0.25 * k;
        assert_int_equal(hedger_insert(h, s, a, lin(s, a), 0, NULL), HEDGER_OK);
      }
    }
  }
  hedger_observe_reward(h, -10.0);
  hedger_observe_reward(h, 10.0);
  hedger_prediction_t p;
  const double inside[2] = {0.5, 0.5};
  assert_int_equal(hedger_predict(h, inside, 0.0, &p), HEDGER_OK);
  assert_int_equal(p.kind, HEDGER_KIND_LWR);
  const double outside[2] = {2.0, 0.5};  // 1 unit beyond the data along s0
  assert_int_equal(hedger_predict(h, outside, 0.0, &p), HEDGER_OK);
  assert_true(p.n_neighbours >= c.k_min);
  assert_int_equal(p.kind, HEDGER_KIND_LWA);
  assert_int_equal(p.fallback, HEDGER_FALLBACK_HULL);
  // LWA never extrapolates: the value lies within the stored values' range.
  assert_true(p.value <= lin((const double[]){1.0, 0.0}, 0.5) + 1e-12);
  assert_int_equal(hedger_counters(h)->fallback_hull, 1);
  hedger_destroy(h);
}

// An LWR value outside [Q_min, Q_max] falls back to the weighted average of the neighbours.
static void test_predict_implausible_value_falls_back_to_lwa(void** state) {
  (void)state;
  // Rewards seen bound values to [0, 1] while the data (lin) reach 3.5.
  const hedger_config_t c = lin_config();
  hedger_t* h = ht_create(&c);
  for (int i = 0; i <= 10; ++i) {
    for (int k = 0; k <= 8; ++k) {
      for (int j = 0; j <= 10; ++j) {
        const double s[2] = {0.1 * i, 0.1 * j};
        const double a = -1.0 + 0.25 * k;
        hedger_insert(h, s, a, lin(s, a), 0, NULL);
      }
    }
  }
  hedger_observe_reward(h, 0.1);  // Q_max = 0.1 / (1 − 0.9) = 1
  const double s[2] = {0.8, 0.2};   // lin = 1 + 1.6 − 0.6 + 0 = 2 > 1
  uint32_t slots[32];
  double w[32];
  hedger_prediction_t p;
  assert_int_equal(hedger_predict_ex(h, s, 0.0, &p, slots, w, 32), HEDGER_OK);
  assert_int_equal(p.kind, HEDGER_KIND_LWA);
  assert_int_equal(p.fallback, HEDGER_FALLBACK_IMPLAUSIBLE);
  double sw = 0.0, swq = 0.0;
  for (uint32_t i = 0; i < p.n_neighbours; ++i) {
    hedger_point_t pt;
    assert_int_equal(hedger_get_point(h, slots[i], &pt), HEDGER_OK);
    sw += w[i];
    swq += w[i] * pt.value;
  }
  assert_true(fabs(p.value - swq / sw) < 1e-12);
  assert_int_equal(hedger_counters(h)->fallback_implausible, 1);
  hedger_destroy(h);
}

// Before any reward, Q_min = Q_max = 0: any non-zero LWR value is implausible.
static void test_predict_no_reward_seen_bounds_are_zero(void** state) {
  (void)state;
  const hedger_config_t c = lin_config();
  hedger_t* h = ht_create(&c);
  for (int i = 0; i <= 5; ++i) {
    for (int k = 0; k <= 5; ++k) {
      const double s[2] = {0.2 * i, 0.5};
      hedger_insert(h, s, -1.0 + 0.4 * k, 1.0 + 0.01 * i, 0, NULL);
      const double s2[2] = {0.2 * i, 0.6};
      hedger_insert(h, s2, -1.0 + 0.4 * k, 1.0 + 0.01 * k, 0, NULL);
    }
  }
  hedger_prediction_t p;
  const double q[2] = {0.5, 0.55};
  assert_int_equal(hedger_predict(h, q, 0.0, &p), HEDGER_OK);
  assert_int_equal(p.kind, HEDGER_KIND_LWA);
  assert_int_equal(p.fallback, HEDGER_FALLBACK_IMPLAUSIBLE);
  hedger_destroy(h);
}

// Fewer than k_min usable neighbours → unknown with the default value.
static void test_predict_fewer_than_kmin_unknown(void** state) {
  (void)state;
  hedger_config_t c = lin_config();
  c.default_value = -7.5;
  hedger_t* h = ht_create(&c);
  hedger_prediction_t p;
  const double s[2] = {0.0, 0.0};
  assert_int_equal(hedger_predict(h, s, 0.0, &p), HEDGER_OK);  // empty store
  assert_int_equal(p.kind, HEDGER_KIND_UNKNOWN);
  assert_true(p.value == -7.5);
  assert_int_equal(p.n_neighbours, 0);
  for (int i = 0; i < 3; ++i) {
    const double si[2] = {0.05 * i, 0.0};
    hedger_insert(h, si, 0.0, 1.0, 0, NULL);
  }
  assert_int_equal(hedger_predict(h, s, 0.0, &p), HEDGER_OK);  // 3 < k_min = 4
  assert_int_equal(p.kind, HEDGER_KIND_UNKNOWN);
  assert_int_equal(p.n_neighbours, 3);
  const double si[2] = {0.0, 0.05};
  hedger_insert(h, si, 0.0, 1.0, 0, NULL);
  assert_int_equal(hedger_predict(h, s, 0.0, &p), HEDGER_OK);  // 4 = k_min: known
  assert_int_equal(p.n_neighbours, 4);
  assert_true(p.kind != HEDGER_KIND_UNKNOWN);
  // Far away (beyond h·sqrt(ln(1/eps))): no usable neighbour.
  const double far[2] = {5.0, 5.0};
  assert_int_equal(hedger_predict(h, far, 0.0, &p), HEDGER_OK);
  assert_int_equal(p.kind, HEDGER_KIND_UNKNOWN);
  assert_int_equal(p.n_neighbours, 0);
  assert_int_equal(hedger_counters(h)->predictions_unknown, 3);
  hedger_destroy(h);
}

// Neighbourhoods hold at most k_max points, nearest first, with weights exp(-d^2/h^2).
static void test_predict_neighbours_sorted_weights_gaussian(void** state) {
  (void)state;
  hedger_t* h = make_linear();
  const double s[2] = {0.52, 0.47};
  uint32_t slots[64];
  double w[64];
  hedger_prediction_t p;
  assert_int_equal(hedger_predict_ex(h, s, 0.1, &p, slots, w, 64), HEDGER_OK);
  assert_int_equal(p.n_neighbours, 32);
  for (uint32_t i = 0; i < p.n_neighbours; ++i) {
    hedger_point_t pt;
    hedger_get_point(h, slots[i], &pt);
    const double d2 = (pt.state[0] - s[0]) * (pt.state[0] - s[0]) + (pt.state[1] - s[1]) * (pt.state[1] - s[1]) +
                      (pt.action - 0.1) * (pt.action - 0.1);
    assert_true(fabs(w[i] - exp(-d2 / 0.09)) < 1e-12);
    if (i > 0) assert_true(w[i] <= w[i - 1]);
  }
  hedger_destroy(h);
}

// The weighted IVH variant also accepts inside (exact LWR) and rejects extrapolation.
static void test_predict_weighted_ivh_mode_works(void** state) {
  (void)state;
  hedger_config_t c = lin_config();
  c.ivh_mode = HEDGER_IVH_WEIGHTED;
  hedger_t* h = ht_create(&c);
  for (int i = 0; i <= 10; ++i) {
    for (int j = 0; j <= 10; ++j) {
      for (int k = 0; k <= 8; ++k) {
        const double s[2] = {0.1 * i, 0.1 * j};
        hedger_insert(h, s, -1.0 + 0.25 * k, lin(s, -1.0 + 0.25 * k), 0, NULL);
      }
    }
  }
  hedger_observe_reward(h, -1.0);
  hedger_observe_reward(h, 1.0);
  hedger_prediction_t p;
  const double in[2] = {0.5, 0.5};
  hedger_predict(h, in, 0.0, &p);
  assert_int_equal(p.kind, HEDGER_KIND_LWR);
  assert_true(fabs(p.value - lin(in, 0.0)) < 1e-9);
  const double out[2] = {1.3, 0.5};
  hedger_predict(h, out, 0.0, &p);
  assert_int_equal(p.kind, HEDGER_KIND_LWA);
  hedger_destroy(h);
}

// Rank-deficient neighbourhoods (hedger.h, HEDGER_FALLBACK_SINGULAR) never give LWR.
// Reproducer: D = 4 (3-D state + action), 4 stored points, query at a stored point: the design
// matrix [x_i, 1] has rank 4 of 5, yet the pivots of its LDLT looked regular (this exact set was
// answered by LWR before the rank test).
static const double k_rep_s[4][3] = {{0x1.22efecb05e6f7p-5, 0x1.9f3b6e1e10e8dp-7, 0x1.edd93d78d808dp-5},
                                     {0x1.ef16b26c3160ap-5, 0x1.9fcb55360976dp-4, 0x1.6947b8afe3729p-3},
                                     {0x1.00eb72819e48p-5, 0x1.940e76765f6c1p-3, 0x1.41fe5f7c81b95p-3},
                                     {0x1.ccf170668119dp-5, 0x1.39fc63edba89p-3, 0x1.66629365d7f7ap-4}};
static const double k_rep_a[4] = {0x1.2399c55b578d6p-3, 0x1.27a54ba840226p-3, -0x1.f008f0b141e5cp-5,
                                  -0x1.44406696736bap-4};
static const double k_rep_q[4] = {0x1.6bd3cae5931dep-1, 0x1.6efa423618e3p-5, 0x1.4f54f1a80d03ep-2,
                                  0x1.77f32404b4b8p-4};

static hedger_config_t rank_config(void) {
  hedger_config_t c = hedger_config_default();  // state_dim 3: D = 4
  c.capacity = 64;
  c.merge_radius = 0.0;
  c.bandwidth = 0.2;
  c.k_min = 3;
  return c;
}

// Stores n points: states s (n rows of 3), actions a, values q.
static hedger_t* rank_instance(const double* s, const double* a, const double* q, int n) {
  const hedger_config_t c = rank_config();
  hedger_t* h = ht_create(&c);
  for (int i = 0; i < n; ++i) {
    assert_int_equal(hedger_insert(h, s + 3 * i, a[i], q[i], 0, NULL), HEDGER_OK);
  }
  hedger_observe_reward(h, -1.0);
  hedger_observe_reward(h, 1.0);
  return h;
}

static void test_predict_rank_deficient_reproducer_singular(void** state) {
  (void)state;
  hedger_t* h = rank_instance(&k_rep_s[0][0], k_rep_a, k_rep_q, 4);
  hedger_prediction_t p;
  assert_int_equal(hedger_predict(h, k_rep_s[0], k_rep_a[0], &p), HEDGER_OK);
  assert_int_equal(p.n_neighbours, 4);
  assert_int_equal(p.kind, HEDGER_KIND_LWA);
  assert_int_equal(p.fallback, HEDGER_FALLBACK_SINGULAR);
  assert_int_equal(hedger_counters(h)->fallback_singular, 1);
  hedger_destroy(h);
}

// The same for every one of 4000 random 4-point neighbourhoods queried at a stored point, and
// for 12 points on a tilted hyperplane (enough points, still rank 4 of 5); D + 1 points in
// general position are not refused.
static void test_predict_rank_deficient_random_singular(void** state) {
  (void)state;
  uint64_t rs = 7;
  for (int t = 0; t < 4000; ++t) {
    double s[4][3], a[4], q[4];
    for (int i = 0; i < 4; ++i) {
      for (int j = 0; j < 3; ++j) s[i][j] = ht_uniform(&rs, 0.0, 0.2);
      a[i] = ht_uniform(&rs, -0.2, 0.2);
      q[i] = ht_uniform(&rs, 0.0, 1.0);
    }
    hedger_t* h = rank_instance(&s[0][0], a, q, 4);
    hedger_prediction_t p;
    assert_int_equal(hedger_predict(h, s[t % 4], a[t % 4], &p), HEDGER_OK);
    assert_int_equal(p.fallback, HEDGER_FALLBACK_SINGULAR);
    hedger_destroy(h);
  }
  for (int t = 0; t < 200; ++t) {
    // Points with n·x = 0.05 for a random normal n (x = state, action): rank 4 of 5.
    double n[4], s[12][3], a[12], q[12];
    for (int j = 0; j < 4; ++j) n[j] = ht_uniform(&rs, 0.5, 1.0);
    for (int i = 0; i < 12; ++i) {
      for (int j = 0; j < 3; ++j) s[i][j] = ht_uniform(&rs, 0.0, 0.1);
      a[i] = (0.05 - n[0] * s[i][0] - n[1] * s[i][1] - n[2] * s[i][2]) / n[3];
      q[i] = ht_uniform(&rs, 0.0, 1.0);
    }
    hedger_t* h = rank_instance(&s[0][0], a, q, 12);
    hedger_prediction_t p;
    assert_int_equal(hedger_predict(h, s[t % 12], a[t % 12], &p), HEDGER_OK);
    assert_int_equal(p.n_neighbours, 12);
    assert_int_equal(p.fallback, HEDGER_FALLBACK_SINGULAR);
    hedger_destroy(h);
  }
  for (int t = 0; t < 200; ++t) {
    double s[5][3], a[5], q[5], centre[3] = {0.0, 0.0, 0.0}, ca = 0.0;
    for (int i = 0; i < 5; ++i) {
      for (int j = 0; j < 3; ++j) {
        s[i][j] = ht_uniform(&rs, 0.0, 0.2);
        centre[j] += s[i][j] / 5.0;
      }
      a[i] = ht_uniform(&rs, -0.2, 0.2);
      ca += a[i] / 5.0;
      q[i] = ht_uniform(&rs, 0.0, 1.0);
    }
    hedger_t* h = rank_instance(&s[0][0], a, q, 5);
    hedger_prediction_t p;
    assert_int_equal(hedger_predict(h, centre, ca, &p), HEDGER_OK);
    assert_int_equal(p.n_neighbours, 5);
    assert_true(p.fallback != HEDGER_FALLBACK_SINGULAR);
    hedger_destroy(h);
  }
}

// HEDGER_LOCAL_LWA: every known prediction is the kernel-weighted average of the neighbours it
// reports (no regression, so near the data's edge it is biased toward the interior where LWR is
// exact); the greedy search ignores the state model; an unknown local model is refused.
static void test_predict_lwa_only_mode(void** state) {
  (void)state;
  hedger_config_t c = lin_config();
  c.local_model = HEDGER_LOCAL_LWA;
  c.greedy_method = HEDGER_GREEDY_STATE_MODEL;
  hedger_t* h = ht_create(&c);
  for (int i = 0; i <= 10; ++i) {
    for (int j = 0; j <= 10; ++j) {
      for (int k = 0; k <= 8; ++k) {
        const double s[2] = {0.1 * i, 0.1 * j};
        const double a = -1.0 + 0.25 * k;
        assert_int_equal(hedger_insert(h, s, a, lin(s, a), 0, NULL), HEDGER_OK);
      }
    }
  }
  const double s[2] = {0.02, 0.97};
  const double a = 0.9;
  hedger_prediction_t p;
  uint32_t slots[32];
  double w[32];
  assert_int_equal(hedger_predict_ex(h, s, a, &p, slots, w, 32), HEDGER_OK);
  assert_int_equal(p.kind, HEDGER_KIND_LWA);
  assert_int_equal(p.fallback, HEDGER_FALLBACK_NONE);
  assert_true(p.n_neighbours >= 4);
  double sw = 0.0, swq = 0.0;
  for (uint32_t i = 0; i < p.n_neighbours; ++i) {
    hedger_point_t pt;
    assert_int_equal(hedger_get_point(h, slots[i], &pt), HEDGER_OK);
    sw += w[i];
    swq += w[i] * pt.value;
  }
  assert_true(fabs(p.value - swq / sw) <= 1e-12 * fabs(swq / sw));
  assert_true(fabs(p.value - lin(s, a)) > 0.05);
  const hedger_counters_t* k = hedger_counters(h);
  assert_int_equal(k->predictions_lwr, 0);
  double ga = 0.0;
  assert_int_equal(hedger_greedy(h, s, &ga, NULL, NULL), HEDGER_OK);
  assert_int_equal(k->greedy_state_model, 0);
  assert_int_equal(k->predictions_lwr, 0);
  hedger_destroy(h);
  c.local_model = 2;
  assert_int_equal(hedger_config_validate(&c), HEDGER_ERR_INVALID_ARG);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_predict_linear_data_lwr_exact),
      cmocka_unit_test(test_predict_far_extrapolation_outside_hull_lwa),
      cmocka_unit_test(test_predict_implausible_value_falls_back_to_lwa),
      cmocka_unit_test(test_predict_no_reward_seen_bounds_are_zero),
      cmocka_unit_test(test_predict_fewer_than_kmin_unknown),
      cmocka_unit_test(test_predict_neighbours_sorted_weights_gaussian),
      cmocka_unit_test(test_predict_weighted_ivh_mode_works),
      cmocka_unit_test(test_predict_rank_deficient_reproducer_singular),
      cmocka_unit_test(test_predict_rank_deficient_random_singular),
      cmocka_unit_test(test_predict_lwa_only_mode),
  };
  return cmocka_run_group_tests_name("hedger.predict", tests, NULL, NULL);
}
