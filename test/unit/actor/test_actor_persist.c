// SPDX-License-Identifier: MIT
// Save and load: a loaded actor continues exactly as the saved one would have; the sliced save
// writes the same bytes; damaged, foreign and incompatible bytes are refused with distinct errors
// and change nothing; configuration validation and storage checks.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "actor_test_util.h"

// Bitwise CRC-32 (IEEE), independent of the library's table-driven one.
static uint32_t crc32_ref(const uint8_t* p, size_t n) {
  uint32_t c = 0xFFFFFFFFu;
  for (size_t i = 0; i < n; ++i) {
    c ^= p[i];
    for (int k = 0; k < 8; ++k) c = (c & 1u) ? (0xEDB88320u ^ (c >> 1)) : (c >> 1);
  }
  return c ^ 0xFFFFFFFFu;
}

static void put_u32(uint8_t* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = (uint8_t)(v >> (8 * i));
}

static void fix_crc(uint8_t* p, size_t n) { put_u32(p + n - 4, crc32_ref(p, n - 4)); }

// Three runs (one cloned, two fitted), then a fourth recorded but not ended.
static actor_t* trained_actor(const actor_config_t* cfg, void** mem, rng_t* rng) {
  actor_t* a = toy_actor(cfg, mem);
  rng_seed(rng, 31);
  for (int run = 0; run < 3; ++run) {
    toy_run(a, run == 0 ? TOY_TEACHER : TOY_ACTOR, rng);
    toy_end_run(a, 800);
  }
  toy_run(a, TOY_ACTOR, rng);
  return a;
}

// A loaded actor acts alike and, given the same further calls, ends with the same bytes.
static void test_actor_load_resumes_identically(void** state) {
  (void)state;
  const actor_config_t cfg = toy_config();
  void* mem1 = NULL;
  rng_t rng1;
  actor_t* a = trained_actor(&cfg, &mem1, &rng1);
  size_t n = 0;
  uint8_t* bytes = toy_save(a, &n);
  assert_int_equal(crc32_ref(bytes, n - 4), (uint32_t)bytes[n - 4] | (uint32_t)bytes[n - 3] << 8 |
                                                (uint32_t)bytes[n - 2] << 16 | (uint32_t)bytes[n - 1] << 24);
  assert_int_equal(actor_saved_length(bytes, n), n);
  void* mem2 = NULL;
  actor_t* b = toy_actor(&cfg, &mem2);
  assert_int_equal(actor_load(b, bytes, n), ACTOR_OK);
  assert_true(actor_trained(b));
  assert_int_equal(actor_run_length(b), actor_run_length(a));
  assert_true(toy_mean_action(a) == toy_mean_action(b));
  // The run under way ends in both, and both learn one more run.
  rng_t rng2 = rng1;
  toy_end_run(a, 300);
  toy_end_run(b, UINT32_MAX);
  toy_run(a, TOY_ACTOR, &rng1);
  toy_run(b, TOY_ACTOR, &rng2);
  toy_end_run(a, 300);
  toy_end_run(b, 300);
  size_t na = 0;
  size_t nb = 0;
  uint8_t* sa = toy_save(a, &na);
  uint8_t* sb = toy_save(b, &nb);
  assert_int_equal(na, nb);
  assert_memory_equal(sa, sb, na);
  free(sa);
  free(sb);
  free(bytes);
  free(mem1);
  free(mem2);
}

// The sliced save writes actor_save's bytes; a record in between is detected.
static void test_actor_sliced_save(void** state) {
  (void)state;
  const actor_config_t cfg = toy_config();
  void* mem = NULL;
  rng_t rng;
  actor_t* a = trained_actor(&cfg, &mem, &rng);
  size_t n = 0;
  uint8_t* whole = toy_save(a, &n);
  uint8_t* sliced = calloc(1, n);
  actor_save_cursor_t cur;
  assert_int_equal(actor_save_begin(a, sliced, n, &cur), ACTOR_OK);
  size_t written = 0;
  int steps = 0;
  while (!cur.done) {
    assert_int_equal(actor_save_step(a, &cur, 50, &written), ACTOR_OK);
    ++steps;
  }
  assert_true(steps > 3);
  assert_int_equal(written, n);
  assert_memory_equal(sliced, whole, n);
  assert_int_equal(actor_save_begin(a, sliced, n, &cur), ACTOR_OK);
  assert_int_equal(actor_save_step(a, &cur, 10, &written), ACTOR_OK);
  const double s[2] = {0.3, 0.0};
  assert_int_equal(actor_record(a, s, 0.0, 0.0, s, 0), ACTOR_OK);
  assert_int_equal(actor_save_step(a, &cur, 10, &written), ACTOR_ERR_CHANGED);
  assert_int_equal(actor_save_begin(a, sliced, n - 1, &cur), ACTOR_ERR_CAPACITY);
  // No save while the between-run work is due.
  int pending = 0;
  assert_int_equal(actor_end_run_begin(a, &pending), ACTOR_OK);
  assert_int_equal(actor_save_begin(a, sliced, 2 * n, &cur), ACTOR_ERR_BUSY);
  free(sliced);
  free(whole);
  free(mem);
}

// Damaged or foreign bytes: each check its own error, the actor unchanged.
static void test_actor_load_refusals(void** state) {
  (void)state;
  const actor_config_t cfg = toy_config();
  void* mem = NULL;
  rng_t rng;
  actor_t* a = trained_actor(&cfg, &mem, &rng);
  size_t n = 0;
  uint8_t* good = toy_save(a, &n);
  uint8_t* b = malloc(n);
  void* mem2 = NULL;
  actor_t* fresh = toy_actor(&cfg, &mem2);
  size_t n0 = 0;
  uint8_t* before = toy_save(fresh, &n0);

  memcpy(b, good, n);
  b[0] = 'X';
  assert_int_equal(actor_load(fresh, b, n), ACTOR_ERR_FORMAT);
  assert_int_equal(actor_saved_length(b, n), 0);
  memcpy(b, good, n);
  put_u32(b + 4, 99);
  assert_int_equal(actor_load(fresh, b, n), ACTOR_ERR_VERSION);
  assert_int_equal(actor_load(fresh, good, n - 1), ACTOR_ERR_TRUNCATED);
  memcpy(b, good, n);
  b[n / 2] ^= 0x40;
  assert_int_equal(actor_load(fresh, b, n), ACTOR_ERR_CHECKSUM);
  // Contents impossible under a valid CRC: a terminal flag of 2 in the first entry.
  const size_t first_entry = n - 4 - (size_t)actor_counters(a)->fill * (8 * (2 * 2 + 3) + 8);
  memcpy(b, good, n);
  put_u32(b + first_entry + 8 * 7 + 4, 2);
  fix_crc(b, n);
  assert_int_equal(actor_load(fresh, b, n), ACTOR_ERR_FORMAT);
  // A NaN parameter.
  memcpy(b, good, n);
  memset(b + 136 + 3 * 16, 0xFF, 8);
  fix_crc(b, n);
  assert_int_equal(actor_load(fresh, b, n), ACTOR_ERR_FORMAT);
  // Saved under another action scale, another hidden size.
  actor_config_t other = cfg;
  other.action_scale = 0.5;
  void* mem3 = NULL;
  actor_t* c = toy_actor(&other, &mem3);
  assert_int_equal(actor_load(c, good, n), ACTOR_ERR_CONFIG_MISMATCH);
  free(mem3);
  other = cfg;
  other.hidden = 8;
  c = toy_actor(&other, &mem3);
  assert_int_equal(actor_load(c, good, n), ACTOR_ERR_CONFIG_MISMATCH);
  free(mem3);
  // A smaller ring than the saved entries.
  other = cfg;
  other.capacity = 64;
  other.max_queries = 64;
  c = toy_actor(&other, &mem3);
  assert_int_equal(actor_load(c, good, n), ACTOR_ERR_CONFIG_MISMATCH);
  free(mem3);
  // Nothing changed.
  size_t n1 = 0;
  uint8_t* after = toy_save(fresh, &n1);
  assert_int_equal(n1, n0);
  assert_memory_equal(after, before, n0);
  assert_false(actor_trained(fresh));
  // Trailing bytes are ignored.
  uint8_t* longer = calloc(1, n + 16);
  memcpy(longer, good, n);
  assert_int_equal(actor_load(fresh, longer, n + 16), ACTOR_OK);
  free(longer);
  free(after);
  free(before);
  free(b);
  free(good);
  free(mem2);
  free(mem);
}

// Configuration ranges, storage size and alignment.
static void test_actor_config_and_storage(void** state) {
  (void)state;
  actor_config_t cfg = toy_config();
  assert_int_equal(actor_config_validate(&cfg), ACTOR_OK);
  const size_t need = actor_storage_size(&cfg);
  assert_true(need > 0 && need % ACTOR_STORAGE_ALIGN == 0);
  actor_config_t c = cfg;
  c.state_dim = 0;
  assert_int_equal(actor_config_validate(&c), ACTOR_ERR_INVALID_ARG);
  assert_int_equal(actor_storage_size(&c), 0);
  c = cfg;
  c.state_dim = ACTOR_MAX_STATE_DIM + 1;
  assert_int_equal(actor_config_validate(&c), ACTOR_ERR_INVALID_ARG);
  c = cfg;
  c.gamma = 1.0;
  assert_int_equal(actor_config_validate(&c), ACTOR_ERR_INVALID_ARG);
  c = cfg;
  c.action_max = c.action_min;
  assert_int_equal(actor_config_validate(&c), ACTOR_ERR_INVALID_ARG);
  c = cfg;
  c.state_scale[1] = 0.0;
  assert_int_equal(actor_config_validate(&c), ACTOR_ERR_INVALID_ARG);
  c = cfg;
  c.max_queries = c.capacity + 1;
  assert_int_equal(actor_config_validate(&c), ACTOR_ERR_INVALID_ARG);
  c = cfg;
  c.model_min_neighbours = c.model_k + 1;
  assert_int_equal(actor_config_validate(&c), ACTOR_ERR_INVALID_ARG);
  c = cfg;
  c.state_min[0] = NAN;
  assert_int_equal(actor_config_validate(&c), ACTOR_ERR_INVALID_ARG);
  uint8_t* mem = aligned_alloc(ACTOR_STORAGE_ALIGN, need + ACTOR_STORAGE_ALIGN);
  actor_t* a = NULL;
  assert_int_equal(actor_init(&a, mem, need - 1, &cfg), ACTOR_ERR_CAPACITY);
  assert_int_equal(actor_init(&a, mem + 8, need, &cfg), ACTOR_ERR_ALIGNMENT);
  assert_int_equal(actor_init(&a, mem, need, &cfg), ACTOR_OK);
  // The same seed gives the same initial weights (bytes), another seed others.
  size_t n1 = 0;
  uint8_t* b1 = toy_save(a, &n1);
  assert_int_equal(actor_init(&a, mem, need, &cfg), ACTOR_OK);
  size_t n2 = 0;
  uint8_t* b2 = toy_save(a, &n2);
  assert_memory_equal(b1, b2, n1);
  c = cfg;
  c.seed = 6;
  assert_int_equal(actor_init(&a, mem, need, &c), ACTOR_OK);
  uint8_t* b3 = toy_save(a, &n2);
  assert_memory_not_equal(b1, b3, n1);
  free(b1);
  free(b2);
  free(b3);
  free(mem);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_actor_load_resumes_identically),
      cmocka_unit_test(test_actor_sliced_save),
      cmocka_unit_test(test_actor_load_refusals),
      cmocka_unit_test(test_actor_config_and_storage),
  };
  return cmocka_run_group_tests_name("actor.persist", tests, NULL, NULL);
}
