// SPDX-License-Identifier: MIT
// Safety supervisor: each cause stops in the tick it appears with its reason and detail, the
// priority order holds, stops latch until cleared (auto or operator), signals never clear.
#include "fw/safety.h"

#include <b21r_test/alloc_counter.h>

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

static fw_safety_config_t lockstep_cfg(bool auto_resume) {
  const fw_safety_config_t c = {.lockstep = true,
                                .laser_limit_ticks = 4,
                                .base_limit_ticks = 3,
                                .laser_limit_us = 350000,
                                .base_limit_us = 350000,
                                .clear_ticks = 5,
                                .auto_resume = auto_resume};
  return c;
}

static fw_safety_inputs_t quiet(void) {
  fw_safety_inputs_t in;
  memset(&in, 0, sizeof in);
  return in;
}

// A quiet tick is OK and leaves no reason.
static void test_safety_quiet_tick_ok(void** state) {
  (void)state;
  fw_safety_t s;
  const fw_safety_config_t c = lockstep_cfg(true);
  fw_safety_init(&s, &c);
  fw_safety_inputs_t in = quiet();
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_OK);
  assert_int_equal(s.reason, FW_STOP_NONE);
  assert_string_equal(s.detail, "");
}

// A laser that sends bytes but no valid telegram is reported as a corrupt stream, not as silent;
// without bad bytes the same silence is "laser silent".
static void test_safety_corrupt_laser_stream_has_own_detail(void** state) {
  (void)state;
  for (int lockstep = 0; lockstep < 2; ++lockstep) {
    for (int corrupt = 0; corrupt < 2; ++corrupt) {
      fw_safety_t s;
      fw_safety_config_t c = lockstep_cfg(true);
      c.lockstep = lockstep != 0;
      fw_safety_init(&s, &c);
      fw_safety_inputs_t in = quiet();
      in.laser_silent_ticks = 4;
      in.laser_age_us = 400000;
      in.laser_bad_since_scan = corrupt ? 812U : 0U;
      assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOP_BEGAN);
      assert_int_equal(s.reason, FW_STOP_LASER_SILENT);
      if (corrupt) {
        assert_non_null(strstr(s.detail, "laser stream corrupt"));
        assert_non_null(strstr(s.detail, "812 bad bytes"));
      } else {
        assert_non_null(strstr(s.detail, "laser silent for"));
      }
    }
  }
}

// Every cause on its own stops in the same tick with its reason and a detail naming it.
static void test_safety_each_cause_stops_with_reason(void** state) {
  (void)state;
  struct {
    int reason;
    const char* detail_part;
  } cases[] = {
      {FW_STOP_LASER_SILENT, "laser silent for 4 ticks"}, {FW_STOP_BASE_SILENT, "base silent for 3 ticks"},
      {FW_STOP_BASE_FAULT, "EMCY 0x5530"},                {FW_STOP_BUMPER, "bump panel 3"},
      {FW_STOP_NON_FINITE, "features s[1]"},              {FW_STOP_DEADMAN, "deadman"},
      {FW_STOP_SIGNAL, "signal 15"},                      {FW_STOP_OPERATOR, "PAUSE"},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
    fw_safety_t s;
    const fw_safety_config_t c = lockstep_cfg(true);
    fw_safety_init(&s, &c);
    fw_safety_inputs_t in = quiet();
    switch (cases[i].reason) {
      case FW_STOP_LASER_SILENT:
        in.laser_silent_ticks = 3;
        assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_OK);  // below the limit
        in.laser_silent_ticks = 4;
        break;
      case FW_STOP_BASE_SILENT:
        in.base_silent_ticks = 3;
        break;
      case FW_STOP_BASE_FAULT:
        in.base_fault = true;
        in.base_fault_detail = "EMCY 0x5530 from node 2";
        break;
      case FW_STOP_BUMPER:
        in.bumper_mask = 1U << 3;
        break;
      case FW_STOP_NON_FINITE:
        in.non_finite = true;
        in.non_finite_where = "features s[1]";
        break;
      case FW_STOP_DEADMAN:
        in.deadman_required = true;
        in.deadman_fresh = false;
        break;
      case FW_STOP_SIGNAL:
        in.signal_number = 15;
        break;
      default:
        in.operator_pause = true;
        break;
    }
    alloc_counter_begin();
    assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOP_BEGAN);
    assert_int_equal(alloc_counter_end(), 0);
    assert_int_equal(s.reason, cases[i].reason);
    assert_non_null(strstr(s.detail, cases[i].detail_part));
    assert_int_equal(s.stops, 1);
    assert_int_equal(s.stops_by_reason[cases[i].reason], 1);
    assert_true(fw_stop_reason_name(s.reason)[0] != '\0');
  }
}

// Real-time thresholds use the ages in microseconds.
static void test_safety_realtime_uses_ages(void** state) {
  (void)state;
  fw_safety_t s;
  fw_safety_config_t c = lockstep_cfg(true);
  c.lockstep = false;
  fw_safety_init(&s, &c);
  fw_safety_inputs_t in = quiet();
  in.laser_silent_ticks = 100;  // ignored in real time
  in.laser_age_us = 349999;
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_OK);
  in.laser_age_us = 350000;
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOP_BEGAN);
  assert_non_null(strstr(s.detail, "350 ms"));
}

// With several causes, the highest-priority one is reported; a more serious cause appearing
// during a stop replaces the reason.
static void test_safety_priority_order(void** state) {
  (void)state;
  fw_safety_t s;
  const fw_safety_config_t c = lockstep_cfg(true);
  fw_safety_init(&s, &c);
  fw_safety_inputs_t in = quiet();
  in.laser_silent_ticks = 10;
  in.deadman_required = true;
  in.bumper_mask = 1;
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOP_BEGAN);
  assert_int_equal(s.reason, FW_STOP_BUMPER);
  in.base_fault = true;
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOP_BEGAN);
  assert_int_equal(s.reason, FW_STOP_BASE_FAULT);
  in.base_fault = false;
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOPPED);
  assert_int_equal(s.reason, FW_STOP_BASE_FAULT);  // a lesser cause does not replace it
  in.signal_number = 2;
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOP_BEGAN);
  assert_int_equal(s.reason, FW_STOP_SIGNAL);
}

// With auto-resume, a stop clears after clear_ticks quiet ticks, not before; a cause returning
// restarts the count.
static void test_safety_auto_resume_after_clear_ticks(void** state) {
  (void)state;
  fw_safety_t s;
  const fw_safety_config_t c = lockstep_cfg(true);
  fw_safety_init(&s, &c);
  fw_safety_inputs_t in = quiet();
  in.base_silent_ticks = 5;
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOP_BEGAN);
  in = quiet();
  for (int i = 0; i < 3; ++i) {
    assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOPPED);
  }
  in.base_silent_ticks = 4;
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOPPED);
  in = quiet();
  for (int i = 0; i < 4; ++i) {
    assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOPPED);
  }
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_RESUMED);
  assert_int_equal(s.reason, FW_STOP_NONE);
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_OK);
  assert_int_equal(s.stops, 1);
}

// Without auto-resume (and always for PAUSE) the operator's RESUME is needed, even one sent
// while the cause was still present.
static void test_safety_operator_resume_required(void** state) {
  (void)state;
  fw_safety_t s;
  const fw_safety_config_t c = lockstep_cfg(false);
  fw_safety_init(&s, &c);
  fw_safety_inputs_t in = quiet();
  in.bumper_mask = 2;
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOP_BEGAN);
  in.operator_resume = true;  // too early: remembered
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOPPED);
  in = quiet();
  for (int i = 0; i < 4; ++i) {
    assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOPPED);
  }
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_RESUMED);

  // Operator pause with auto-resume on still needs RESUME.
  const fw_safety_config_t c2 = lockstep_cfg(true);
  fw_safety_init(&s, &c2);
  in = quiet();
  in.operator_pause = true;
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOP_BEGAN);
  in = quiet();
  for (int i = 0; i < 20; ++i) {
    assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOPPED);
  }
  in.operator_resume = true;
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_RESUMED);
}

// A signal stop never clears.
static void test_safety_signal_never_clears(void** state) {
  (void)state;
  fw_safety_t s;
  const fw_safety_config_t c = lockstep_cfg(true);
  fw_safety_init(&s, &c);
  fw_safety_inputs_t in = quiet();
  in.signal_number = 15;
  assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOP_BEGAN);
  in = quiet();
  in.operator_resume = true;
  for (int i = 0; i < 50; ++i) {
    assert_int_equal(fw_safety_update(&s, &in), FW_SAFETY_STOPPED);
  }
  assert_int_equal(s.reason, FW_STOP_SIGNAL);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_safety_quiet_tick_ok),
      cmocka_unit_test(test_safety_each_cause_stops_with_reason),
      cmocka_unit_test(test_safety_corrupt_laser_stream_has_own_detail),
      cmocka_unit_test(test_safety_realtime_uses_ages),
      cmocka_unit_test(test_safety_priority_order),
      cmocka_unit_test(test_safety_auto_resume_after_clear_ticks),
      cmocka_unit_test(test_safety_operator_resume_required),
      cmocka_unit_test(test_safety_signal_never_clears),
  };
  return cmocka_run_group_tests_name("firmware.safety", tests, NULL, NULL);
}
