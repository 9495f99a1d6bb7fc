// SPDX-License-Identifier: MIT
// tools.train_checkpoint: b21r-train's trainer (tools/train/train.h) and the hold past the
// obstacle in checkpoints. An --init whose obstacle shift moved resumes only with the hold it was
// learned with where its file records it (a refusal names the setting); a file that does not
// record it resumes under the configuration's hold and says so (init_pass_hold_unrecorded); the
// checkpoint the trainer writes records the configuration's hold with such a shift (a 104-byte
// controller section) and none for a shift that never moved (96 bytes).
#define _POSIX_C_SOURCE 200809L
#include "train.h"

#include <fw/checkpoint.h>
#include <fw/config.h>
#include <fw/loop.h>
#include <fw/progress.h>
#include <hedger/hedger.h>

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

static char g_dir[64];

static fw_config_t obstacle_config(int32_t hold_steps) {
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_config_set(&c, "task", "obstacles", "test", err, sizeof err), 0);
  c.obstacle_pass_hold_steps = hold_steps;
  return c;
}

// A checkpoint at path: an empty learned state of cfg's shape under an obstacle controller
// section with the shift's weight w (a = b = 0) and the hold recorded (>= 0) or not (-1).
static void write_init(const fw_config_t* cfg, const char* path, double imitation, int32_t recorded_hold) {
  hedger_config_t hc;
  fw_loop_learner_config(cfg, &hc);
  hedger_t* h = NULL;
  assert_int_equal(hedger_create(&h, &hc), HEDGER_OK);
  static uint8_t payload[1 << 16];
  size_t ps = 0;
  assert_int_equal(hedger_save(h, payload, sizeof payload, &ps), HEDGER_OK);
  hedger_destroy(h);
  fw_progress_t g;
  memset(&g, 0, sizeof g);
  g.task = FW_TASK_OBSTACLES;
  g.state_dim = hc.state_dim;
  g.schedule.phase = 2;
  g.schedule.training_runs = 40;
  g.schedule.phase_one_runs = 30;
  g.schedule.phase_two_runs = 10;
  g.run_id = 50;
  g.shift.imitation = imitation;
  g.shift.pairs = imitation != 0.0 ? 5U : 0U;
  g.pass_hold_recorded = recorded_hold >= 0;
  g.obstacle_pass_hold_steps = recorded_hold >= 0 ? recorded_hold : 0;
  uint8_t meta[FW_PROGRESS_BYTES];
  const size_t meta_n = fw_progress_encode(&g, meta);
  char err[FW_CHECKPOINT_ERR_MAX];
  assert_int_equal(fw_checkpoint_write(path, meta, meta_n, payload, ps, err, sizeof err), 0);
}

// The controller section of the checkpoint at path.
static size_t read_section(const char* path, fw_progress_t* out) {
  uint8_t meta[FW_PROGRESS_BYTES + 1];
  static uint8_t payload[1 << 20];
  size_t ms = 0;
  size_t ps = 0;
  char err[FW_CHECKPOINT_ERR_MAX];
  assert_int_equal(fw_checkpoint_read(path, meta, sizeof meta, &ms, payload, sizeof payload, &ps, err, sizeof err), 1);
  assert_int_equal(fw_progress_decode(meta, ms, out, NULL, 0), 0);
  return ms;
}

static void test_train_checkpoint_pass_hold(void** state) {
  (void)state;
  char init[128];
  char out[128];
  snprintf(init, sizeof init, "%s/init.ckpt", g_dir);
  snprintf(out, sizeof out, "%s/out.ckpt", g_dir);
  struct {
    int32_t recorded;    // the --init file's hold (-1: not recorded)
    double imitation;    // its shift's w
    int32_t configured;  // the trainer's obstacle_pass_hold_steps
    int expect;          // trainer_load_checkpoint's result
  } const cases[] = {
      {10, -0.5, 10, 0}, {6, -0.5, 10, -1}, {-1, -0.5, 10, 0}, {-1, -0.5, 4, 0}, {-1, 0.0, 10, 0}, {3, 0.0, 10, 0},
  };
  const train_options_t opt = {.progress = NULL, .progress_period_s = 1.0};
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
    const fw_config_t c = obstacle_config(cases[i].configured);
    write_init(&c, init, cases[i].imitation, cases[i].recorded);
    char err[TRAIN_ERR_MAX] = "";
    trainer_t* t = trainer_create(&c, &opt, err, sizeof err);
    assert_non_null(t);
    const int r = trainer_load_checkpoint(t, init, err, sizeof err);
    if (r != cases[i].expect) {
      fail_msg("case %zu: load gave %d (%s)", i, r, err);
    }
    if (r != 0) {
      char want[96];
      snprintf(want, sizeof want, "train with obstacle_pass_hold_steps = %d", (int)cases[i].recorded);
      if (strstr(err, want) == NULL || strstr(err, init) == NULL) {
        fail_msg("case %zu: '%s' does not say '%s'", i, err, want);
      }
      trainer_destroy(t);
      continue;
    }
    const bool moved = cases[i].imitation != 0.0;
    assert_int_equal(trainer_stats(t).init_pass_hold_unrecorded, moved && cases[i].recorded < 0);
    (void)unlink(out);
    assert_int_equal(trainer_write_checkpoint(t, out, false, err, sizeof err), 0);
    trainer_destroy(t);
    fw_progress_t g;
    const size_t ms = read_section(out, &g);
    if (ms != (moved ? FW_PROGRESS_BYTES : FW_PROGRESS_BYTES_BASE) || g.pass_hold_recorded != moved ||
        g.obstacle_pass_hold_steps != (moved ? cases[i].configured : 0) || g.shift.imitation != cases[i].imitation) {
      fail_msg("case %zu: wrote a %zu-byte section, hold %s %d, w %g", i, ms,
               g.pass_hold_recorded ? "recorded" : "not recorded", (int)g.obstacle_pass_hold_steps, g.shift.imitation);
    }
  }
  (void)unlink(out);
  (void)unlink(init);
}

static int setup(void** state) {
  (void)state;
  snprintf(g_dir, sizeof g_dir, "/tmp/b21r-train-ckpt-XXXXXX");
  return mkdtemp(g_dir) != NULL ? 0 : -1;
}

static int teardown(void** state) {
  (void)state;
  return rmdir(g_dir);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_train_checkpoint_pass_hold),
  };
  return cmocka_run_group_tests_name("tools.train_checkpoint", tests, setup, teardown);
}
