// SPDX-License-Identifier: MIT
// Every LCM type survives encode -> decode -> encode bit for bit, and its fields come back equal.
// With a directory argument, the encoded bytes are also written there (<type>.bin) for the
// Python and Java round-trip tests, which decode them and check the same field values.
#include <b21r/b21r_command_t.h>
#include <b21r/b21r_command_v1_t.h>
#include <b21r/b21r_eval_t.h>
#include <b21r/b21r_experience_t.h>
#include <b21r/b21r_pose_t.h>
#include <b21r/b21r_scan_t.h>
#include <b21r/b21r_status_t.h>
#include <b21r/b21r_session_t.h>
#include <b21r/b21r_teleop_t.h>
#include <b21r/b21r_teleop_v1_t.h>
#include <b21r_test/alloc_counter.h>

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

static const char* g_golden_dir;
static uint8_t g_buf_a[8192];
static uint8_t g_buf_b[8192];

static void write_golden(const char* name, const uint8_t* data, int size) {
  if (g_golden_dir == NULL) {
    return;
  }
  char path[1024];
  snprintf(path, sizeof path, "%s/%s.bin", g_golden_dir, name);
  FILE* f = fopen(path, "wb");
  assert_non_null(f);
  assert_int_equal(fwrite(data, 1, (size_t)size, f), (size_t)size);
  assert_int_equal(fclose(f), 0);
}

// Encodes msg, decodes it into out, re-encodes and checks byte equality. For fixed-size types
// (the ones the firmware decodes) a truncated buffer must also be refused without reading past it.
// (lcm-gen's decoders leak a partly decoded string on failure, so string types skip that check.)
#define ROUND_TRIP(type, msg, out) ROUND_TRIP_CHECKED(type, msg, out, 1)
#define ROUND_TRIP_VARIABLE(type, msg, out) ROUND_TRIP_CHECKED(type, msg, out, 0)
#define ROUND_TRIP_CHECKED(type, msg, out, check_truncated)                                               \
  do {                                                                           \
    const int size_ = type##_encoded_size(&(msg));                               \
    assert_true(size_ > 0 && size_ <= (int)sizeof g_buf_a);                      \
    assert_int_equal(type##_encode(g_buf_a, 0, size_, &(msg)), size_);           \
    assert_int_equal(type##_decode(g_buf_a, 0, size_, &(out)), size_);          \
    assert_int_equal(type##_encode(g_buf_b, 0, size_, &(out)), size_);           \
    assert_memory_equal(g_buf_a, g_buf_b, (size_t)size_);                        \
    if (check_truncated) {                                                       \
      type out_short_;                                                           \
      assert_true(type##_decode(g_buf_a, 0, size_ - 1, &out_short_) < 0);        \
    }                                                                            \
    write_golden(#type, g_buf_a, size_);                                         \
  } while (0)

// experience_t: all fixed-size fields, the stream the learner and lcm-logger see.
static void test_msgs_experience_round_trip_equal(void** state) {
  (void)state;
  b21r_experience_t m;
  memset(&m, 0, sizeof m);
  m.utime = 1234567890123LL;
  m.seq = 42;
  m.run_id = 7;
  m.step_id = 99;
  m.task = B21R_EXPERIENCE_T_TASK_CORRIDOR;
  m.phase = 2;
  m.source = B21R_EXPERIENCE_T_SOURCE_EXPLORATION;
  m.evaluating = 1;
  m.state_dim = 3;
  for (int i = 0; i < B21R_EXPERIENCE_T_MAX_STATE_DIM; ++i) {
    m.s[i] = 0.125 * (i + 1);
    m.s_next[i] = -0.5 * (i + 1);
  }
  m.action_radps = -0.75;
  m.translation_mps = 0.5;
  m.reward = 10.0;
  m.terminal = 1;
  m.q_value = 3.25;
  m.q_kind = 1;
  b21r_experience_t out;
  ROUND_TRIP(b21r_experience_t, m, out);
  assert_int_equal(out.seq, 42);
  assert_int_equal(out.run_id, 7);
  assert_int_equal(out.source, B21R_EXPERIENCE_T_SOURCE_EXPLORATION);
  assert_memory_equal(out.s, m.s, sizeof m.s);
  assert_memory_equal(out.s_next, m.s_next, sizeof m.s_next);
  assert_true(out.reward == 10.0 && out.terminal == 1 && out.action_radps == -0.75);
}

// teleop_t is decoded by the firmware: decoding must not allocate.
static void test_msgs_teleop_round_trip_no_allocation(void** state) {
  (void)state;
  b21r_teleop_t m = {.utime = 5, .seq = 6, .deadman = 1, .rotation_radps = 0.3, .translation_mps = 0.4};
  for (int i = 0; i < 8; ++i) {
    m.key_id[i] = (uint8_t)(0xA0 + i);
  }
  for (int i = 0; i < 16; ++i) {
    m.session[i] = (uint8_t)(0xB0 + i);
  }
  for (int i = 0; i < 32; ++i) {
    m.mac[i] = (uint8_t)(0xC0 + i);
  }
  b21r_teleop_t out;
  alloc_counter_begin();
  ROUND_TRIP(b21r_teleop_t, m, out);
  assert_int_equal(alloc_counter_end(), 0);
  assert_true(out.deadman == 1 && out.rotation_radps == 0.3 && out.translation_mps == 0.4);
  assert_int_equal(out.seq, 6);
  assert_memory_equal(out.key_id, m.key_id, 8);
  assert_memory_equal(out.session, m.session, 16);
  assert_memory_equal(out.mac, m.mac, 32);
}

// command_t is decoded by the firmware: decoding must not allocate.
static void test_msgs_command_round_trip_no_allocation(void** state) {
  (void)state;
  b21r_command_t m = {.utime = 9, .seq = 10, .command = B21R_COMMAND_T_CONFIRM_START_POSE, .argument = 3};
  m.mac[31] = 0x7F;
  b21r_command_t out;
  alloc_counter_begin();
  ROUND_TRIP(b21r_command_t, m, out);
  assert_int_equal(alloc_counter_end(), 0);
  assert_int_equal(out.command, B21R_COMMAND_T_CONFIRM_START_POSE);
  assert_int_equal(out.argument, 3);
  assert_int_equal(out.mac[31], 0x7F);
}

// session_t: fixed-size, decoded by the operator tools.
static void test_msgs_session_round_trip_equal(void** state) {
  (void)state;
  b21r_session_t m = {.utime = 11, .started_us = 1700000000000000LL};
  m.nonce[0] = 0x42;
  m.key_id[7] = 0x17;
  m.mac[0] = 0x99;
  b21r_session_t out;
  ROUND_TRIP(b21r_session_t, m, out);
  assert_true(out.started_us == 1700000000000000LL && out.nonce[0] == 0x42 && out.mac[0] == 0x99);
}

// The old unauthenticated types keep the fingerprints of the B21R_TELEOP and B21R_COMMAND they
// were (LCM leaves a type's name out of its fingerprint), so that old recordings decode with them.
static void test_msgs_v1_types_keep_the_old_fingerprints(void** state) {
  (void)state;
  const b21r_teleop_v1_t t = {.utime = 1, .seq = 2, .deadman = 1, .rotation_radps = 0.5};
  b21r_teleop_v1_t tout;
  ROUND_TRIP(b21r_teleop_v1_t, t, tout);
  static const uint8_t teleop_v1[8] = {0x7c, 0xc1, 0xb7, 0x37, 0x0d, 0xf2, 0x0b, 0xb8};
  assert_memory_equal(g_buf_a, teleop_v1, 8);
  const b21r_command_v1_t c = {.utime = 1, .seq = 2, .command = B21R_COMMAND_T_SHUTDOWN};
  b21r_command_v1_t cout;
  ROUND_TRIP(b21r_command_v1_t, c, cout);
  static const uint8_t command_v1[8] = {0x36, 0x52, 0x04, 0x48, 0x19, 0xc4, 0x0f, 0x11};
  assert_memory_equal(g_buf_a, command_v1, 8);
  // ... and neither decodes as the authenticated type, nor the other way round.
  b21r_teleop_t now;
  assert_true(b21r_teleop_t_decode(g_buf_a, 0, (int)sizeof g_buf_a, &now) < 0);
}

static void test_msgs_pose_round_trip_equal(void** state) {
  (void)state;
  b21r_pose_t m = {.utime = 1, .run_id = 2, .step_id = 3, .x_m = 1.5, .y_m = -2.25, .theta_rad = 3.0,
                   .translation_mps = 0.5, .rotation_radps = -0.1};
  b21r_pose_t out;
  ROUND_TRIP(b21r_pose_t, m, out);
  assert_memory_equal(&out, &m, sizeof m);
}

static void test_msgs_eval_round_trip_equal(void** state) {
  (void)state;
  b21r_eval_t m;
  memset(&m, 0, sizeof m);
  m.utime = 77;
  m.block = 4;
  m.training_runs = 20;
  m.phase = 1;
  m.task = B21R_EXPERIENCE_T_TASK_OBSTACLES;
  m.n_starts = 10;
  for (int i = 0; i < B21R_EVAL_T_MAX_STARTS; ++i) {
    m.steps[i] = 100 + i;
    m.success[i] = (int8_t)(i % 2);
  }
  m.successes = 8;
  m.mean_steps = 104.5;
  m.ci95_halfwidth = 2.5;
  b21r_eval_t out;
  ROUND_TRIP(b21r_eval_t, m, out);
  assert_memory_equal(out.steps, m.steps, sizeof m.steps);
  assert_memory_equal(out.success, m.success, sizeof m.success);
  assert_true(out.mean_steps == 104.5 && out.ci95_halfwidth == 2.5);
}

static void test_msgs_status_round_trip_equal(void** state) {
  (void)state;
  b21r_status_t m;
  memset(&m, 0, sizeof m);
  char detail[] = "laser silent for 0.35 s";
  m.utime = 11;
  m.phase = 1;
  m.mode = B21R_STATUS_T_MODE_STOPPED;
  m.stop_reason = B21R_STATUS_T_STOP_LASER_SILENT;
  m.stop_detail = detail;
  m.tick_p99_us = 812;
  m.store_fill = 1000;
  m.store_capacity = 20000;
  m.hedger_lwr = 123456789012LL;
  m.safety_stops = 1;
  m.experiences_dropped = 3;
  m.battery_v = 24.5;
  b21r_status_t out;
  ROUND_TRIP_VARIABLE(b21r_status_t, m, out);
  assert_string_equal(out.stop_detail, detail);
  assert_int_equal(out.tick_p99_us, 812);
  assert_int_equal(out.hedger_lwr, 123456789012LL);
  assert_int_equal(out.experiences_dropped, 3);
  assert_true(out.battery_v == 24.5);
  b21r_status_t_decode_cleanup(&out);
}

static void test_msgs_scan_round_trip_equal(void** state) {
  (void)state;
  b21r_scan_t m;
  memset(&m, 0, sizeof m);
  m.utime = 3;
  m.angle_min_rad = -1.5707964f;
  m.angle_increment_rad = 0.017453292f;
  m.n_beams = 181;
  for (int i = 0; i < B21R_SCAN_T_MAX_BEAMS; ++i) {
    m.ranges_m[i] = (float)i * 0.01f;
    m.no_return_reason[i] = (int8_t)(i % 3);
  }
  b21r_scan_t out;
  ROUND_TRIP(b21r_scan_t, m, out);
  assert_memory_equal(out.ranges_m, m.ranges_m, sizeof m.ranges_m);
  assert_memory_equal(out.no_return_reason, m.no_return_reason, sizeof m.no_return_reason);
}

int main(int argc, char** argv) {
  g_golden_dir = argc > 1 ? argv[1] : NULL;
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_msgs_experience_round_trip_equal),
      cmocka_unit_test(test_msgs_teleop_round_trip_no_allocation),
      cmocka_unit_test(test_msgs_command_round_trip_no_allocation),
      cmocka_unit_test(test_msgs_session_round_trip_equal),
      cmocka_unit_test(test_msgs_v1_types_keep_the_old_fingerprints),
      cmocka_unit_test(test_msgs_pose_round_trip_equal),
      cmocka_unit_test(test_msgs_eval_round_trip_equal),
      cmocka_unit_test(test_msgs_status_round_trip_equal),
      cmocka_unit_test(test_msgs_scan_round_trip_equal),
  };
  return cmocka_run_group_tests_name("msgs.roundtrip_c", tests, NULL, NULL);
}
