// SPDX-License-Identifier: MIT
// Checkpoint files: round trip, every kind of damage refused with a "start fresh" hint, kill -9
// at random instants never leaves a broken file, and the background writer keeps the newest;
// journal records round-trip, damage ends the journal, and the writer makes runs durable in order.
#define _POSIX_C_SOURCE 200809L
#include "fw/checkpoint.h"
#include "fw/journal.h"

#include <b21r_test/alloc_counter.h>

#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <cmocka.h>

static char g_dir[256];
static char g_path[512];

static int setup(void** state) {
  (void)state;
  snprintf(g_dir, sizeof g_dir, "/tmp/b21r-ckpt-XXXXXX");
  if (mkdtemp(g_dir) == NULL) {
    return -1;
  }
  snprintf(g_path, sizeof g_path, "%s/hedger.ckpt", g_dir);
  return 0;
}

static int teardown(void** state) {
  (void)state;
  char cmd[300];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", g_dir);
  return system(cmd) == 0 ? 0 : -1;
}

static int reset_file(void** state) {
  (void)state;
  unlink(g_path);
  return 0;
}

// Payload of generation g: a pattern that identifies g in every byte.
static void fill_generation(uint8_t* p, size_t n, uint32_t g) {
  for (size_t i = 0; i < n; ++i) {
    p[i] = (uint8_t)((g * 131U + (uint32_t)i * 7U) & 0xFFU);
  }
}

static size_t generation_size(uint32_t g) { return 100000U + (g % 7U) * 40000U; }

// CRC-32 matches the IEEE check value.
static void test_crc32_check_value_matches(void** state) {
  (void)state;
  assert_int_equal(fw_crc32(0, "123456789", 9), 0xCBF43926U);
  assert_int_equal(fw_crc32(fw_crc32(0, "1234", 4), "56789", 5), 0xCBF43926U);
  assert_int_equal(fw_crc32(0, NULL, 0), 0U);
}

// Written meta and payload come back identical; peek reports the sizes.
static void test_checkpoint_round_trip_identical(void** state) {
  (void)state;
  static uint8_t payload[200000];
  static uint8_t back[200000];
  fill_generation(payload, sizeof payload, 3);
  const char meta[] = "phase=2 runs=17";
  char err[FW_CHECKPOINT_ERR_MAX];
  assert_int_equal(fw_checkpoint_write(g_path, meta, sizeof meta, payload, sizeof payload, err, sizeof err), 0);
  size_t ms = 0;
  size_t ps = 0;
  assert_int_equal(fw_checkpoint_peek(g_path, &ms, &ps, err, sizeof err), 1);
  assert_int_equal(ms, sizeof meta);
  assert_int_equal(ps, sizeof payload);
  char meta_back[64];
  assert_int_equal(fw_checkpoint_read(g_path, meta_back, sizeof meta_back, &ms, back, sizeof back, &ps, err, sizeof err), 1);
  assert_memory_equal(meta_back, meta, sizeof meta);
  assert_memory_equal(back, payload, sizeof payload);
  struct stat st;
  char tmp[600];
  snprintf(tmp, sizeof tmp, "%s.tmp", g_path);
  assert_int_equal(stat(tmp, &st), -1);  // no temp file left behind
}

// No file: 0, not an error.
static void test_checkpoint_missing_file_is_not_an_error(void** state) {
  (void)state;
  char err[FW_CHECKPOINT_ERR_MAX];
  size_t ms = 0;
  size_t ps = 0;
  uint8_t buf[16];
  assert_int_equal(fw_checkpoint_peek(g_path, &ms, &ps, err, sizeof err), 0);
  assert_int_equal(fw_checkpoint_read(g_path, buf, sizeof buf, &ms, buf, sizeof buf, &ps, err, sizeof err), 0);
}

static void corrupt_byte(long offset, uint8_t xor_mask) {
  FILE* f = fopen(g_path, "r+b");
  assert_non_null(f);
  assert_int_equal(fseek(f, offset, SEEK_SET), 0);
  const int c = fgetc(f);
  assert_true(c != EOF);
  assert_int_equal(fseek(f, offset, SEEK_SET), 0);
  fputc(c ^ xor_mask, f);
  fclose(f);
}

static int read_back(char* err, size_t cap) {
  static uint8_t meta[64];
  static uint8_t payload[4096];
  size_t ms = 0;
  size_t ps = 0;
  return fw_checkpoint_read(g_path, meta, sizeof meta, &ms, payload, sizeof payload, &ps, err, cap);
}

static void write_small(void) {
  uint8_t payload[1000];
  fill_generation(payload, sizeof payload, 9);
  char err[FW_CHECKPOINT_ERR_MAX];
  assert_int_equal(fw_checkpoint_write(g_path, "m", 1, payload, sizeof payload, err, sizeof err), 0);
}

// Damaged files are refused, each with a message that names the damage and how to start fresh.
static void test_checkpoint_damage_refused_with_fresh_hint(void** state) {
  (void)state;
  char err[FW_CHECKPOINT_ERR_MAX];
  // A flipped payload bit.
  write_small();
  corrupt_byte(48 + 1 + 500, 0x01);
  assert_int_equal(read_back(err, sizeof err), -1);
  assert_non_null(strstr(err, "section checksum mismatch"));
  assert_non_null(strstr(err, "to start fresh"));
  assert_non_null(strstr(err, "mv "));
  // A flipped header bit.
  write_small();
  corrupt_byte(20, 0x40);
  assert_int_equal(read_back(err, sizeof err), -1);
  assert_non_null(strstr(err, "header checksum mismatch"));
  // Bad magic.
  write_small();
  corrupt_byte(0, 0xFF);
  assert_int_equal(read_back(err, sizeof err), -1);
  assert_non_null(strstr(err, "not a B21r checkpoint"));
  // Truncated inside the payload, and inside the header.
  write_small();
  assert_int_equal(truncate(g_path, 48 + 1 + 999), 0);
  assert_int_equal(read_back(err, sizeof err), -1);
  assert_non_null(strstr(err, "truncated"));
  assert_int_equal(truncate(g_path, 20), 0);
  assert_int_equal(read_back(err, sizeof err), -1);
  assert_non_null(strstr(err, "truncated"));
  // Trailing garbage.
  write_small();
  FILE* f = fopen(g_path, "ab");
  assert_non_null(f);
  fputs("x", f);
  fclose(f);
  assert_int_equal(read_back(err, sizeof err), -1);
  assert_non_null(strstr(err, "trailing"));
  // Empty file.
  f = fopen(g_path, "wb");
  assert_non_null(f);
  fclose(f);
  assert_int_equal(read_back(err, sizeof err), -1);
  assert_non_null(strstr(err, "to start fresh"));
}

// A directory, a device or a FIFO given as the checkpoint is refused by what it is, not as
// "truncated".
static void test_checkpoint_not_a_regular_file_named(void** state) {
  (void)state;
  char err[FW_CHECKPOINT_ERR_MAX];
  size_t ms = 0;
  size_t ps = 0;
  assert_int_equal(fw_checkpoint_peek(g_dir, &ms, &ps, err, sizeof err), -1);
  assert_non_null(strstr(err, g_dir));
  assert_non_null(strstr(err, "is a directory"));
  assert_null(strstr(err, "truncated"));
  uint8_t meta[8];
  uint8_t payload[8];
  assert_int_equal(fw_checkpoint_read(g_dir, meta, sizeof meta, &ms, payload, sizeof payload, &ps, err, sizeof err),
                   -1);
  assert_non_null(strstr(err, "is a directory"));
  assert_int_equal(fw_checkpoint_peek("/dev/null", &ms, &ps, err, sizeof err), -1);
  assert_non_null(strstr(err, "not a regular file"));
  // A FIFO is refused at once (opening it must not wait for a writer).
  char fifo[300];
  snprintf(fifo, sizeof fifo, "%s/fifo", g_dir);
  assert_int_equal(mkfifo(fifo, 0600), 0);
  assert_int_equal(fw_checkpoint_peek(fifo, &ms, &ps, err, sizeof err), -1);
  assert_non_null(strstr(err, "not a regular file"));
  assert_int_equal(unlink(fifo), 0);
}

// A file from another format version is refused by name of the version.
static void test_checkpoint_other_version_refused(void** state) {
  (void)state;
  write_small();
  // Rewrite the version field and fix the header CRC, as a future writer would.
  FILE* f = fopen(g_path, "r+b");
  assert_non_null(f);
  uint8_t h[48];
  assert_int_equal(fread(h, 1, 48, f), 48);
  h[8] = 2;
  const uint32_t crc = fw_crc32(0, h, 44);
  for (int i = 0; i < 4; ++i) {
    h[44 + i] = (uint8_t)(crc >> (8 * i));
  }
  assert_int_equal(fseek(f, 0, SEEK_SET), 0);
  assert_int_equal(fwrite(h, 1, 48, f), 48);
  fclose(f);
  char err[FW_CHECKPOINT_ERR_MAX];
  assert_int_equal(read_back(err, sizeof err), -1);
  assert_non_null(strstr(err, "format version 2"));
}

// A checkpoint larger than the caller's buffers is refused (not truncated silently).
static void test_checkpoint_too_big_for_buffers_refused(void** state) {
  (void)state;
  static uint8_t payload[10000];
  char err[FW_CHECKPOINT_ERR_MAX];
  assert_int_equal(fw_checkpoint_write(g_path, "m", 1, payload, sizeof payload, err, sizeof err), 0);
  assert_int_equal(read_back(err, sizeof err), -1);
  assert_non_null(strstr(err, "hedger_capacity"));
}

// kill -9 at random instants while a process rewrites the checkpoint in a loop: the file on disk
// is always a complete, valid checkpoint of some generation, never a broken one.
static void test_checkpoint_kill9_random_instants_never_broken(void** state) {
  (void)state;
  static uint8_t payload[400000];
  static uint8_t back[400000];
  char err[FW_CHECKPOINT_ERR_MAX];
  fill_generation(payload, generation_size(0), 0);
  uint32_t g0 = 0;
  assert_int_equal(fw_checkpoint_write(g_path, &g0, sizeof g0, payload, generation_size(0), err, sizeof err), 0);
  uint64_t rng = 0x9E3779B97F4A7C15ULL;  // fixed seed: the kill instants are reproducible
  uint32_t start_generation = 1;
  int mid_write_kills = 0;
  const int rounds = 40;
  for (int round = 0; round < rounds; ++round) {
    const pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
      for (uint32_t g = start_generation;; ++g) {
        fill_generation(payload, generation_size(g), g);
        if (fw_checkpoint_write(g_path, &g, sizeof g, payload, generation_size(g), err, sizeof err) != 0) {
          _exit(3);
        }
      }
    }
    rng = rng * 6364136223846793005ULL + 1442695040888963407ULL;
    const long delay_us = 200 + (long)((rng >> 33) % 15000U);
    const struct timespec ts = {0, delay_us * 1000L};
    nanosleep(&ts, NULL);
    assert_int_equal(kill(pid, SIGKILL), 0);
    int status = 0;
    assert_int_equal(waitpid(pid, &status, 0), pid);
    assert_true(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
    uint32_t g = 0;
    size_t ms = 0;
    size_t ps = 0;
    const int r = fw_checkpoint_read(g_path, &g, sizeof g, &ms, back, sizeof back, &ps, err, sizeof err);
    if (r != 1) {
      fail_msg("round %d: checkpoint broken after kill -9: %s", round, err);
    }
    assert_int_equal(ms, sizeof g);
    assert_int_equal(ps, generation_size(g));
    fill_generation(payload, ps, g);
    assert_memory_equal(back, payload, ps);
    char tmp[600];
    snprintf(tmp, sizeof tmp, "%s.tmp", g_path);
    struct stat st;
    if (stat(tmp, &st) == 0) {
      mid_write_kills++;  // killed between create and rename: the old file survived
    }
    start_generation = g + 1000U;
  }
  print_message("kill -9 rounds: %d, of which %d left a partial temp file (harmless)\n", rounds, mid_write_kills);
}

// The background writer writes the newest submitted state; a flood of submissions supersedes
// older pending ones instead of queueing them, and acquire/submit allocate nothing.
static void test_ckpt_writer_keeps_newest_and_counts(void** state) {
  (void)state;
  char err[FW_CHECKPOINT_ERR_MAX];
  fw_ckpt_writer_t* w = fw_ckpt_writer_create(g_path, 16, 400000, err, sizeof err);
  assert_non_null(w);
  uint32_t last = 0;
  alloc_counter_begin();
  for (uint32_t g = 1; g <= 50; ++g) {
    void* meta = NULL;
    void* payload = NULL;
    size_t mc = 0;
    size_t pc = 0;
    const int h = fw_ckpt_writer_acquire(w, &meta, &mc, &payload, &pc);
    if (h < 0) {
      continue;
    }
    memcpy(meta, &g, sizeof g);
    fill_generation((uint8_t*)payload, generation_size(g), g);
    fw_ckpt_writer_submit(w, h, sizeof g, generation_size(g));
    last = g;
  }
  assert_int_equal(alloc_counter_end(), 0);
  fw_ckpt_writer_flush(w);
  const fw_ckpt_counters_t c = fw_ckpt_writer_counters(w);
  assert_true(c.written >= 1);
  assert_int_equal(c.failed, 0);
  assert_int_equal(c.written + c.superseded + c.busy, 50);
  static uint8_t back[400000];
  static uint8_t want[400000];
  uint32_t g = 0;
  size_t ms = 0;
  size_t ps = 0;
  assert_int_equal(fw_checkpoint_read(g_path, &g, sizeof g, &ms, back, sizeof back, &ps, err, sizeof err), 1);
  assert_int_equal(g, last);
  fill_generation(want, ps, g);
  assert_memory_equal(back, want, ps);
  fw_ckpt_writer_destroy(w);
}

// A write into a directory that does not exist fails with the path and leaves nothing behind.
static void test_checkpoint_write_failure_names_path(void** state) {
  (void)state;
  char err[FW_CHECKPOINT_ERR_MAX];
  assert_int_equal(fw_checkpoint_write("/nonexistent-dir/x.ckpt", "m", 1, "p", 1, err, sizeof err), -1);
  assert_non_null(strstr(err, "/nonexistent-dir/x.ckpt.tmp"));
}

// A journal record round-trips every field and transition; a record cut short reads as the end
// of the journal, a changed byte as damage.
static void test_journal_record_round_trip_and_damage(void** state) {
  (void)state;
  static uint8_t rec[4096];
  const uint32_t dim = 4;
  const fw_journal_run_t run = {.run_id = 17, .kind = 0, .phase = 2, .training_index = 9, .eval_index = -1,
                                .steps = 3, .goal = true, .aborted = false, .learned = true, .state_dim = dim, .n = 3};
  for (uint32_t i = 0; i < 3; ++i) {
    fw_journal_transition_t t;
    memset(&t, 0, sizeof t);
    for (uint32_t k = 0; k < dim; ++k) {
      t.s[k] = 0.25 * i + k;
      t.s_next[k] = -1.5 * i - k;
    }
    t.a = 0.1 * i;
    t.r = -1.0;
    t.terminal = i == 2;
    assert_true(fw_journal_put_transition(rec, sizeof rec, dim, i, &t));
  }
  const size_t n = fw_journal_finish(rec, sizeof rec, &run);
  assert_int_equal(n, fw_journal_record_bytes(dim, 3));
  assert_false(fw_journal_put_transition(rec, n, dim, 3, &(fw_journal_transition_t){0}));  // no room
  fw_journal_run_t back;
  const uint8_t* tr = NULL;
  size_t size = 0;
  assert_int_equal(fw_journal_next(rec, n, &back, &tr, &size), 1);
  assert_int_equal(size, n);
  assert_true(back.run_id == 17 && back.kind == 0 && back.phase == 2 && back.training_index == 9 &&
              back.eval_index == -1 && back.steps == 3 && back.goal && !back.aborted && back.learned &&
              back.state_dim == dim && back.n == 3);
  for (uint32_t i = 0; i < 3; ++i) {
    fw_journal_transition_t t;
    fw_journal_get_transition(tr, dim, i, &t);
    assert_true(t.s[3] == 0.25 * i + 3 && t.s_next[1] == -1.5 * i - 1 && t.a == 0.1 * i && t.r == -1.0);
    assert_int_equal(t.terminal, i == 2);
  }
  for (size_t cut = 0; cut < n; cut += 7) {
    assert_int_equal(fw_journal_next(rec, cut, &back, &tr, &size), 0);
  }
  for (size_t at = 0; at < n; at += 5) {
    if (at >= 8 && at < 12) {
      continue;  // the body size: a larger one reads as cut short, checked above
    }
    rec[at] ^= 0x10U;
    const int r = fw_journal_next(rec, n, &back, &tr, &size);
    rec[at] ^= 0x10U;
    assert_int_equal(r, -1);
  }
}

static long file_size(const char* path) {
  struct stat st;
  return stat(path, &st) == 0 ? (long)st.st_size : -1L;
}

// The writer appends and syncs each run's record in order and reports the run durable; a run
// missing from the sequence stops the journal until a checkpoint covers it, and a checkpoint that
// covers the journalled runs empties the file.
static void test_journal_writer_durable_in_order(void** state) {
  (void)state;
  char err[FW_CHECKPOINT_ERR_MAX];
  char jpath[600];
  snprintf(jpath, sizeof jpath, "%s.journal", g_path);
  fw_ckpt_writer_t* w = fw_ckpt_writer_create(g_path, 16, 4096, err, sizeof err);
  assert_non_null(w);
  assert_int_equal(fw_ckpt_writer_durable_run(w), -1);
  assert_int_equal(fw_ckpt_writer_journal_init(w, 1024, 4, 5, 0, err, sizeof err), 0);
  assert_int_equal(fw_ckpt_writer_durable_run(w), 5);
  static uint8_t rec[1024];
  const fw_journal_run_t run = {.run_id = 6, .kind = 1, .phase = 1, .eval_index = 0, .steps = 40, .state_dim = 3};
  const size_t n = fw_journal_finish(rec, sizeof rec, &run);
  assert_true(n > 0);
  assert_int_equal(fw_ckpt_writer_journal_submit(w, rec, n, 6), 0);
  assert_int_equal(fw_ckpt_writer_journal_submit(w, rec, n, 7), 0);
  fw_ckpt_writer_flush(w);
  assert_int_equal(fw_ckpt_writer_durable_run(w), 7);
  assert_int_equal(file_size(jpath), (long)(2 * n));
  // Run 8 not journalled (too large): 9 cannot follow it.
  assert_int_equal(fw_ckpt_writer_journal_submit(w, rec, 2000, 8), -1);
  assert_int_equal(fw_ckpt_writer_journal_submit(w, rec, n, 9), 0);
  fw_ckpt_writer_flush(w);
  assert_int_equal(fw_ckpt_writer_durable_run(w), 7);
  fw_ckpt_counters_t c = fw_ckpt_writer_counters(w);
  assert_int_equal(c.journal_written, 2);
  assert_int_equal(c.journal_skipped, 2);
  // A checkpoint of the state after run 9 makes 8 and 9 durable and empties the journal.
  void* meta = NULL;
  void* payload = NULL;
  size_t mc = 0;
  size_t pc = 0;
  const int h = fw_ckpt_writer_acquire(w, &meta, &mc, &payload, &pc);
  assert_true(h >= 0);
  memset(meta, 1, 16);
  memset(payload, 2, 100);
  fw_ckpt_writer_submit_run(w, h, 16, 100, 9);
  fw_ckpt_writer_flush(w);
  assert_int_equal(fw_ckpt_writer_durable_run(w), 9);
  assert_int_equal(file_size(jpath), 0);
  // The journal goes on after it.
  assert_int_equal(fw_ckpt_writer_journal_submit(w, rec, n, 10), 0);
  fw_ckpt_writer_flush(w);
  assert_int_equal(fw_ckpt_writer_durable_run(w), 10);
  assert_int_equal(file_size(jpath), (long)n);
  fw_ckpt_writer_destroy(w);
  // A new writer keeps the part of the journal it is told to keep and cuts the rest.
  w = fw_ckpt_writer_create(g_path, 16, 4096, err, sizeof err);
  assert_non_null(w);
  assert_int_equal(fw_ckpt_writer_journal_init(w, 1024, 4, 10, 10, err, sizeof err), 0);
  assert_int_equal(file_size(jpath), 10);
  fw_ckpt_writer_destroy(w);
  unlink(jpath);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_crc32_check_value_matches),
      cmocka_unit_test_setup(test_checkpoint_round_trip_identical, reset_file),
      cmocka_unit_test_setup(test_checkpoint_missing_file_is_not_an_error, reset_file),
      cmocka_unit_test_setup(test_checkpoint_damage_refused_with_fresh_hint, reset_file),
      cmocka_unit_test_setup(test_checkpoint_not_a_regular_file_named, reset_file),
      cmocka_unit_test_setup(test_checkpoint_other_version_refused, reset_file),
      cmocka_unit_test_setup(test_checkpoint_too_big_for_buffers_refused, reset_file),
      cmocka_unit_test_setup(test_checkpoint_kill9_random_instants_never_broken, reset_file),
      cmocka_unit_test_setup(test_ckpt_writer_keeps_newest_and_counts, reset_file),
      cmocka_unit_test(test_checkpoint_write_failure_names_path),
      cmocka_unit_test(test_journal_record_round_trip_and_damage),
      cmocka_unit_test_setup(test_journal_writer_durable_in_order, reset_file),
  };
  return cmocka_run_group_tests_name("firmware.checkpoint", tests, setup, teardown);
}
