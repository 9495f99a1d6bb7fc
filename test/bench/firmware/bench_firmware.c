// SPDX-License-Identifier: MIT
// firmware.bench: compute time of the control tick (features, HEDGER update + greedy action,
// safety, publishing into the queue) at 1k, 10k, 20k and 100k stored samples, p50 / p99 / max,
// and the longest tick between runs (run ends: the replay and checkpoint slices of learning.c).
// Target: every tick at 20k samples, run ends included, under 2 ms; the in-run max is the
// reference measured in the same process. Times are the tick thread's CPU time
// (CLOCK_THREAD_CPUTIME_ID): the tick's own cost, which preemption by other work on a shared
// machine does not inflate (that is what the deadline test, label rt, measures); the wall-clock
// max is printed beside it.
// The robot is the in-process fake (lockstep); its simulation time is excluded. The store is
// pre-filled through a checkpoint of synthetic samples spread over the corridor's state space,
// then the learned policy drives with learning on (phase two), as on the robot.
// Arguments: `--set key=value` (repeatable) measures another setting, e.g. a larger hedger_k_max.
#define _POSIX_C_SOURCE 200809L
#include "fw/checkpoint.h"
#include "fw/config_task.h"
#include "loop_harness.h"

#include <hedger/hedger.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

static int64_t mono_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static int64_t cpu_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static int cmp_i64(const void* a, const void* b) {
  const int64_t x = *(const int64_t*)a;
  const int64_t y = *(const int64_t*)b;
  return (x > y) - (x < y);
}

// Writes a checkpoint holding n synthetic samples with plausible corridor values.
static int write_store(const fw_config_t* cfg, uint32_t n, const char* path) {
  hedger_config_t hc;
  fw_config_hedger(cfg, &hc);
  hedger_t* h = NULL;
  if (hedger_create(&h, &hc) != HEDGER_OK) {
    return -1;
  }
  uint64_t s = 12345;
  while (hedger_size(h) < n) {
    double u[5];
    for (int i = 0; i < 5; ++i) {
      s = s * 6364136223846793005ULL + 1442695040888963407ULL;
      u[i] = (double)(s >> 11) / 9007199254740992.0;
    }
    // end distance, lateral fraction, target angle, and (state_rotation) the executed rotation
    const double state[4] = {10.0 * u[0], 0.1 + 0.8 * u[1], -1.2 + 2.4 * u[2], -1.0 + 2.0 * u[4]};
    const double a = -1.0 + 2.0 * u[3];
    const double q = 10.0 * pow(0.99, state[0] / 0.06) * (1.0 - 0.5 * fabs(state[1] - 0.5));
    if (hedger_insert(h, state, a, q, 0, NULL) != HEDGER_OK) {
      hedger_destroy(h);
      return -1;
    }
  }
  // The controller section of a fresh phase-two schedule (the loop's own format, version 1).
  uint8_t meta[96];
  memset(meta, 0, sizeof meta);
  memcpy(meta, "FWMETA01", 8);
  meta[12] = (uint8_t)hc.state_dim;
  meta[16] = 2;   // phase two
  const size_t size = hedger_serialized_size(h);
  void* buf = malloc(size);
  size_t written = 0;
  int rc = -1;
  char err[FW_CHECKPOINT_ERR_MAX];
  if (buf != NULL && hedger_save(h, buf, size, &written) == HEDGER_OK &&
      fw_checkpoint_write(path, meta, sizeof meta, buf, written, err, sizeof err) == 0) {
    rc = 0;
  }
  free(buf);
  hedger_destroy(h);
  return rc;
}

int main(int argc, char** argv) {
  const uint32_t sizes[] = {1000, 10000, 20000, 100000};
  const int ticks = 3000;
  const int64_t target_us = 2000;  // at 20k samples
  static int64_t t_us[3000];
  // The harness's settings with the command line's --set applied, once, before anything is made.
  fw_config_t base;
  harness_config(&base);
  for (int a = 1; a < argc; ++a) {
    if (strcmp(argv[a], "--set") != 0 || a + 1 == argc) {
      fprintf(stderr, "bench: usage: %s [--set key=value]...\n", argv[0]);
      return 2;
    }
    char err[FW_CONFIG_ERR_MAX];
    if (fw_config_set_arg(&base, argv[++a], err, sizeof err) != 0) {
      fprintf(stderr, "bench: %s\n", err);
      return 2;
    }
  }
  char dir[] = "/tmp/b21r-bench-XXXXXX";
  if (mkdtemp(dir) == NULL) {
    return 1;
  }
  printf("firmware.bench: tick compute time (lockstep fake robot, corridor, learning on, phase two)\n");
  printf("%8s %8s %8s %8s %8s %12s %10s %10s\n", "samples", "p50_us", "p99_us", "max_us", "mean_us", "run_end_max",
         "run_ends", "store_end");
  int status = 0;
  for (size_t k = 0; k < sizeof sizes / sizeof sizes[0]; ++k) {
    fw_config_t c = base;
    c.phase_one_runs = 0;
    c.phase_two_runs = 1000;
    c.eval_every_runs = 1000;
    c.hedger_capacity = 110000;
    snprintf(c.checkpoint_file, sizeof c.checkpoint_file, "%s/store-%u.ckpt", dir, (unsigned)sizes[k]);
    if (write_store(&c, sizes[k], c.checkpoint_file) != 0) {
      fprintf(stderr, "bench: cannot build a store of %u samples\n", (unsigned)sizes[k]);
      return 1;
    }
    harness_t h;
    if (harness_open(&h, &c, false, 1) != 0) {
      return 1;
    }
    char err[FW_LOOP_ERR_MAX];
    if (fw_loop_load_checkpoint(h.loop, err, sizeof err) != 1) {
      fprintf(stderr, "bench: %s\n", err);
      return 1;
    }
    harness_run(&h, 50);  // warm up: a run under way
    double sum = 0.0;
    int64_t run_end_max_us = 0;
    int64_t in_run_max_us = 0;
    int64_t wall_max_us = 0;
    fw_loop_stats_t st0;
    fw_loop_get_stats(h.loop, &st0);
    for (int i = 0; i < ticks; ++i) {
      const int64_t t = fw_loop_wait(h.loop);
      const int64_t busy0 = h.fake.busy_ns;
      fw_loop_stats_t before;
      fw_loop_get_stats(h.loop, &before);
      const int64_t w0 = mono_ns();
      const int64_t t0 = cpu_ns();
      (void)fw_loop_tick(h.loop, t);
      const int64_t dt = cpu_ns() - t0 - (h.fake.busy_ns - busy0);
      const int64_t wall_us = (mono_ns() - w0) / 1000;
      if (wall_us > wall_max_us) {
        wall_max_us = wall_us;
      }
      fw_loop_stats_t after;
      fw_loop_get_stats(h.loop, &after);
      t_us[i] = dt / 1000;
      sum += (double)dt / 1000.0;
      // A tick that ended a run or did between-run learning work (replay, checkpoint slices).
      const bool run_end = after.learn_ticks != before.learn_ticks || after.runs_finished != before.runs_finished ||
                           after.runs_aborted != before.runs_aborted;
      int64_t* mx = run_end ? &run_end_max_us : &in_run_max_us;
      if (t_us[i] > *mx) {
        *mx = t_us[i];
      }
      harness_drain(&h);
    }
    fw_loop_stats_t st;
    fw_loop_get_stats(h.loop, &st);
    const int run_ends = (st.runs_finished + st.runs_aborted) - (st0.runs_finished + st0.runs_aborted);
    qsort(t_us, (size_t)ticks, sizeof t_us[0], cmp_i64);
    printf("%8u %8lld %8lld %8lld %8.1f %12lld %10d %10u\n", (unsigned)sizes[k], (long long)t_us[ticks / 2],
           (long long)t_us[(ticks * 99) / 100], (long long)t_us[ticks - 1], sum / ticks, (long long)run_end_max_us,
           run_ends, st.store_fill);
    printf("         run-end max / in-run max (reference, same process) = %lld / %lld us = %.2f\n",
           (long long)run_end_max_us, (long long)in_run_max_us,
           in_run_max_us > 0 ? (double)run_end_max_us / (double)in_run_max_us : 0.0);
    printf("         longest tick in wall-clock time (preemption included): %lld us\n", (long long)wall_max_us);
    if (st.store_fill < sizes[k] || run_ends == 0) {
      fprintf(stderr, "bench: %u samples: store %u, %d run ends: not the case measured\n", (unsigned)sizes[k],
              st.store_fill, run_ends);
      status = 1;
    }
    if (sizes[k] == 20000 && t_us[ticks - 1] >= target_us) {
      fprintf(stderr, "bench: FAIL: the longest tick at 20000 samples took %lld us (target < %lld us)\n",
              (long long)t_us[ticks - 1], (long long)target_us);
      status = 1;
    }
    harness_close(&h);
    unlink(c.checkpoint_file);
  }
  rmdir(dir);
  printf("(one tick = read inputs, features, safety, HEDGER update with the greedy search at s', the\n"
         " action, clamp, command encoding, experience/pose/status into the queue; 10 Hz budget 100000 us)\n");
  return status;
}
