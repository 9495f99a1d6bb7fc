// SPDX-License-Identifier: MIT
// tools.train_checkpoint: b21r-train's trainer (tools/train/train.h) and checkpoints. An --init of
// today's format with an actor resumes silently with it; one without an actor (the greedy policy,
// revision 2, or revision 1: an older controller's section with a policy shift learned from
// ranked pairs) resumes with its values, the actor cloned from their stored points
// (init_actor_cloned), and says where its shift had moved (init_legacy_shift); with policy =
// greedy an actor in the --init is dropped (init_actor_dropped). The checkpoint the trainer writes
// is of today's format either way, in phase two, and holds the --init's learned values.
#define _POSIX_C_SOURCE 200809L
#include "train.h"

#include <tasks/decl.h>
#include <fw/checkpoint.h>
#include <fw/config.h>
#include <fw/config_task.h>
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

static fw_config_t obstacle_config(void) {
  fw_config_t c;
  fw_config_defaults(&c);
  char err[FW_CONFIG_ERR_MAX];
  assert_int_equal(fw_config_set(&c, "task", "obstacles", "test", err, sizeof err), 0);
  assert_int_equal(fw_config_set(&c, "policy", "actor", "test", err, sizeof err), 0);
  return c;
}

// A checkpoint at path: a learned state of cfg's shape with one point under an obstacle controller
// section in phase two, without an actor: of revision 3 with the greedy policy (legacy_a < 0), of
// revision 2 (legacy_a = -2) or of revision 1 with its shift's a = legacy_a.
static void write_init(const fw_config_t* cfg, const char* path, double legacy_a) {
  hedger_config_t hc;
  fw_config_hedger(cfg, &hc);
  hedger_t* h = NULL;
  assert_int_equal(hedger_create(&h, &hc), HEDGER_OK);
  // the obstacle task's state (goal, obstacle, the obstacle's age) and the executed rotation
  assert_int_equal(hc.state_dim, 6);
  const double s[6] = {0.1, 2.5, -0.3, 1.2, 0.5, 0.0};
  assert_int_equal(hedger_insert(h, s, 0.25, 0.5, 0U, NULL), HEDGER_OK);
  static uint8_t payload[1 << 16];
  size_t ps = 0;
  assert_int_equal(hedger_save(h, payload, sizeof payload, &ps), HEDGER_OK);
  hedger_destroy(h);
  fw_progress_t g;
  memset(&g, 0, sizeof g);
  g.task = (int32_t)tasks_obstacles_decl.id;
  g.state_dim = hc.state_dim;
  g.schedule.phase = 2;
  g.schedule.training_runs = 40;
  g.schedule.phase_one_runs = 30;
  g.schedule.phase_two_runs = 10;
  g.run_id = 50;
  g.policy = LEARN_POLICY_GREEDY;
  uint8_t meta[FW_PROGRESS_READ_MAX];
  memset(meta, 0, sizeof meta);
  size_t meta_n = fw_progress_encode(&g, meta);
  if (legacy_a < -1.5) {
    memcpy(meta, "FWMETA02", 8);
    meta_n = FW_PROGRESS_BYTES_2;
  } else if (legacy_a >= 0.0) {
    memcpy(meta, "FWMETA01", 8);
    memcpy(meta + 56, &legacy_a, sizeof legacy_a);  // little-endian host
    meta_n = 96;
  }
  char err[FW_CHECKPOINT_ERR_MAX];
  assert_int_equal(fw_checkpoint_write(path, meta, meta_n, payload, ps, err, sizeof err), 0);
}

// The controller section of the checkpoint at path; its payload into the static buffer (*payload_n).
static uint8_t g_payload[1 << 23];
static size_t read_section(const char* path, fw_progress_t* out, size_t* payload_n) {
  uint8_t meta[FW_PROGRESS_READ_MAX];
  size_t ms = 0;
  char err[FW_CHECKPOINT_ERR_MAX];
  assert_int_equal(
      fw_checkpoint_read(path, meta, sizeof meta, &ms, g_payload, sizeof g_payload, payload_n, err, sizeof err), 1);
  assert_int_equal(fw_progress_decode(meta, ms, out, NULL, 0), 0);
  return ms;
}

// The actor section's size recorded in the checkpoint at path.
static uint64_t actor_bytes_of(const char* path) {
  fw_progress_t g;
  size_t pn = 0;
  (void)read_section(path, &g, &pn);
  return g.actor_bytes;
}

static void test_train_checkpoint_revisions(void** state) {
  (void)state;
  char init[128];
  char out[128];
  snprintf(init, sizeof init, "%s/init.ckpt", g_dir);
  snprintf(out, sizeof out, "%s/out.ckpt", g_dir);
  // today's format with the greedy policy, revision 2; revision 1 without, with a shift
  const double legacy_a[] = {-1.0, -2.0, 0.0, 0.75};
  const train_options_t opt = {.progress = NULL, .progress_period_s = 1.0};
  static uint8_t first_out[1 << 23];
  size_t first_n = 0;
  for (size_t i = 0; i < sizeof legacy_a / sizeof legacy_a[0]; ++i) {
    const fw_config_t c = obstacle_config();
    write_init(&c, init, legacy_a[i]);
    char err[TRAIN_ERR_MAX] = "";
    trainer_t* t = trainer_create(&c, &opt, err, sizeof err);
    assert_non_null(t);
    if (trainer_load_checkpoint(t, init, err, sizeof err) != 0) {
      fail_msg("case %zu: %s", i, err);
    }
    assert_int_equal(trainer_stats(t).init_legacy_shift, legacy_a[i] > 0.0);
    assert_int_equal(trainer_stats(t).init_actor_cloned, 1);  // from the one stored point
    assert_int_equal(hedger_size(trainer_hedger(t)), 1);
    (void)unlink(out);
    assert_int_equal(trainer_write_checkpoint(t, out, false, err, sizeof err), 0);
    trainer_destroy(t);
    fw_progress_t g;
    size_t pn = 0;
    assert_int_equal(read_section(out, &g, &pn), FW_PROGRESS_BYTES);
    assert_false(g.legacy_shift);
    assert_int_equal(g.schedule.phase, 2);
    assert_int_equal(g.task, (int32_t)tasks_obstacles_decl.id);
    assert_int_equal(g.policy, LEARN_POLICY_ACTOR);
    assert_true(g.actor_bytes > 0 && g.actor_bytes < pn);
    if (i == 0) {
      memcpy(first_out, g_payload, pn);
      first_n = pn;
    } else {
      // The same values, the same cloning: the same learned state whatever the revision.
      assert_int_equal(pn, first_n);
      assert_memory_equal(g_payload, first_out, pn);
    }
  }
  // An --init with an actor: loaded as it is (nothing cloned), written back unchanged.
  char again[128];
  snprintf(again, sizeof again, "%s/again.ckpt", g_dir);
  fw_config_t c = obstacle_config();
  char err[TRAIN_ERR_MAX] = "";
  trainer_t* t = trainer_create(&c, &opt, err, sizeof err);
  assert_int_equal(trainer_load_checkpoint(t, out, err, sizeof err), 0);
  assert_int_equal(trainer_stats(t).init_actor_cloned, 0);
  (void)unlink(again);
  assert_int_equal(trainer_write_checkpoint(t, again, false, err, sizeof err), 0);
  trainer_destroy(t);
  fw_progress_t g;
  size_t pn = 0;
  (void)read_section(again, &g, &pn);
  assert_int_equal(pn, first_n);
  assert_memory_equal(g_payload, first_out, pn);
  // With policy = greedy the actor is dropped, and said so.
  assert_int_equal(fw_config_set(&c, "policy", "greedy", "test", err, sizeof err), 0);
  t = trainer_create(&c, &opt, err, sizeof err);
  assert_int_equal(trainer_load_checkpoint(t, out, err, sizeof err), 0);
  assert_true(trainer_stats(t).init_actor_dropped);
  (void)unlink(again);
  assert_int_equal(trainer_write_checkpoint(t, again, false, err, sizeof err), 0);
  trainer_destroy(t);
  (void)read_section(again, &g, &pn);
  assert_int_equal(g.policy, LEARN_POLICY_GREEDY);
  assert_int_equal(g.actor_bytes, 0);
  assert_int_equal(pn, first_n - actor_bytes_of(out));
  (void)unlink(again);
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
      cmocka_unit_test(test_train_checkpoint_revisions),
  };
  return cmocka_run_group_tests_name("tools.train_checkpoint", tests, setup, teardown);
}
