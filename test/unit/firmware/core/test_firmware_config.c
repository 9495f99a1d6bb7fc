// SPDX-License-Identifier: MIT
// Config parsing: defaults, every error names source, key and allowed values; overrides; the
// reference file in firmware/app is exactly the generated documentation of the defaults.
#define _POSIX_C_SOURCE 200809L
#include <tasks/decl.h>
#include "fw/config.h"
#include "fw/config_task.h"

#include <b21r_test/alloc_counter.h>

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

static const char* g_reference_path;
static char g_dir[256];

static const char* write_tmp(const char* name, const char* text) {
  static char path[512];
  snprintf(path, sizeof path, "%s/%s", g_dir, name);
  FILE* f = fopen(path, "w");
  assert_non_null(f);
  fputs(text, f);
  fclose(f);
  return path;
}

static int setup(void** state) {
  (void)state;
  snprintf(g_dir, sizeof g_dir, "/tmp/b21r-config-XXXXXX");
  return mkdtemp(g_dir) == NULL ? -1 : 0;
}

static int teardown(void** state) {
  (void)state;
  char cmd[300];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", g_dir);
  return system(cmd) == 0 ? 0 : -1;
}

// The defaults are the paper's settings and pass the cross-key checks.
static void test_config_defaults_are_paper_settings_and_valid(void** state) {
  (void)state;
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_config_validate(&c, err, sizeof err), 0);
  assert_true(c.tick_rate_hz == 10.0);
  assert_true(c.alpha == 0.2);
  assert_true(c.gamma == 0.0);  // the task's own: 0.99 for the corridor
  assert_int_equal(c.eval_every_runs, 5);
  assert_int_equal(c.eval_starts, 10);
  assert_int_equal(c.phase_one_runs, 30);
  assert_int_equal(c.phase_two_runs, 35);
  assert_int_equal(c.base_protocol, FW_BASE_RFLEX);
  assert_int_equal(c.laser_resolution_cdeg, 100);
  assert_int_equal(fw_config_period_us(&c), 100000);
  assert_int_equal(fw_config_ticks(&c, 0.35), 4);
  assert_int_equal(fw_config_ticks(&c, 0.3), 3);
  assert_int_equal(fw_config_ticks(&c, 0.0), 1);
}

// An unknown key is an error naming the file, the line and the key, the nearest known key and
// the option that lists every key.
static void test_config_unknown_key_names_file_line_and_key(void** state) {
  (void)state;
  const char* p = write_tmp("unknown.conf", "# comment\n\ntick_rat_hz = 10\n");
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_config_load_file(&c, p, err, sizeof err), -1);
  assert_non_null(strstr(err, "unknown.conf:3"));
  assert_non_null(strstr(err, "unknown key 'tick_rat_hz'"));
  assert_non_null(strstr(err, "did you mean 'tick_rate_hz'?"));
  assert_non_null(strstr(err, "--print-reference-config"));
}

// The suggestion is the nearest key: typos, swapped letters, a left-out unit suffix; nothing
// is suggested for a name that resembles no key.
static void test_config_unknown_key_suggests_nearest(void** state) {
  (void)state;
  static const struct {
    const char* typed;
    const char* meant;  // NULL: no suggestion
  } cases[] = {
      {"aplha", "alpha"},                          // swapped letters
      {"max_rotation", "max_rotation_radps"},      // unit suffix left out
      {"max_rotation_rads", "max_rotation_radps"}, // one letter dropped
      {"teleop_timeout", "teleop_timeout_s"},
      {"lockstepp", "lockstep"},
      {"hedger_k_mx", "hedger_k_max"},
      {"lcm-url", "lcm_url"},
      {"xyzzy", NULL},
      {"colour_scheme", NULL},
      {"a_very_long_name_that_resembles_no_key_of_the_controller_at_all", NULL},
  };
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
    assert_int_equal(fw_config_set(&c, cases[i].typed, "1", "--set", err, sizeof err), -1);
    assert_non_null(strstr(err, "--print-reference-config"));
    if (cases[i].meant == NULL) {
      if (strstr(err, "did you mean") != NULL) {
        fail_msg("'%s': unexpected suggestion: %s", cases[i].typed, err);
      }
    } else {
      char want[128];
      snprintf(want, sizeof want, "did you mean '%s'?", cases[i].meant);
      if (strstr(err, want) == NULL) {
        fail_msg("'%s': expected \"%s\" in: %s", cases[i].typed, want, err);
      }
    }
  }
}

// A value out of range names the key, the line and the allowed range.
static void test_config_out_of_range_names_allowed_range(void** state) {
  (void)state;
  const char* p = write_tmp("range.conf", "alpha = 0.2\ntick_rate_hz = 500\n");
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_config_load_file(&c, p, err, sizeof err), -1);
  assert_non_null(strstr(err, "range.conf:2"));
  assert_non_null(strstr(err, "'tick_rate_hz'"));
  assert_non_null(strstr(err, "[1, 100]"));
  assert_true(c.tick_rate_hz == 10.0);  // unchanged
}

// Bad enum, bool, number, NaN and infinity are refused with the allowed values in the message.
static void test_config_bad_values_refused_with_choices(void** state) {
  (void)state;
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_config_set(&c, "base_protocol", "usb", "x.conf:4", err, sizeof err), -1);
  assert_non_null(strstr(err, "one of rflex, canopen"));
  assert_non_null(strstr(err, "x.conf:4"));
  assert_int_equal(fw_config_set(&c, "lockstep", "maybe", "s", err, sizeof err), -1);
  assert_non_null(strstr(err, "true or false"));
  assert_int_equal(fw_config_set(&c, "alpha", "abc", "s", err, sizeof err), -1);
  assert_int_equal(fw_config_set(&c, "alpha", "nan", "s", err, sizeof err), -1);
  assert_int_equal(fw_config_set(&c, "alpha", "inf", "s", err, sizeof err), -1);
  assert_int_equal(fw_config_set(&c, "alpha", "", "s", err, sizeof err), -1);
  assert_int_equal(fw_config_set(&c, "alpha", "0", "s", err, sizeof err), -1);  // open lower bound
  assert_non_null(strstr(err, "(0, 1]"));
  assert_int_equal(fw_config_set(&c, "gamma", "1", "s", err, sizeof err), -1);  // open upper bound
  assert_non_null(strstr(err, "[0, 1)"));
  assert_int_equal(fw_config_set(&c, "eval_starts", "10.5", "s", err, sizeof err), -1);
  assert_int_equal(fw_config_set(&c, "eval_starts", "17", "s", err, sizeof err), -1);
  assert_int_equal(fw_config_set(&c, "seed", "-1", "s", err, sizeof err), -1);
  assert_int_equal(fw_config_set(&c, "seed", "18446744073709551615", "s", err, sizeof err), -1);
  assert_int_equal(fw_config_set(&c, "laser_baud", "57600", "s", err, sizeof err), -1);
  assert_non_null(strstr(err, "9600, 19200, 38400, 500000"));
  assert_true(c.alpha == 0.2);
  assert_int_equal(fw_config_set(&c, "seed", "123456789012", "s", err, sizeof err), 0);
  assert_true(c.seed == 123456789012ULL);
}

// The real-time keys: scheduler choices, priority range, CPU lists (numbers, ranges, blanks)
// to a mask and back to the canonical list, refusals that keep the old value and say the syntax.
static void test_config_realtime_keys_parse_and_print(void** state) {
  (void)state;
  fw_config_t c;
  fw_config_defaults(&c);
  assert_int_equal(c.rt_scheduler, FW_RT_OTHER);
  assert_int_equal(c.rt_priority, 50);
  assert_true(c.rt_cpus == 0);
  assert_false(c.rt_lock_memory);
  assert_false(c.rt_prefault);
  assert_true(c.late_start_threshold_s == 0.01);
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_config_set(&c, "rt_scheduler", "fifo", "s", err, sizeof err), 0);
  assert_int_equal(c.rt_scheduler, FW_RT_FIFO);
  assert_int_equal(fw_config_set(&c, "rt_scheduler", "rr", "s", err, sizeof err), 0);
  assert_int_equal(c.rt_scheduler, FW_RT_RR);
  assert_int_equal(fw_config_set(&c, "rt_scheduler", "deadline", "s", err, sizeof err), -1);
  assert_non_null(strstr(err, "one of other, fifo, rr"));
  assert_int_equal(fw_config_set(&c, "rt_priority", "0", "s", err, sizeof err), -1);
  assert_non_null(strstr(err, "[1, 99]"));
  assert_int_equal(fw_config_set(&c, "rt_priority", "100", "s", err, sizeof err), -1);
  assert_int_equal(fw_config_set(&c, "rt_priority", "80", "s", err, sizeof err), 0);
  assert_int_equal(c.rt_priority, 80);

  assert_int_equal(fw_config_set(&c, "rt_cpus", "1", "s", err, sizeof err), 0);
  assert_true(c.rt_cpus == 0x2U);
  assert_int_equal(fw_config_set(&c, "rt_cpus", " 0, 2-4 ,7,63 ", "s", err, sizeof err), 0);
  assert_true(c.rt_cpus == (0x1U | 0x1CU | 0x80U | (UINT64_C(1) << 63)));
  char list[256];
  fw_config_format_cpus(c.rt_cpus, list, sizeof list);
  assert_string_equal(list, "0,2-4,7,63");
  fw_config_format_cpus(0, list, sizeof list);
  assert_string_equal(list, "");
  const char* bad[] = {"64", "-1", "1-", "3-1", "1,,2", "1,", "a", "1 2", "0x1", "1-2-3"};
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; ++i) {
    err[0] = '\0';
    assert_int_equal(fw_config_set(&c, "rt_cpus", bad[i], "robot.conf:9", err, sizeof err), -1);
    assert_non_null(strstr(err, "robot.conf:9"));
    assert_non_null(strstr(err, "'rt_cpus'"));
    assert_non_null(strstr(err, "CPU numbers and ranges in [0, 63]"));
  }
  assert_true(c.rt_cpus == (0x1U | 0x1CU | 0x80U | (UINT64_C(1) << 63)));  // unchanged
  assert_int_equal(fw_config_set(&c, "rt_cpus", "", "s", err, sizeof err), 0);
  assert_true(c.rt_cpus == 0);

  // Printed and loaded back: the same settings.
  assert_int_equal(fw_config_set(&c, "rt_cpus", "1,3-5", "s", err, sizeof err), 0);
  assert_int_equal(fw_config_set(&c, "rt_lock_memory", "true", "s", err, sizeof err), 0);
  assert_int_equal(fw_config_set(&c, "rt_prefault", "true", "s", err, sizeof err), 0);
  const char* p = write_tmp("rt.conf", "");
  FILE* f = fopen(p, "w");
  assert_non_null(f);
  fw_config_print(&c, f);
  fclose(f);
  fw_config_t back;
  fw_config_defaults(&back);
  assert_int_equal(fw_config_load_file(&back, p, err, sizeof err), 0);
  assert_memory_equal(&back, &c, offsetof(fw_config_t, origins));
  assert_int_equal(fw_config_validate(&back, err, sizeof err), 0);
}

// A boolean is exactly what its error message says: true or false, nothing else.
static void test_config_bool_accepts_exactly_true_or_false(void** state) {
  (void)state;
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  static const char* const refused[] = {"on", "off", "yes", "no", "1", "0", "True", "FALSE", "t", ""};
  for (size_t i = 0; i < sizeof refused / sizeof refused[0]; ++i) {
    assert_int_equal(fw_config_set(&c, "lockstep", refused[i], "s", err, sizeof err), -1);
    assert_non_null(strstr(err, "expected true or false"));
    assert_false(c.lockstep);
  }
  assert_int_equal(fw_config_set(&c, "lockstep", "true", "s", err, sizeof err), 0);
  assert_true(c.lockstep);
  assert_int_equal(fw_config_set(&c, "lockstep", "false", "s", err, sizeof err), 0);
  assert_false(c.lockstep);
  assert_int_equal(fw_config_set(&c, "seed", "123456789012", "s", err, sizeof err), 0);
  assert_true(c.seed == 123456789012ULL);
}

// Syntax errors (no '=', missing key, unterminated quote, duplicate key) name the line.
static void test_config_syntax_errors_name_line(void** state) {
  (void)state;
  fw_config_t c;
  char err[FW_CONFIG_ERR_MAX];
  fw_config_defaults(&c);
  assert_int_equal(fw_config_load_file(&c, write_tmp("a.conf", "seed 3\n"), err, sizeof err), -1);
  assert_non_null(strstr(err, "a.conf:1: expected 'key = value'"));
  fw_config_defaults(&c);
  assert_int_equal(fw_config_load_file(&c, write_tmp("b.conf", "\n = 3\n"), err, sizeof err), -1);
  assert_non_null(strstr(err, "b.conf:2: missing key"));
  fw_config_defaults(&c);
  assert_int_equal(fw_config_load_file(&c, write_tmp("c.conf", "log_file = \"abc\n"), err, sizeof err), -1);
  assert_non_null(strstr(err, "unterminated"));
  fw_config_defaults(&c);
  assert_int_equal(fw_config_load_file(&c, write_tmp("d.conf", "seed = 3\nseed = 4\n"), err, sizeof err), -1);
  assert_non_null(strstr(err, "d.conf:2: key 'seed' appears twice in this file (first on line 1)"));
  fw_config_defaults(&c);
  assert_int_equal(fw_config_load_file(&c, "/nonexistent/b21r.conf", err, sizeof err), -1);
  assert_non_null(strstr(err, "/nonexistent/b21r.conf: cannot open"));
}

// Comments, blanks, quoted values with spaces and '#', CRLF line ends are handled.
static void test_config_comments_quotes_and_crlf_parse(void** state) {
  (void)state;
  const char* p = write_tmp("ok.conf",
                            "# header\n"
                            "   \n"
                            "log_file = \"out dir/a # b.log\"   # trailing comment\r\n"
                            "  tick_rate_hz=20  \r\n"
                            "task = obstacles # the other task\n"
                            "checkpoint_file = plain/path.ckpt\n");
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_config_load_file(&c, p, err, sizeof err), 0);
  assert_string_equal(c.log_file, "out dir/a # b.log");
  assert_true(c.tick_rate_hz == 20.0);
  assert_int_equal(c.task, (int32_t)tasks_obstacles_decl.id);
  assert_string_equal(c.checkpoint_file, "plain/path.ckpt");
  assert_int_equal(fw_config_period_us(&c), 50000);
}

// --set overrides and its errors name "--set".
static void test_config_set_arg_overrides_and_errors(void** state) {
  (void)state;
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_config_set_arg(&c, "alpha=0.5", err, sizeof err), 0);
  assert_true(c.alpha == 0.5);
  assert_int_equal(fw_config_set_arg(&c, "lcm_url = memq://", err, sizeof err), 0);
  assert_string_equal(c.lcm_url, "memq://");
  assert_int_equal(fw_config_set_arg(&c, "alpha", err, sizeof err), -1);
  assert_non_null(strstr(err, "--set 'alpha'"));
  assert_int_equal(fw_config_set_arg(&c, "alpha=2", err, sizeof err), -1);
  assert_non_null(strstr(err, "--set: bad value '2' for key 'alpha'"));
  assert_int_equal(fw_config_set_arg(&c, "nope=1", err, sizeof err), -1);
  assert_non_null(strstr(err, "--set: unknown key 'nope'"));
}

// A string value with a double quote or a control character is refused: the file format cannot
// write it back (found by fuzz_config: `log_file = x"a b"` printed as a line that no longer
// parsed); a shorter value replaces a longer one completely.
static void test_config_strings_round_trip_through_print(void** state) {
  (void)state;
  fw_config_t c;
  fw_config_defaults(&c);
  const fw_config_t before = c;
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_config_set_arg(&c, "log_file = x\"out dir/#1\"", err, sizeof err), -1);
  assert_non_null(strstr(err, "without double quotes or control characters"));
  assert_int_equal(fw_config_set(&c, "log_file", "a\nb", "--set", err, sizeof err), -1);
  assert_int_equal(fw_config_set(&c, "log_file", "tab\there", "--set", err, sizeof err), -1);
  assert_memory_equal(&c, &before, sizeof c);  // a refusal does not even record an origin
  assert_int_equal(fw_config_set(&c, "log_file", "a long name for a log file #1.lcmlog", "--set", err, sizeof err), 0);
  assert_int_equal(fw_config_set(&c, "log_file", "short", "--set", err, sizeof err), 0);
  const char* p = write_tmp("printed.conf", "");
  FILE* f = fopen(p, "w");
  assert_non_null(f);
  fw_config_print(&c, f);
  fclose(f);
  fw_config_t back;
  fw_config_defaults(&back);
  assert_int_equal(fw_config_load_file(&back, p, err, sizeof err), 0);
  // Settings byte for byte (no stale tail after "short"); origins name the file, not "--set".
  assert_memory_equal(&back, &c, offsetof(fw_config_t, origins));
}

// Cross-key rules are enforced with a message that names both keys.
static void test_config_validate_cross_key_rules(void** state) {
  (void)state;
  fw_config_t c;
  char err[FW_CONFIG_ERR_MAX];
  fw_config_defaults(&c);
  c.laser_resolution_cdeg = 25;
  assert_int_equal(fw_config_validate(&c, err, sizeof err), -1);
  assert_non_null(strstr(err, "laser_fov_deg = 100"));
  c.laser_fov_deg = 100;
  assert_int_equal(fw_config_validate(&c, err, sizeof err), 0);
  fw_config_defaults(&c);
  c.hedger_k_max = 32;
  c.hedger_k_min = 40;
  assert_int_equal(fw_config_validate(&c, err, sizeof err), -1);
  assert_non_null(strstr(err, "hedger_k_min"));
  fw_config_defaults(&c);
  c.reposition = FW_REPOSITION_EMULATOR;
  assert_int_equal(fw_config_validate(&c, err, sizeof err), -1);
  assert_non_null(strstr(err, "emulator_control"));
  fw_config_defaults(&c);
  c.queue_capacity = 1000;
  assert_int_equal(fw_config_validate(&c, err, sizeof err), -1);
  assert_non_null(strstr(err, "power of two"));
  // The example policy's gain range: two gains, the lowest first; one gain or a reversed pair
  // is refused with the key and the fix.
  static const char* const bad_ranges[] = {"2,1", "1.5", "0.5,1,2"};
  for (size_t i = 0; i < sizeof bad_ranges / sizeof bad_ranges[0]; ++i) {
    fw_config_defaults(&c);
    assert_int_equal(fw_config_set(&c, "example_gain_range", bad_ranges[i], "--set", err, sizeof err), 0);
    assert_int_equal(fw_config_validate(&c, err, sizeof err), -1);
    assert_non_null(strstr(err, "it needs two gains"));
    assert_non_null(strstr(err, bad_ranges[i]));  // the value given is quoted back
  }
  // Gains are positive and at most 100 1/s: the list parser refuses the rest with the key.
  static const char* const out_of_range[] = {"0,2", "-1,2", "1,200"};
  for (size_t i = 0; i < sizeof out_of_range / sizeof out_of_range[0]; ++i) {
    fw_config_defaults(&c);
    assert_int_equal(fw_config_set(&c, "example_gain_range", out_of_range[i], "--set", err, sizeof err), -1);
    assert_non_null(strstr(err, "example_gain_range"));
  }
  fw_config_defaults(&c);
  assert_int_equal(fw_config_set(&c, "example_gain_range", "1.75,2", "--set", err, sizeof err), 0);
  assert_int_equal(fw_config_validate(&c, err, sizeof err), 0);
  assert_int_equal(c.example_gain_range_n, 2);
  assert_true(c.example_gain_range[0] > 1.7499 && c.example_gain_range[0] < 1.7501);
  assert_true(c.example_gain_range[1] > 1.9999 && c.example_gain_range[1] < 2.0001);
  // Empty: the task's range again.
  assert_int_equal(fw_config_set(&c, "example_gain_range", "", "--set", err, sizeof err), 0);
  assert_int_equal(c.example_gain_range_n, 0);
  assert_int_equal(fw_config_validate(&c, err, sizeof err), 0);
}

// Keys of the removed ranked pairs (and the hold past the obstacle) are refused with why and the
// fix, in a file and on the command line alike, and change nothing; an unknown key still gets the
// nearest-key suggestion.
static void test_config_retired_pair_keys_refused(void** state) {
  (void)state;
  fw_config_t c;
  fw_config_defaults(&c);
  const fw_config_t before = c;
  char err[FW_CONFIG_ERR_MAX];
  const char* const retired[] = {"pair_runs", "pair_shift_rate", "pair_safety", "pair_shift_vet",
                                 "obstacle_pass_hold_steps", "pair_phase_one_from_run"};
  for (size_t i = 0; i < sizeof retired / sizeof retired[0]; ++i) {
    assert_int_equal(fw_config_set(&c, retired[i], "true", "robot.conf:3", err, sizeof err), -1);
    assert_non_null(strstr(err, "robot.conf:3: key '"));
    assert_non_null(strstr(err, retired[i]));
    assert_non_null(strstr(err, "no longer exists"));
    assert_non_null(strstr(err, "delete the line"));
    assert_false(fw_config_has_key(retired[i]));
  }
  assert_int_equal(fw_config_set_arg(&c, "pair_runs=false", err, sizeof err), -1);
  assert_non_null(strstr(err, "--set: key 'pair_runs' no longer exists"));
  assert_memory_equal(&c, &before, offsetof(fw_config_t, origins));
  assert_int_equal(fw_config_set(&c, "pair_rnus", "true", "--set", err, sizeof err), -1);
  assert_non_null(strstr(err, "unknown key 'pair_rnus'"));
}

// The program refuses joystick driving where no operator can drive: in lockstep, and with LCM
// off; the message names both keys and where they were set. In-process users (fw_config_validate)
// may still combine them (their tests post B21R_TELEOP themselves).
static void test_config_program_refuses_joystick_without_operator(void** state) {
  (void)state;
  fw_config_t c;
  char err[FW_CONFIG_ERR_MAX];
  fw_config_defaults(&c);
  assert_int_equal(fw_config_set(&c, "operator_key_file", "/etc/b21r/operator.key", "robot.conf:2", err, sizeof err), 0);
  assert_int_equal(fw_config_set(&c, "phase_one_driver", "joystick", "robot.conf:7", err, sizeof err), 0);
  assert_int_equal(fw_config_set_arg(&c, "lockstep=true", err, sizeof err), 0);
  assert_int_equal(fw_config_validate(&c, err, sizeof err), 0);
  assert_int_equal(fw_config_validate_program(&c, err, sizeof err), -1);
  assert_non_null(strstr(err, "robot.conf:7: phase_one_driver = joystick"));
  assert_non_null(strstr(err, "lockstep = true (set at --set)"));
  c.lockstep = false;
  assert_int_equal(fw_config_validate_program(&c, err, sizeof err), 0);
  assert_int_equal(fw_config_set_arg(&c, "lcm_url=none", err, sizeof err), 0);
  assert_int_equal(fw_config_validate_program(&c, err, sizeof err), -1);
  assert_non_null(strstr(err, "phase_one_driver = joystick"));
  assert_non_null(strstr(err, "lcm_url = none (set at --set)"));
  // Without the joystick, both are fine; evaluation never drives by joystick.
  c.phase_driver = FW_DRIVER_EXAMPLE;
  c.lockstep = true;
  assert_int_equal(fw_config_validate_program(&c, err, sizeof err), 0);
  c.phase_driver = FW_DRIVER_JOYSTICK;
  c.mode = FW_MODE_EVALUATE;
  assert_int_equal(fw_config_validate_program(&c, err, sizeof err), 0);
  // The ordinary checks come first.
  c.queue_capacity = 1000;
  assert_int_equal(fw_config_validate_program(&c, err, sizeof err), -1);
  assert_non_null(strstr(err, "power of two"));
}

// What only the operator can say (CONFIRM_START_POSE with reposition = operator, joystick driving,
// START_PHASE_TWO with phase_switch = operator) is taken only signed with the operator key: without
// operator_key_file such a configuration is refused, naming the key that waits for the operator,
// operator_key_file and how to make a key. With LCM off, or nothing to wait for, no key is needed.
// lcm_scope takes host (the default) or network.
static void test_config_program_needs_operator_key(void** state) {
  (void)state;
  fw_config_t c;
  char err[FW_CONFIG_ERR_MAX];
  fw_config_defaults(&c);
  assert_int_equal(c.lcm_scope, FW_LCM_SCOPE_HOST);
  assert_string_equal(c.operator_key_file, "");
  assert_int_equal(fw_config_validate(&c, err, sizeof err), 0);
  assert_int_equal(fw_config_validate_program(&c, err, sizeof err), -1);
  assert_non_null(strstr(err, "default: reposition = operator waits for the operator's CONFIRM_START_POSE"));
  assert_non_null(strstr(err, "operator_key_file is not set"));
  assert_non_null(strstr(err, "tools/b21r_key.py create"));
  fw_config_t robot = c;
  assert_int_equal(fw_config_set(&robot, "operator_key_file", "/etc/b21r/operator.key", "robot.conf:2", err,
                                 sizeof err), 0);
  assert_int_equal(fw_config_validate_program(&robot, err, sizeof err), 0);
  fw_config_t quiet = c;
  assert_int_equal(fw_config_set_arg(&quiet, "lcm_url=none", err, sizeof err), 0);
  assert_int_equal(fw_config_validate_program(&quiet, err, sizeof err), 0);
  // In the emulator the example driver needs nothing of the operator ...
  assert_int_equal(fw_config_set(&c, "reposition", "emulator", "--set", err, sizeof err), 0);
  assert_int_equal(fw_config_set(&c, "emulator_control", "/tmp/sim.sock", "--set", err, sizeof err), 0);
  assert_int_equal(fw_config_validate_program(&c, err, sizeof err), 0);
  // ... the joystick and the operator's phase switch do.
  fw_config_t joystick = c;
  assert_int_equal(fw_config_set(&joystick, "phase_one_driver", "joystick", "robot.conf:7", err, sizeof err), 0);
  assert_int_equal(fw_config_validate_program(&joystick, err, sizeof err), -1);
  assert_non_null(strstr(err, "robot.conf:7: phase_one_driver = joystick drives with the operator's B21R_TELEOP"));
  fw_config_t switched = c;
  assert_int_equal(fw_config_set(&switched, "phase_switch", "operator", "robot.conf:8", err, sizeof err), 0);
  assert_int_equal(fw_config_validate_program(&switched, err, sizeof err), -1);
  assert_non_null(strstr(err, "robot.conf:8: phase_switch = operator waits for the operator's START_PHASE_TWO"));
  assert_int_equal(fw_config_set(&switched, "operator_key_file", "k", "--set", err, sizeof err), 0);
  assert_int_equal(fw_config_validate_program(&switched, err, sizeof err), 0);
  assert_int_equal(fw_config_set(&c, "lcm_scope", "network", "--set", err, sizeof err), 0);
  assert_int_equal(c.lcm_scope, FW_LCM_SCOPE_NETWORK);
  assert_int_equal(fw_config_set(&c, "lcm_scope", "world", "--set", err, sizeof err), -1);
  assert_non_null(strstr(err, "lcm_scope"));
}

// Every cross-key error starts with the file and line (or option) of the offending key and
// names where the other key involved was set, whichever source set it.
static void test_config_validate_errors_carry_file_and_line(void** state) {
  (void)state;
  static const struct {
    const char* file_text;  // written to robot.conf
    const char* set_arg;    // then applied with --set (NULL: none)
    const char* want[2];    // substrings of the error
  } cases[] = {
      {"# robot\nalpha = 0.3\nhedger_k_min = 40\nhedger_k_max = 32\n", NULL, {"robot.conf:3: hedger_k_min (40)", "robot.conf:4)"}},
      {"hedger_k_max = 4\n", "hedger_k_min=5", {"--set: hedger_k_min (5)", "robot.conf:1)"}},
      {"\nlaser_resolution_deg = 0.25\n", NULL, {"robot.conf:2: laser_resolution_deg = 0.25", "(set at default;"}},
      {"task = obstacles\nstate_rotation = false\n", "hedger_input_scale=1,2,3,4", {"--set: hedger_input_scale has 4 values", "robot.conf:1) needs 6"}},
      {"alpha = 0.2\n", "hedger_input_scale=1,2,3,4", {"--set: hedger_input_scale has 4 values", "needs 5 (state dimensions, the last one the executed rotation"}},
      {"seed = 2\nreposition = emulator\n", NULL, {"robot.conf:2: reposition = emulator needs emulator_control", NULL}},
      {"queue_capacity = 1000\n", NULL, {"robot.conf:1: queue_capacity = 1000", NULL}},
      {"\nhedger_greedy_reach = 0.5\n", NULL, {"robot.conf:2: hedger_greedy_reach = 0.5 must be 0", NULL}},
      {"phase_one_runs = 0\nphase_two_runs = 0\n", NULL, {"robot.conf:1: phase_one_runs", "robot.conf:2): nothing to learn"}},
      {"phase_switch = auto\nphase_one_runs = 3\n", NULL, {"default: auto_switch_min_runs (5)", "robot.conf:2), the latest switch"}},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
    fw_config_t c;
    fw_config_defaults(&c);
    char err[FW_CONFIG_ERR_MAX];
    const char* p = write_tmp("robot.conf", cases[i].file_text);
    assert_int_equal(fw_config_load_file(&c, p, err, sizeof err), 0);
    if (cases[i].set_arg != NULL) {
      assert_int_equal(fw_config_set_arg(&c, cases[i].set_arg, err, sizeof err), 0);
    }
    assert_int_equal(fw_config_validate(&c, err, sizeof err), -1);
    for (int j = 0; j < 2; ++j) {
      if (cases[i].want[j] != NULL && strstr(err, cases[i].want[j]) == NULL) {
        fail_msg("case %zu: expected \"%s\" in: %s", i, cases[i].want[j], err);
      }
    }
  }
  // The second file's keys are named by that file; the first file's keys keep theirs.
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  char where[FW_CONFIG_STR_MAX + 16];
  assert_int_equal(fw_config_load_file(&c, write_tmp("a.conf", "alpha = 0.3\nseed = 4\n"), err, sizeof err), 0);
  assert_int_equal(fw_config_load_file(&c, write_tmp("b.conf", "\n\nseed = 5\n"), err, sizeof err), 0);
  fw_config_origin(&c, "alpha", where, sizeof where);
  assert_non_null(strstr(where, "a.conf:1"));
  fw_config_origin(&c, "seed", where, sizeof where);
  assert_non_null(strstr(where, "b.conf:3"));
  fw_config_origin(&c, "gamma", where, sizeof where);
  assert_string_equal(where, "default");
  fw_config_origin(&c, "no_such_key", where, sizeof where);
  assert_string_equal(where, "unknown key");
}

// The generated reference parses back to exactly the defaults, and the checked-in reference
// file is byte for byte that generated text (so documentation and code cannot drift apart).
static void test_config_reference_file_matches_defaults(void** state) {
  (void)state;
  char gen_path[512];
  snprintf(gen_path, sizeof gen_path, "%s/generated.conf", g_dir);
  FILE* f = fopen(gen_path, "w");
  assert_non_null(f);
  fw_config_print_reference(f);
  fclose(f);
  fw_config_t a;
  fw_config_t d;
  fw_config_defaults(&d);
  memset(&a, 0x5A, sizeof a);
  fw_config_defaults(&a);
  a.alpha = 0.9;
  a.lockstep = true;
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_config_load_file(&a, gen_path, err, sizeof err), 0);
  assert_memory_equal(&a, &d, offsetof(fw_config_t, origins));  // settings only, not their origins

  // The printed current values parse back to the same struct too.
  char cur_path[512];
  snprintf(cur_path, sizeof cur_path, "%s/current.conf", g_dir);
  fw_config_t b;
  fw_config_defaults(&b);
  b.alpha = 0.125;
  strcpy(b.log_file, "x y");
  f = fopen(cur_path, "w");
  assert_non_null(f);
  fw_config_print(&b, f);
  fclose(f);
  fw_config_t b2;
  fw_config_defaults(&b2);
  assert_int_equal(fw_config_load_file(&b2, cur_path, err, sizeof err), 0);
  assert_memory_equal(&b, &b2, offsetof(fw_config_t, origins));

  if (g_reference_path != NULL) {
    char cmd[1200];
    snprintf(cmd, sizeof cmd, "cmp -s '%s' '%s'", gen_path, g_reference_path);
    if (system(cmd) != 0) {
      fail_msg("%s differs from the generated reference: regenerate it with "
               "`b21r-controller --print-reference-config > %s`",
               g_reference_path, g_reference_path);
    }
  }
}

// Parsing and validation allocate only what stdio needs (no hidden growth per key).
// Tools extend the format with keys of their own: the handler sees only keys the controller does
// not know; it may take them, pass (then: unknown key) or refuse a value; each key once per file.
typedef struct extra_seen {
  int taken;
  char last[64];
} extra_seen_t;

static int extra_handler(void* user, const char* key, const char* value, const char* source, char* err,
                         size_t err_cap) {
  extra_seen_t* x = (extra_seen_t*)user;
  if (strncmp(key, "tool.", 5) != 0) {
    return 1;
  }
  if (strcmp(value, "bad") == 0) {
    snprintf(err, err_cap, "%s: bad value '%s' for key '%s'", source, value, key);
    return -1;
  }
  x->taken++;
  snprintf(x->last, sizeof x->last, "%s=%s", key, value);
  return 0;
}

static void test_config_extra_keys_go_to_the_handler(void** state) {
  (void)state;
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  extra_seen_t x = {0, ""};
  const char* p = write_tmp("x.conf", "tool.kind = sweep\nseed = 9\ncorridor_length_m = 15\ntool.n = 3\n");
  assert_int_equal(fw_config_load_file_with(&c, p, extra_handler, &x, err, sizeof err), 0);
  assert_int_equal(x.taken, 2);
  assert_string_equal(x.last, "tool.n=3");
  assert_true(c.seed == 9U && c.corridor_length_m == 15.0);
  x.taken = 0;
  assert_int_equal(fw_config_load_file_with(&c, write_tmp("y.conf", "tool.a = 1\ntool.a = 2\n"), extra_handler, &x,
                                            err, sizeof err), -1);
  assert_non_null(strstr(err, "y.conf:2"));
  assert_non_null(strstr(err, "appears twice"));
  assert_int_equal(fw_config_load_file_with(&c, write_tmp("z.conf", "tool.a = bad\n"), extra_handler, &x, err,
                                            sizeof err), -1);
  assert_non_null(strstr(err, "z.conf:1"));
  assert_int_equal(fw_config_load_file_with(&c, write_tmp("w.conf", "other.a = 1\n"), extra_handler, &x, err,
                                            sizeof err), -1);
  assert_non_null(strstr(err, "unknown key 'other.a'"));
  // Without a handler the tool's keys are unknown keys.
  assert_int_equal(fw_config_load_file(&c, write_tmp("v.conf", "tool.a = 1\n"), err, sizeof err), -1);
  assert_true(fw_config_has_key("corridor_length_m"));
  assert_false(fw_config_has_key("tool.a"));
  // The corridor length has a documented range.
  assert_int_equal(fw_config_set(&c, "corridor_length_m", "3", "--set", err, sizeof err), -1);
  assert_non_null(strstr(err, "[4, 200]"));
}

static void test_config_set_allocates_nothing(void** state) {
  (void)state;
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  alloc_counter_begin();
  for (int i = 0; i < 1000; ++i) {
    (void)fw_config_set(&c, "alpha", "0.3", "s", err, sizeof err);
    (void)fw_config_set(&c, "alpha", "bad", "s", err, sizeof err);
  }
  assert_int_equal(alloc_counter_end(), 0);
}

// learner: hedger by default; lwa and tabular accepted, anything else refused with the choices;
// the tabular learner's table keys have ranges; tabular with a checkpoint file is refused by
// validation, naming both keys and the fix.
static void test_config_learner_key(void** state) {
  (void)state;
  fw_config_t c;
  char err[512];
  fw_config_defaults(&c);
  assert_int_equal(c.learner, FW_LEARNER_HEDGER);
  assert_int_equal(c.tabular_bins, 10);
  assert_int_equal(c.tabular_actions, 9);
  assert_int_equal(fw_config_set(&c, "learner", "lwa", "s", err, sizeof err), 0);
  assert_int_equal(c.learner, FW_LEARNER_LWA);
  assert_int_equal(fw_config_set(&c, "learner", "tabular", "s", err, sizeof err), 0);
  assert_int_equal(c.learner, FW_LEARNER_TABULAR);
  assert_int_equal(fw_config_set(&c, "learner", "lwr", "x.conf:2", err, sizeof err), -1);
  assert_non_null(strstr(err, "x.conf:2"));
  assert_non_null(strstr(err, "tabular"));
  assert_int_equal(fw_config_set(&c, "tabular_bins", "0", "s", err, sizeof err), -1);
  assert_int_equal(fw_config_set(&c, "tabular_actions", "1", "s", err, sizeof err), -1);
  assert_int_equal(fw_config_validate(&c, err, sizeof err), 0);
  assert_int_equal(fw_config_set(&c, "checkpoint_file", "/tmp/q.ckpt", "b.conf:7", err, sizeof err), 0);
  assert_int_equal(fw_config_validate(&c, err, sizeof err), -1);
  assert_non_null(strstr(err, "learner = tabular cannot checkpoint"));
  assert_non_null(strstr(err, "b.conf:7"));
  assert_int_equal(fw_config_set(&c, "learner", "lwa", "s", err, sizeof err), 0);
  assert_int_equal(fw_config_validate(&c, err, sizeof err), 0);
}

// fw_task_name: the task key's own names, and "unknown" for a value no configuration can hold
// (a log's task byte written by something else).
static void test_config_task_name(void** state) {
  (void)state;
  assert_string_equal(fw_task_name((int32_t)tasks_corridor_decl.id), "corridor");
  assert_string_equal(fw_task_name((int32_t)tasks_obstacles_decl.id), "obstacles");
  assert_string_equal(fw_task_name((int32_t)tasks_doorway_decl.id), "doorway");
  assert_null(tasks_by_id(200));  // no task declares it
  assert_string_equal(fw_task_name(200), "unknown");
  assert_string_equal(fw_task_name(-1), "unknown");
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_config_set(&c, "task", fw_task_name((int32_t)tasks_obstacles_decl.id), "test", err, sizeof err), 0);
  assert_int_equal(c.task, (int32_t)tasks_obstacles_decl.id);
}

// task_params: the task's own parameters by name, checked against the declared task (at validate,
// so the order of task and task_params does not matter) with errors naming the fix; applied by
// fw_config_task; corridor_length_m is the corridor's length_m.
static void test_config_task_params(void** state) {
  (void)state;
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_config_set(&c, "task_params", " width_m = 3 ,goal_reward=5", "test", err, sizeof err), 0);
  assert_int_equal(fw_config_validate(&c, err, sizeof err), 0);
  tasks_episode_t ep;
  tasks_command_limits_t lim;
  assert_int_equal(fw_config_task(&c, &ep, &lim, err, sizeof err), 0);
  assert_ptr_equal(ep.decl, &tasks_corridor_decl);
  assert_true(tasks_spec_get_param(ep.decl, tasks_episode_spec_const(&ep), "width_m") == 3.0);
  assert_true(tasks_spec_get_param(ep.decl, tasks_episode_spec_const(&ep), "goal_reward") == 5.0);
  assert_true(tasks_spec_get_param(ep.decl, tasks_episode_spec_const(&ep), "length_m") == c.corridor_length_m);
  // task_params wins over corridor_length_m (it is the more specific setting).
  assert_int_equal(fw_config_set(&c, "task_params", "length_m=20", "test", err, sizeof err), 0);
  assert_int_equal(fw_config_task(&c, &ep, &lim, err, sizeof err), 0);
  assert_true(tasks_spec_get_param(ep.decl, tasks_episode_spec_const(&ep), "length_m") == 20.0);

  // A parameter of another task: the message names the task, where it was set and the choices.
  assert_int_equal(fw_config_set(&c, "task", "obstacles", "a.conf:3", err, sizeof err), 0);
  assert_int_equal(fw_config_validate(&c, err, sizeof err), -1);
  assert_non_null(strstr(err, "task obstacles (set at a.conf:3) has no parameter 'length_m'"));
  assert_non_null(strstr(err, "goal_radius_m"));
  assert_int_equal(fw_config_task(&c, &ep, &lim, err, sizeof err), -1);
  // Out of range: the range and the parameter's help.
  assert_int_equal(fw_config_set(&c, "task_params", "goal_radius_m=9", "test", err, sizeof err), 0);
  assert_int_equal(fw_config_validate(&c, err, sizeof err), -1);
  assert_non_null(strstr(err, "goal_radius_m = '9', expected a number in [0.05, 5]"));
  assert_int_equal(fw_config_set(&c, "task_params", "goal_radius_m=abc", "test", err, sizeof err), 0);
  assert_int_equal(fw_config_validate(&c, err, sizeof err), -1);
  assert_int_equal(fw_config_set(&c, "task_params", "goal_radius_m", "test", err, sizeof err), 0);
  assert_int_equal(fw_config_validate(&c, err, sizeof err), -1);
  assert_non_null(strstr(err, "expected name=value"));
  assert_int_equal(fw_config_set(&c, "task_params", "goal_radius_m=0.5,v_mps=0.4", "test", err, sizeof err), 0);
  assert_int_equal(fw_config_validate(&c, err, sizeof err), 0);
  assert_int_equal(fw_config_task(&c, &ep, &lim, err, sizeof err), 0);
  assert_ptr_equal(ep.decl, &tasks_obstacles_decl);
  assert_true(tasks_spec_get_param(ep.decl, tasks_episode_spec_const(&ep), "v_mps") == 0.4);
}

// eval_poses: the evaluation blocks' own poses; fewer than eval_starts is refused naming both
// keys; bad syntax names the expected form; fw_config_task gives them to the episode.
static void test_config_eval_poses(void** state) {
  (void)state;
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_config_set(&c, "eval_poses", "1,0.5,0.1; 2,-0.5,-0.1", "b.conf:7", err, sizeof err), 0);
  assert_int_equal(c.eval_poses_n, 2);
  assert_int_equal(fw_config_validate(&c, err, sizeof err), -1);
  assert_non_null(strstr(err, "b.conf:7: eval_poses gives 2 poses, but eval_starts"));
  assert_int_equal(fw_config_set(&c, "eval_starts", "2", "test", err, sizeof err), 0);
  assert_int_equal(fw_config_validate(&c, err, sizeof err), 0);
  tasks_episode_t ep;
  assert_int_equal(fw_config_task(&c, &ep, NULL, err, sizeof err), 0);
  assert_int_equal(tasks_episode_n_eval_starts(&ep), 2);
  const features_pose_t p1 = tasks_episode_eval_start(&ep, 1);
  assert_true(p1.x_m == 2.0 && p1.y_m == -0.5 && p1.theta_rad == -0.1);
  const char* bad[] = {"1,2", "1,2,3;", "a,b,c", "1,2,nan", "1,2,3,4",
                       "0,0,0;0,0,0;0,0,0;0,0,0;0,0,0;0,0,0;0,0,0;0,0,0;0,0,0;0,0,0;0,0,0;0,0,0;0,0,0;0,0,0;0,0,0;0,0,0;0,0,0"};
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; ++i) {
    fw_config_t d = c;
    assert_int_equal(fw_config_set(&d, "eval_poses", bad[i], "test", err, sizeof err), -1);
    assert_non_null(strstr(err, "eval_poses"));
    assert_int_equal(d.eval_poses_n, 2);  // nothing changed
  }
  // Round trip through the file format; "" restores the task's own poses.
  char buf[4096];
  FILE* f = fmemopen(buf, sizeof buf, "w");
  fw_config_print(&c, f);
  fclose(f);
  assert_non_null(strstr(buf, "eval_poses = \"1,0.5,0.1; 2,-0.5,-0.1\""));
  assert_int_equal(fw_config_set(&c, "eval_poses", "", "test", err, sizeof err), 0);
  assert_int_equal(c.eval_poses_n, 0);
  assert_int_equal(fw_config_task(&c, &ep, NULL, err, sizeof err), 0);
  assert_int_equal(tasks_episode_n_eval_starts(&ep), TASKS_N_EVAL_STARTS);
}

int main(int argc, char** argv) {
  g_reference_path = argc > 1 ? argv[1] : NULL;
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_config_defaults_are_paper_settings_and_valid),
      cmocka_unit_test(test_config_unknown_key_names_file_line_and_key),
      cmocka_unit_test(test_config_unknown_key_suggests_nearest),
      cmocka_unit_test(test_config_out_of_range_names_allowed_range),
      cmocka_unit_test(test_config_bad_values_refused_with_choices),
      cmocka_unit_test(test_config_bool_accepts_exactly_true_or_false),
      cmocka_unit_test(test_config_realtime_keys_parse_and_print),
      cmocka_unit_test(test_config_syntax_errors_name_line),
      cmocka_unit_test(test_config_comments_quotes_and_crlf_parse),
      cmocka_unit_test(test_config_set_arg_overrides_and_errors),
      cmocka_unit_test(test_config_validate_cross_key_rules),
      cmocka_unit_test(test_config_validate_errors_carry_file_and_line),
      cmocka_unit_test(test_config_strings_round_trip_through_print),
      cmocka_unit_test(test_config_reference_file_matches_defaults),
      cmocka_unit_test(test_config_extra_keys_go_to_the_handler),
      cmocka_unit_test(test_config_set_allocates_nothing),
      cmocka_unit_test(test_config_retired_pair_keys_refused),
      cmocka_unit_test(test_config_program_refuses_joystick_without_operator),
      cmocka_unit_test(test_config_program_needs_operator_key),
      cmocka_unit_test(test_config_learner_key),
      cmocka_unit_test(test_config_task_name),
      cmocka_unit_test(test_config_task_params),
      cmocka_unit_test(test_config_eval_poses),
  };
  return cmocka_run_group_tests_name("firmware.config", tests, setup, teardown);
}
