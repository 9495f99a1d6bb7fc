// SPDX-License-Identifier: MIT
// tools.train_bench / tools.train_instructions: the cost of offline training (b21r-train's
// trainer) on a whole session of the paper's schedule (30 example runs, 35 learned runs, an
// evaluation block every 5 runs) driven by the controller's loop over the in-process fake robot,
// written to an LCM event log as the controller's --experience-log does (experiences only: no
// B21R_RUN records, so nothing is ranked or vetted).
//
// Two modes:
//   time (default)   three learner settings, each recording its own session: the controller's
//                    defaults (every learned experience is one update, and the between-runs
//                    backward replay makes hedger_replay_passes (3) more of it, each with a greedy
//                    search for the lambda-return, at the replay step hedger_replay_alpha = 0.7741,
//                    which moves a value as far as 20 passes of alpha = 0.2; hedger_k_max = 48),
//                    hedger_replay_passes = 1, and the former defaults (20 passes of alpha,
//                    hedger_k_max = 64), to which the defaults' rate is compared. CPU and wall time
//                    of decoding, of an in-run reference (the same HEDGER calls on experiences
//                    already decoded in memory: the learner's own cost, which no trainer can beat)
//                    and of the trainer, interleaved (reference, trainer, trainer, reference, ...)
//                    and the best of 5 each, so that a burst of other work on a shared machine
//                    falls on both. Experiences and updates per CPU second and the trainer's CPU
//                    time over the reference are printed, not checked: they depend on the load
//                    (measured on this 2-core machine with one other job: the same binary gave
//                    -4 % to +46 % over the reference, best of 3, run after run). Exit 1 when the
//                    trainer learns another state than the reference or makes other updates.
//   --instructions   under callgrind (CTest tools.train_instructions): the trainer's instructions
//                    per learned experience at the controller's defaults, against the budget and
//                    the throughput target below; and, with one replay pass (where the trainer's
//                    own work, reading and decoding the log and calling the framework, is the
//                    largest part of the whole), the trainer's instructions against those of
//                    decoding plus the in-run reference: at most 10 % more (exit 1 over any of the
//                    three); and the former defaults' instructions per learned experience
//                    (printed, with the defaults' ratio to them).
// The budget: an hour of a 10 Hz robot's driving (36,000 experiences) retrains in a minute on the
// slowest computer the controller targets, a Cortex-A53-class board (1.2 GHz, 0.5 instructions
// per cycle, AArch64 needing up to 1.25x the x86-64 count: 480 M x86-64 instructions per second):
// 60 s × 480 M/s / 36,000 = 800,000 instructions per learned experience. The controller's own
// between-run replay costs the same per experience (it is the same HEDGER work), so within it a
// run's replay on the robot takes at most about 1.7 ms of A53 time per step driven.
// The throughput target (issue 44): 20,000 learned experiences per CPU second at the defaults on
// this project's reference machine (the 2-core x86-64 VM of docs/development.md), which runs the
// trainer's work at 5.73 G instructions per CPU second (the median of six timed runs,
// 21,601 learned/s at 265,423 instructions each; 4.7-5.3 G/s in a slower hour): at most
// 5.73 G / 20,000 = 286,000 instructions per learned experience. Checked in instructions so that
// the verdict is the code's, not the machine's load; the timed mode prints the rate itself.
// Usage: bench_train [--instructions]
#define _POSIX_C_SOURCE 200809L
#include "instr.h"
#include "loop_harness.h"
#include "train.h"

#include <fw/config_task.h>

#include <hedger/hedger.h>
#include <lcm/eventlog.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#define BUDGET_INSTRUCTIONS_PER_EXPERIENCE 800000.0
#define TARGET_INSTRUCTIONS_PER_EXPERIENCE 286000.0
#define REPEATS 5
#define OVERHEAD_LIMIT 0.10

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
static long reference(const hedger_config_t* hc, const exp_rec_t* x, long n, uint8_t** saved,
                      size_t* saved_n, uint64_t* updates) {
  hedger_t* h = NULL;
  if (hedger_create(&h, hc) != HEDGER_OK) {
    return -1;
  }
  long used = 0;
  bool in_run = false;
  int32_t run = 0;
  for (long i = 0; i < n; ++i) {
    const bool starts_run = i == 0 || x[i].run_id != run;
    if (in_run && starts_run) {
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
  *updates = hedger_counters(h)->updates;
  if (saved != NULL) {
    *saved_n = hedger_serialized_size(h);
    *saved = (uint8_t*)malloc(*saved_n);
    (void)hedger_save(h, *saved, *saved_n, saved_n);
  }
  hedger_destroy(h);
  return used;
}

typedef struct measured {
  long experiences;    // in the log
  long used;           // learned by the reference (training runs)
  train_stats_t st;    // the trainer's counters (last repeat)
  uint64_t updates;    // the trainer's HEDGER updates, learned + replayed
  uint64_t ref_updates;  // the reference's
  times_t decode;
  times_t ref;
  times_t train;
  bool same_state;
} measured_t;

// One timed trainer run on the log at path; compares its learned state with the reference's
// (ref_state: the reference has run before). Returns 0, or -1 with a message.
static int time_trainer(fw_config_t* c, const char* path, measured_t* m, const uint8_t* ref_state,
                        size_t ref_state_n) {
  const train_options_t opt = {.progress = NULL, .progress_period_s = 1.0};
  char err[TRAIN_ERR_MAX];
  const times_t t0 = now_times();
  trainer_t* t = trainer_create(c, &opt, err, sizeof err);
  if (t == NULL || trainer_add_log(t, path, err, sizeof err) != 0) {
    fprintf(stderr, "bench_train: %s\n", err);
    trainer_destroy(t);
    return -1;
  }
  trainer_finish(t);
  keep_best(&m->train, since(t0));
  m->st = trainer_stats(t);
  hedger_t* h = trainer_hedger(t);
  m->updates = hedger_counters(h)->updates;
  const size_t sz = hedger_serialized_size(h);
  uint8_t* buf = (uint8_t*)malloc(sz);
  size_t written = 0;
  m->same_state = buf != NULL && ref_state != NULL && hedger_save(h, buf, sz, &written) == HEDGER_OK &&
                  written == ref_state_n && memcmp(buf, ref_state, written) == 0;
  free(buf);
  trainer_destroy(t);
  return 0;
}

// Records a session with c, then times decoding, the reference and the trainer on its log.
// Returns 0, or -1 with a message on stderr.
static int measure(fw_config_t* c, const char* dir, measured_t* m) {
  memset(m, 0, sizeof *m);
  char path[128];
  snprintf(path, sizeof path, "%s/session.lcmlog", dir);
  const long n_log = record_session(c, path);
  if (n_log <= 0) {
    fprintf(stderr, "bench_train: could not record the session\n");
    return -1;
  }
  hedger_config_t hc;
  fw_config_hedger(c, &hc);
  exp_rec_t* x = (exp_rec_t*)malloc((size_t)n_log * sizeof *x);
  if (x == NULL) {
    return -1;
  }
  for (int r = 0; r < REPEATS; ++r) {
    const times_t t0 = now_times();
    m->experiences = decode_all(path, x, n_log);
    keep_best(&m->decode, since(t0));
  }
  uint8_t* ref_state = NULL;
  size_t ref_state_n = 0;
  int rc = 0;
  // Interleaved, the order alternating (reference first in even repeats), so that a stretch of
  // load on the machine slows both rather than one.
  for (int r = 0; r < REPEATS && rc == 0; ++r) {
    for (int leg = 0; leg < 2 && rc == 0; ++leg) {
      if ((leg == 0) == (r % 2 == 0)) {
        const times_t t0 = now_times();
        m->used = reference(&hc, x, m->experiences, ref_state == NULL ? &ref_state : NULL, &ref_state_n,
                            &m->ref_updates);
        keep_best(&m->ref, since(t0));
      } else {
        rc = time_trainer(c, path, m, ref_state, ref_state_n);
      }
    }
  }
  unlink(path);
  free(ref_state);
  free(x);
  return rc;
}

// Prints one setting's table; returns true when its checks pass.
static bool report(const char* name, const fw_config_t* c, const measured_t* m) {
  const double used = (double)m->used;
  const double per_exp = m->st.used > 0 ? (double)m->updates / (double)m->st.used : 0.0;
  printf("\n%s: replay %s, %d pass%s (lambda %.2g, step %.4g); k %d..%d, capacity %d\n", name,
         c->hedger_replay ? "on" : "off", c->hedger_replay_passes, c->hedger_replay_passes == 1 ? "" : "es",
         c->hedger_replay_lambda, c->hedger_replay_alpha > 0.0 ? c->hedger_replay_alpha : c->alpha, c->hedger_k_min,
         c->hedger_k_max, c->hedger_capacity);
  printf("log: %ld experiences, %llu learned (training runs), %llu runs, %llu HEDGER updates (%.1f per learned)\n",
         m->experiences, (unsigned long long)m->st.used, (unsigned long long)m->st.runs,
         (unsigned long long)m->updates, per_exp);
  printf("%-44s %9s %9s %14s %14s %14s\n", "", "wall s", "CPU s", "exp/s (wall)", "exp/s (CPU)", "updates/s (CPU)");
  printf("%-44s %9.4f %9.4f\n", "decode the log (LCM event log -> structs)", m->decode.wall_s, m->decode.cpu_s);
  // The reference makes the trainer's updates exactly (the learned states are compared below).
  printf("%-44s %9.4f %9.4f %14.0f %14.0f %14.0f\n", "reference: HEDGER calls on decoded data", m->ref.wall_s,
         m->ref.cpu_s, used / m->ref.wall_s, used / m->ref.cpu_s, (double)m->ref_updates / m->ref.cpu_s);
  const double rate_exp = (double)m->st.used / m->train.cpu_s;
  const double rate_upd = (double)m->updates / m->train.cpu_s;
  printf("%-44s %9.4f %9.4f %14.0f %14.0f %14.0f\n", "trainer (b21r-train): log file -> HEDGER", m->train.wall_s,
         m->train.cpu_s, (double)m->st.used / m->train.wall_s, rate_exp, rate_upd);
  const double overhead = m->train.cpu_s / (m->ref.cpu_s + m->decode.cpu_s) - 1.0;
  printf("trainer CPU time over reference + decoding: %+.1f %% (printed only; checked in instructions by "
         "tools.train_instructions)\n", 100.0 * overhead);
  printf("learned experiences per CPU second: %.0f (each costs %.1f updates; a 10 Hz robot's hour of driving trains "
         "in %.1f s of this machine's CPU)\n", rate_exp, per_exp, 36000.0 / rate_exp);
  printf("learned state identical to the reference's: %s\n", m->same_state ? "yes" : "NO");
  return m->same_state && (long)m->st.used == m->used && m->ref_updates == m->updates;
}

// Instructions of one trainer (trainer_create to trainer_finish) on the log at path; its counters
// into st and updates. UINT64_MAX on failure (message on stderr).
static uint64_t trainer_instructions(const fw_config_t* c, const char* path, train_stats_t* st, uint64_t* updates) {
  const train_options_t opt = {.progress = NULL, .progress_period_s = 1.0};
  char err[TRAIN_ERR_MAX];
  instr_begin();
  trainer_t* t = trainer_create(c, &opt, err, sizeof err);
  if (t == NULL || trainer_add_log(t, path, err, sizeof err) != 0) {
    fprintf(stderr, "bench_train: %s\n", err);
    trainer_destroy(t);
    return UINT64_MAX;
  }
  trainer_finish(t);
  const uint64_t n = instr_end();
  *st = trainer_stats(t);
  *updates = hedger_counters(trainer_hedger(t))->updates;
  trainer_destroy(t);
  return n;
}

// Under callgrind, each setting's session recorded before the counting starts (instr_start):
// - the controller's defaults: the trainer's instructions per learned experience, against the
//   budget and the throughput target;
// - one replay pass: the trainer's instructions against decoding plus the in-run reference, at
//   most OVERHEAD_LIMIT more (the trainer's own work is the same per experience at any pass count,
//   and the largest fraction of the whole with one pass).
// - the former defaults (20 passes of alpha, k_max 64): printed, with the defaults' ratio to them.
// Returns true when the first two hold.
static bool count_instructions(fw_config_t* c, fw_config_t* one_pass, fw_config_t* former, const char* dir) {
  char path[128];
  char path_one[128];
  snprintf(path, sizeof path, "%s/session.lcmlog", dir);
  snprintf(path_one, sizeof path_one, "%s/session-one-pass.lcmlog", dir);
  const long n_log = record_session(c, path);
  const long n_log_one = record_session(one_pass, path_one);
  char path_former[128];
  snprintf(path_former, sizeof path_former, "%s/session-former.lcmlog", dir);
  const long n_log_former = record_session(former, path_former);
  if (n_log <= 0 || n_log_one <= 0 || n_log_former <= 0) {
    fprintf(stderr, "bench_train: could not record the sessions\n");
    return false;
  }
  exp_rec_t* x = (exp_rec_t*)malloc((size_t)n_log_one * sizeof *x);
  if (x == NULL) {
    return false;
  }
  hedger_config_t hc_one;
  fw_config_hedger(one_pass, &hc_one);
  instr_start();

  train_stats_t st;
  uint64_t updates = 0;
  const uint64_t n = trainer_instructions(c, path, &st, &updates);

  train_stats_t st_one;
  uint64_t updates_one = 0;
  const uint64_t n_train_one = trainer_instructions(one_pass, path_one, &st_one, &updates_one);
  uint64_t ref_updates_one = 0;
  instr_begin();
  const long n_exp_one = decode_all(path_one, x, n_log_one);
  const long used_one = reference(&hc_one, x, n_exp_one, NULL, NULL, &ref_updates_one);
  const uint64_t n_ref_one = instr_end();
  train_stats_t st_former;
  uint64_t updates_former = 0;
  const uint64_t n_former = trainer_instructions(former, path_former, &st_former, &updates_former);
  unlink(path_former);
  free(x);
  unlink(path);
  unlink(path_one);
  if (n == UINT64_MAX || n_train_one == UINT64_MAX || n_ref_one == UINT64_MAX || n_former == UINT64_MAX ||
      st.used == 0 || n_ref_one == 0 || st_former.used == 0) {
    return false;
  }
  const double per_exp = (double)n / (double)st.used;
  const bool ok_budget = per_exp <= BUDGET_INSTRUCTIONS_PER_EXPERIENCE;
  const bool ok_target = per_exp <= TARGET_INSTRUCTIONS_PER_EXPERIENCE;
  const bool ok = ok_budget && ok_target;
  printf("tools.train_instructions: b21r-train's trainer on a session of the paper's schedule (corridor, the "
         "controller's defaults: %d replay passes)\n", c->hedger_replay_passes);
  printf("%ld experiences in the log, %llu learned, %llu runs, %llu HEDGER updates (%.1f per learned)\n", n_log,
         (unsigned long long)st.used, (unsigned long long)st.runs, (unsigned long long)updates,
         (double)updates / (double)st.used);
  printf("%llu instructions: %.0f per learned experience, %.0f per update\n", (unsigned long long)n, per_exp,
         (double)n / (double)updates);
  printf("budget %.0f per learned experience (an hour of driving retrained in a minute on a Cortex-A53 at 1.2 GHz): "
         "%s (%.0f %%)\n", BUDGET_INSTRUCTIONS_PER_EXPERIENCE, ok_budget ? "within" : "OVER",
         100.0 * per_exp / BUDGET_INSTRUCTIONS_PER_EXPERIENCE);
  printf("throughput target %.0f per learned experience (20,000 learned experiences per CPU second on the reference "
         "machine, 5.73 G instructions per CPU second): %s (%.0f %%)\n", TARGET_INSTRUCTIONS_PER_EXPERIENCE,
         ok_target ? "within" : "OVER", 100.0 * per_exp / TARGET_INSTRUCTIONS_PER_EXPERIENCE);
  const double overhead = (double)n_train_one / (double)n_ref_one - 1.0;
  const bool same = (long)st_one.used == used_one && updates_one == ref_updates_one;
  const bool ok_overhead = same && overhead <= OVERHEAD_LIMIT;
  printf("\none replay pass, its own session (%ld experiences, %llu learned, %llu HEDGER updates):\n", n_log_one,
         (unsigned long long)st_one.used, (unsigned long long)updates_one);
  printf("decoding + in-run reference %llu instructions, trainer %llu: %+.1f %% (limit %+.0f %%)%s: %s\n",
         (unsigned long long)n_ref_one, (unsigned long long)n_train_one, 100.0 * overhead, 100.0 * OVERHEAD_LIMIT,
         same ? "" : "; the trainer and the reference learned other experiences or made other updates",
         ok_overhead ? "within" : "OVER");
  const double per_exp_former = (double)n_former / (double)st_former.used;
  printf("\nthe former defaults (hedger_replay_passes = %d, hedger_replay_alpha = %.4g (= alpha), hedger_k_max = %d), "
         "their own session (%ld experiences, %llu learned, %llu HEDGER updates):\n%llu instructions: %.0f per learned "
         "experience; the defaults take %.2f x that\n",
         former->hedger_replay_passes, former->hedger_replay_alpha, former->hedger_k_max, n_log_former,
         (unsigned long long)st_former.used, (unsigned long long)updates_former, (unsigned long long)n_former,
         per_exp_former, per_exp / per_exp_former);
  return ok && ok_overhead;
}

int main(int argc, char** argv) {
  const bool instructions = argc > 1 && strcmp(argv[1], "--instructions") == 0;
  if ((argc > 1 && !instructions) || argc > 2) {
    fprintf(stderr, "usage: bench_train [--instructions]\n");
    return 2;
  }
  if (instructions && !instr_active()) {
    fprintf(stderr, "bench_train: --instructions counts under callgrind: ctest --preset bench -R tools.train_instructions\n");
    return 2;
  }
  char dir[] = "/tmp/b21r-bench-train-XXXXXX";
  if (mkdtemp(dir) == NULL) {
    return 1;
  }
  fw_config_t c;
  harness_config(&c);
  c.phase_one_runs = 30;
  c.phase_two_runs = 35;
  c.eval_every_runs = 5;
  fw_config_t one_pass = c;
  one_pass.hedger_replay_passes = 1;
  fw_config_t former = c;  // the defaults until the replay got its own step (docs/LEARNING.md)
  former.hedger_replay_passes = 20;
  former.hedger_replay_alpha = 0.0;
  former.hedger_k_max = 64;
  if (instructions) {
    const bool ok = count_instructions(&c, &one_pass, &former, dir);
    rmdir(dir);
    printf("%s\n", ok ? "tools.train_instructions: within budget" : "tools.train_instructions: FAILED");
    return ok ? 0 : 1;
  }
  measured_t m_defaults;
  measured_t m_one_pass;
  measured_t m_former;
  const int rc = measure(&c, dir, &m_defaults) | measure(&one_pass, dir, &m_one_pass) | measure(&former, dir, &m_former);
  rmdir(dir);
  if (rc != 0) {
    return 1;
  }
  printf("tools.train_bench: offline HEDGER training from an experience log (corridor, the controller's HEDGER\n"
         "settings; each setting records its own session; reference and trainer interleaved, best of %d each; times\n"
         "depend on the machine's load and are printed, not checked)\n",
         REPEATS);
  const bool ok_defaults = report("the controller's defaults", &c, &m_defaults);
  const bool ok_one_pass = report("one replay pass (hedger_replay_passes = 1)", &one_pass, &m_one_pass);
  const bool ok_former = report("the former defaults (20 passes of alpha, k_max 64)", &former, &m_former);
  printf("the defaults' learned experiences per CPU second against the former defaults', same process: %.2f x\n",
         ((double)m_defaults.st.used / m_defaults.train.cpu_s) / ((double)m_former.st.used / m_former.train.cpu_s));
  const bool ok = ok_defaults && ok_one_pass && ok_former;
  printf("\n%s\n", ok ? "tools.train_bench: all checks pass" : "tools.train_bench: FAILED");
  return ok ? 0 : 1;
}
