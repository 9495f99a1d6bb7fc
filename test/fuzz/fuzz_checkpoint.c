// SPDX-License-Identifier: MIT
// libFuzzer target: the checkpoint loader as the controller runs it, fw_loop_load_checkpoint():
// the file format (fw/checkpoint.h), the controller section (fw/progress.h) and the learner's
// own format (hedger_load). Input byte 0 holds flags, the rest is the file: bit 0 recomputes
// the learner's CRC and bit 1 the file's section and header CRCs after the mutation, so that
// the fuzzer reaches the content checks behind the checksums. Properties: a refusal names the
// file and says how to start fresh (or what to fix) and leaves the loop as it was; an accepted
// file gives a consistent schedule and a store within capacity.
//
// Seeds: B21R_FUZZ_SEEDS_OUT=<dir> fuzz_checkpoint writes valid checkpoints for this target's
// configuration into <dir> and exits (test/fuzz/corpus/checkpoint was made that way).
#include <tasks/decl.h>
#include "fw/checkpoint.h"
#include "fw/config.h"
#include "fw/config_task.h"
#include "fw/loop.h"
#include "fw/progress.h"
#include "fuzz_util.h"

#include <hedger/hedger.h>

#include <math.h>

int LLVMFuzzerInitialize(int* argc, char*** argv);

static fuzz_file_t g_file;
static fw_loop_t* g_loop;
static fw_config_t g_cfg;
static bool g_verbose;  // B21R_FUZZ_VERBOSE set: print each verdict (for checking the seeds)

// The loop never touches a device while loading: a binding that has none.
static int64_t null_now(void* user) {
  (void)user;
  return 0;
}
static int null_wait(void* user, int64_t deadline_us) {
  (void)user;
  (void)deadline_us;
  return 0;
}
static int null_laser(void* user, int64_t now_us, lms_scan_t* out) {
  (void)user;
  (void)now_us;
  (void)out;
  return 0;
}
static ssize_t null_read(void* user, uint8_t* buf, size_t cap) {
  (void)user;
  (void)buf;
  (void)cap;
  return 0;
}
static int null_write(void* user, const uint8_t* buf, size_t n) {
  (void)user;
  (void)buf;
  (void)n;
  return 0;
}
static const fw_io_vtable_t k_null_vt = {.now_us = null_now, .wait = null_wait, .laser_poll = null_laser,
                                        .base_read = null_read, .base_write = null_write};

static void config(fw_config_t* c, const char* path) {
  fw_config_defaults(c);
  strcpy(c->lcm_url, "none");
  c->hedger_capacity = 256;
  snprintf(c->checkpoint_file, sizeof c->checkpoint_file, "%s", path);
}

static uint64_t get_u64(const uint8_t* p) {
  uint64_t v = 0;
  for (int i = 7; i >= 0; --i) {
    v = (v << 8) | p[i];
  }
  return v;
}

static void put_u32(uint8_t* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) {
    p[i] = (uint8_t)(v >> (8 * i));
  }
}

// Makes the checksums match the (mutated) contents, as a writer with a bug would have.
static void fix_crcs(uint8_t* f, size_t n, uint8_t flags) {
  if (n < FW_CHECKPOINT_HEADER_SIZE) {
    return;
  }
  const uint64_t m = get_u64(f + 16);
  const uint64_t p = get_u64(f + 24);
  const bool sections_fit = m <= n && p <= n && FW_CHECKPOINT_HEADER_SIZE + m + p <= n;
  if ((flags & 1U) != 0 && sections_fit && p >= 16) {
    uint8_t* payload = f + FW_CHECKPOINT_HEADER_SIZE + m;
    const uint64_t total = get_u64(payload + 8);
    if (total >= 4 && total <= p) {
      put_u32(payload + total - 4, fw_crc32(0, payload, (size_t)total - 4));
    }
  }
  if ((flags & 2U) != 0) {
    if (sections_fit) {
      put_u32(f + 32, fw_crc32(0, f + FW_CHECKPOINT_HEADER_SIZE, (size_t)m));
      put_u32(f + 36, fw_crc32(0, f + FW_CHECKPOINT_HEADER_SIZE + m, (size_t)p));
    }
    put_u32(f + 44, fw_crc32(0, f, 44));
  }
}

// Valid checkpoints for g_cfg: an empty learner at the start, and a learner with stored points
// in the middle of phase one and in phase two; each with flags 0 and 3.
static void write_seeds(const char* dir) {
  hedger_config_t hc;
  fw_config_hedger(&g_cfg, &hc);
  hedger_t* h = NULL;
  FUZZ_CHECK(hedger_create(&h, &hc) == HEDGER_OK);
  static uint8_t payload[1 << 20];
  static const int points[3] = {0, 12, 40};
  for (int k = 0; k < 3; ++k) {
    for (int i = (int)hedger_size(h); i < points[k]; ++i) {
      double s[HEDGER_MAX_STATE_DIM] = {0.0};  // hc.state_dim entries (the executed rotation 0)
      s[0] = 0.25 * i;
      s[1] = 0.1 * (i % 7) - 0.3;
      s[2] = 0.05 * (i % 5);
      FUZZ_CHECK(hedger_insert(h, s, 0.1 * (i % 9) - 0.4, 0.5 + 0.01 * i, i % 11 == 0 ? 1U : 0U, NULL) == HEDGER_OK);
    }
    if (k > 0) {
      (void)hedger_observe_reward(h, 10.0);
    }
    size_t n = 0;
    FUZZ_CHECK(hedger_save(h, payload, sizeof payload, &n) == HEDGER_OK);
    fw_progress_t g;
    memset(&g, 0, sizeof g);
    g.task = (int32_t)tasks_corridor_decl.id;
    g.state_dim = hc.state_dim;
    g.schedule.phase = k == 2 ? 2 : 1;
    g.schedule.phase_one_runs = k == 0 ? 0 : 12;
    g.schedule.phase_two_runs = k == 2 ? 3 : 0;
    g.schedule.training_runs = g.schedule.phase_one_runs + g.schedule.phase_two_runs;
    g.schedule.eval_blocks = k;
    g.schedule.example_runs = k == 0 ? 0 : 9;
    g.schedule.example_steps_sum = k == 0 ? 0.0 : 9.0 * 140.0;
    g.schedule.best_example_steps = k == 0 ? 0 : 126;
    g.run_id = k == 0 ? -1 : g.schedule.training_runs + 10 * k;
    uint8_t meta[FW_PROGRESS_BYTES];
    const size_t meta_n = fw_progress_encode(&g, meta);
    char tmp[512];
    snprintf(tmp, sizeof tmp, "%s/.seed.ckpt", dir);
    char err[FW_CHECKPOINT_ERR_MAX];
    FUZZ_CHECK(fw_checkpoint_write(tmp, meta, meta_n, payload, n, err, sizeof err) == 0);
    FILE* in = fopen(tmp, "rb");
    FUZZ_CHECK(in != NULL);
    static uint8_t file[1 << 20];
    file[0] = 0;
    const size_t len = fread(file + 1, 1, sizeof file - 1, in);
    fclose(in);
    unlink(tmp);
    for (int flags = 0; flags <= 3; flags += 3) {
      file[0] = (uint8_t)flags;
      char path[512];
      snprintf(path, sizeof path, "%s/ckpt_%d_points_flags%d", dir, points[k], flags);
      FILE* out = fopen(path, "wb");
      FUZZ_CHECK(out != NULL && fwrite(file, 1, len + 1, out) == len + 1);
      fclose(out);
    }
  }
  hedger_destroy(h);
}

int LLVMFuzzerInitialize(int* argc, char*** argv) {
  (void)argc;
  (void)argv;
  FUZZ_CHECK(fuzz_file_open(&g_file, "checkpoint") == 0);
  config(&g_cfg, g_file.path);
  const fw_io_t io = {&k_null_vt, NULL};
  char err[FW_LOOP_ERR_MAX];
  g_loop = fw_loop_create(&g_cfg, &io, NULL, err, sizeof err);
  if (g_loop == NULL) {
    fprintf(stderr, "fuzz_checkpoint: %s\n", err);
    abort();
  }
  g_verbose = getenv("B21R_FUZZ_VERBOSE") != NULL;
  const char* seeds = getenv("B21R_FUZZ_SEEDS_OUT");
  if (seeds != NULL) {
    write_seeds(seeds);
    exit(0);
  }
  return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) {
    return 0;
  }
  static uint8_t file[1 << 20];
  const size_t n = size - 1 < sizeof file ? size - 1 : sizeof file;
  memcpy(file, data + 1, n);
  fix_crcs(file, n, data[0]);
  (void)fuzz_file_set(&g_file, file, n);
  fw_loop_stats_t before;
  fw_loop_get_stats(g_loop, &before);
  char err[FW_LOOP_ERR_MAX];
  err[0] = '\0';
  const int r = fw_loop_load_checkpoint(g_loop, err, sizeof err);
  fw_loop_stats_t after;
  fw_loop_get_stats(g_loop, &after);
  if (g_verbose) {
    fprintf(stderr, "fuzz_checkpoint: %d %s\n", r, r < 0 ? err : "loaded");
  }
  if (r < 0) {
    FUZZ_CHECK(memchr(err, '\0', sizeof err) != NULL);
    FUZZ_CHECK(strstr(err, g_file.path) != NULL);
    FUZZ_CHECK(strstr(err, "to start fresh") != NULL || strstr(err, "checkpoint_file") != NULL ||
               strstr(err, "cannot") != NULL);
    FUZZ_CHECK(memcmp(&before, &after, sizeof before) == 0);
    return 0;
  }
  FUZZ_CHECK(r == 1);
  FUZZ_CHECK(memchr(err, '\0', sizeof err) != NULL && (err[0] == '\0' || strstr(err, g_file.path) != NULL));
  FUZZ_CHECK(after.phase == 1 || after.phase == 2);
  FUZZ_CHECK(after.training_runs >= 0 && after.eval_blocks >= 0 && after.run_id >= -1);
  FUZZ_CHECK(after.store_fill <= (uint32_t)g_cfg.hedger_capacity);
  FUZZ_CHECK(isfinite(after.mean_example_steps) && after.mean_example_steps >= 0.0);
  return 0;
}
