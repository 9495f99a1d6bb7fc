// SPDX-License-Identifier: MIT
// tools.train_bench: throughput of offline training (b21r-train's trainer) in experiences per
// second, against an in-run reference: the same HEDGER calls on experiences already decoded in
// memory (the learner's own cost, which no trainer can beat). The data is a whole session of the
// paper's schedule (30 example runs, 35 learned runs, an evaluation block every 5 runs) driven
// by the controller's loop over the in-process fake robot, written to an LCM event log as the
// controller's --experience-log does. Prints wall-clock and CPU-time rates (best of 3 each: the
// machine may be shared) and exits 1 when the trainer's CPU time exceeds the reference's plus
// the decoding by more than 10 %, when it learns a different state than the reference, or when
// it trains fewer than 20,000 experiences per CPU second (the product's target).
// Usage: bench_train
#define _POSIX_C_SOURCE 200809L
#include "loop_harness.h"
#include "train.h"

#include <hedger/hedger.h>
#include <lcm/eventlog.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#define TARGET_PER_S 20000.0
#define REPEATS 3

typedef struct times {
  double wall_s;
  double cpu_s;
} times_t;

static times_t now_times(void) {
  struct timespec w;
  struct timespec c;
  clock_gettime(CLOCK_MONOTONIC, &w);
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c);
  return (times_t){(double)w.tv_sec + (double)w.tv_nsec * 1e-9, (double)c.tv_sec + (double)c.tv_nsec * 1e-9};
}

static times_t since(times_t t0) {
  const times_t t = now_times();
  return (times_t){t.wall_s - t0.wall_s, t.cpu_s - t0.cpu_s};
}

// best starts at {0, 0} (no measurement yet).
static void keep_best(times_t* best, times_t t) {
  if (!(best->wall_s > 0.0) || t.wall_s < best->wall_s) {
    best->wall_s = t.wall_s;
  }
  if (!(best->cpu_s > 0.0) || t.cpu_s < best->cpu_s) {
    best->cpu_s = t.cpu_s;
  }
}

// Runs a session over the fake robot and writes its experiences to path. Returns the count.
static long record_session(fw_config_t* c, const char* path) {
  harness_t h;
  if (harness_open(&h, c, false, 7) != 0) {
    return -1;
  }
  lcm_eventlog_t* log = lcm_eventlog_create(path, "w");
  if (log == NULL) {
    return -1;
  }
  long n = 0;
  int64_t t_us = 0;
  for (bool more = true; more;) {
    const int64_t t = fw_loop_wait(h.loop);
    more = fw_loop_tick(h.loop, t);
    const fw_msg_t* m;
    while ((m = fw_pubq_peek(h.q)) != NULL) {
      if (m->kind == FW_MSG_EXPERIENCE) {
        uint8_t buf[2048];
        const int len = b21r_experience_t_encode(buf, 0, (int)sizeof buf, &m->u.experience);
        lcm_eventlog_event_t ev = {.eventnum = n, .timestamp = t_us, .channellen = 15, .datalen = len,
                                   .channel = (char*)"B21R_EXPERIENCE", .data = buf};
        t_us += 100000;
        if (len < 0 || lcm_eventlog_write_event(log, &ev) != 0) {
          return -1;
        }
        n++;
      }
      fw_pubq_pop(h.q);
    }
  }
  lcm_eventlog_destroy(log);
  harness_close(&h);
  return n;
}

typedef struct exp_rec {
  double s[8];
  double s_next[8];
  double a;
  double r;
  int32_t run_id;
  int8_t terminal;
  int8_t evaluating;
} exp_rec_t;

static long decode_all(const char* path, exp_rec_t* out, long cap) {
  lcm_eventlog_t* log = lcm_eventlog_create(path, "r");
  long n = 0;
  lcm_eventlog_event_t* ev;
  while (log != NULL && (ev = lcm_eventlog_read_next_event(log)) != NULL) {
    b21r_experience_t e;
    if (n < cap && b21r_experience_t_decode(ev->data, 0, ev->datalen, &e) >= 0) {
      memcpy(out[n].s, e.s, sizeof e.s);
      memcpy(out[n].s_next, e.s_next, sizeof e.s_next);
      out[n].a = e.action_radps;
      out[n].r = e.reward;
      out[n].run_id = e.run_id;
      out[n].terminal = (int8_t)e.terminal;
      out[n].evaluating = (int8_t)e.evaluating;
      n++;
    }
    lcm_eventlog_free_event(ev);
  }
  if (log != NULL) {
    lcm_eventlog_destroy(log);
  }
  return n;
}

// The reference: the controller's learning calls on decoded experiences, nothing else.
static long reference(const hedger_config_t* hc, const exp_rec_t* x, long n, uint8_t** saved, size_t* saved_n) {
  hedger_t* h = NULL;
  if (hedger_create(&h, hc) != HEDGER_OK) {
    return -1;
  }
  long used = 0;
  bool in_run = false;
  int32_t run = 0;
  for (long i = 0; i < n; ++i) {
    if (in_run && x[i].run_id != run) {
      (void)hedger_end_run(h, NULL);
      in_run = false;
    }
    run = x[i].run_id;
    if (x[i].evaluating) {
      continue;
    }
    if (hedger_update(h, x[i].s, x[i].a, x[i].r, x[i].s_next, x[i].terminal, NULL) == HEDGER_OK) {
      used++;
      in_run = true;
    }
  }
  if (in_run) {
    (void)hedger_end_run(h, NULL);
  }
  if (saved != NULL) {
    *saved_n = hedger_serialized_size(h);
    *saved = (uint8_t*)malloc(*saved_n);
    (void)hedger_save(h, *saved, *saved_n, saved_n);
  }
  hedger_destroy(h);
  return used;
}

int main(void) {
  char dir[] = "/tmp/b21r-bench-train-XXXXXX";
  if (mkdtemp(dir) == NULL) {
    return 1;
  }
  char path[128];
  snprintf(path, sizeof path, "%s/session.lcmlog", dir);

  fw_config_t c;
  harness_config(&c);
  c.phase_one_runs = 30;
  c.phase_two_runs = 35;
  c.eval_every_runs = 5;
  const long n_log = record_session(&c, path);
  if (n_log <= 0) {
    fprintf(stderr, "bench_train: could not record the session\n");
    return 1;
  }
  hedger_config_t hc;
  fw_loop_learner_config(&c, &hc);

  exp_rec_t* x = (exp_rec_t*)malloc((size_t)n_log * sizeof *x);
  times_t t_decode = {0, 0};
  long n = 0;
  for (int r = 0; r < REPEATS; ++r) {
    const times_t t0 = now_times();
    n = decode_all(path, x, n_log);
    keep_best(&t_decode, since(t0));
  }
  times_t t_ref = {0, 0};
  long used_ref = 0;
  uint8_t* ref_state = NULL;
  size_t ref_state_n = 0;
  for (int r = 0; r < REPEATS; ++r) {
    const times_t t0 = now_times();
    used_ref = reference(&hc, x, n, r == 0 ? &ref_state : NULL, &ref_state_n);
    keep_best(&t_ref, since(t0));
  }

  times_t t_train = {0, 0};
  train_stats_t st;
  memset(&st, 0, sizeof st);
  bool same_state = false;
  for (int r = 0; r < REPEATS; ++r) {
    const train_options_t opt = {.progress = NULL, .progress_period_s = 1.0};
    char err[TRAIN_ERR_MAX];
    const times_t t0 = now_times();
    trainer_t* t = trainer_create(&c, &opt, err, sizeof err);
    if (t == NULL || trainer_add_log(t, path, err, sizeof err) != 0) {
      fprintf(stderr, "bench_train: %s\n", err);
      return 1;
    }
    trainer_finish(t);
    keep_best(&t_train, since(t0));
    st = trainer_stats(t);
    hedger_t* h = trainer_hedger(t);
    const size_t sz = hedger_serialized_size(h);
    uint8_t* buf = (uint8_t*)malloc(sz);
    size_t written = 0;
    same_state = buf != NULL && hedger_save(h, buf, sz, &written) == HEDGER_OK && written == ref_state_n &&
                 memcmp(buf, ref_state, written) == 0;
    free(buf);
    trainer_destroy(t);
  }
  unlink(path);
  rmdir(dir);

  const double per = (double)used_ref;
  printf("tools.train_bench: offline HEDGER training from an experience log (corridor, the controller's default\n"
         "HEDGER settings: capacity %u, k %u..%u, replay %s; best of %d; the machine may be shared)\n",
         hc.capacity, hc.k_min, hc.k_max, hc.replay ? "on" : "off", REPEATS);
  printf("log: %ld experiences, %llu learned (training runs), %llu runs, %llu replayed updates\n", n,
         (unsigned long long)st.used, (unsigned long long)st.runs, (unsigned long long)st.replayed);
  printf("%-44s %12s %12s %14s %14s\n", "", "wall s", "CPU s", "exp/s (wall)", "exp/s (CPU)");
  printf("%-44s %12.4f %12.4f %14s %14s\n", "decode the log (LCM event log -> structs)", t_decode.wall_s,
         t_decode.cpu_s, "", "");
  printf("%-44s %12.4f %12.4f %14.0f %14.0f\n", "reference: HEDGER calls on decoded data", t_ref.wall_s, t_ref.cpu_s,
         per / t_ref.wall_s, per / t_ref.cpu_s);
  printf("%-44s %12.4f %12.4f %14.0f %14.0f\n", "trainer (b21r-train): log file -> HEDGER", t_train.wall_s,
         t_train.cpu_s, (double)st.used / t_train.wall_s, (double)st.used / t_train.cpu_s);
  const double overhead = t_train.cpu_s / (t_ref.cpu_s + t_decode.cpu_s) - 1.0;
  const double rate_cpu = (double)st.used / t_train.cpu_s;
  printf("trainer CPU time over reference + decoding: %+.1f %% (limit +10 %%)\n", 100.0 * overhead);
  printf("target %.0f experiences/s: %s (%.0f per CPU second, %.0f per wall second)\n", TARGET_PER_S,
         rate_cpu >= TARGET_PER_S ? "met" : "NOT met", rate_cpu, (double)st.used / t_train.wall_s);
  printf("learned state identical to the reference's: %s\n", same_state ? "yes" : "NO");
  free(ref_state);
  free(x);
  const bool ok = same_state && (long)st.used == used_ref && overhead <= 0.10 && rate_cpu >= TARGET_PER_S;
  return ok ? 0 : 1;
}
