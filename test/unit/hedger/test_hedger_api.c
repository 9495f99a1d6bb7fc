// SPDX-License-Identifier: MIT
// C API contract: config validation, storage size and init errors, strings, create/destroy.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "hedger_test_util.h"

// The default config is valid and matches its documentation.
static void test_api_default_config_valid(void** state) {
  (void)state;
  const hedger_config_t c = hedger_config_default();
  assert_int_equal(hedger_config_validate(&c), HEDGER_OK);
  assert_int_equal(c.state_dim, 3);
  assert_true(c.action_min == -1.0 && c.action_max == 1.0);
  assert_int_equal(c.k_min, 3);
  assert_int_equal(c.k_max, 16);
  assert_true(hedger_storage_size(&c) > 0);
  assert_int_equal(hedger_storage_size(&c) % HEDGER_STORAGE_ALIGN, 0);
}

// Every out-of-range field is refused.
static void test_api_invalid_config_fields_refused(void** state) {
  (void)state;
  hedger_config_t c;
#define BAD(stmt)                                                     \
  do {                                                                \
    c = hedger_config_default();                                      \
    stmt;                                                             \
    assert_int_equal(hedger_config_validate(&c), HEDGER_ERR_INVALID_ARG); \
    assert_int_equal(hedger_storage_size(&c), 0);                     \
  } while (0)
  BAD(c.state_dim = 0);
  BAD(c.state_dim = HEDGER_MAX_STATE_DIM + 1);
  BAD(c.action_min = 1.0);
  BAD(c.action_max = NAN);
  BAD(c.capacity = 0);
  BAD(c.capacity = HEDGER_MAX_CAPACITY + 1);
  BAD(c.k_min = 0);
  BAD(c.k_min = c.k_max + 1);
  BAD(c.k_max = HEDGER_MAX_K + 1);
  BAD(c.bandwidth = 0.0);
  BAD(c.bandwidth = INFINITY);
  BAD(c.weight_epsilon = 1.0);
  BAD(c.ridge = -1.0);
  BAD(c.alpha = 0.0);
  BAD(c.alpha = 1.5);
  BAD(c.gamma = 1.0);
  BAD(c.input_scale[2] = 0.0);
  BAD(c.input_scale[3] = NAN);
  BAD(c.default_value = NAN);
  BAD(c.greedy_coarse_actions = 1);
  BAD(c.greedy_coarse_actions = HEDGER_MAX_COARSE_ACTIONS + 1);
  BAD(c.greedy_refine_iters = HEDGER_MAX_REFINE_ITERS + 1);
  BAD(c.ivh_mode = 7);
  BAD(c.merge_radius = -0.1);
  BAD(c.evict_candidates = 0);
  BAD(c.fresh_capacity = 4);
  BAD(c.run_capacity = HEDGER_MAX_RUN + 1);
  BAD(c.replay = 1);  // without a run buffer
#undef BAD
  assert_int_equal(hedger_config_validate(NULL), HEDGER_ERR_INVALID_ARG);
  // Scales beyond the input dimension are ignored.
  c = hedger_config_default();
  c.input_scale[HEDGER_MAX_INPUT_DIM - 1] = NAN;
  assert_int_equal(hedger_config_validate(&c), HEDGER_OK);
}

// hedger_init refuses NULL, misaligned and too small storage and writes nothing then.
static void test_api_init_storage_errors(void** state) {
  (void)state;
  hedger_config_t c = hedger_config_default();
  c.capacity = 64;
  const size_t n = hedger_storage_size(&c);
  uint8_t* mem = aligned_alloc(HEDGER_STORAGE_ALIGN, n + HEDGER_STORAGE_ALIGN);
  hedger_t* h = (hedger_t*)(void*)0x1;
  assert_int_equal(hedger_init(NULL, mem, n, &c), HEDGER_ERR_INVALID_ARG);
  assert_int_equal(hedger_init(&h, NULL, n, &c), HEDGER_ERR_INVALID_ARG);
  assert_int_equal(hedger_init(&h, mem + 8, n, &c), HEDGER_ERR_ALIGNMENT);
  memset(mem, 0xA5, n);
  assert_int_equal(hedger_init(&h, mem, n - 1, &c), HEDGER_ERR_CAPACITY);
  assert_true(h == (hedger_t*)(void*)0x1);
  assert_int_equal(mem[0], 0xA5);
  assert_int_equal(hedger_init(&h, mem, n, &c), HEDGER_OK);
  assert_true((void*)h == (void*)mem);
  assert_int_equal(hedger_size(h), 0);
  assert_int_equal(hedger_get_config(h)->capacity, 64);
  hedger_destroy(h);  // caller storage: a no-op
  free(mem);
}

// create/destroy pair; destroy(NULL) is a no-op.
static void test_api_create_destroy(void** state) {
  (void)state;
  const hedger_config_t c = hedger_config_default();
  hedger_t* h = NULL;
  assert_int_equal(hedger_create(&h, &c), HEDGER_OK);
  assert_non_null(h);
  assert_non_null(hedger_counters(h));
  assert_int_equal(hedger_counters(h)->store_fill, 0);
  hedger_destroy(h);
  hedger_destroy(NULL);
  hedger_config_t bad = c;
  bad.k_min = 0;
  assert_int_equal(hedger_create(&h, &bad), HEDGER_ERR_INVALID_ARG);
}

// Every status has a distinct, non-empty description; kinds have names.
static void test_api_status_strings_distinct(void** state) {
  (void)state;
  const char* seen[16];
  for (int s = 0; s <= HEDGER_ERR_CONFIG_MISMATCH; ++s) {
    seen[s] = hedger_status_str((hedger_status_t)s);
    assert_non_null(seen[s]);
    assert_true(strlen(seen[s]) > 0);
    for (int t = 0; t < s; ++t) assert_string_not_equal(seen[s], seen[t]);
  }
  assert_string_equal(hedger_status_str((hedger_status_t)99), "unknown status");
  assert_string_equal(hedger_kind_str(HEDGER_KIND_LWR), "lwr");
  assert_string_equal(hedger_kind_str(HEDGER_KIND_LWA), "lwa");
  assert_string_equal(hedger_kind_str(HEDGER_KIND_UNKNOWN), "unknown");
}

// Input scaling: distances are taken in raw / input_scale units.
static void test_api_input_scale_applies(void** state) {
  (void)state;
  hedger_config_t c = hedger_config_default();
  c.state_dim = 1;
  c.k_min = 1;
  c.bandwidth = 1.0;
  c.input_scale[0] = 10.0;  // state in units of 10
  hedger_t* h = ht_create(&c);
  const double s[1] = {0.0};
  hedger_insert(h, s, 0.0, 1.0, 0, NULL);
  hedger_prediction_t p;
  uint32_t slot;
  double w;
  const double q[1] = {10.0};  // one scaled unit away
  hedger_predict_ex(h, q, 0.0, &p, &slot, &w, 1);
  assert_int_equal(p.n_neighbours, 1);
  assert_true(fabs(w - exp(-1.0)) < 1e-15);
  hedger_point_t pt;
  assert_int_equal(hedger_get_point(h, 0, &pt), HEDGER_OK);
  assert_true(pt.state[0] == 0.0);
  assert_int_equal(hedger_get_point(h, 1, &pt), HEDGER_ERR_INVALID_ARG);
  hedger_destroy(h);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_api_default_config_valid),
      cmocka_unit_test(test_api_invalid_config_fields_refused),
      cmocka_unit_test(test_api_init_storage_errors),
      cmocka_unit_test(test_api_create_destroy),
      cmocka_unit_test(test_api_status_strings_distinct),
      cmocka_unit_test(test_api_input_scale_applies),
  };
  return cmocka_run_group_tests_name("hedger.api", tests, NULL, NULL);
}
