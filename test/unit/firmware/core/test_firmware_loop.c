// SPDX-License-Identifier: MIT
// Loop core over the fake lockstep robot: learns the corridor from examples, is deterministic,
// allocates nothing per tick, and reacts to every safety cause within one tick.
#define _POSIX_C_SOURCE 200809L
#include "loop_harness.h"

#include "fw/checkpoint.h"
#include "fw/config_task.h"
#include "fw/progress.h"
#include <learn/learn.h>
#include "fw/safety.h"

#include <hedger/hedger.h>
#include <tasks/decl.h>

#include <b21r_test/alloc_counter.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

static harness_t g_h;

// The paper's 30 example runs, then 5 learned runs; one block after each phase (a block every
// 5 runs costs too much time in the sanitizer build; the integration tests and the main job run
// the paper's cadence).
static void short_schedule(fw_config_t* c) {
  harness_config(c);
  c->phase_one_runs = 30;
  c->phase_two_runs = 5;
  c->eval_every_runs = 30;
  c->progress = true;
}

// The controller learns the corridor from example runs and, in phase two, reaches the goal
// from all 10 evaluation poses; the experience stream has no gaps.
static void test_loop_learns_corridor_reaches_goal_from_all_poses(void** state) {
  (void)state;
  fw_config_t c;
  short_schedule(&c);
  assert_int_equal(harness_open(&g_h, &c, false, 7), 0);
  g_h.print_text = getenv("B21R_TEST_VERBOSE") != NULL;
  harness_run(&g_h, 200000);
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  print_message("ticks %lld, steps %lld, runs %d, blocks %d, last block %d/%d mean %.1f +- %.1f, best example %d\n",
                (long long)st.ticks, (long long)st.steps, st.runs_finished, st.eval_blocks, st.last_block.successes,
                st.last_block.n_starts, st.last_block.mean_steps, st.last_block.ci95_halfwidth, st.best_example_steps);
  assert_true(st.done);
  assert_int_equal(st.training_runs, 35);
  assert_int_equal(st.eval_blocks, 2);
  assert_int_equal(g_h.evals, 2);
  assert_int_equal(g_h.last_eval.phase, 2);
  assert_int_equal(g_h.last_eval.successes, 10);
  assert_int_equal(g_h.exp_gaps, 0);
  assert_int_equal(st.experiences_dropped, 0);
  harness_close(&g_h);
}

// The short schedule of the learner-state tests: 5 phase-one and 3 phase-two runs, an evaluation
// block every 4 runs, 2 replay passes (the rest the harness's).
static void short_session_config(fw_config_t* c) {
  harness_config(c);
  c->phase_one_runs = 5;
  c->phase_two_runs = 3;
  c->eval_every_runs = 4;
  c->hedger_replay_passes = 2;
}

// state_rotation: the state ends with the rotation the base executes, i.e. the command in force
// while the step ran (the previous action, after the acceleration limit), so every transition's
// s_next ends with its own action and its s with the run's previous action (0 at the start: the
// robot stands while it is placed). Without the option the state keeps the task's 3 entries.
static void test_loop_state_rotation_is_the_executed_command(void** state) {
  (void)state;
  for (int on = 0; on <= 1; ++on) {
    fw_config_t c;
    short_session_config(&c);
    c.state_rotation = on != 0;
    c.decision_ticks = 1;  // a fresh command every tick: no ramp towards a held decision (next test)
    assert_int_equal(harness_open(&g_h, &c, false, 3), 0);
    harness_run(&g_h, 100000);
    fw_loop_stats_t st;
    fw_loop_get_stats(g_h.loop, &st);
    print_message("state_rotation %d: %lld experiences, state_dim %d, executed rotation checked %lld times, %lld "
                  "mismatches\n", on, (long long)g_h.exp_count, g_h.exp_state_dim, (long long)g_h.rotation_checked,
                  (long long)g_h.rotation_mismatches);
    assert_true(st.done);
    assert_int_equal(g_h.exp_state_dim, on ? 4 : 3);
    assert_int_equal(g_h.rotation_checked, on ? g_h.exp_count : 0);
    assert_int_equal(g_h.rotation_mismatches, 0);
    assert_int_equal(g_h.rotation_ramping, 0);
    assert_true(g_h.exp_count > 500);
    harness_close(&g_h);
  }
}

// decision_ticks: the driver and the policy decide every N ticks and the command holds in
// between (the executed rotation at a decision's last tick, s_next's last entry, is the decision:
// a fresh action at that tick would differ); each decision is one experience ending at the run's
// steps N-1, 2N-1, ... (a run's last may end early), learned with the discount gamma^N. At N = 1
// every step is one.
static void test_loop_decision_ticks_hold_and_learn_each_decision(void** state) {
  (void)state;
  int64_t count[3] = {0, 0, 0};
  for (int n = 1; n <= 2; ++n) {
    fw_config_t c;
    short_session_config(&c);
    c.decision_ticks = n;
    assert_int_equal(harness_open(&g_h, &c, false, 3), 0);
    harness_run(&g_h, 100000);
    fw_loop_stats_t st;
    fw_loop_get_stats(g_h.loop, &st);
    print_message("decision_ticks %d: %lld experiences, %lld off the decisions' steps, %lld ending a window "
                  "early, %lld rotation mismatches, %lld ramping, %d runs\n", n, (long long)g_h.exp_count,
                  (long long)g_h.window_breaks, (long long)g_h.window_early, (long long)g_h.rotation_mismatches,
                  (long long)g_h.rotation_ramping, g_h.runs);
    assert_true(st.done);
    assert_int_equal(g_h.window_breaks, 0);
    assert_true(n == 1 ? g_h.window_early == 0 : g_h.window_early <= g_h.runs);
    assert_int_equal(g_h.rotation_mismatches, 0);
    assert_true(n == 1 ? g_h.rotation_ramping == 0 : g_h.rotation_ramping < g_h.exp_count / 10);
    assert_true(g_h.rotation_checked == g_h.exp_count);
    // The learner's discount per experience.
    hedger_config_t hc;
    fw_config_hedger(&c, &hc);
    const double g = hc.gamma;
    fw_config_t c1 = c;
    c1.decision_ticks = 1;
    fw_config_hedger(&c1, &hc);
    assert_true(n == 1 ? g == hc.gamma : g == pow(hc.gamma, 2.0));
    count[n] = g_h.exp_count;
    harness_close(&g_h);
  }
  // About half as many experiences for as many runs of about the same length.
  assert_true(count[2] < count[1] * 6 / 10 && count[2] > count[1] * 4 / 10);
}

// Runs c's schedule on a fresh fake robot (fake seed 5; CANopen with its frames can_lag_us behind
// the laser, and stall_us more from the bump-panel node's heartbeat on in the fake's period
// stall_period, 1 = the first tick's, when canopen) for at most 100,000 ticks; returns the hash of
// the experience stream.
static uint64_t run_stream(const fw_config_t* c, bool canopen, int64_t can_lag_us, int64_t stall_us,
                           int64_t stall_period, int64_t* count, fw_loop_stats_t* st) {
  assert_int_equal(canopen ? harness_open_can_lag(&g_h, c, 5, can_lag_us) : harness_open(&g_h, c, false, 5), 0);
  assert_int_equal(g_h.fake.ticks, 0);  // the start moved the emulator's time by no period
  g_h.fake.can_stall_us = stall_us;
  g_h.fake.can_stall_period = stall_period;
  harness_run(&g_h, 100000);
  fw_loop_get_stats(g_h.loop, st);
  *count = g_h.exp_count;
  const uint64_t hash = g_h.exp_hash;
  harness_close(&g_h);
  return hash;
}

// The same configuration and seeds give bit-identical experience streams; another seed differs.
static void test_loop_same_seed_bit_identical_experiences(void** state) {
  (void)state;
  fw_config_t c;
  harness_config(&c);
  c.phase_one_runs = 3;
  c.phase_two_runs = 2;
  c.eval_every_runs = 5;
  c.eval_starts = 2;
  uint64_t hashes[3];
  int64_t counts[3];
  for (int i = 0; i < 3; ++i) {
    c.seed = i < 2 ? 11 : 12;
    fw_loop_stats_t st;
    hashes[i] = run_stream(&c, false, 0, 0, 0, &counts[i], &st);
  }
  print_message("experiences %lld, hash %016llx / %016llx / %016llx\n", (long long)counts[0],
                (unsigned long long)hashes[0], (unsigned long long)hashes[1], (unsigned long long)hashes[2]);
  assert_true(counts[0] > 100);
  assert_int_equal(counts[0], counts[1]);
  assert_true(hashes[0] == hashes[1]);
  assert_true(hashes[0] != hashes[2]);
}

// CANopen in lockstep: the drives' answers may reach the controller later than the period's scan
// (separate channels; a loaded machine delays either). Each tick waits for the answers to every
// SYNC it has sent, and the start sends no SYNC of its own, so the experience stream is the same
// whatever the lag: with answers 150 ms late, a start that kept sending SYNCs on its timer left an
// answer in flight that later ticks took for their own, one period stale. The emulator may also
// stall between two frames of one period (a loaded machine stops it for seconds after it sent the
// bump-panel node's heartbeat, before the drives' answers): the nodes' heartbeats are judged on the
// ticks' time, which the emulator's periods pace, so the stall is no lost heartbeat. (On wall time the
// node's heartbeat aged 2.5 s while its PDOs came in: a base fault that aborted the run.) The start's
// enable cycles wait for their answers as long as a tick does (lockstep_timeout_s): answers 25 s
// late start the same run (at 0.5 s a cycle, 40 cycles gave up after 20 s: "drives not enabled"),
// and the start costs the emulator no period (a cycle cut short sent one SYNC more, which costs a
// period once the emulator streams: here with answers 1.5 s late, 3 periods).
static void test_loop_canopen_stream_independent_of_answer_lag(void** state) {
  (void)state;
  fw_config_t c;
  harness_config(&c);
  c.phase_one_runs = 2;
  c.phase_two_runs = 1;
  c.eval_every_runs = 3;
  c.eval_starts = 1;
  c.seed = 11;
  c.lockstep_timeout_s = 30.0;  // the product's default: the emulator is waited for
  enum { CASES = 8 };
  const int64_t lags_us[CASES] = {0, 30000, 150000, 450000, 1500000, 25000000, 0, 0};
  const int64_t stalls_us[CASES] = {0, 0, 0, 0, 0, 0, 2500000, 2500000};
  const int64_t stall_periods[CASES] = {0, 0, 0, 0, 0, 0, 40, 7};
  uint64_t hashes[CASES];
  int64_t counts[CASES];
  for (int i = 0; i < CASES; ++i) {
    fw_loop_stats_t st;
    hashes[i] = run_stream(&c, true, lags_us[i], stalls_us[i], stall_periods[i], &counts[i], &st);
    assert_true(st.done);
    assert_int_equal(st.safety_stops, 0);
    print_message("CAN answers %3lld ms after the scan, a stall of %4lld ms in period %2lld: %lld experiences, "
                  "hash %016llx\n",
                  (long long)(lags_us[i] / 1000), (long long)(stalls_us[i] / 1000), (long long)stall_periods[i],
                  (long long)counts[i], (unsigned long long)hashes[i]);
  }
  assert_true(counts[0] > 100);
  for (int i = 1; i < CASES; ++i) {
    assert_int_equal(counts[i], counts[0]);
    assert_true(hashes[i] == hashes[0]);
  }
}

// After start-up, thousands of ticks (runs, run ends, evaluation blocks, phase switch) perform
// no heap allocation.
static void test_loop_tick_allocates_nothing(void** state) {
  (void)state;
  fw_config_t c;
  harness_config(&c);
  c.phase_one_runs = 3;
  c.phase_two_runs = 3;
  c.eval_every_runs = 3;
  c.eval_starts = 4;
  c.progress = true;
  assert_int_equal(harness_open(&g_h, &c, false, 3), 0);
  harness_run(&g_h, 5);
  alloc_counter_begin();
  int64_t ticks = 0;
  for (; ticks < 3000; ++ticks) {
    const int64_t t = fw_loop_wait(g_h.loop);
    const bool more = fw_loop_tick(g_h.loop, t);
    harness_drain(&g_h);
    if (!more) {
      break;
    }
  }
  const uint64_t allocs = alloc_counter_end();
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  print_message("%lld ticks, %d runs, %d blocks: %llu allocations\n", (long long)ticks, st.runs_finished,
                st.eval_blocks, (unsigned long long)allocs);
  assert_true(ticks > 1500);
  assert_true(st.eval_blocks >= 1);
  assert_int_equal(allocs, 0);
  harness_close(&g_h);
}

// The learned state and the schedule's progress survive a restart: a new loop loading the
// checkpoint written at the end of each training run continues with the same counts, phase and
// samples; a corrupt checkpoint is refused with the "start fresh" hint and changes nothing.
// Attaches a checkpoint writer for c's checkpoint_file to the open harness; *meta_cap and
// *payload_cap receive the loop's capacities.
static fw_ckpt_writer_t* attach_checkpoints(const fw_config_t* c, size_t* meta_cap, size_t* payload_cap) {
  fw_loop_checkpoint_capacity(g_h.loop, meta_cap, payload_cap);
  char err[FW_LOOP_ERR_MAX];
  fw_ckpt_writer_t* w = fw_ckpt_writer_create(c->checkpoint_file, *meta_cap, *payload_cap, err, sizeof err);
  assert_non_null(w);
  fw_loop_attach_checkpoints(g_h.loop, w);
  return w;
}

// The controller section of the checkpoint at path (its payload read and dropped).
static fw_progress_t checkpoint_progress(const char* path, size_t payload_cap) {
  uint8_t meta[FW_PROGRESS_READ_MAX];
  size_t ms = 0;
  size_t ps = 0;
  uint8_t* payload = malloc(payload_cap);
  assert_non_null(payload);
  char err[FW_LOOP_ERR_MAX];
  assert_int_equal(fw_checkpoint_read(path, meta, sizeof meta, &ms, payload, payload_cap, &ps, err, sizeof err), 1);
  free(payload);
  fw_progress_t g;
  assert_int_equal(fw_progress_decode(meta, ms, &g, NULL, 0), 0);
  return g;
}

// policy = select: phase two's training runs come in pairs that start from one pose (the second
// run repeats the first's start pose, whatever evaluation block comes between), and the ranked
// pairs go into the checkpoint (revision 4), from which a restart takes them up.
static void test_loop_select_pairs_share_start_and_checkpoint(void** state) {
  (void)state;
  char dir[] = "/tmp/b21r-loopselect-XXXXXX";
  assert_non_null(mkdtemp(dir));
  fw_config_t c;
  harness_config(&c);
  c.phase_one_runs = 2;
  c.phase_two_runs = 5;
  c.eval_every_runs = 3;
  c.eval_starts = 1;
  c.policy = FW_POLICY_SELECT;
  snprintf(c.checkpoint_file, sizeof c.checkpoint_file, "%s/hedger.ckpt", dir);
  assert_int_equal(harness_open(&g_h, &c, false, 3), 0);
  size_t meta_cap = 0;
  size_t payload_cap = 0;
  fw_ckpt_writer_t* w = attach_checkpoints(&c, &meta_cap, &payload_cap);
  harness_run(&g_h, 200000);
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  assert_true(st.done);
  fw_ckpt_writer_flush(w);
  // Phase two's training runs, in order: pairs (0, 1) and (2, 3) share their start; the pairs and
  // the unpaired last run start elsewhere (the training starts are drawn, jittered).
  const b21r_run_t* two[8];
  int n = 0;
  for (int i = 0; i < g_h.runs && i < 64; ++i) {
    const b21r_run_t* r = &g_h.run[i];
    if (r->kind == B21R_RUN_T_KIND_TRAINING && r->phase == 2 && r->end_reason != B21R_RUN_T_END_SAFETY_STOP) {
      assert_true(n < 8);
      two[n++] = r;
    }
  }
  assert_int_equal(n, 5);
  for (int k = 0; k < 2; ++k) {
    const b21r_run_t* a = two[2 * k];
    const b21r_run_t* b = two[2 * k + 1];
    assert_true(a->start_x_m == b->start_x_m && a->start_y_m == b->start_y_m &&
                a->start_theta_rad == b->start_theta_rad);
  }
  assert_true(two[0]->start_x_m != two[2]->start_x_m || two[0]->start_y_m != two[2]->start_y_m);
  assert_true(two[2]->start_x_m != two[4]->start_x_m || two[2]->start_y_m != two[4]->start_y_m);
  harness_close(&g_h);
  fw_ckpt_writer_destroy(w);
  // The checkpoint holds the actor and the two ranked pairs: the steps the greedy policy saved are
  // the actor's runs' steps minus the greedy policy's (pair 0 greedy first, pair 1 the actor first).
  const fw_progress_t g = checkpoint_progress(c.checkpoint_file, payload_cap);
  assert_int_equal(g.revision, 4);
  assert_int_equal(g.policy, LEARN_POLICY_SELECT);
  assert_true(g.actor_bytes > 0);
  assert_int_equal(g.selection.pairs, 2);
  const double saved = ((double)two[1]->steps - (double)two[0]->steps) + ((double)two[2]->steps - (double)two[3]->steps);
  assert_true(g.selection.greedy_saved_steps == saved);
  // A restart takes the ranking up.
  char err[FW_LOOP_ERR_MAX];
  assert_int_equal(harness_open(&g_h, &c, false, 3), 0);
  assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), 1);
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.selection.pairs, 2);
  assert_true(st.selection.greedy_saved_steps == saved);
  harness_close(&g_h);
  remove(c.checkpoint_file);
  rmdir(dir);
}

static void test_loop_checkpoint_restart_resumes(void** state) {
  (void)state;
  char dir[] = "/tmp/b21r-loopckpt-XXXXXX";
  assert_non_null(mkdtemp(dir));
  fw_config_t c;
  harness_config(&c);
  c.phase_one_runs = 4;
  c.phase_two_runs = 2;
  c.eval_every_runs = 10;
  c.eval_starts = 1;
  c.policy = FW_POLICY_ACTOR;  // the checkpoint holds the actor too
  snprintf(c.checkpoint_file, sizeof c.checkpoint_file, "%s/hedger.ckpt", dir);
  assert_int_equal(harness_open(&g_h, &c, false, 3), 0);
  size_t meta_cap = 0;
  size_t payload_cap = 0;
  fw_ckpt_writer_t* w = attach_checkpoints(&c, &meta_cap, &payload_cap);
  char err[FW_LOOP_ERR_MAX];
  // Run until the checkpoint of the third training run is handed over (it is written in slices
  // while the robot stands after the run), then stop as after a power cut.
  fw_loop_stats_t st;
  do {
    harness_run(&g_h, 1);
    fw_loop_get_stats(g_h.loop, &st);
  } while (st.checkpoints_submitted < 3);
  assert_int_equal(st.training_runs, 3);
  fw_ckpt_writer_flush(w);
  const uint32_t fill = st.store_fill;
  harness_close(&g_h);
  fw_ckpt_writer_destroy(w);

  assert_int_equal(harness_open(&g_h, &c, false, 3), 0);
  assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), 1);
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.training_runs, 3);
  assert_int_equal(st.phase, 1);
  assert_int_equal(st.store_fill, fill);
  assert_true(st.best_example_steps > 0);
  harness_run(&g_h, 100000);
  fw_loop_get_stats(g_h.loop, &st);
  assert_true(st.done);
  assert_int_equal(st.training_runs, 6);
  assert_int_equal(st.phase, 2);
  harness_close(&g_h);

  // Valid checksums but a progress field out of range (as a bug or another writer could leave
  // it): refused like a corrupt file, naming the file, the field and the way out; the loop is
  // left as it was (the learner untouched too).
  uint8_t meta[FW_PROGRESS_BYTES];
  size_t ms = 0;
  size_t ps = 0;
  uint8_t* payload = malloc(payload_cap);
  assert_non_null(payload);
  assert_int_equal(fw_checkpoint_read(c.checkpoint_file, meta, sizeof meta, &ms, payload, payload_cap, &ps, err,
                                      sizeof err),
                   1);
  fw_progress_t g;
  assert_int_equal(fw_progress_decode(meta, ms, &g, NULL, 0), 0);
  assert_int_equal(g.schedule.training_runs, 3);  // written by the first session
  g.schedule.phase = 7;
  uint8_t bad[FW_PROGRESS_BYTES];
  const size_t bad_n = fw_progress_encode(&g, bad);
  assert_int_equal(fw_checkpoint_write(c.checkpoint_file, bad, bad_n, payload, ps, err, sizeof err), 0);
  assert_int_equal(harness_open(&g_h, &c, false, 3), 0);
  assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), -1);
  assert_non_null(strstr(err, c.checkpoint_file));
  assert_non_null(strstr(err, "is corrupt (controller section: phase 7, expected 1 or 2)"));
  assert_non_null(strstr(err, "to start fresh"));
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.training_runs, 0);
  assert_int_equal(st.phase, 1);
  assert_int_equal(st.store_fill, 0);
  harness_close(&g_h);

  // A header claiming more learned state than this configuration can hold is refused without
  // allocating that much (found by fuzz_checkpoint: the claimed size was allocated first).
  uint8_t header[FW_CHECKPOINT_HEADER_SIZE];
  memset(header, 0, sizeof header);
  memcpy(header, "B21RCKPT", 8);
  const uint64_t sizes[2] = {FW_PROGRESS_BYTES, (uint64_t)1 << 40};
  header[8] = FW_CHECKPOINT_VERSION;
  header[12] = FW_CHECKPOINT_HEADER_SIZE;
  for (int k = 0; k < 2; ++k) {
    for (int i = 0; i < 8; ++i) {
      header[16 + 8 * k + i] = (uint8_t)(sizes[k] >> (8 * i));
    }
  }
  const uint32_t hcrc = fw_crc32(0, header, 44);
  for (int i = 0; i < 4; ++i) {
    header[44 + i] = (uint8_t)(hcrc >> (8 * i));
  }
  FILE* hf = fopen(c.checkpoint_file, "wb");
  assert_non_null(hf);
  assert_int_equal(fwrite(header, 1, sizeof header, hf), sizeof header);
  fclose(hf);
  assert_int_equal(harness_open(&g_h, &c, false, 3), 0);
  assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), -1);
  assert_non_null(strstr(err, "more than this configuration can load"));
  assert_non_null(strstr(err, "to start fresh"));
  harness_close(&g_h);

  // The good file back: it loads again.
  assert_int_equal(fw_checkpoint_write(c.checkpoint_file, meta, ms, payload, ps, err, sizeof err), 0);
  assert_int_equal(harness_open(&g_h, &c, false, 3), 0);
  assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), 1);
  harness_close(&g_h);

  // Files without an actor (today's section with the greedy policy; revision 2; revision 1, an
  // older controller's 96-byte section, which added a policy shift learned from ranked pairs, without
  // and with a shift that had moved) hold HEDGER's values alone. They resume with their values and
  // progress. With policy = actor the actor starts as the policy of the values' stored points (a note
  // says so, and where a revision-1 shift had moved, that it is no longer used): an evaluation drives
  // alike from each of them, and otherwise than from today's file with its learned actor. With
  // policy = greedy every file, today's with its actor too (a note: the next checkpoint drops it),
  // drives as the values' greedy action, alike.
  fw_progress_t good;
  assert_int_equal(fw_progress_decode(meta, ms, &good, NULL, 0), 0);
  assert_int_equal(good.policy, LEARN_POLICY_ACTOR);
  assert_true(good.actor_bytes > 0 && good.actor_bytes < ps);
  const size_t values_n = ps - (size_t)good.actor_bytes;
  uint64_t eval_hash[2][5];
  for (int policy = 0; policy < 2; ++policy) {
    for (int variant = 0; variant < 5; ++variant) {
      uint8_t old[FW_PROGRESS_READ_MAX];
      memset(old, 0, sizeof old);
      size_t old_n = ms;
      if (variant == 0) {
        memcpy(old, meta, ms);
      } else {
        fw_progress_t values_only = good;
        values_only.policy = LEARN_POLICY_GREEDY;
        values_only.actor_bytes = 0;
        old_n = fw_progress_encode(&values_only, old);
      }
      if (variant == 2) {
        memcpy(old, "FWMETA02", 8);
        old_n = FW_PROGRESS_BYTES_2;
      } else if (variant >= 3) {
        memcpy(old, "FWMETA01", 8);
        memset(old + 56, 0, sizeof old - 56);
        old_n = 96;
        const double a = variant == 4 ? 0.75 : 0.0;
        memcpy(old + 56, &a, sizeof a);  // little-endian host (the tests run on x86-64 and arm64)
      }
      assert_int_equal(
          fw_checkpoint_write(c.checkpoint_file, old, old_n, payload, variant == 0 ? ps : values_n, err, sizeof err), 0);
      fw_config_t ce = c;
      ce.mode = FW_MODE_EVALUATE;
      ce.evaluate_policy = FW_EVAL_LEARNED;
      ce.eval_starts = 2;
      ce.policy = policy == 0 ? FW_POLICY_ACTOR : FW_POLICY_GREEDY;
      assert_int_equal(harness_open(&g_h, &ce, false, 3), 0);
      assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), 1);
      if (variant == 4) {
        assert_non_null(strstr(err, "note: checkpoint"));
        assert_non_null(strstr(err, "ranked pairs"));
      }
      if (policy == 0 && variant > 0) {
        assert_non_null(strstr(err, "holds no actor"));
      } else if (policy == 1 && variant == 0) {
        assert_non_null(strstr(err, "also holds an actor"));
      } else if (variant != 4) {
        assert_string_equal(err, "");
      }
      fw_loop_get_stats(g_h.loop, &st);
      assert_true(st.store_fill > 0);
      harness_run(&g_h, 100000);
      fw_loop_get_stats(g_h.loop, &st);
      assert_true(st.done);
      assert_int_equal(g_h.runs, 2);
      eval_hash[policy][variant] = g_h.exp_hash;
      harness_close(&g_h);
    }
  }
  for (int variant = 2; variant < 5; ++variant) {
    assert_true(eval_hash[0][variant] == eval_hash[0][1]);
  }
  assert_true(eval_hash[0][0] != eval_hash[0][1]);
  for (int variant = 1; variant < 5; ++variant) {
    assert_true(eval_hash[1][variant] == eval_hash[1][0]);
  }
  assert_int_equal(fw_checkpoint_write(c.checkpoint_file, meta, ms, payload, ps, err, sizeof err), 0);
  free(payload);

  // Learned with the executed rotation in the state (the default), loaded without it: refused
  // with the setting that continues it, and nothing loaded.
  assert_true(c.state_rotation);
  fw_config_t cr = c;
  cr.state_rotation = false;
  assert_int_equal(harness_open(&g_h, &cr, false, 3), 0);
  assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), -1);
  assert_non_null(strstr(err, c.checkpoint_file));
  assert_non_null(strstr(err, "set state_rotation = true to go on with it"));
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.store_fill, 0);
  harness_close(&g_h);

  // Learned with one decision_ticks, loaded with another (another discount per learned step):
  // refused, the message naming the setting that goes on with it, nothing loaded, the file kept.
  fw_config_t cn = c;
  cn.decision_ticks = c.decision_ticks == 1 ? 3 : 1;
  assert_int_equal(harness_open(&g_h, &cn, false, 3), 0);
  assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), -1);
  assert_non_null(strstr(err, c.checkpoint_file));
  char want[96];
  snprintf(want, sizeof want, "learned with decision_ticks = %d (this configuration: %d); set decision_ticks = %d",
           (int)c.decision_ticks, (int)cn.decision_ticks, (int)c.decision_ticks);
  assert_non_null(strstr(err, want));
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.store_fill, 0);
  harness_close(&g_h);
  // Another gamma that no decision_ticks gives: named as the discount, both settings to check.
  fw_config_t cg = c;
  cg.gamma = 0.95;
  assert_int_equal(harness_open(&g_h, &cg, false, 3), 0);
  assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), -1);
  assert_non_null(strstr(err, "set gamma and decision_ticks as when it was written"));
  harness_close(&g_h);
  // Other input scales (the stored points are in scaled units): refused, naming the scales it was
  // written with; the value named, set as given, loads it.
  assert_int_equal(c.hedger_input_scale_n, 0);  // the task's scales and the executed rotation's
  fw_config_t cs = c;
  const double other_scales[5] = {1.0, 0.5, 0.125, 2.0, 0.25};
  memcpy(cs.hedger_input_scale, other_scales, sizeof other_scales);
  cs.hedger_input_scale_n = 5;
  assert_int_equal(harness_open(&g_h, &cs, false, 3), 0);
  assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), -1);
  assert_non_null(strstr(err, "(this configuration: 1,0.5,0.125,2,0.25); set hedger_input_scale = "));
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.store_fill, 0);
  harness_close(&g_h);
  const char* named = strstr(err, "set hedger_input_scale = ") + strlen("set hedger_input_scale = ");
  cs.hedger_input_scale_n = 0;
  for (char* end = NULL;; named = end + 1) {
    cs.hedger_input_scale[cs.hedger_input_scale_n++] = strtod(named, &end);
    assert_true(end != named);
    if (*end != ',') break;
  }
  assert_int_equal(cs.hedger_input_scale_n, 5);
  assert_int_equal(harness_open(&g_h, &cs, false, 3), 0);
  assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), 1);
  fw_loop_get_stats(g_h.loop, &st);
  assert_true(st.store_fill > 0);
  harness_close(&g_h);
  {
    size_t ms2 = 0, ps2 = 0;
    assert_int_equal(fw_checkpoint_peek(c.checkpoint_file, &ms2, &ps2, err, sizeof err), 1);
    assert_int_equal(ps2, ps);  // every refusal kept the file as it was
  }

  // A directory given as the checkpoint is named as such (not "truncated").
  fw_config_t cd = c;
  snprintf(cd.checkpoint_file, sizeof cd.checkpoint_file, "%s", dir);
  assert_int_equal(harness_open(&g_h, &cd, false, 3), 0);
  assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), -1);
  assert_non_null(strstr(err, "is a directory"));
  assert_null(strstr(err, "truncated"));
  harness_close(&g_h);

  // Damage the file: refused, with the way out in the message.
  FILE* f = fopen(c.checkpoint_file, "r+b");
  assert_non_null(f);
  assert_int_equal(fseek(f, 200, SEEK_SET), 0);
  fputc(0xAB, f);
  fclose(f);
  assert_int_equal(harness_open(&g_h, &c, false, 3), 0);
  assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), -1);
  assert_non_null(strstr(err, "to start fresh"));
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.training_runs, 0);
  harness_close(&g_h);
  char cmd[128];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
  assert_int_equal(system(cmd), 0);
}

// A checkpoint of the obstacle task written before its state remembered the obstacle (four
// features, plus the executed rotation: a state of 5 and input scales 1,1,1,1,1 then 0.5 for the
// action) is refused with either state_rotation setting, naming the file and the way out, and
// nothing is loaded: with the rotation the state dimensions differ (6 against 5); without it
// they agree, and the learned state's input scales (the age's 3 s against the rotation's 1 rad/s)
// refuse it.
static void test_loop_old_obstacle_checkpoint_refused(void** state) {
  (void)state;
  char dir[] = "/tmp/b21r-loopobst-XXXXXX";
  assert_non_null(mkdtemp(dir));
  fw_config_t c;
  harness_config(&c);
  c.task = (int32_t)tasks_obstacles_decl.id;
  snprintf(c.checkpoint_file, sizeof c.checkpoint_file, "%s/hedger.ckpt", dir);
  assert_int_equal(tasks_obstacles_decl.state_dim, 5);
  // The old learned state: one stored sample in the old layout.
  hedger_config_t hc;
  fw_config_hedger(&c, &hc);
  assert_int_equal(hc.state_dim, 6);  // today: 5 features and the executed rotation
  hc.state_dim = 5;
  const double old_scale[6] = {1.0, 1.0, 1.0, 1.0, 1.0, 0.5};
  memcpy(hc.input_scale, old_scale, sizeof old_scale);
  hedger_t* old = NULL;
  assert_int_equal(hedger_create(&old, &hc), HEDGER_OK);
  const double s_old[5] = {0.1, 2.5, -0.3, 1.2, 0.0};
  assert_int_equal(hedger_observe_reward(old, 1.0), HEDGER_OK);
  assert_int_equal(hedger_observe_reward(old, -1.0), HEDGER_OK);
  assert_int_equal(hedger_insert(old, s_old, 0.2, 0.5, 0U, NULL), HEDGER_OK);
  const size_t ps = hedger_serialized_size(old);
  uint8_t* payload = malloc(ps);
  assert_non_null(payload);
  size_t written = 0;
  assert_int_equal(hedger_save(old, payload, ps, &written), HEDGER_OK);
  hedger_destroy(old);
  fw_progress_t g;
  memset(&g, 0, sizeof g);
  g.task = c.task;
  g.state_dim = 5U;
  g.schedule.phase = 1;
  g.schedule.training_runs = 3;
  g.schedule.phase_one_runs = 3;
  g.run_id = 2;
  uint8_t meta[FW_PROGRESS_BYTES];
  const size_t ms = fw_progress_encode(&g, meta);
  char err[FW_LOOP_ERR_MAX];
  assert_int_equal(fw_checkpoint_write(c.checkpoint_file, meta, ms, payload, written, err, sizeof err), 0);
  free(payload);
  for (int rotation = 1; rotation >= 0; --rotation) {
    fw_config_t cr = c;
    cr.state_rotation = rotation != 0;
    assert_int_equal(harness_open(&g_h, &cr, false, 3), 0);
    assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), -1);
    print_message("state_rotation %d: %s\n", rotation, err);
    assert_non_null(strstr(err, c.checkpoint_file));
    assert_non_null(strstr(err, "move the file away"));
    fw_loop_stats_t st;
    fw_loop_get_stats(g_h.loop, &st);
    assert_int_equal(st.store_fill, 0);
    assert_int_equal(st.training_runs, 0);
    harness_close(&g_h);
  }
  char cmd[128];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
  assert_int_equal(system(cmd), 0);
}

// Reads a whole file (NULL when absent); *n its size.
static uint8_t* slurp(const char* path, size_t* n) {
  *n = 0;
  FILE* f = fopen(path, "rb");
  if (f == NULL) {
    return NULL;
  }
  uint8_t* buf = malloc(1U << 24);
  assert_non_null(buf);
  *n = fread(buf, 1, 1U << 24, f);
  fclose(f);
  return buf;
}

static void spill(const char* path, const uint8_t* data, size_t n) {
  FILE* f = fopen(path, "wb");
  assert_non_null(f);
  assert_int_equal(fwrite(data, 1, n, f), n);
  fclose(f);
}

// A run reported done survives a kill before its checkpoint: B21R_RUN comes only once the run's
// journal record is on disk, and a loop resuming from the checkpoint and the journal learns the
// journalled runs again to exactly the learned state, progress and run id of the uninterrupted
// loop (its state saved once the run's between-run work is done), for an evaluation run (2) and a
// training run (4). A torn record at the journal's end is ignored, and the resumed loop finishes
// the schedule.
static void journal_kill_after(int32_t kill_run, int32_t training_runs) {
  char dir[] = "/tmp/b21r-loopjournal-XXXXXX";
  assert_non_null(mkdtemp(dir));
  fw_config_t c;
  harness_config(&c);
  c.phase_one_runs = 4;
  c.phase_two_runs = 2;
  c.eval_every_runs = 2;
  c.eval_starts = 1;
  c.hedger_replay_passes = 3;
  c.learn_updates_per_tick = 2;  // the replay spans many ticks: the kill falls inside it
  snprintf(c.checkpoint_file, sizeof c.checkpoint_file, "%s/hedger.ckpt", dir);
  char journal[sizeof c.checkpoint_file + 16];
  snprintf(journal, sizeof journal, "%s.journal", c.checkpoint_file);
  char err[FW_LOOP_ERR_MAX];
  size_t meta_cap = 0;
  size_t payload_cap = 0;

  assert_int_equal(harness_open(&g_h, &c, false, 5), 0);
  fw_ckpt_writer_t* w = attach_checkpoints(&c, &meta_cap, &payload_cap);
  // Runs 0, 1 train, 2 evaluates, 3, 4 train. Until the report of kill_run; the writer is flushed
  // after every tick so that what is on disk does not depend on its speed.
  fw_loop_stats_t st;
  int32_t reported = -1;
  while (reported < kill_run) {
    harness_run(&g_h, 1);
    fw_ckpt_writer_flush(w);
    if (g_h.runs > 0) {
      reported = g_h.run[g_h.runs - 1].run_id;
    }
  }
  assert_int_equal(reported, kill_run);
  assert_int_equal(g_h.run[2].kind, B21R_RUN_T_KIND_EVALUATION);
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.run_id, kill_run);
  assert_int_equal(st.training_runs, training_runs);
  // The kill: what is on disk now. The checkpoint covers an earlier run; kill_run is journalled.
  size_t ck_n = 0;
  size_t j_n = 0;
  uint8_t* ck = slurp(c.checkpoint_file, &ck_n);
  uint8_t* jr = slurp(journal, &j_n);
  assert_non_null(ck);
  assert_non_null(jr);
  uint8_t meta[FW_PROGRESS_READ_MAX];
  size_t ms = 0;
  size_t ps = 0;
  uint8_t* payload = malloc(payload_cap);
  assert_non_null(payload);
  assert_int_equal(fw_checkpoint_read(c.checkpoint_file, meta, sizeof meta, &ms, payload, payload_cap, &ps, err,
                                      sizeof err),
                   1);
  fw_progress_t g;
  assert_int_equal(fw_progress_decode(meta, ms, &g, NULL, 0), 0);
  print_message("at the kill after run %d: checkpoint after run %d, journal %zu bytes\n", (int)kill_run,
                (int)g.run_id, j_n);
  assert_true(g.run_id < kill_run);
  assert_true(j_n > 0);
  // The uninterrupted loop: its state once the run's between-run work is done is the reference.
  assert_int_equal(fw_loop_shutdown(g_h.loop), 0);
  size_t ref_n = 0;
  uint8_t* ref = slurp(c.checkpoint_file, &ref_n);
  assert_non_null(ref);
  harness_close(&g_h);
  fw_ckpt_writer_destroy(w);

  // Resume from the files as the kill left them, plus part of a record (a kill during an append).
  spill(c.checkpoint_file, ck, ck_n);
  uint8_t* torn = malloc(j_n + 40);
  assert_non_null(torn);
  memcpy(torn, jr, j_n);
  memcpy(torn + j_n, jr, 40);
  spill(journal, torn, j_n + 40);
  assert_int_equal(harness_open(&g_h, &c, false, 5), 0);
  assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), 1);
  print_message("%s\n", err);
  assert_non_null(strstr(err, "learned again"));
  fw_loop_get_stats(g_h.loop, &st);
  assert_int_equal(st.run_id, kill_run);
  assert_int_equal(st.training_runs, training_runs);
  w = attach_checkpoints(&c, &meta_cap, &payload_cap);
  // The torn tail is cut, the resumed records kept.
  size_t kept = 0;
  free(slurp(journal, &kept));
  assert_int_equal(kept, j_n);
  // The resumed state, saved at once, is the uninterrupted loop's byte for byte.
  assert_int_equal(fw_loop_shutdown(g_h.loop), 0);
  size_t got_n = 0;
  uint8_t* got = slurp(c.checkpoint_file, &got_n);
  assert_non_null(got);
  assert_int_equal(got_n, ref_n);
  assert_memory_equal(got, ref, ref_n);
  harness_close(&g_h);
  fw_ckpt_writer_destroy(w);

  // Resumed again (from that checkpoint, the journal now emptied), the schedule completes.
  free(slurp(journal, &kept));
  assert_int_equal(kept, 0);
  assert_int_equal(harness_open(&g_h, &c, false, 5), 0);
  assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), 1);
  w = attach_checkpoints(&c, &meta_cap, &payload_cap);
  harness_run(&g_h, 100000);
  fw_loop_get_stats(g_h.loop, &st);
  assert_true(st.done);
  assert_int_equal(st.training_runs, 6);
  assert_int_equal(g_h.run[0].run_id, kill_run + 1);
  harness_close(&g_h);
  fw_ckpt_writer_destroy(w);
  free(ck);
  free(jr);
  free(torn);
  free(ref);
  free(got);
  free(payload);
  char cmd[128];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
  assert_int_equal(system(cmd), 0);
}

static void test_loop_journal_resumes_reported_runs_exactly(void** state) {
  (void)state;
  journal_kill_after(2, 2);
  journal_kill_after(4, 4);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_loop_learns_corridor_reaches_goal_from_all_poses),
      cmocka_unit_test(test_loop_same_seed_bit_identical_experiences),
      cmocka_unit_test(test_loop_state_rotation_is_the_executed_command),
      cmocka_unit_test(test_loop_decision_ticks_hold_and_learn_each_decision),
      cmocka_unit_test(test_loop_canopen_stream_independent_of_answer_lag),
      cmocka_unit_test(test_loop_tick_allocates_nothing),
      cmocka_unit_test(test_loop_checkpoint_restart_resumes),
      cmocka_unit_test(test_loop_select_pairs_share_start_and_checkpoint),
      cmocka_unit_test(test_loop_old_obstacle_checkpoint_refused),
      cmocka_unit_test(test_loop_journal_resumes_reported_runs_exactly),
  };
  return cmocka_run_group_tests_name("firmware.loop", tests, NULL, NULL);
}
