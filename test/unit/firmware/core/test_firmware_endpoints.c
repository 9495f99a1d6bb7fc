// SPDX-License-Identifier: MIT
// --endpoints: the emulator's ready line (given directly or in a file) sets the device paths and
// the settings that go with them; every bad argument is refused by name and changes nothing.
#define _POSIX_C_SOURCE 200809L
#include "fw/endpoints.h"

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

static char g_file[64];

static int setup(void** state) {
  (void)state;
  snprintf(g_file, sizeof g_file, "/tmp/b21r-endpoints-XXXXXX");
  const int fd = mkstemp(g_file);
  if (fd < 0) {
    return -1;
  }
  close(fd);
  return 0;
}

static int teardown(void** state) {
  (void)state;
  return unlink(g_file);
}

static void write_file(const char* text) {
  FILE* f = fopen(g_file, "w");
  assert_non_null(f);
  fputs(text, f);
  fclose(f);
}

// The ready lines b21r-sim prints, for both bases, directly and through a file.
static void test_endpoints_ready_lines_apply(void** state) {
  (void)state;
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_endpoints_apply(&c, "laser=/dev/pts/5 base=/dev/pts/6 control=/tmp/b21r.ctl\n", err, sizeof err),
                   0);
  assert_string_equal(c.laser_device, "/dev/pts/5");
  assert_string_equal(c.base_device, "/dev/pts/6");
  assert_string_equal(c.emulator_control, "/tmp/b21r.ctl");
  assert_int_equal(c.base_protocol, FW_BASE_RFLEX);
  assert_int_equal(c.reposition, FW_REPOSITION_EMULATOR);
  assert_int_equal(c.base_write_gap_us, 0);
  fw_config_defaults(&c);
  write_file("laser=/dev/pts/7\tcan=/tmp/b21r.can  control=/tmp/c.ctl world=corridor10\nsecond line ignored\n");
  assert_int_equal(fw_endpoints_apply(&c, g_file, err, sizeof err), 0);
  assert_string_equal(c.laser_device, "/dev/pts/7");
  assert_string_equal(c.can_socket, "/tmp/b21r.can");
  assert_string_equal(c.base_device, "/dev/ttyS0");  // untouched
  assert_int_equal(c.base_protocol, FW_BASE_CANOPEN);
  // Words without '=' and unknown fields are ignored; a repeated field: the last one wins.
  fw_config_defaults(&c);
  assert_int_equal(fw_endpoints_apply_line(&c, "ready: laser=/a laser=/b speed=fast", err, sizeof err), 0);
  assert_string_equal(c.laser_device, "/b");
  assert_int_equal(c.reposition, FW_REPOSITION_OPERATOR);
}

static void expect_refused(const char* arg, bool is_file_text, const char* what) {
  fw_config_t c;
  fw_config_defaults(&c);
  const fw_config_t before = c;
  char err[FW_CONFIG_ERR_MAX];
  if (is_file_text) {
    write_file(arg);
    assert_int_equal(fw_endpoints_apply(&c, g_file, err, sizeof err), -1);
  } else {
    assert_int_equal(fw_endpoints_apply(&c, arg, err, sizeof err), -1);
  }
  if (strstr(err, what) == NULL) {
    fail_msg("'%s': message '%s' does not say '%s'", arg, err, what);
  }
  assert_memory_equal(&c, &before, sizeof c);
}

// Bad arguments: refused with the reason, the config unchanged even when fields before the bad
// one were fine.
static void test_endpoints_bad_arguments_refused(void** state) {
  (void)state;
  expect_refused("no-such-file", false, "neither a readable file nor");
  expect_refused("speed=1 world=x", false, "no laser=/base=/can=/control= fields");
  expect_refused("laser=/dev/pts/1 base=", false, "base= has no value");
  char long_line[600];
  memset(long_line, 'x', sizeof long_line);
  memcpy(long_line, "laser=/dev/pts/1 base=", 22);
  long_line[sizeof long_line - 1] = '\0';
  expect_refused(long_line, false, "longer than 255 characters");
  expect_refused("", true, "empty file");
  static char huge[1500];
  memset(huge, 'y', sizeof huge);
  memcpy(huge, "laser=/x ", 9);
  huge[sizeof huge - 1] = '\0';
  expect_refused(huge, true, "first line longer than 1023 characters");
  expect_refused("hello\n", true, "no laser=/base=/can=/control= fields");
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_endpoints_ready_lines_apply),
      cmocka_unit_test(test_endpoints_bad_arguments_refused),
  };
  return cmocka_run_group_tests_name("firmware.endpoints", tests, setup, teardown);
}
