// SPDX-License-Identifier: MIT
// Save/load: round trip to identical predictions; truncated, corrupted, wrong-version and
// incompatible buffers are refused with distinct errors and leave the instance unchanged.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "hedger_test_util.h"

static hedger_config_t persist_config(void) {
  hedger_config_t c = hedger_config_default();
  c.state_dim = 2;
  c.capacity = 120;
  c.bandwidth = 0.3;
  c.input_scale[0] = 2.0;
  c.input_scale[1] = 0.5;
  c.input_scale[2] = 1.5;
  c.seed = 77;
  return c;
}

static void train(hedger_t* h, uint64_t* rs, int n) {
  for (int t = 0; t < n; ++t) {
    double s[2], sn[2];
    for (int d = 0; d < 2; ++d) {
      s[d] = ht_uniform(rs, -1.0, 1.0);
      sn[d] = s[d] + 0.1 * ht_normal(rs);
    }
    const int terminal = (t % 40) == 39;
    hedger_update(h, s, ht_uniform(rs, -1.0, 1.0), terminal ? 1.0 : (t % 7 == 0 ? -0.1 : 0.0), sn, terminal, NULL);
  }
}

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

static uint8_t* save_all(const hedger_t* h, size_t* n) {
  *n = hedger_serialized_size(h);
  uint8_t* b = malloc(*n);
  size_t w = 0;
  assert_int_equal(hedger_save(h, b, *n, &w), HEDGER_OK);
  assert_int_equal(w, *n);
  return b;
}

// Save → load into a fresh instance → bit-identical predictions, greedy results and further
// learning (the loaded instance has a different kd-tree layout and an empty fresh buffer).
static void test_persist_round_trip_identical(void** state) {
  (void)state;
  const hedger_config_t c = persist_config();
  hedger_t* a = ht_create(&c);
  uint64_t rs = 4;
  train(a, &rs, 700);
  size_t n;
  uint8_t* buf = save_all(a, &n);
  assert_true(crc32_ref((const uint8_t*)"123456789", 9) == 0xCBF43926u);
  assert_int_equal(((uint32_t)buf[n - 4] | (uint32_t)buf[n - 3] << 8 | (uint32_t)buf[n - 2] << 16 |
                    (uint32_t)buf[n - 1] << 24),
                   crc32_ref(buf, n - 4));
  assert_true(n <= hedger_serialized_max_size(&c));
  hedger_t* b = ht_create(&c);
  assert_int_equal(hedger_load(b, buf, n), HEDGER_OK);
  assert_int_equal(hedger_size(b), hedger_size(a));
  assert_int_equal(hedger_counters(b)->loads, 1);
  uint64_t q1 = 8, q2 = 8;
  for (int i = 0; i < 300; ++i) {
    const double s[2] = {ht_uniform(&q1, -1.2, 1.2), ht_uniform(&q1, -1.2, 1.2)};
    const double act = ht_uniform(&q1, -1.0, 1.0);
    hedger_prediction_t pa, pb;
    hedger_predict(a, s, act, &pa);
    hedger_predict(b, s, act, &pb);
    assert_true(memcmp(&pa.value, &pb.value, 8) == 0 && pa.kind == pb.kind && pa.n_neighbours == pb.n_neighbours);
    double aa, va, ab, vb;
    assert_int_equal(hedger_greedy(a, s, &aa, &va, NULL), hedger_greedy(b, s, &ab, &vb, NULL));
    assert_true(memcmp(&aa, &ab, 8) == 0 && memcmp(&va, &vb, 8) == 0);
  }
  // Learning continues identically (the eviction generator state was saved too).
  uint64_t ra = rs, rb = rs;
  train(a, &ra, 300);
  train(b, &rb, 300);
  (void)q2;
  size_t na, nb;
  uint8_t* ba = save_all(a, &na);
  uint8_t* bb = save_all(b, &nb);
  assert_int_equal(na, nb);
  assert_memory_equal(ba, bb, na);
  free(ba);
  free(bb);
  free(buf);
  hedger_destroy(a);
  hedger_destroy(b);
}

// A failed load leaves the target exactly as it was (checked through its saved bytes).
static void expect_refused(hedger_t* h, const uint8_t* before, size_t nbefore, const uint8_t* buf, size_t n,
                           hedger_status_t want) {
  assert_int_equal(hedger_load(h, buf, n), want);
  size_t m;
  uint8_t* after = save_all(h, &m);
  assert_int_equal(m, nbefore);
  assert_memory_equal(after, before, m);
  free(after);
}

// Every truncation is refused as TRUNCATED.
static void test_persist_truncated_refused(void** state) {
  (void)state;
  const hedger_config_t c = persist_config();
  hedger_t* src = ht_create(&c);
  uint64_t rs = 5;
  train(src, &rs, 60);
  size_t n;
  uint8_t* buf = save_all(src, &n);
  hedger_t* dst = ht_create(&c);
  uint64_t r2 = 6;
  train(dst, &r2, 30);
  size_t nd;
  uint8_t* before = save_all(dst, &nd);
  for (size_t len = 1; len < n; ++len) {
    uint8_t* cut = malloc(len);  // exact-size copy: ASan catches any read beyond len
    memcpy(cut, buf, len);
    expect_refused(dst, before, nd, cut, len, HEDGER_ERR_TRUNCATED);
    free(cut);
  }
  assert_int_equal(hedger_load(dst, buf, 0), HEDGER_ERR_TRUNCATED);  // an empty file is a truncated one
  free(before);
  free(buf);
  hedger_destroy(src);
  hedger_destroy(dst);
}

// Every single-byte corruption is refused (mostly CHECKSUM; header fields may fail earlier).
static void test_persist_corrupted_refused(void** state) {
  (void)state;
  const hedger_config_t c = persist_config();
  hedger_t* src = ht_create(&c);
  uint64_t rs = 7;
  train(src, &rs, 80);
  size_t n;
  uint8_t* buf = save_all(src, &n);
  hedger_t* dst = ht_create(&c);
  size_t nd;
  uint8_t* before = save_all(dst, &nd);
  int checksum = 0;
  for (size_t i = 0; i < n; ++i) {
    uint8_t* bad = malloc(n);
    memcpy(bad, buf, n);
    bad[i] ^= (uint8_t)(1u << (i % 8));
    const hedger_status_t st = hedger_load(dst, bad, n);
    assert_true(st == HEDGER_ERR_CHECKSUM || st == HEDGER_ERR_FORMAT || st == HEDGER_ERR_VERSION ||
                st == HEDGER_ERR_TRUNCATED);
    checksum += st == HEDGER_ERR_CHECKSUM;
    expect_refused(dst, before, nd, bad, n, st);
    free(bad);
  }
  assert_true(checksum > (int)n - 20);
  free(before);
  free(buf);
  hedger_destroy(src);
  hedger_destroy(dst);
}

// Another format version is refused as VERSION even with a valid CRC; bad magic as FORMAT.
static void test_persist_wrong_version_and_magic_refused(void** state) {
  (void)state;
  const hedger_config_t c = persist_config();
  hedger_t* h = ht_create(&c);
  uint64_t rs = 9;
  train(h, &rs, 20);
  size_t n;
  uint8_t* buf = save_all(h, &n);
  size_t nb;
  uint8_t* before = save_all(h, &nb);
  put_u32(buf + 4, HEDGER_FORMAT_VERSION + 1);
  fix_crc(buf, n);
  expect_refused(h, before, nb, buf, n, HEDGER_ERR_VERSION);
  put_u32(buf + 4, HEDGER_FORMAT_VERSION);
  buf[0] = 'X';
  fix_crc(buf, n);
  expect_refused(h, before, nb, buf, n, HEDGER_ERR_FORMAT);
  free(before);
  free(buf);
  hedger_destroy(h);
}

// A buffer saved under an incompatible config is refused as CONFIG_MISMATCH.
static void test_persist_config_mismatch_refused(void** state) {
  (void)state;
  const hedger_config_t c = persist_config();
  hedger_t* src = ht_create(&c);
  uint64_t rs = 10;
  train(src, &rs, 200);
  size_t n;
  uint8_t* buf = save_all(src, &n);
  hedger_config_t other[5];
  for (int i = 0; i < 5; ++i) other[i] = c;
  other[0].state_dim = 3;
  other[1].input_scale[1] = 0.25;
  other[2].action_max = 2.0;
  other[3].gamma = 0.9;
  other[4].capacity = hedger_size(src) - 1;
  for (int i = 0; i < 5; ++i) {
    hedger_t* dst = ht_create(&other[i]);
    size_t nd;
    uint8_t* before = save_all(dst, &nd);
    expect_refused(dst, before, nd, buf, n, HEDGER_ERR_CONFIG_MISMATCH);
    free(before);
    hedger_destroy(dst);
  }
  // What the buffer was written for, read back without an instance (the caller's message on a
  // CONFIG_MISMATCH names the setting from it); a corrupted byte is refused as hedger_load does.
  hedger_saved_t saved;
  assert_int_equal(hedger_saved_config(buf, n, &saved), HEDGER_OK);
  assert_int_equal(saved.state_dim, c.state_dim);
  assert_int_equal(saved.count, hedger_size(src));
  assert_memory_equal(&saved.gamma, &c.gamma, sizeof(double));
  assert_memory_equal(&saved.action_min, &c.action_min, sizeof(double));
  assert_memory_equal(&saved.action_max, &c.action_max, sizeof(double));
  assert_memory_equal(saved.input_scale, c.input_scale, sizeof(double) * (c.state_dim + 1U));
  for (uint32_t i = c.state_dim + 1U; i < HEDGER_MAX_INPUT_DIM; ++i) assert_true(saved.input_scale[i] == 0.0);
  assert_int_equal(hedger_saved_config(buf, n - 1, &saved), HEDGER_ERR_TRUNCATED);
  buf[n / 2] ^= 0x10;
  assert_int_equal(hedger_saved_config(buf, n, &saved), HEDGER_ERR_CHECKSUM);
  buf[n / 2] ^= 0x10;
  assert_int_equal(hedger_saved_config(NULL, n, &saved), HEDGER_ERR_INVALID_ARG);
  // Learning parameters may differ (alpha, k, bandwidth): the data stay meaningful.
  hedger_config_t tuned = c;
  tuned.alpha = 0.5;
  tuned.capacity = 500;
  hedger_t* dst = ht_create(&tuned);
  assert_int_equal(hedger_load(dst, buf, n), HEDGER_OK);
  assert_int_equal(hedger_size(dst), hedger_size(src));
  hedger_destroy(dst);
  free(buf);
  hedger_destroy(src);
}

// Valid CRC over invalid contents (a NaN value, unknown flags) is refused as FORMAT.
static void test_persist_invalid_contents_refused(void** state) {
  (void)state;
  const hedger_config_t c = persist_config();
  hedger_t* h = ht_create(&c);
  uint64_t rs = 12;
  train(h, &rs, 30);
  size_t n;
  uint8_t* buf = save_all(h, &n);
  size_t nb;
  uint8_t* before = save_all(h, &nb);
  const size_t first = 88 + 8 * 3;  // header + input scales (D = 3)
  uint8_t* bad = malloc(n);
  memcpy(bad, buf, n);
  const double nan = NAN;
  memcpy(bad + first + 3 * 8, &nan, 8);  // value of point 0
  fix_crc(bad, n);
  expect_refused(h, before, nb, bad, n, HEDGER_ERR_FORMAT);
  memcpy(bad, buf, n);
  bad[first + 4 * 8] = 0x42;  // flags of point 0
  fix_crc(bad, n);
  expect_refused(h, before, nb, bad, n, HEDGER_ERR_FORMAT);
  // Run tags and anchor weights: a tag after the current run, a weight outside [0, 16] or not a
  // number, a reserved header word that is not 0.
  memcpy(bad, buf, n);
  put_u32(bad + first + 4 * 8 + 4, 1u);  // run tag of point 0 > current tag (0)
  fix_crc(bad, n);
  expect_refused(h, before, nb, bad, n, HEDGER_ERR_FORMAT);
  const float bad_weights[3] = {-1.0f, 17.0f, NAN};
  for (int i = 0; i < 3; ++i) {
    memcpy(bad, buf, n);
    memcpy(bad + first + 4 * 8 + 8, &bad_weights[i], 4);
    fix_crc(bad, n);
    expect_refused(h, before, nb, bad, n, HEDGER_ERR_FORMAT);
  }
  memcpy(bad, buf, n);
  put_u32(bad + 84, 7u);
  fix_crc(bad, n);
  expect_refused(h, before, nb, bad, n, HEDGER_ERR_FORMAT);
  free(bad);
  free(before);
  free(buf);
  hedger_destroy(h);
}

// Saving into a short buffer fails with CAPACITY and writes nothing.
static void test_persist_save_short_buffer_capacity(void** state) {
  (void)state;
  const hedger_config_t c = persist_config();
  hedger_t* h = ht_create(&c);
  uint64_t rs = 13;
  train(h, &rs, 10);
  const size_t n = hedger_serialized_size(h);
  uint8_t* b = malloc(n);
  memset(b, 0x5A, n);
  size_t w = 123;
  assert_int_equal(hedger_save(h, b, n - 1, &w), HEDGER_ERR_CAPACITY);
  assert_int_equal(w, 123);
  for (size_t i = 0; i < n; ++i) assert_int_equal(b[i], 0x5A);
  free(b);
  hedger_destroy(h);
}


// Run tags, anchor weights and the current tag survive a save and load: the loaded instance's
// points and greedy choices equal the source's bit for bit.
static void test_persist_run_tags_round_trip(void** state) {
  (void)state;
  hedger_config_t c = persist_config();
  c.greedy_method = HEDGER_GREEDY_STATE_MODEL;
  c.greedy_pessimism = 2.0;
  c.anchor_recency_runs = 3.0;
  hedger_t* src = ht_create(&c);
  uint64_t rs = 21;
  for (uint32_t run = 1; run <= 4; ++run) {
    assert_int_equal(hedger_set_run_tag(src, run * 10u), HEDGER_OK);
    train(src, &rs, 40);
  }
  uint32_t weighted = 0;
  assert_int_equal(hedger_weight_run(src, 20u, 3.5, &weighted), HEDGER_OK);
  assert_true(weighted > 0);
  size_t n;
  uint8_t* buf = save_all(src, &n);
  hedger_t* dst = ht_create(&c);
  assert_int_equal(hedger_load(dst, buf, n), HEDGER_OK);
  assert_int_equal(hedger_size(dst), hedger_size(src));
  uint32_t seen_weighted = 0;
  for (uint32_t i = 0; i < hedger_size(src); ++i) {
    hedger_point_t a, b;
    assert_int_equal(hedger_get_point(src, i, &a), HEDGER_OK);
    assert_int_equal(hedger_get_point(dst, i, &b), HEDGER_OK);
    assert_int_equal(a.run_tag, b.run_tag);
    assert_true(a.anchor_weight == b.anchor_weight);
    seen_weighted += b.anchor_weight == 3.5 ? 1u : 0u;
  }
  assert_int_equal(seen_weighted, weighted);
  for (int q = 0; q < 50; ++q) {
    const double s[2] = {ht_uniform(&rs, -1.0, 1.0), ht_uniform(&rs, -1.0, 1.0)};
    double a1 = 0.0, v1 = 0.0, a2 = 1.0, v2 = 1.0;
    const hedger_status_t s1 = hedger_greedy(src, s, &a1, &v1, NULL);
    const hedger_status_t s2 = hedger_greedy(dst, s, &a2, &v2, NULL);
    assert_int_equal(s1, s2);
    assert_memory_equal(&a1, &a2, sizeof a1);
    assert_memory_equal(&v1, &v2, sizeof v1);
  }
  // The current tag came along: an earlier one is refused, the same one accepted.
  assert_int_equal(hedger_run_tag(dst), 40);
  assert_int_equal(hedger_set_run_tag(dst, 39u), HEDGER_ERR_INVALID_ARG);
  assert_int_equal(hedger_set_run_tag(dst, 40u), HEDGER_OK);
  free(buf);
  hedger_destroy(dst);
  hedger_destroy(src);
}

// A version-1 buffer (before run tags) still loads: the same points and values, every tag 0 and
// every anchor weight 1, so the greedy choices are those of an instance that never tagged.
static void test_persist_version1_loads(void** state) {
  (void)state;
  hedger_config_t c = persist_config();
  c.greedy_method = HEDGER_GREEDY_STATE_MODEL;
  c.greedy_pessimism = 2.0;
  hedger_t* src = ht_create(&c);
  uint64_t rs = 23;
  train(src, &rs, 150);
  size_t n;
  uint8_t* v2 = save_all(src, &n);
  // Version 2 → 1: drop the header's run-tag words and each record's tag and weight.
  const uint32_t d = 3, count = hedger_size(src);
  const size_t rec2 = 8u * d + 20u, rec1 = 8u * d + 12u;
  const size_t n1 = 80u + 8u * d + count * rec1 + 4u;
  uint8_t* v1 = malloc(n1);
  memcpy(v1, v2, 80);
  memcpy(v1 + 80, v2 + 88, 8u * d);
  for (uint32_t i = 0; i < count; ++i) memcpy(v1 + 80 + 8u * d + i * rec1, v2 + 88 + 8u * d + i * rec2, rec1);
  put_u32(v1 + 4, 1u);
  for (int i = 0; i < 8; ++i) v1[8 + i] = (uint8_t)((uint64_t)n1 >> (8 * i));
  fix_crc(v1, n1);
  hedger_t* dst = ht_create(&c);
  assert_int_equal(hedger_load(dst, v1, n1), HEDGER_OK);
  assert_int_equal(hedger_size(dst), count);
  for (uint32_t i = 0; i < count; ++i) {
    hedger_point_t a, b;
    assert_int_equal(hedger_get_point(src, i, &a), HEDGER_OK);
    assert_int_equal(hedger_get_point(dst, i, &b), HEDGER_OK);
    assert_memory_equal(&a.value, &b.value, sizeof a.value);
    assert_int_equal(b.run_tag, 0);
    assert_true(b.anchor_weight == 1.0);
  }
  for (int q = 0; q < 50; ++q) {
    const double s[2] = {ht_uniform(&rs, -1.0, 1.0), ht_uniform(&rs, -1.0, 1.0)};
    double a1 = 0.0, v1v = 0.0, a2 = 1.0, v2v = 1.0;
    assert_int_equal(hedger_greedy(src, s, &a1, &v1v, NULL), hedger_greedy(dst, s, &a2, &v2v, NULL));
    assert_memory_equal(&a1, &a2, sizeof a1);
  }
  // Saved again, it is a version-2 buffer.
  size_t n2;
  uint8_t* again = save_all(dst, &n2);
  assert_int_equal(n2, n);
  assert_int_equal(again[4], HEDGER_FORMAT_VERSION);
  free(again);
  free(v1);
  free(v2);
  hedger_destroy(dst);
  hedger_destroy(src);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_persist_round_trip_identical),
      cmocka_unit_test(test_persist_truncated_refused),
      cmocka_unit_test(test_persist_corrupted_refused),
      cmocka_unit_test(test_persist_wrong_version_and_magic_refused),
      cmocka_unit_test(test_persist_config_mismatch_refused),
      cmocka_unit_test(test_persist_invalid_contents_refused),
      cmocka_unit_test(test_persist_save_short_buffer_capacity),
      cmocka_unit_test(test_persist_run_tags_round_trip),
      cmocka_unit_test(test_persist_version1_loads),
  };
  return cmocka_run_group_tests_name("hedger.persist", tests, NULL, NULL);
}
