// SPDX-License-Identifier: MIT
// Bounded store: eviction keeps reward-bearing points and coverage; the kd-tree + fresh buffer
// with rebuilds in progress answer exactly like a brute-force scan of the store.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "hedger_test_util.h"

static hedger_config_t store_config(uint32_t cap) {
  hedger_config_t c = hedger_config_default();
  c.state_dim = 3;
  c.capacity = cap;
  c.k_min = 3;
  c.k_max = 16;
  c.bandwidth = 0.15;
  c.merge_radius = 0.0;
  return c;
}

static int find_point(const hedger_t* h, const double* s, double a) {
  for (uint32_t i = 0; i < hedger_size(h); ++i) {
    hedger_point_t p;
    hedger_get_point(h, i, &p);
    if (p.state[0] == s[0] && p.state[1] == s[1] && p.state[2] == s[2] && p.action == a) return (int)i;
  }
  return -1;
}

// A full store evicts, but never a protected (reward-bearing / terminal) point while
// unprotected candidates exist.
static void test_store_eviction_keeps_reward_points(void** state) {
  (void)state;
  const hedger_config_t c = store_config(64);
  hedger_t* h = ht_create(&c);
  uint64_t rs = 7;
  double prot[10][4];
  for (int i = 0; i < 10; ++i) {
    for (int d = 0; d < 4; ++d) prot[i][d] = ht_uniform(&rs, -1.0, 1.0);
    hedger_store_op_t op;
    assert_int_equal(hedger_insert(h, prot[i], prot[i][3], 5.0, HEDGER_POINT_PROTECTED, &op), HEDGER_OK);
    assert_int_equal(op, HEDGER_STORE_INSERTED);
  }
  for (int i = 0; i < 5000; ++i) {
    double x[4];
    for (int d = 0; d < 4; ++d) x[d] = ht_uniform(&rs, -1.0, 1.0);
    assert_int_equal(hedger_insert(h, x, x[3], 0.0, 0, NULL), HEDGER_OK);
  }
  const hedger_counters_t* n = hedger_counters(h);
  assert_int_equal(hedger_size(h), 64);
  print_message("protected: evictions %llu, merges %llu, inserts %llu\n", (unsigned long long)n->evictions,
                (unsigned long long)n->merges, (unsigned long long)n->inserts);
  assert_true(n->evictions > 200 && n->evictions + n->merges == 5000 + 10 - 64);
  assert_int_equal(n->protected_evictions, 0);
  assert_int_equal(n->store_protected, 10);
  for (int i = 0; i < 10; ++i) assert_true(find_point(h, prot[i], prot[i][3]) >= 0);
  hedger_destroy(h);
}

// Terminal transitions stored by updates are protected the same way.
static void test_store_terminal_updates_survive_eviction(void** state) {
  (void)state;
  hedger_config_t c = store_config(100);
  c.bandwidth = 0.05;
  hedger_t* h = ht_create(&c);
  uint64_t rs = 9;
  const double goal[3] = {0.9, 0.9, 0.9};
  hedger_update(h, goal, 0.5, 1.0, NULL, 1, NULL);
  for (int i = 0; i < 3000; ++i) {
    double s[3], sn[3];
    for (int d = 0; d < 3; ++d) {
      s[d] = ht_uniform(&rs, -1.0, 0.5);
      sn[d] = s[d] + 0.01;
    }
    hedger_update(h, s, ht_uniform(&rs, -1.0, 1.0), 0.0, sn, 0, NULL);
  }
  assert_true(find_point(h, goal, 0.5) >= 0);
  assert_int_equal(hedger_counters(h)->protected_evictions, 0);
  hedger_destroy(h);
}

// When protected points are all the candidates there are, eviction still makes room (counted).
static void test_store_all_protected_still_evicts(void** state) {
  (void)state;
  const hedger_config_t c = store_config(16);
  hedger_t* h = ht_create(&c);
  uint64_t rs = 11;
  for (int i = 0; i < 200; ++i) {
    double x[4];
    for (int d = 0; d < 4; ++d) x[d] = ht_uniform(&rs, -1.0, 1.0);
    assert_int_equal(hedger_insert(h, x, x[3], 1.0, HEDGER_POINT_PROTECTED, NULL), HEDGER_OK);
  }
  assert_int_equal(hedger_size(h), 16);
  assert_true(hedger_counters(h)->protected_evictions > 0);
  assert_int_equal(hedger_counters(h)->store_protected, 16);
  hedger_destroy(h);
}

// Coverage: a stream that is 90 % one tight cluster keeps most of the store outside it, so the
// sparse region stays known (eviction thins dense regions first).
static void test_store_eviction_thins_dense_regions(void** state) {
  (void)state;
  const hedger_config_t c = store_config(200);
  hedger_t* h = ht_create(&c);
  uint64_t rs = 13;
  for (int i = 0; i < 20000; ++i) {
    double x[4];
    const int clustered = (ht_next(&rs) % 10) != 0;
    for (int d = 0; d < 4; ++d) x[d] = clustered ? ht_uniform(&rs, 0.0, 0.05) : ht_uniform(&rs, -1.0, 1.0);
    hedger_insert(h, x, x[3], 0.0, 0, NULL);
  }
  uint32_t in_cluster = 0;
  for (uint32_t i = 0; i < hedger_size(h); ++i) {
    hedger_point_t p;
    hedger_get_point(h, i, &p);
    int in = 1;
    for (int d = 0; d < 3; ++d) in = in && p.state[d] >= 0.0 && p.state[d] <= 0.05;
    in = in && p.action >= 0.0 && p.action <= 0.05;
    in_cluster += (uint32_t)in;
  }
  print_message("store coverage: %u of %u stored points in the cluster (stream: 90 %%)\n", in_cluster,
                hedger_size(h));
  // About k_min points stay in the cluster (it stays known); the rest covers the sparse region.
  assert_true(in_cluster >= 3 && in_cluster < 200 / 4);
  hedger_destroy(h);
}

// Brute-force neighbour set over the stored points (scale 1: stored coordinates are exact).
static uint32_t brute_neighbours(const hedger_t* h, const double* x, uint32_t k, double r2, uint32_t* out) {
  uint32_t n = 0;
  double d2s[64];
  for (uint32_t i = 0; i < hedger_size(h); ++i) {
    hedger_point_t p;
    hedger_get_point(h, i, &p);
    const double y[4] = {p.state[0], p.state[1], p.state[2], p.action};
    double d2 = 0.0;
    for (int d = 0; d < 4; ++d) d2 += (x[d] - y[d]) * (x[d] - y[d]);
    if (d2 > r2) continue;
    uint32_t pos = n < k ? n++ : k;
    if (pos == k && !(d2 < d2s[k - 1])) continue;  // ties keep the lower slot (earlier i)
    if (pos == k) pos = k - 1;
    while (pos > 0 && d2 < d2s[pos - 1]) {
      d2s[pos] = d2s[pos - 1];
      out[pos] = out[pos - 1];
      --pos;
    }
    d2s[pos] = d2;
    out[pos] = i;
  }
  return n;
}

static void check_against_brute(hedger_t* h, uint64_t* rs, int queries) {
  const hedger_config_t* c = hedger_get_config(h);
  const double r2 = c->bandwidth * c->bandwidth * log(1.0 / c->weight_epsilon);
  for (int q = 0; q < queries; ++q) {
    double x[4];
    for (int d = 0; d < 4; ++d) x[d] = ht_uniform(rs, -1.0, 1.0);
    uint32_t got[64], want[64];
    hedger_prediction_t p;
    hedger_predict_ex(h, x, x[3], &p, got, NULL, 64);
    const uint32_t n = brute_neighbours(h, x, c->k_max, r2, want);
    assert_int_equal(p.n_neighbours, n);
    for (uint32_t i = 0; i < n; ++i) assert_int_equal(got[i], want[i]);
  }
}

// With evictions, sliced rebuilds in progress and forced rebuilds, neighbour sets always equal
// the brute-force scan of the store.
static void test_store_index_matches_brute_force_during_churn(void** state) {
  (void)state;
  hedger_config_t c = store_config(300);
  c.bandwidth = 0.3;
  c.fresh_capacity = 16;
  c.rebuild_work_per_update = 97;  // slow rebuilds: several in flight, some forced
  hedger_t* h = ht_create(&c);
  uint64_t rs = 21;
  for (int i = 0; i < 3000; ++i) {
    double s[3], sn[3];
    for (int d = 0; d < 3; ++d) {
      s[d] = ht_uniform(&rs, -1.0, 1.0);
      sn[d] = s[d] + ht_uniform(&rs, -0.05, 0.05);
    }
    hedger_update(h, s, ht_uniform(&rs, -1.0, 1.0), (i % 97 == 0) ? 1.0 : 0.0, sn, 0, NULL);
    if (i % 50 == 0) check_against_brute(h, &rs, 20);
  }
  const hedger_counters_t* n = hedger_counters(h);
  print_message("churn: rebuilds %llu, forced work %llu, evictions %llu, max work/call %u\n",
                (unsigned long long)n->rebuilds, (unsigned long long)n->forced_rebuild_work,
                (unsigned long long)n->evictions, n->max_rebuild_work);
  assert_true(n->rebuilds > 10);
  assert_true(n->forced_rebuild_work > 0);
  assert_true(n->evictions > 300);
  hedger_destroy(h);
}

// With the automatic budget the rebuild work per update stays bounded and nothing is forced.
static void test_store_rebuild_work_per_update_bounded(void** state) {
  (void)state;
  hedger_config_t c = store_config(2000);
  c.fresh_capacity = 64;
  hedger_t* h = ht_create(&c);
  uint64_t rs = 23;
  for (int i = 0; i < 6000; ++i) {
    double x[4];
    for (int d = 0; d < 4; ++d) x[d] = ht_uniform(&rs, -1.0, 1.0);
    hedger_insert(h, x, x[3], 0.0, 0, NULL);
  }
  check_against_brute(h, &rs, 50);
  const hedger_counters_t* n = hedger_counters(h);
  print_message("auto budget: rebuilds %llu, max work per call %u, forced %llu\n", (unsigned long long)n->rebuilds,
                n->max_rebuild_work, (unsigned long long)n->forced_rebuild_work);
  assert_int_equal(n->forced_rebuild_work, 0);
  assert_true(n->rebuilds > 50);
  // budget = estimate(2000)/(64/2); one call may add the O(fresh) swap.
  assert_true(n->max_rebuild_work < 5000);
  hedger_destroy(h);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_store_eviction_keeps_reward_points),
      cmocka_unit_test(test_store_terminal_updates_survive_eviction),
      cmocka_unit_test(test_store_all_protected_still_evicts),
      cmocka_unit_test(test_store_eviction_thins_dense_regions),
      cmocka_unit_test(test_store_index_matches_brute_force_during_churn),
      cmocka_unit_test(test_store_rebuild_work_per_update_bounded),
  };
  return cmocka_run_group_tests_name("hedger.store", tests, NULL, NULL);
}
