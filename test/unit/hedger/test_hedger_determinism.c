// SPDX-License-Identifier: MIT
// Determinism (same calls → bit-identical outputs and bytes) and zero allocation after init.
#include <b21r_test/alloc_counter.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "hedger_test_util.h"

static hedger_config_t det_config(void) {
  hedger_config_t c = hedger_config_default();
  c.state_dim = 3;
  c.capacity = 400;  // small: evictions and merges happen
  c.fresh_capacity = 32;
  c.bandwidth = 0.25;
  c.run_capacity = 64;
  c.replay = 1;
  c.seed = 1234;
  return c;
}

static int same_info(const hedger_update_info_t* a, const hedger_update_info_t* b) {
  return a->next_status == b->next_status && memcmp(&a->next_action, &b->next_action, 8) == 0 &&
         memcmp(&a->next_value, &b->next_value, 8) == 0 && a->next_kind == b->next_kind &&
         memcmp(&a->q_next, &b->q_next, 8) == 0 && memcmp(&a->q_old, &b->q_old, 8) == 0 && a->kind == b->kind &&
         memcmp(&a->target, &b->target, 8) == 0 && memcmp(&a->q_new, &b->q_new, 8) == 0 &&
         a->n_pulled == b->n_pulled && a->store_op == b->store_op;
}

// Drives one episode-structured random workload; writes a digest of every output.
typedef struct {
  hedger_update_info_t info;
  hedger_prediction_t pred;
  double ga, gv;
  hedger_kind_t gk;
  hedger_status_t gs;
} step_out_t;

static void step(hedger_t* h, uint64_t* rs, int t, step_out_t* o) {
  double s[3], sn[3];
  for (int d = 0; d < 3; ++d) {
    s[d] = ht_uniform(rs, -1.0, 1.0);
    sn[d] = s[d] + 0.05 * ht_normal(rs);
  }
  const double a = ht_uniform(rs, -1.0, 1.0);
  const int terminal = (t % 50) == 49;
  const double r = terminal ? 1.0 : 0.0;
  hedger_update(h, s, a, r, sn, terminal, &o->info);
  hedger_predict(h, sn, a, &o->pred);
  o->gs = hedger_greedy(h, s, &o->ga, &o->gv, &o->gk);
  if (terminal) hedger_end_run(h, NULL);
}

// Two instances fed the same calls produce bit-identical outputs, counters and saved bytes.
static void test_determinism_two_instances_bit_identical(void** state) {
  (void)state;
  const hedger_config_t c = det_config();
  hedger_t* a = ht_create(&c);
  hedger_t* b = ht_create(&c);
  uint64_t ra = 99, rb = 99;
  for (int t = 0; t < 1000; ++t) {
    step_out_t oa, ob;
    step(a, &ra, t, &oa);
    step(b, &rb, t, &ob);
    assert_true(same_info(&oa.info, &ob.info));
    assert_true(memcmp(&oa.pred.value, &ob.pred.value, 8) == 0 && oa.pred.kind == ob.pred.kind &&
                oa.pred.n_neighbours == ob.pred.n_neighbours);
    assert_true(oa.gs == ob.gs && memcmp(&oa.ga, &ob.ga, 8) == 0 && memcmp(&oa.gv, &ob.gv, 8) == 0);
  }
  assert_true(memcmp(hedger_counters(a), hedger_counters(b), sizeof(hedger_counters_t)) == 0);
  assert_true(ht_same_saved(a, b));
  const hedger_counters_t* k = hedger_counters(a);
  print_message("determinism workload: %llu updates, lwr %llu, lwa %llu, unknown %llu, evictions %llu, merges %llu, "
                "rebuilds %llu\n",
                (unsigned long long)k->updates, (unsigned long long)k->predictions_lwr,
                (unsigned long long)k->predictions_lwa, (unsigned long long)k->predictions_unknown,
                (unsigned long long)k->evictions, (unsigned long long)k->merges, (unsigned long long)k->rebuilds);
  assert_true(k->evictions > 0 && k->rebuilds > 0 && k->predictions_lwr > 0 && k->replayed_updates > 0);
  hedger_destroy(a);
  hedger_destroy(b);
}

// A k-NN search is bounded by the neighbours of the previous search of its kind (hedger.h,
// "kd-tree"): along a path of close queries the bound is tight from the start. Two instances with
// the same store answer the same queries bit for bit, whether or not each query follows a close
// one (the other instance asks about a far state in between, so its bounds start wide open), with
// the state model's query (greedy, k_max 64 of a dense store) and the prediction's.
static void test_determinism_results_independent_of_search_history(void** state) {
  (void)state;
  hedger_config_t c = hedger_config_default();
  c.state_dim = 3;
  c.capacity = 6000;
  c.k_min = 6;
  c.k_max = 64;
  c.bandwidth = 0.3;
  c.greedy_method = HEDGER_GREEDY_STATE_MODEL;
  c.greedy_pessimism = 4.0;
  c.greedy_reach = 3.0;
  hedger_t* h[2] = {ht_create(&c), ht_create(&c)};
  uint64_t rs = 31;
  for (int i = 0; i < 5000; ++i) {
    double x[3];
    for (int d = 0; d < 3; ++d) x[d] = ht_uniform(&rs, -1.0, 1.0);
    const double a = ht_uniform(&rs, -1.0, 1.0);
    const double q = x[0] + 0.5 * x[1] * a - 0.3 * a * a;
    for (int k = 0; k < 2; ++k) assert_int_equal(hedger_insert(h[k], x, a, q, 0, NULL), HEDGER_OK);
  }
  for (int k = 0; k < 2; ++k) assert_int_equal(hedger_observe_reward(h[k], 1.0), HEDGER_OK);
  double s[3] = {-0.8, -0.5, 0.1};
  double a = 0.0;
  for (int t = 0; t < 400; ++t) {
    const double far[3] = {ht_uniform(&rs, -3.0, 3.0), 2.5, -2.5};
    assert_int_equal(hedger_greedy(h[1], far, NULL, NULL, NULL), HEDGER_NO_KNOWN_ACTION);
    hedger_prediction_t pf;
    assert_int_equal(hedger_predict(h[1], far, 0.0, &pf), HEDGER_OK);
    double ga[2], gv[2];
    hedger_prediction_t p[2];
    uint32_t slots[2][64];
    for (int k = 0; k < 2; ++k) {
      assert_int_equal(hedger_greedy(h[k], s, &ga[k], &gv[k], NULL), HEDGER_OK);
      assert_int_equal(hedger_predict_ex(h[k], s, a, &p[k], slots[k], NULL, 64), HEDGER_OK);
    }
    assert_true(memcmp(&ga[0], &ga[1], 8) == 0 && memcmp(&gv[0], &gv[1], 8) == 0);
    assert_true(memcmp(&p[0].value, &p[1].value, 8) == 0);
    assert_int_equal(p[0].n_neighbours, 64);
    assert_memory_equal(slots[0], slots[1], sizeof slots[0]);
    a = ga[0];
    s[0] += 0.004;
    s[1] += 0.0025 * sin(0.05 * t);
    s[2] += 0.01 * a;
  }
  hedger_destroy(h[0]);
  hedger_destroy(h[1]);
}

// predict, greedy, update, insert, end_run (replay), save and load allocate nothing, over
// thousands of calls with a full store, evictions and rebuilds.
static void test_determinism_no_allocation_after_init(void** state) {
  (void)state;
  const hedger_config_t c = det_config();
  hedger_t* h = ht_create(&c);
  const size_t cap = hedger_serialized_max_size(&c);
  uint8_t* buf = malloc(cap);
  uint64_t rs = 5;
  alloc_counter_begin();
  for (int t = 0; t < 2500; ++t) {
    step_out_t o;
    step(h, &rs, t, &o);
    if (t % 800 == 799) {
      size_t n = 0;
      assert_int_equal(hedger_save(h, buf, cap, &n), HEDGER_OK);
      assert_int_equal(hedger_load(h, buf, n), HEDGER_OK);
    }
  }
  const double s[3] = {0.1, 0.2, 0.3};
  hedger_insert(h, s, 0.5, 0.25, 0, NULL);
  const uint64_t allocs = alloc_counter_end();
  assert_int_equal(allocs, 0);
  assert_true(hedger_counters(h)->evictions > 0);
  assert_true(hedger_counters(h)->rebuilds > 10);
  free(buf);
  hedger_destroy(h);
}

// hedger_init into caller storage works without any allocation at all.
static void test_determinism_init_into_static_storage(void** state) {
  (void)state;
  hedger_config_t c = det_config();
  c.capacity = 100;
  const size_t n = hedger_storage_size(&c);
  static _Alignas(HEDGER_STORAGE_ALIGN) uint8_t storage[1 << 20];
  assert_true(n > 0 && n <= sizeof storage);
  hedger_t* h = NULL;
  alloc_counter_begin();
  assert_int_equal(hedger_init(&h, storage, n, &c), HEDGER_OK);
  uint64_t rs = 3;
  for (int t = 0; t < 500; ++t) {
    step_out_t o;
    step(h, &rs, t, &o);
  }
  assert_int_equal(alloc_counter_end(), 0);
  assert_int_equal(hedger_size(h), 100);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_determinism_two_instances_bit_identical),
      cmocka_unit_test(test_determinism_results_independent_of_search_history),
      cmocka_unit_test(test_determinism_no_allocation_after_init),
      cmocka_unit_test(test_determinism_init_into_static_storage),
  };
  return cmocka_run_group_tests_name("hedger.determinism", tests, NULL, NULL);
}
