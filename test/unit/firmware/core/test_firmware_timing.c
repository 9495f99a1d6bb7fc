// SPDX-License-Identifier: MIT
// Tick timing: nearest-rank percentiles equal a sorted reference, the window slides, overruns count;
// deadline accounting against the absolute schedule (lateness, late starts, missed periods, gaps).
#include "fw/timing.h"

#include <b21r_test/alloc_counter.h>

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

static int cmp_i32(const void* a, const void* b) {
  const int32_t x = *(const int32_t*)a;
  const int32_t y = *(const int32_t*)b;
  return (x > y) - (x < y);
}

static fw_timing_t g_t;

// p50/p99/max equal the nearest-rank values of a sorted copy, for many sizes and seeds.
static void test_timing_percentiles_match_sorted_reference(void** state) {
  (void)state;
  static int32_t ref[FW_TIMING_WINDOW];
  uint64_t rng = 12345;
  const uint32_t sizes[] = {1, 2, 3, 10, 99, 100, 101, 500, 1023, 1024};
  for (size_t s = 0; s < sizeof sizes / sizeof sizes[0]; ++s) {
    fw_timing_init(&g_t, 100000, 10000);
    const uint32_t n = sizes[s];
    for (uint32_t i = 0; i < n; ++i) {
      rng = rng * 6364136223846793005ULL + 1442695040888963407ULL;
      const int32_t v = (int32_t)((rng >> 40) % (s % 2 == 0 ? 50U : 100000U));  // duplicates too
      ref[i] = v;
      fw_timing_record(&g_t, v, false);
    }
    qsort(ref, n, sizeof ref[0], cmp_i32);
    const fw_timing_summary_t sum = fw_timing_summary(&g_t);
    assert_int_equal(sum.p50_us, ref[(n + 1) / 2 - 1]);
    assert_int_equal(sum.p99_us, ref[(99 * n + 99) / 100 - 1]);
    assert_int_equal(sum.max_us, ref[n - 1]);
    assert_int_equal(sum.ticks, n);
  }
}

// Only the newest FW_TIMING_WINDOW ticks count for the percentiles; max_ever and overruns persist.
static void test_timing_window_slides_overruns_persist(void** state) {
  (void)state;
  fw_timing_init(&g_t, 100000, 10000);
  fw_timing_record(&g_t, 90000, true);
  for (uint32_t i = 0; i < FW_TIMING_WINDOW; ++i) {
    fw_timing_record(&g_t, 100, false);
  }
  fw_timing_record(&g_t, -5, false);  // clock anomaly -> 0
  alloc_counter_begin();
  const fw_timing_summary_t s = fw_timing_summary(&g_t);
  assert_int_equal(alloc_counter_end(), 0);
  assert_int_equal(s.max_us, 100);
  assert_int_equal(s.p99_us, 100);
  assert_int_equal(s.max_ever_us, 90000);
  assert_int_equal(s.overruns, 1);
  assert_int_equal(s.ticks, FW_TIMING_WINDOW + 2);
}

// An empty window reports zeros.
static void test_timing_empty_reports_zero(void** state) {
  (void)state;
  fw_timing_init(&g_t, 100000, 10000);
  const fw_timing_summary_t s = fw_timing_summary(&g_t);
  assert_int_equal(s.p50_us, 0);
  assert_int_equal(s.max_us, 0);
}

// Ticks at S_k = k·P (P = 100 ms): on time, 61 ms late (a late start, not a missed period), on
// time again, then 250 ms late (two scheduled starts passed: two missed periods).
static void test_timing_deadlines_against_absolute_schedule(void** state) {
  (void)state;
  const int64_t P = 100000;
  fw_timing_init(&g_t, P, 10000);
  fw_timing_record_start(&g_t, 0, 50);           // 50 us late: on time
  fw_timing_record_start(&g_t, P, P + 61000);    // 61 ms late
  fw_timing_record_start(&g_t, 2 * P, 2 * P + 10000);  // exactly the threshold: not late
  fw_timing_record_start(&g_t, 3 * P, 3 * P + 250000);
  fw_timing_record_start(&g_t, 6 * P, 6 * P - 5);  // early (clock anomaly): on time
  const fw_timing_summary_t s = fw_timing_summary(&g_t);
  assert_int_equal(s.late_starts, 2);
  assert_int_equal(s.missed_periods, 2);
  assert_int_equal(s.late_max_ever_us, 250000);
  assert_int_equal(s.late_max_us, 250000);
  assert_int_equal(s.late_p99_us, 250000);
  // Gaps between starts: 161 ms, 49 ms, 340 ms, 49.75 ms.
  assert_int_equal(s.gap_max_ever_us, 340000);
}

// A tick 61 ms late counts even when its compute time is short and it ends before the next
// scheduled start (the case compute-only timing never saw); one a period late is a missed period.
static void test_timing_late_start_counted_without_overrun(void** state) {
  (void)state;
  const int64_t P = 100000;
  fw_timing_init(&g_t, P, 10000);
  fw_timing_record_start(&g_t, 0, 61000);
  fw_timing_record(&g_t, 200, false);
  fw_timing_summary_t s = fw_timing_summary(&g_t);
  assert_int_equal(s.late_starts, 1);
  assert_int_equal(s.missed_periods, 0);
  assert_int_equal(s.overruns, 0);
  assert_int_equal(s.max_ever_us, 200);
  fw_timing_record_start(&g_t, P, 2 * P);  // exactly one period late: the start at 2P passed
  s = fw_timing_summary(&g_t);
  assert_int_equal(s.missed_periods, 1);
  assert_int_equal(s.late_starts, 2);
}

// The lateness window slides like the compute window; the since-start values persist.
static void test_timing_lateness_window_slides(void** state) {
  (void)state;
  fw_timing_init(&g_t, 100000, 10000);
  fw_timing_record_start(&g_t, 0, 90000);
  for (uint32_t i = 1; i <= FW_TIMING_WINDOW; ++i) {
    fw_timing_record_start(&g_t, (int64_t)i * 100000, (int64_t)i * 100000 + 30);
  }
  const fw_timing_summary_t s = fw_timing_summary(&g_t);
  assert_int_equal(s.late_max_us, 30);
  assert_int_equal(s.late_p99_us, 30);
  assert_int_equal(s.late_max_ever_us, 90000);
  assert_int_equal(s.late_starts, 1);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_timing_percentiles_match_sorted_reference),
      cmocka_unit_test(test_timing_window_slides_overruns_persist),
      cmocka_unit_test(test_timing_empty_reports_zero),
      cmocka_unit_test(test_timing_deadlines_against_absolute_schedule),
      cmocka_unit_test(test_timing_late_start_counted_without_overrun),
      cmocka_unit_test(test_timing_lateness_window_slides),
  };
  return cmocka_run_group_tests_name("firmware.timing", tests, NULL, NULL);
}
