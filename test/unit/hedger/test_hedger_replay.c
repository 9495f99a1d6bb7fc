// SPDX-License-Identifier: MIT
// The backward replay's record cache (cfg.replay_cache): the same results, bit for bit, as
// recomputing every replayed update, under everything that moves the store's geometry while a
// replay is under way (evictions, run tags, anchor weights, loads).
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "hedger_test_util.h"

// The firmware's kind of learner, small: the state model with a wide second attempt, anchor
// recency, 4 passes of the λ-return; a store of the given capacity (small: it fills, and replayed
// points get evicted).
static hedger_config_t replay_config(uint32_t cache, uint32_t capacity) {
  hedger_config_t c = hedger_config_default();
  c.state_dim = 3;
  c.capacity = capacity;
  c.fresh_capacity = 32;
  c.k_min = 4;
  c.k_max = 24;
  c.bandwidth = 0.3;
  c.run_capacity = 64;
  c.replay = 1;
  c.replay_passes = 4;
  c.replay_lambda = 0.9;
  c.greedy_method = HEDGER_GREEDY_STATE_MODEL;
  c.greedy_pessimism = 2.0;
  c.greedy_reach = 3.0;
  c.anchor_recency_runs = 5.0;
  c.seed = 77;
  c.replay_cache = cache;
  return c;
}

static int same_bits(double a, double b) { return memcmp(&a, &b, sizeof a) == 0; }

static void assert_same_info(const hedger_update_info_t* a, const hedger_update_info_t* b) {
  assert_int_equal(a->next_status, b->next_status);
  assert_true(same_bits(a->next_action, b->next_action) && same_bits(a->next_value, b->next_value));
  assert_true(same_bits(a->q_old, b->q_old) && same_bits(a->target, b->target) && same_bits(a->q_new, b->q_new));
  assert_int_equal(a->kind, b->kind);
  assert_int_equal(a->n_pulled, b->n_pulled);
  assert_int_equal(a->store_op, b->store_op);
}

// One run: a smooth trajectory (neighbourhoods overlap from step to step, as on the robot) whose
// actions follow the state, with a reward at the end.
static void drive_run(hedger_t* const* h, int n_inst, uint64_t* rs, int steps) {
  double s[3] = {ht_uniform(rs, -1.0, 1.0), ht_uniform(rs, -1.0, 1.0), ht_uniform(rs, -0.5, 0.5)};
  for (int t = 0; t < steps; ++t) {
    const double a = -0.8 * s[2] + 0.3 * ht_normal(rs);
    double sn[3] = {s[0] + 0.04, s[1] + 0.02 * ht_normal(rs), s[2] + 0.1 * a};
    const int terminal = t + 1 == steps;
    const double r = terminal ? (sn[1] > 0.0 ? 1.0 : -1.0) : 0.0;
    hedger_update_info_t info[2];
    for (int i = 0; i < n_inst; ++i) assert_int_equal(hedger_update(h[i], s, a, r, sn, terminal, &info[i]), HEDGER_OK);
    if (n_inst == 2) assert_same_info(&info[0], &info[1]);
    memcpy(s, sn, sizeof s);
  }
}

// Ends the run in slices; between slices (the calls a controller makes while the robot stands)
// greedy searches, and now and then a run tag, a run's anchor weight or a save and load.
static void end_run_sliced(hedger_t* const* h, uint64_t* rs, uint32_t run, uint8_t* buf, size_t cap) {
  uint32_t pending[2];
  for (int i = 0; i < 2; ++i) assert_int_equal(hedger_end_run_begin(h[i], &pending[i]), HEDGER_OK);
  assert_int_equal(pending[0], pending[1]);
  // The instance with the cache takes slices of 7 update-equivalents (more updates once its
  // records are formed); the other one takes as many updates as it did, so that the calls in
  // between meet both at the same point of the replay.
  uint32_t before = pending[0];
  for (uint32_t slice = 0;; ++slice) {
    uint32_t left[2];
    assert_int_equal(hedger_end_run_step(h[0], 7, &left[0]), HEDGER_OK);
    assert_int_equal(hedger_end_run_step(h[1], before - left[0], &left[1]), HEDGER_OK);
    assert_int_equal(left[0], left[1]);
    before = left[0];
    if (left[0] == 0) break;
    const double q[3] = {ht_uniform(rs, -1.0, 1.0), ht_uniform(rs, -1.0, 1.0), ht_uniform(rs, -0.5, 0.5)};
    double ga[2], gv[2];
    hedger_status_t gs[2];
    for (int i = 0; i < 2; ++i) gs[i] = hedger_greedy(h[i], q, &ga[i], &gv[i], NULL);
    assert_int_equal(gs[0], gs[1]);
    assert_true(same_bits(ga[0], ga[1]) && same_bits(gv[0], gv[1]));
    if (slice == 3 && run % 3 == 1) {
      for (int i = 0; i < 2; ++i) assert_int_equal(hedger_weight_run(h[i], run - 1, 0.25, NULL), HEDGER_OK);
    }
    if (slice == 5 && run % 4 == 2) {
      // A jump of 150 tags fades every older point below 1e-12 of the newest (recency 5 tags):
      // the anchors of neighbourhoods without a new point fall back to the kernel weights.
      for (int i = 0; i < 2; ++i) assert_int_equal(hedger_set_run_tag(h[i], hedger_run_tag(h[i]) + 150), HEDGER_OK);
    }
    if (slice == 2 && run % 7 == 6) {
      // A load replaces the learned state and drops the run: both instances go on without it.
      size_t n = 0;
      assert_int_equal(hedger_save(h[0], buf, cap, &n), HEDGER_OK);
      for (int i = 0; i < 2; ++i) assert_int_equal(hedger_load(h[i], buf, n), HEDGER_OK);
    }
  }
}

// Feeds the same runs to an instance with the record cache and one without; every update's
// result, every greedy search in between, the counters and the saved bytes must be identical.
static void check_against_recomputing(uint32_t capacity, uint64_t seed, hedger_counters_t* out) {
  const hedger_config_t cc = replay_config(1, capacity);
  const hedger_config_t cn = replay_config(0, capacity);
  hedger_t* h[2] = {ht_create(&cc), ht_create(&cn)};
  const size_t cap = hedger_serialized_max_size(&cc);
  uint8_t* buf = malloc(cap);
  uint64_t rs = seed;
  for (uint32_t run = 1; run <= 30; ++run) {
    for (int i = 0; i < 2; ++i) assert_int_equal(hedger_set_run_tag(h[i], hedger_run_tag(h[i]) + 1), HEDGER_OK);
    drive_run(h, 2, &rs, 20 + (int)(ht_next(&rs) % 30));
    end_run_sliced(h, &rs, hedger_run_tag(h[0]), buf, cap);
  }
  const hedger_counters_t* k0 = hedger_counters(h[0]);
  const hedger_counters_t* k1 = hedger_counters(h[1]);
  print_message("capacity %u: %llu replayed updates, %llu searches reused, %llu evictions, %llu via the wide "
                "kernel, %llu greedy searches per action\n",
                capacity, (unsigned long long)k0->replayed_updates, (unsigned long long)k0->replay_reused,
                (unsigned long long)k0->evictions, (unsigned long long)k0->greedy_reached,
                (unsigned long long)(k0->greedy_calls - k0->greedy_state_model));
  *out = *k0;
  assert_int_equal(k1->replay_reused, 0);
  hedger_counters_t a = *k0, b = *k1;
  a.replay_reused = b.replay_reused = 0;
  assert_memory_equal(&a, &b, sizeof a);
  assert_true(ht_same_saved(h[0], h[1]));
  free(buf);
  hedger_destroy(h[0]);
  hedger_destroy(h[1]);
}

// A store that fills: replayed points are evicted and replaced mid-replay, which moves the
// geometry of the records around them; the wide kernel and the per-action search are reached.
static void test_replay_cache_identical_with_evictions(void** state) {
  (void)state;
  hedger_counters_t k;
  check_against_recomputing(350, 2024, &k);
  assert_true(k.replay_reused > k.replayed_updates / 2);
  assert_true(k.evictions > 100 && k.greedy_reached > 0 && k.greedy_calls > k.greedy_state_model);
}

// A store that never fills: the records' geometry holds through whole replays (nearly every
// search reused), so only the run tags, anchor weights and loads between slices invalidate it.
static void test_replay_cache_identical_across_tags_and_weights(void** state) {
  (void)state;
  hedger_counters_t k;
  check_against_recomputing(4000, 7, &k);
  assert_int_equal(k.evictions, 0);
  assert_true(k.replay_reused > k.replayed_updates);
}

// A run whose every point merges into the store (no geometry change during it) replays records
// that sit where another run's records sat in the previous replay: nothing cached may carry over.
static void test_replay_cache_not_carried_to_the_next_run(void** state) {
  (void)state;
  hedger_t* h[2];
  hedger_config_t cfg[2] = {replay_config(1, 1000), replay_config(0, 1000)};
  for (int i = 0; i < 2; ++i) h[i] = ht_create(&cfg[i]);
  double s[30][3];
  double a[30];
  uint64_t rs = 11;
  for (int t = 0; t < 30; ++t) {
    for (int d = 0; d < 3; ++d) s[t][d] = ht_uniform(&rs, -1.0, 1.0);
    a[t] = ht_uniform(&rs, -1.0, 1.0);
  }
  // Run 1 stores the 29 transitions; run 2 repeats them backwards (every point merges).
  for (int run = 0; run < 2; ++run) {
    for (int k = 0; k < 29; ++k) {
      const int t = run == 0 ? k : 28 - k;
      hedger_update_info_t info[2];
      for (int i = 0; i < 2; ++i) {
        assert_int_equal(hedger_update(h[i], s[t], a[t], t == 28 ? 1.0 : 0.0, s[t + 1], 0, &info[i]), HEDGER_OK);
      }
      assert_same_info(&info[0], &info[1]);
      if (run == 1) assert_int_equal(info[0].store_op, HEDGER_STORE_MERGED);
    }
    for (int i = 0; i < 2; ++i) assert_int_equal(hedger_end_run(h[i], NULL), HEDGER_OK);
  }
  assert_true(ht_same_saved(h[0], h[1]));
  hedger_destroy(h[0]);
  hedger_destroy(h[1]);
}

// Slices of a replay (hedger_end_run_step with max_updates 4) with the cache: the first pass forms
// every record's geometry and goes 4 updates per slice; the later ones reuse it and go about 8
// times as many. Without the cache every slice is 4 updates. The learned states are the same.
static void test_replay_cache_slices_reused_updates_eight_to_one(void** state) {
  (void)state;
  hedger_config_t c[2] = {replay_config(1, 4000), replay_config(0, 4000)};
  uint32_t first_pass_slices[2] = {0, 0}, slices[2] = {0, 0};
  hedger_t* h[2];
  for (int i = 0; i < 2; ++i) {
    h[i] = ht_create(&c[i]);
    uint64_t rs = 5;
    drive_run(&h[i], 1, &rs, 40);
    assert_int_equal(hedger_end_run(h[i], NULL), HEDGER_OK);
    drive_run(&h[i], 1, &rs, 40);
    uint32_t pending = 0, left = 0;
    assert_int_equal(hedger_end_run_begin(h[i], &pending), HEDGER_OK);
    assert_int_equal(pending, 4 * 40);
    do {
      assert_int_equal(hedger_end_run_step(h[i], 4, &left), HEDGER_OK);
      ++slices[i];
      if (left >= pending - 40) first_pass_slices[i] = slices[i];
    } while (left > 0);
  }
  // First pass: 40 updates, 4 per slice (10 slices). Then 3 × 40 reused updates at 2 units each
  // of a slice's 64 (16 per update-equivalent), but for the terminal record's, which makes no
  // greedy search and saves only on its prediction (9 units): 3 × 87 units in 5 slices.
  assert_int_equal(first_pass_slices[0], 10);
  assert_int_equal(slices[0], 10 + 5);
  assert_int_equal(slices[1], 40);
  assert_true(ht_same_saved(h[0], h[1]));
  hedger_destroy(h[0]);
  hedger_destroy(h[1]);
}

// While the kd-tree is being rebuilt every replayed update also advances the rebuild, reused or
// not, so a reused update then counts three eighths of an update (6 units of 16), as in a full
// store: a slow rebuild (rebuild_work_per_update 64 over a store of 3,000 points) stays under way
// through the whole replay: the first pass takes 40 × 16 units, 10 slices of 64, and the reused
// passes 3 × 39 × 6 + 3 × 13 = 741 units, 13 slices (at 2 units they took 5, and a slice then did
// up to 32 updates' rebuild work). The learned state is the same as without the cache.
static void test_replay_cache_slices_count_the_rebuild(void** state) {
  (void)state;
  hedger_config_t c[2] = {replay_config(1, 4000), replay_config(0, 4000)};
  uint32_t reused_slices = 0;
  hedger_t* h[2];
  for (int i = 0; i < 2; ++i) {
    c[i].fresh_capacity = 4096;
    c[i].rebuild_work_per_update = 64;
    h[i] = ht_create(&c[i]);
    uint64_t rs = 9;
    for (int j = 0; j < 3000; ++j) {
      const double x[3] = {ht_uniform(&rs, -3.0, 3.0), ht_uniform(&rs, -3.0, 3.0), ht_uniform(&rs, -1.0, 1.0)};
      assert_int_equal(hedger_insert(h[i], x, ht_uniform(&rs, -1.0, 1.0), 0.0, 0, NULL), HEDGER_OK);
    }
    drive_run(&h[i], 1, &rs, 40);
    uint32_t pending = 0, left = 0;
    assert_int_equal(hedger_end_run_begin(h[i], &pending), HEDGER_OK);
    assert_int_equal(pending, 4 * 40);
    const uint64_t rebuilds = hedger_counters(h[i])->rebuilds;
    do {
      assert_int_equal(hedger_end_run_step(h[i], 4, &left), HEDGER_OK);
      if (i == 0 && left < pending - 40) ++reused_slices;
    } while (left > 0);
    assert_int_equal(hedger_counters(h[i])->rebuilds, rebuilds);  // under way throughout
  }
  assert_true(hedger_counters(h[0])->replay_reused > 200);
  assert_int_equal(reused_slices, 13);
  assert_true(ht_same_saved(h[0], h[1]));
  hedger_destroy(h[0]);
  hedger_destroy(h[1]);
}

// The cache costs run_capacity records of memory, and nothing without a replay.
static void test_replay_cache_memory_only_with_replay(void** state) {
  (void)state;
  hedger_config_t on = replay_config(1, 350), off = replay_config(0, 350);
  assert_true(hedger_storage_size(&on) > hedger_storage_size(&off));
  on.replay = 0;
  off.replay = 0;
  assert_int_equal(hedger_storage_size(&on), hedger_storage_size(&off));
  on.replay_cache = 2;
  assert_int_equal(hedger_config_validate(&on), HEDGER_ERR_INVALID_ARG);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_replay_cache_identical_with_evictions),
      cmocka_unit_test(test_replay_cache_identical_across_tags_and_weights),
      cmocka_unit_test(test_replay_cache_not_carried_to_the_next_run),
      cmocka_unit_test(test_replay_cache_slices_reused_updates_eight_to_one),
      cmocka_unit_test(test_replay_cache_slices_count_the_rebuild),
      cmocka_unit_test(test_replay_cache_memory_only_with_replay),
  };
  return cmocka_run_group_tests_name("hedger.replay", tests, NULL, NULL);
}
