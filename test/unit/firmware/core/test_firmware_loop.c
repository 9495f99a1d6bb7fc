// SPDX-License-Identifier: MIT
// Loop core over the fake lockstep robot: learns the corridor from examples, is deterministic,
// allocates nothing per tick, and reacts to every safety cause within one tick.
#define _POSIX_C_SOURCE 200809L
#include "loop_harness.h"

#include "fw/progress.h"
#include "fw/safety.h"
#include "fw/shift_vet.h"

#include <b21r_test/alloc_counter.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

static harness_t g_h;

// The paper's 30 example runs, then 5 learned runs; one block after each phase (a block every
// 5 runs, and the default 20 replay passes, cost too much time in the sanitizer build; the
// integration tests and the main job run the defaults and the paper's cadence).
static void short_schedule(fw_config_t* c) {
  harness_config(c);
  c->phase_one_runs = 30;
  c->phase_two_runs = 5;
  c->eval_every_runs = 30;
  c->hedger_replay_passes = 4;
  c->progress = true;
}

// The pair tests' session: short_schedule with 10 phase-one runs, phase_two_runs phase-two runs,
// an evaluation of 2 poses every 10 runs (so one, after phase one), pair runs on.
static void pair_session_schedule(fw_config_t* c, int32_t phase_two_runs) {
  short_schedule(c);
  c->phase_one_runs = 10;
  c->phase_two_runs = phase_two_runs;
  c->eval_every_runs = 10;
  c->eval_starts = 2;
  c->pair_runs_mode = FW_PAIR_RUNS_ON;
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

// The ranker's rule (fw_pair_ranker_end, tested alone below) applied by hand to a pair's two
// B21R_RUN records (a: the first run, b: the second): moves shift[] (gain, centring, imitation) as
// the controller should have (within the imitation's bounds; the others' are tested alone).
static void expect_pair_step(const fw_config_t* c, const b21r_run_t* a, const b21r_run_t* b, double shift[3]) {
  const bool ga = a->end_reason == B21R_RUN_T_END_GOAL && !a->pair_vetoed;
  const bool gb = b->end_reason == B21R_RUN_T_END_GOAL && !b->pair_vetoed;
  const double u = ga && gb ? tanh((double)(b->steps - a->steps) / c->pair_shift_tau_steps)
                            : (ga == gb ? 0.0 : (ga ? 1.0 : -1.0));
  const double k = c->pair_shift_decay_pairs;
  const double rate = c->pair_shift_rate * k / (k + (double)a->shift_pairs);
  shift[0] += rate * u * a->pair_gain;
  shift[1] += rate * u * a->pair_centring;
  shift[2] = fmin(FW_PAIR_IMITATION_MAX, fmax(FW_PAIR_IMITATION_MIN, shift[2] + rate * u * a->pair_imitation));
}

// pair_runs: phase two's training runs come in pairs from one start pose (the B21R_RUN start
// poses of a pair are equal, those of different pairs differ), every pair's ranking reaches the
// store between runs, and the same seed still gives the same experience stream. The imitation's
// weight is perturbed and moved only with pair_imitation_sigma > 0 (repetitions 2 and 3).
static void test_loop_pair_runs_share_start_and_rank(void** state) {
  (void)state;
  uint64_t hash[4];
  for (int rep = 0; rep < 4; ++rep) {
    const bool imitation = rep >= 2;
    fw_config_t c;
    pair_session_schedule(&c, 6);
    c.pair_shift_vet = false;  // the ranker's rule alone (the vet: test_loop_shift_vet_runs_between_runs)
    c.pair_imitation_sigma = imitation ? 0.25 : 0.0;
    assert_int_equal(harness_open(&g_h, &c, false, 9), 0);
    harness_run(&g_h, 200000);
    fw_loop_stats_t st;
    fw_loop_get_stats(g_h.loop, &st);
    assert_true(st.done);
    assert_int_equal(st.training_runs, 16);
    assert_int_equal(st.pairs_ranked, 3);
    const b21r_run_t* two[6];
    int n = 0;
    for (int i = 0; i < g_h.runs && i < 64; ++i) {
      const b21r_run_t* r = &g_h.run[i];
      if (r->kind == B21R_RUN_T_KIND_TRAINING && r->phase == 2 && n < 6) {
        two[n++] = r;
      } else {
        assert_int_equal(r->pair_member, -1);  // phase one and evaluations: no pair
      }
    }
    assert_int_equal(n, 6);
    for (int i = 0; i < 6; ++i) {
      assert_int_equal(two[i]->pair_member, i % 2);  // B21R_RUN says which run of its pair it was
    }
    // B21R_RUN carries each pair's perturbation and the shift in force; the shift moves by the
    // ranker's rule after each pair (fw_pair_ranker_end, tested alone below) and nowhere else.
    double shift[3] = {0.0, 0.0, 0.0};
    for (int p = 0; p < 3; ++p) {
      const b21r_run_t* a = two[2 * p];
      const b21r_run_t* b = two[2 * p + 1];
      assert_true(a->pair_gain == b->pair_gain && a->pair_centring == b->pair_centring &&
                  a->pair_imitation == b->pair_imitation);
      assert_true(a->pair_gain != 0.0 && a->pair_centring != 0.0);
      assert_true(imitation ? a->pair_imitation != 0.0 : a->pair_imitation == 0.0);
      assert_true(a->shift_gain == shift[0] && a->shift_centring == shift[1] && a->shift_imitation == shift[2]);
      assert_true(b->shift_gain == shift[0] && b->shift_centring == shift[1] && b->shift_imitation == shift[2]);
      assert_int_equal(a->shift_pairs, p);
      expect_pair_step(&c, a, b, shift);
    }
    assert_true(st.shift.gain == shift[0] && st.shift.centring == shift[1] && st.shift.imitation == shift[2]);
    assert_true(shift[0] != 0.0 || shift[1] != 0.0);
    assert_true(imitation ? shift[2] != 0.0 : shift[2] == 0.0);
    for (int p = 0; p < 3; ++p) {
      const b21r_run_t* a = two[2 * p];
      const b21r_run_t* b = two[2 * p + 1];
      assert_true(a->start_x_m == b->start_x_m && a->start_y_m == b->start_y_m &&
                  a->start_theta_rad == b->start_theta_rad);
      if (p > 0) assert_true(a->start_x_m != two[2 * p - 2]->start_x_m);
    }
    assert_int_equal(g_h.exp_gaps, 0);
    hash[rep] = g_h.exp_hash;
    harness_close(&g_h);
  }
  assert_true(hash[0] == hash[1]);
  assert_true(hash[2] == hash[3]);
  assert_true(hash[0] != hash[2]);  // the imitation's perturbation changed what the pairs drove
}

// pair_shift_vet in the controller, with perturbations far beyond the defaults (large steps):
// each ranked pair's step waits for the vet between runs, and the next pair's B21R_RUN shows the
// whole step, a fraction of it or none (the cut ones counted as the vet's), after the vet drove every
// step on the model from its starts (at least 10 training runs' and their mirror images). Without
// the vet the shift moves by the rule alone and nothing is driven. Here the fake corridor's pairs
// rank steps the model finds safe, so every step is taken: which steps the vet cuts, and why, is
// firmware.shift_vet's test.
static void test_loop_shift_vet_runs_between_runs(void** state) {
  (void)state;
  for (int vet = 0; vet < 2; ++vet) {
    fw_config_t c;
    pair_session_schedule(&c, 8);
    c.pair_gain_sigma = 3.0;
    c.pair_centring_sigma = 3.0;
    c.pair_imitation_sigma = 0.5;
    c.pair_shift_vet = vet == 1;
    assert_int_equal(harness_open(&g_h, &c, false, 9), 0);
    harness_run(&g_h, 300000);
    fw_loop_stats_t st;
    fw_loop_get_stats(g_h.loop, &st);
    assert_true(st.done);
    // The pairs' runs in order: a first run (member 0) and its second (member 1) each.
    const b21r_run_t* pr[64];
    int n = 0;
    for (int i = 0; i < g_h.runs && i < 64; ++i) {
      if (g_h.run[i].kind == B21R_RUN_T_KIND_TRAINING && g_h.run[i].pair_member >= 0) {
        pr[n++] = &g_h.run[i];
      }
    }
    assert_int_equal(n, 2 * st.pairs_ranked);
    int cut = 0;
    int moved = 0;  // pairs whose rule step moves the shift (the others are decided without a rollout)
    for (int p = 0; p < st.pairs_ranked; ++p) {
      const b21r_run_t* a = pr[2 * p];
      assert_int_equal(a->pair_member, 0);
      assert_int_equal(pr[2 * p + 1]->pair_member, 1);
      const double before[3] = {a->shift_gain, a->shift_centring, a->shift_imitation};
      double rule[3] = {before[0], before[1], before[2]};
      expect_pair_step(&c, a, pr[2 * p + 1], rule);
      for (int k = 0; k < 2; ++k) {
        rule[k] = fmin(FW_PAIR_SHIFT_MAX, fmax(-FW_PAIR_SHIFT_MAX, rule[k]));  // as the ranker bounds it
      }
      // The shift the next pair drove with (after the last pair: the session's).
      const bool last = p + 1 == st.pairs_ranked;
      const double taken[3] = {last ? st.shift.gain : pr[2 * p + 2]->shift_gain,
                               last ? st.shift.centring : pr[2 * p + 2]->shift_centring,
                               last ? st.shift.imitation : pr[2 * p + 2]->shift_imitation};
      if (!last) {
        assert_int_equal(pr[2 * p + 2]->shift_pairs, p + 1);  // the pair counts whatever the verdict
      }
      bool whole = true;
      bool none = true;
      bool rule_moves = false;
      for (int k = 0; k < 3; ++k) {
        whole = whole && taken[k] == rule[k];
        none = none && taken[k] == before[k];
        rule_moves = rule_moves || rule[k] != before[k];
      }
      moved += rule_moves ? 1 : 0;
      bool fraction = false;  // a half, a quarter or an eighth of the step (FW_SHIFT_VET_HALVINGS), all three terms
      for (int k = 1; k <= FW_SHIFT_VET_HALVINGS; ++k) {
        const double f = ldexp(1.0, -k);
        bool all = true;
        for (int j = 0; j < 3; ++j) {
          all = all && fabs(taken[j] - (before[j] + f * (rule[j] - before[j]))) < 1e-12;
        }
        fraction = fraction || all;
      }
      assert_true(whole || fraction || none);
      if (vet == 0) {
        assert_true(whole);
      }
      cut += whole ? 0 : 1;
    }
    assert_int_equal(cut, st.shift_steps_halved + st.shift_steps_refused);
    // With the vet every step that moves the shift was driven on the model from at least 10 starts
    // and their mirror images (at least 100 periods per rollout) before the next run; without it
    // nothing was.
    assert_true(st.shift.imitation != 0.0);  // the imitation's weight moved too
    if (vet == 1) {
      assert_true(moved >= 1);
      assert_true(st.shift_vet_periods >= (int64_t)moved * 2 * 10 * 100);
    } else {
      assert_int_equal(st.shift_vet_periods, 0);
    }
    harness_close(&g_h);
  }
}

// pair_phase_one: from training run pair_phase_one_from_run on, phase one's example runs come in
// pairs too. A pair's two runs start from one pose with the same example gain and dither and
// differ by exactly the pair's perturbation (+ then -); the examples still drive every step; the
// pairs move the shift by the ranker's rule during phase one, so the evaluation after phase one
// already has it, and phase two goes on counting from there. Before that run, and with
// pair_phase_one = false, phase one is the plain examples. Paired from run 5 of 10, the last
// phase-one run is left without its pair: phase two starts a pair of its own (a pair never spans
// the switch). With pair_imitation_sigma (variant 3, without the dither so that the example's
// own action is the mean of the pair's first commands) the perturbation also weighs the
// example's action by m.
static void test_loop_phase_one_pairs(void** state) {
  (void)state;
  for (int variant = 0; variant < 4; ++variant) {
    const bool on = variant > 0;
    const int32_t from_run = variant == 2 ? 5 : 4;
    const int32_t phase_one_pairs = on ? (10 - from_run) / 2 : 0;
    fw_config_t c;
    pair_session_schedule(&c, 2);
    c.pair_shift_vet = false;  // the ranker's rule alone (the vet: test_loop_shift_vet_runs_between_runs)
    c.pair_phase_one = on;
    c.pair_phase_one_from_run = from_run;
    if (variant == 3) {
      c.pair_imitation_sigma = 0.25;
      c.example_noise_radps = 0.0;
    }
    assert_int_equal(harness_open(&g_h, &c, false, 9), 0);
    g_h.fake.lidar.noise_sigma_m = 0.0;  // a pair's two runs then see the same first state
    harness_run(&g_h, 200000);
    fw_loop_stats_t st;
    fw_loop_get_stats(g_h.loop, &st);
    assert_true(st.done);
    assert_int_equal(st.training_runs, 12);
    assert_int_equal(st.pairs_ranked, phase_one_pairs + 1);
    const b21r_run_t* one[10];
    int n = 0;
    int phase_two_runs = 0;
    for (int i = 0; i < g_h.runs && i < 64; ++i) {
      const b21r_run_t* r = &g_h.run[i];
      if (r->kind == B21R_RUN_T_KIND_TRAINING && r->phase == 1) {
        assert_true(n < 10);
        one[n++] = r;
        assert_int_equal(r->steps_by_source[B21R_EXPERIENCE_T_SOURCE_EXAMPLE], r->steps);  // the examples drive
      } else if (r->kind == B21R_RUN_T_KIND_TRAINING) {
        assert_int_equal(r->shift_pairs, phase_one_pairs);  // phase two counts on from phase one's pairs
        assert_int_equal(r->pair_member, phase_two_runs % 2);  // phase two's first run starts a pair
        phase_two_runs++;
      }
    }
    assert_int_equal(n, 10);
    assert_int_equal(phase_two_runs, 2);
    double shift[3] = {0.0, 0.0, 0.0};
    int compared = 0;
    for (int i = 0; i < 10; ++i) {
      const b21r_run_t* r = one[i];
      assert_int_equal(r->pair_member, on && i >= from_run ? (i - from_run) % 2 : -1);
      assert_true(r->shift_gain == shift[0] && r->shift_centring == shift[1] && r->shift_imitation == shift[2]);
      if (r->pair_member != 1) {
        continue;
      }
      const b21r_run_t* a = one[i - 1];
      assert_true(a->pair_gain == r->pair_gain && a->pair_centring == r->pair_centring && a->pair_gain != 0.0);
      assert_true(a->pair_imitation == r->pair_imitation && (variant == 3) == (a->pair_imitation != 0.0));
      assert_true(a->start_x_m == r->start_x_m && a->start_y_m == r->start_y_m &&
                  a->start_theta_rad == r->start_theta_rad);
      // The first commands: the same example action (gain, dither) plus and minus the perturbation
      // (where the acceleration limit from rest, 0.29 rad/s per tick, did not cut either).
      const double* s0 = g_h.run_first_s[a->run_id];
      const double* s1 = g_h.run_first_s[r->run_id];
      assert_true(s0[0] == s1[0] && s0[1] == s1[1] && s0[2] == s1[2]);
      const double a0 = g_h.run_first_action[a->run_id];
      const double a1 = g_h.run_first_action[r->run_id];
      if (fabs(a0) < 0.28 && fabs(a1) < 0.28) {
        const double own = 0.5 * (a0 + a1);  // the example's action (variant 3: no dither)
        const double offset = a->pair_gain * s0[2] + a->pair_centring * (s0[1] - 0.5) + a->pair_imitation * own;
        assert_true(fabs(0.5 * (a0 - a1) - offset) < 1e-12);
        compared++;
      }
      expect_pair_step(&c, a, r, shift);
    }
    assert_true(!on || shift[0] != 0.0 || shift[1] != 0.0);
    assert_true(variant != 1 || compared > 0);  // (seed 9: the first commands of a pair compared)
    assert_true(variant != 3 || (compared > 0 && shift[2] != 0.0));
    // The evaluation after phase one drove with the shift phase one's pairs learned.
    int evaluated = 0;
    for (int i = 0; i < g_h.runs && i < 64 && evaluated == 0; ++i) {
      const b21r_run_t* r = &g_h.run[i];
      if (r->kind == B21R_RUN_T_KIND_EVALUATION) {
        assert_true(r->shift_gain == shift[0] && r->shift_centring == shift[1] && r->shift_imitation == shift[2]);
        evaluated++;
      }
    }
    assert_int_equal(evaluated, 1);
    harness_close(&g_h);
  }
}

// Run tags increase from run to run: a run's id while the ids run ahead of the store's tag, else
// one past the tag (a resume from a b21r-train checkpoint starts its ids again at 0).
static void test_pair_run_tag_always_increases(void** state) {
  (void)state;
  assert_int_equal(fw_pair_run_tag(40, 30), 40);
  assert_int_equal(fw_pair_run_tag(31, 30), 31);
  assert_int_equal(fw_pair_run_tag(30, 30), 31);
  assert_int_equal(fw_pair_run_tag(5, 30), 31);
  assert_int_equal(fw_pair_run_tag(0, 0), 1);
  assert_int_equal(fw_pair_run_tag(-1, 0), 1);
  assert_true(fw_pair_run_tag(3, UINT32_MAX) == UINT32_MAX);
}

// The ranker's rule for the learned policy's shift: the faster run's side of the perturbation by
// tanh(d / tau) times the rate, a run that missed the goal loses, two that missed move nothing,
// the bound holds, both runs weigh 0; with rate 0 the old imitation weights and no shift.
static void test_pair_ranker_moves_the_shift(void** state) {
  (void)state;
  fw_config_t c;
  fw_config_defaults(&c);
  assert_true(c.pair_shift_rate == 1.0 && c.pair_shift_tau_steps == 2.0 && c.pair_shift_decay_pairs == 30.0);
  c.pair_shift_decay_pairs = 0.0;  // a constant rate first; the falling one at the end
  fw_pair_ranker_t r;
  memset(&r, 0, sizeof r);
  uint32_t tags[2];
  double w[2];
  // First run (+perturbation) 140 steps, second (−) 142: the first was faster by 2.
  assert_int_equal(fw_pair_ranker_end(&r, &c, false, 0, false, true, 140, 7, 0.2, -0.4, 0.1, tags, w), 1);
  assert_true(w[0] == 0.0 && tags[0] == 7);
  assert_int_equal(fw_pair_ranker_end(&r, &c, false, 1, false, true, 142, 8, 0.2, -0.4, 0.1, tags, w), 2);
  assert_true(tags[0] == 7 && tags[1] == 8 && w[0] == 0.0 && w[1] == 0.0);
  assert_true(fabs(r.shift.gain - 0.2 * tanh(1.0)) < 1e-15 && fabs(r.shift.centring + 0.4 * tanh(1.0)) < 1e-15);
  assert_true(fabs(r.shift.imitation - 0.1 * tanh(1.0)) < 1e-15);  // the imitation's weight by the same rule
  const double a1 = r.shift.gain;
  const double w1 = r.shift.imitation;
  const double b1 = r.shift.centring;
  // The first run missed the goal (or the filter corrected it): the second's side, in full.
  (void)fw_pair_ranker_end(&r, &c, false, 0, false, false, 300, 9, 0.5, 1.0, -0.3, tags, w);
  (void)fw_pair_ranker_end(&r, &c, false, 1, false, true, 150, 10, 0.5, 1.0, -0.3, tags, w);
  assert_true(r.shift.gain == a1 - 0.5 && r.shift.centring == b1 - 1.0 && r.shift.imitation == w1 + 0.3);
  // Both missed: nothing is learned.
  (void)fw_pair_ranker_end(&r, &c, false, 0, false, false, 300, 11, 0.5, 1.0, -0.3, tags, w);
  (void)fw_pair_ranker_end(&r, &c, false, 1, false, false, 300, 12, 0.5, 1.0, -0.3, tags, w);
  assert_true(r.shift.gain == a1 - 0.5 && r.shift.centring == b1 - 1.0);
  // A second run without its first (an aborted first run) ranks nothing and moves nothing.
  (void)fw_pair_ranker_end(&r, &c, false, 0, true, false, 20, 13, 3.0, 3.0, 3.0, tags, w);
  assert_int_equal(fw_pair_ranker_end(&r, &c, false, 1, false, true, 140, 14, 3.0, 3.0, 3.0, tags, w), 0);
  assert_true(r.shift.gain == a1 - 0.5);
  // The bound: at most FW_PAIR_SHIFT_MAX per component.
  c.pair_shift_rate = 4.0;
  for (int i = 0; i < 4; ++i) {
    (void)fw_pair_ranker_end(&r, &c, false, 0, false, true, 100, 20U + 2U * (uint32_t)i, 2.0, -2.0, 0.5, tags, w);
    (void)fw_pair_ranker_end(&r, &c, false, 1, false, true, 200, 21U + 2U * (uint32_t)i, 2.0, -2.0, 0.5, tags, w);
  }
  assert_true(r.shift.gain == FW_PAIR_SHIFT_MAX && r.shift.centring == -FW_PAIR_SHIFT_MAX);
  assert_true(r.shift.imitation == FW_PAIR_IMITATION_MAX);  // its own bounds, [-1, 1]
  for (int i = 0; i < 4; ++i) {
    (void)fw_pair_ranker_end(&r, &c, false, 0, false, true, 200, 30U + 2U * (uint32_t)i, 0.0, 0.0, 0.5, tags, w);
    (void)fw_pair_ranker_end(&r, &c, false, 1, false, true, 100, 31U + 2U * (uint32_t)i, 0.0, 0.0, 0.5, tags, w);
  }
  assert_true(r.shift.imitation == FW_PAIR_IMITATION_MIN && r.shift.gain == FW_PAIR_SHIFT_MAX);
  // Rate 0: the ranking weighs the runs in the imitation and the shift stays.
  c.pair_shift_rate = 0.0;
  (void)fw_pair_ranker_end(&r, &c, false, 0, false, true, 140, 40, 0.2, 0.4, 0.1, tags, w);
  (void)fw_pair_ranker_end(&r, &c, false, 1, false, true, 141, 41, 0.2, 0.4, 0.1, tags, w);
  assert_true(fabs(w[0] - 2.0 / (1.0 + exp(-1.0 / c.pair_tau_steps))) < 1e-15 && fabs(w[0] + w[1] - 2.0) < 1e-15);
  assert_true(r.shift.gain == FW_PAIR_SHIFT_MAX && r.shift.centring == -FW_PAIR_SHIFT_MAX);
  // Pairs of the example policy (phase one): the same step, and both runs stay imitated (weight
  // 1: their perturbations cancel there); with rate 0 they are ranked into the imitation instead.
  fw_pair_ranker_t e;
  memset(&e, 0, sizeof e);
  c.pair_shift_rate = 1.0;
  c.pair_shift_decay_pairs = 0.0;
  assert_int_equal(fw_pair_ranker_end(&e, &c, true, 0, false, true, 140, 60, 0.2, -0.4, 0.1, tags, w), 1);
  assert_true(tags[0] == 60 && w[0] == 1.0);
  assert_int_equal(fw_pair_ranker_end(&e, &c, true, 1, false, true, 142, 61, 0.2, -0.4, 0.1, tags, w), 2);
  assert_true(tags[0] == 60 && tags[1] == 61 && w[0] == 1.0 && w[1] == 1.0);
  assert_true(fabs(e.shift.gain - 0.2 * tanh(1.0)) < 1e-15 && fabs(e.shift.centring + 0.4 * tanh(1.0)) < 1e-15);
  assert_int_equal(e.shift.pairs, 1);
  c.pair_shift_rate = 0.0;
  (void)fw_pair_ranker_end(&e, &c, true, 0, false, true, 140, 62, 0.2, 0.4, 0.1, tags, w);
  assert_true(w[0] == 0.0);
  (void)fw_pair_ranker_end(&e, &c, true, 1, false, true, 141, 63, 0.2, 0.4, 0.1, tags, w);
  assert_true(fabs(w[0] - 2.0 / (1.0 + exp(-1.0 / c.pair_tau_steps))) < 1e-15 && fabs(w[0] + w[1] - 2.0) < 1e-15);
  assert_true(fabs(e.shift.gain - 0.2 * tanh(1.0)) < 1e-15);
  // The falling rate: after n pairs a pair moves the shift by rate * K / (K + n) of its side.
  fw_pair_ranker_t q;
  memset(&q, 0, sizeof q);
  c.pair_shift_rate = 1.0;
  c.pair_shift_decay_pairs = 30.0;
  q.shift.pairs = 90;
  (void)fw_pair_ranker_end(&q, &c, false, 0, false, false, 300, 50, 0.4, -0.8, 0.2, tags, w);
  (void)fw_pair_ranker_end(&q, &c, false, 1, false, true, 150, 51, 0.4, -0.8, 0.2, tags, w);
  assert_true(fabs(q.shift.gain + 0.4 * 0.25) < 1e-15 && fabs(q.shift.centring - 0.8 * 0.25) < 1e-15);
  assert_int_equal(q.shift.pairs, 91);
  // A non-finite perturbation (a damaged log record) moves nothing.
  (void)fw_pair_ranker_end(&q, &c, false, 0, false, true, 140, 52, NAN, 0.5, 0.1, tags, w);
  (void)fw_pair_ranker_end(&q, &c, false, 1, false, true, 150, 53, NAN, 0.5, 0.1, tags, w);
  assert_true(fabs(q.shift.gain + 0.4 * 0.25) < 1e-15 && fabs(q.shift.centring - 0.8 * 0.25) < 1e-15);
  // Among obstacles a step leaves the bend's coefficient at FW_PAIR_OBSTACLE_CENTRING_MIN at
  // least (0: the bend only widens the berth), where the corridor's goes down to
  // -FW_PAIR_SHIFT_MAX; the gain moves as in the corridor, and a step up is taken whole.
  fw_pair_ranker_t o;
  memset(&o, 0, sizeof o);
  fw_config_t oc = c;
  oc.task = FW_TASK_OBSTACLES;
  oc.pair_shift_decay_pairs = 0.0;
  o.shift.centring = 0.3;
  (void)fw_pair_ranker_end(&o, &oc, false, 0, false, true, 140, 70, 0.4, -0.8, 0.0, tags, w);
  (void)fw_pair_ranker_end(&o, &oc, false, 1, false, true, 150, 71, 0.4, -0.8, 0.0, tags, w);
  const double u = tanh(10.0 / oc.pair_shift_tau_steps);
  assert_true(o.shift.centring == FW_PAIR_OBSTACLE_CENTRING_MIN && fabs(o.shift.gain - 0.4 * u) < 1e-15);
  (void)fw_pair_ranker_end(&o, &oc, false, 0, false, true, 140, 72, 0.0, 0.5, 0.0, tags, w);
  (void)fw_pair_ranker_end(&o, &oc, false, 1, false, true, 150, 73, 0.0, 0.5, 0.0, tags, w);
  assert_true(fabs(o.shift.centring - 0.5 * u) < 1e-15);
  fw_pair_ranker_t k;
  memset(&k, 0, sizeof k);
  fw_config_t kc = oc;
  kc.task = FW_TASK_CORRIDOR;
  k.shift.centring = 0.3;
  (void)fw_pair_ranker_end(&k, &kc, false, 0, false, true, 140, 74, 0.4, -0.8, 0.0, tags, w);
  (void)fw_pair_ranker_end(&k, &kc, false, 1, false, true, 150, 75, 0.4, -0.8, 0.0, tags, w);
  assert_true(fabs(k.shift.centring - (0.3 - 0.8 * u)) < 1e-15 && k.shift.centring < 0.0);
  const double q_imitation = q.shift.imitation;
  (void)fw_pair_ranker_end(&q, &c, false, 0, false, true, 140, 54, 0.4, 0.5, NAN, tags, w);
  (void)fw_pair_ranker_end(&q, &c, false, 1, false, true, 150, 55, 0.4, 0.5, NAN, tags, w);
  assert_true(fabs(q.shift.gain + 0.4 * 0.25) < 1e-15 && q.shift.imitation == q_imitation);
  // The shift at a state: a * target angle + b * (lateral fraction - 0.5); the learned policy
  // (1 + w) * greedy plus that.
  r.shift.gain = 0.5;
  r.shift.centring = -2.0;
  r.shift.imitation = -0.75;
  const double s[3] = {5.0, 0.75, 0.2};
  assert_true(fabs(fw_pair_shift_at(&r.shift, FW_TASK_CORRIDOR, 0.5, s) - (0.5 * 0.2 - 2.0 * 0.25)) < 1e-15);
  assert_true(fabs(fw_pair_policy_action(&r.shift, FW_TASK_CORRIDOR, 0.5, s, 0.8, false) - (0.25 * 0.8 + 0.5 * 0.2 - 2.0 * 0.25)) <
              1e-15);
  // Among obstacles: a * (goal bearing + bend) + b * bend, the bend the goal direction's turn to
  // the edge of the nearest obstacle's cone of half-angle asin(clearance / distance) on the goal's
  // side, the clearance 0.5 m (pair_obstacle_clearance_m's default).
  const double cl = 0.5;
  const double left_near[4] = {0.3, 3.0, 0.4, 0.6};  // the goal just right of the obstacle: bend right
  const double bend = -(asin(cl / 0.6) - 0.1);
  double basis[2];
  fw_pair_basis(FW_TASK_OBSTACLES, cl, left_near, basis);
  assert_true(fabs(basis[0] - (0.4 - asin(cl / 0.6))) < 1e-15);  // the cone's right edge
  assert_true(fabs(basis[1] - bend) < 1e-15);
  // A tighter clearance narrows the cone: the same state bends less.
  fw_pair_basis(FW_TASK_OBSTACLES, 0.45, left_near, basis);
  assert_true(fabs(basis[1] + (asin(0.45 / 0.6) - 0.1)) < 1e-15 && fabs(basis[1]) < fabs(bend));
  assert_true(fabs(basis[0] - (0.4 - asin(0.45 / 0.6))) < 1e-15);
  fw_pair_basis(FW_TASK_CORRIDOR, 0.45, s, basis);  // the corridor's terms ignore it
  assert_true(basis[0] == 0.2 && basis[1] == 0.25);
  assert_true(fabs(fw_pair_shift_at(&r.shift, FW_TASK_OBSTACLES, cl, left_near) - (0.5 * (0.3 + bend) - 2.0 * bend)) < 1e-15);
  const double right_near[4] = {-0.3, 3.0, -0.4, 0.6};  // its mirror image
  assert_true(fabs(fw_pair_shift_at(&r.shift, FW_TASK_OBSTACLES, cl, right_near) - (-0.5 * (0.3 + bend) + 2.0 * bend)) < 1e-15);
  const double within[4] = {0.3, 3.0, -0.5, 0.4};  // nearer than the clearance: the cone is a right angle
  const double bend_within = 0.5 * 3.141592653589793 - 0.8;
  assert_true(fabs(fw_pair_shift_at(&r.shift, FW_TASK_OBSTACLES, cl, within) -
                   (0.5 * (0.3 + bend_within) - 2.0 * bend_within)) < 1e-14);
  const double clear[4] = {1.2, 3.0, 0.0, 1.0};  // the goal direction outside the cone (0.52 rad): no bend
  assert_true(fabs(fw_pair_shift_at(&r.shift, FW_TASK_OBSTACLES, cl, clear) - 0.5 * 1.2) < 1e-15);
  const double behind[4] = {0.2, 3.0, 0.2, 1.0};  // the goal exactly behind it: no side, no bend
  assert_true(fabs(fw_pair_shift_at(&r.shift, FW_TASK_OBSTACLES, cl, behind) - 0.5 * 0.2) < 1e-15);
  const double beyond_goal[4] = {0.3, 0.8, 0.4, 1.0};  // the obstacle farther than the goal
  assert_true(fabs(fw_pair_shift_at(&r.shift, FW_TASK_OBSTACLES, cl, beyond_goal) - 0.5 * 0.3) < 1e-15);
  const double far[4] = {0.3, 3.0, 0.4, 2.0};  // beyond FW_PAIR_OBSTACLE_RANGE_M: the goal bearing alone
  assert_true(fabs(fw_pair_shift_at(&r.shift, FW_TASK_OBSTACLES, cl, far) - 0.5 * 0.3) < 1e-15);
  const double hidden[4] = {0.3, 3.0, 3.141592653589793, 8.0};
  assert_true(fabs(fw_pair_shift_at(&r.shift, FW_TASK_OBSTACLES, cl, hidden) - 0.5 * 0.3) < 1e-15);
  // The bent direction stays within +-pi: an obstacle at the edge of the view, within the
  // clearance, the goal behind on its far side.
  const double edge_of_view[4] = {3.0, 3.0, 1.5, 0.3};
  fw_pair_basis(FW_TASK_OBSTACLES, cl, edge_of_view, basis);
  assert_true(fabs(basis[0] - (1.5 + 0.5 * 3.141592653589793)) < 1e-15 && basis[0] <= 3.141592653589793);
}

// One pair-runs session to its end: its statistics, its phase-two training runs that ended on a
// wall and their advisor steps, and its pair runs (from the B21R_RUN records).
typedef struct pair_session {
  fw_loop_stats_t st;
  int collisions;
  int advisor_steps;
  int vetoed;         // B21R_RUN records marked pair_vetoed
  int paired;         // B21R_RUN records of pair runs (any phase, any kind)
  uint64_t exp_hash;  // the session's experience stream
} pair_session_t;

static pair_session_t run_pair_session(const fw_config_t* c, uint64_t fake_seed, int64_t max_ticks) {
  pair_session_t out;
  memset(&out, 0, sizeof out);
  assert_int_equal(harness_open(&g_h, c, false, fake_seed), 0);
  harness_run(&g_h, max_ticks);
  fw_loop_get_stats(g_h.loop, &out.st);
  assert_true(out.st.done);
  out.exp_hash = g_h.exp_hash;
  for (int i = 0; i < g_h.runs && i < 64; ++i) {
    const b21r_run_t* r = &g_h.run[i];
    out.paired += r->pair_member >= 0 ? 1 : 0;
    if (r->kind == B21R_RUN_T_KIND_TRAINING && r->phase == 2) {
      out.collisions += r->end_reason == B21R_RUN_T_END_COLLISION;
      out.advisor_steps += r->steps_by_source[B21R_EXPERIENCE_T_SOURCE_ADVISOR];
      out.vetoed += r->pair_vetoed ? 1 : 0;
    }
  }
  harness_close(&g_h);
  return out;
}

// pair_runs = auto, the default, runs pairs in the emulator only, with HEDGER's
// state-model search: with the per-action search, or on the robot (reposition = operator), no run
// is a pair run and no pair is ranked. On the robot the learner still tags and fades its runs as
// with pairs (the experience stream differs from pair_runs = false's), so that a learned state
// acts alike there and in the emulator.
static void test_loop_pair_runs_auto_off_where_it_does_not_apply(void** state) {
  (void)state;
  enum { PER_ACTION, ROBOT, ROBOT_PAIRS_OFF, EMULATOR, N_CASES };
  pair_session_t ps[N_CASES];
  for (int k = 0; k < N_CASES; ++k) {
    fw_config_t c;
    short_schedule(&c);
    c.phase_one_runs = 4;
    c.phase_two_runs = 4;
    c.eval_every_runs = 10;
    c.eval_starts = 1;
    assert_int_equal(c.pair_runs_mode, FW_PAIR_RUNS_AUTO);
    c.hedger_greedy_method = k == PER_ACTION ? (int32_t)HEDGER_GREEDY_PER_ACTION : (int32_t)HEDGER_GREEDY_STATE_MODEL;
    c.reposition = k == ROBOT || k == ROBOT_PAIRS_OFF ? FW_REPOSITION_OPERATOR : FW_REPOSITION_EMULATOR;
    c.pair_runs_mode = k == ROBOT_PAIRS_OFF ? FW_PAIR_RUNS_OFF : FW_PAIR_RUNS_AUTO;
    ps[k] = run_pair_session(&c, 3, 200000);
    assert_int_equal(ps[k].st.training_runs, 8);
    assert_int_equal(ps[k].paired, k == EMULATOR ? 4 : 0);
    assert_int_equal(ps[k].st.pairs_ranked, k == EMULATOR ? 2 : 0);
  }
  assert_true(ps[ROBOT].exp_hash != ps[ROBOT_PAIRS_OFF].exp_hash);  // tags and fading act on the robot too
}

// pair_safety: with perturbations far wilder than the defaults (gain sd 2, centring sd 4) and no
// per-step exploration noise, pair runs without the filter end on a wall; with it none does.
// Every run the filter corrected is ranked as one that missed the goal, and after its first
// correction the run drives without its perturbation, so the filter seldom has to act again in
// it (a few commands per corrected run; it would be dozens if the perturbation went on). Every
// pair is still ranked.
static void test_loop_pair_safety_keeps_pair_runs_off_the_walls(void** state) {
  (void)state;
  pair_session_t ps[2];
  for (int on = 0; on <= 1; ++on) {
    fw_config_t c;
    short_schedule(&c);
    c.phase_one_runs = 10;
    c.phase_two_runs = 12;
    c.eval_every_runs = 30;
    c.eval_starts = 1;
    c.pair_runs_mode = FW_PAIR_RUNS_ON;
    c.pair_gain_sigma = 2.0;
    c.pair_centring_sigma = 4.0;
    c.explore_sigma_radps = 0.0;
    c.pair_safety = on == 1;
    ps[on] = run_pair_session(&c, 11, 400000);
    assert_int_equal(ps[on].st.pairs_ranked, 6);
  }
  const fw_loop_stats_t* off = &ps[0].st;
  const fw_loop_stats_t* with = &ps[1].st;
  print_message("phase-two training runs on a wall: %d without the filter, %d with it; with it %d runs corrected "
                "(%lld commands), %d ranked as missing the goal\n",
                ps[0].collisions, ps[1].collisions, with->pair_runs_vetoed, (long long)with->pair_safety_overrides,
                with->pair_runs_missed);
  assert_true(ps[0].collisions >= 2);
  assert_true(off->pair_runs_missed >= ps[0].collisions);  // (and the step limit's)
  assert_int_equal(off->pair_runs_vetoed, 0);
  assert_int_equal(ps[1].collisions, 0);
  assert_true(with->pair_runs_vetoed >= 2);
  assert_int_equal(ps[1].vetoed, with->pair_runs_vetoed);  // each corrected run's B21R_RUN says so
  assert_int_equal(ps[0].vetoed, 0);
  assert_int_equal(with->pair_runs_missed, with->pair_runs_vetoed);
  assert_true(with->pair_safety_overrides >= with->pair_runs_vetoed);
  assert_true(with->pair_safety_overrides <= 6 * (int64_t)with->pair_runs_vetoed);
}

// pair_safety vets every command of a pair run, also where the learner knows no action yet: with
// an empty store, no advisor (nothing known: hold course) and pair runs from the first phase-two
// run, runs that hold course from starts heading for a wall end on it without the filter; with
// it none does, and the filter's corrections come from the recovery law (source advisor).
static void test_loop_pair_safety_vets_unknown_actions(void** state) {
  (void)state;
  pair_session_t ps[2];
  for (int on = 0; on <= 1; ++on) {
    fw_config_t c;
    short_schedule(&c);
    c.phase_one_runs = 0;
    c.phase_two_runs = 6;
    c.eval_every_runs = 30;
    c.eval_starts = 1;
    c.advisor = false;
    c.pair_runs_mode = FW_PAIR_RUNS_ON;
    c.pair_safety = on == 1;
    ps[on] = run_pair_session(&c, 5, 200000);
  }
  print_message("training runs on a wall: %d without the filter, %d with it (%lld commands replaced, %d advisor "
                "steps)\n", ps[0].collisions, ps[1].collisions, (long long)ps[1].st.pair_safety_overrides,
                ps[1].advisor_steps);
  assert_true(ps[0].collisions >= 1);
  assert_int_equal(ps[0].advisor_steps, 0);
  assert_int_equal(ps[1].collisions, 0);
  assert_true(ps[1].st.pair_safety_overrides > 0);
  assert_true(ps[1].advisor_steps > 0);
}

// state_rotation: the state ends with the rotation the base executes, i.e. the command in force
// while the step ran (the previous action, after the acceleration limit), so every transition's
// s_next ends with its own action and its s with the run's previous action (0 at the start: the
// robot stands while it is placed). Without the option the state keeps the task's 3 entries.
static void test_loop_state_rotation_is_the_executed_command(void** state) {
  (void)state;
  for (int on = 0; on <= 1; ++on) {
    fw_config_t c;
    harness_config(&c);
    c.phase_one_runs = 5;
    c.phase_two_runs = 3;
    c.eval_every_runs = 4;
    c.hedger_replay_passes = 2;
    c.state_rotation = on != 0;
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
    assert_true(g_h.exp_count > 500);
    harness_close(&g_h);
  }
}

// Runs c's schedule on a fresh fake robot (fake seed 5; CANopen with its frames can_lag_us behind
// the laser when canopen) for at most 100,000 ticks; returns the hash of the experience stream.
static uint64_t run_stream(const fw_config_t* c, bool canopen, int64_t can_lag_us, int64_t* count, bool* done) {
  assert_int_equal(canopen ? harness_open_can_lag(&g_h, c, 5, can_lag_us) : harness_open(&g_h, c, false, 5), 0);
  harness_run(&g_h, 100000);
  fw_loop_stats_t st;
  fw_loop_get_stats(g_h.loop, &st);
  *done = st.done;
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
    bool done = false;
    hashes[i] = run_stream(&c, false, 0, &counts[i], &done);
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
// answer in flight that later ticks took for their own, one period stale.
static void test_loop_canopen_stream_independent_of_answer_lag(void** state) {
  (void)state;
  fw_config_t c;
  harness_config(&c);
  c.phase_one_runs = 2;
  c.phase_two_runs = 1;
  c.eval_every_runs = 3;
  c.eval_starts = 1;
  c.seed = 11;
  const int64_t lags_us[4] = {0, 30000, 150000, 450000};
  uint64_t hashes[4];
  int64_t counts[4];
  for (int i = 0; i < 4; ++i) {
    bool done = false;
    hashes[i] = run_stream(&c, true, lags_us[i], &counts[i], &done);
    assert_true(done);
    print_message("CAN answers %3lld ms after the scan: %lld experiences, hash %016llx\n",
                  (long long)(lags_us[i] / 1000), (long long)counts[i], (unsigned long long)hashes[i]);
  }
  assert_true(counts[0] > 100);
  for (int i = 1; i < 4; ++i) {
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
  c.hedger_replay_passes = 4;  // shorter between-run slices: more runs and blocks in 3000 ticks
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
  snprintf(c.checkpoint_file, sizeof c.checkpoint_file, "%s/hedger.ckpt", dir);
  assert_int_equal(harness_open(&g_h, &c, false, 3), 0);
  size_t meta_cap = 0;
  size_t payload_cap = 0;
  fw_loop_checkpoint_capacity(g_h.loop, &meta_cap, &payload_cap);
  char err[FW_LOOP_ERR_MAX];
  fw_ckpt_writer_t* w = fw_ckpt_writer_create(c.checkpoint_file, meta_cap, payload_cap, err, sizeof err);
  assert_non_null(w);
  fw_loop_attach_checkpoints(g_h.loop, w);
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

  // The learned policy's shift is learned state: a file carrying one (a, b) resumes with it, and
  // an evaluation of the learned policy drives with it (its B21R_RUN says so, and the actions
  // differ from those of the same file without the shift); with it out of range the file is refused.
  uint64_t eval_hash[2];
  for (int with_shift = 0; with_shift <= 1; ++with_shift) {
    fw_progress_t gs;
    assert_int_equal(fw_progress_decode(meta, ms, &gs, NULL, 0), 0);
    gs.shift.gain = with_shift ? 0.75 : 0.0;
    gs.shift.centring = with_shift ? -1.25 : 0.0;
    uint8_t shifted[FW_PROGRESS_BYTES];
    size_t shifted_n = fw_progress_encode(&gs, shifted);
    assert_int_equal(fw_checkpoint_write(c.checkpoint_file, shifted, shifted_n, payload, ps, err, sizeof err), 0);
    fw_config_t ce = c;
    ce.mode = FW_MODE_EVALUATE;
    ce.evaluate_policy = FW_EVAL_LEARNED;
    ce.eval_starts = 2;
    assert_int_equal(harness_open(&g_h, &ce, false, 3), 0);
    assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), 1);
    fw_loop_get_stats(g_h.loop, &st);
    assert_true(st.shift.gain == gs.shift.gain && st.shift.centring == gs.shift.centring);
    harness_run(&g_h, 100000);
    fw_loop_get_stats(g_h.loop, &st);
    assert_true(st.done);
    assert_int_equal(g_h.runs, 2);
    for (int i = 0; i < g_h.runs; ++i) {
      assert_true(g_h.run[i].shift_gain == gs.shift.gain && g_h.run[i].shift_centring == gs.shift.centring);
    }
    eval_hash[with_shift] = g_h.exp_hash;
    harness_close(&g_h);
    if (with_shift) {
      gs.shift.gain = FW_PAIR_SHIFT_MAX * 1.5;
      shifted_n = fw_progress_encode(&gs, shifted);
      assert_int_equal(fw_checkpoint_write(c.checkpoint_file, shifted, shifted_n, payload, ps, err, sizeof err), 0);
      assert_int_equal(harness_open(&g_h, &c, false, 3), 0);
      assert_int_equal(fw_loop_load_checkpoint(g_h.loop, err, sizeof err), -1);
      assert_non_null(strstr(err, "learned policy shift"));
      harness_close(&g_h);
    }
  }
  assert_true(eval_hash[0] != eval_hash[1]);
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

// Writes a checkpoint of g and an empty learned state to c's checkpoint_file, then loads it into
// a controller of c with pair_obstacle_clearance_m = configured_m and obstacle_pass_hold_steps =
// configured_hold. Returns fw_loop_load_checkpoint's result (err its message, st the loop's
// statistics after it). With rewrite_path, a loaded controller then shuts down writing its own
// checkpoint there.
static int load_with(const fw_config_t* c, const fw_progress_t* g, double configured_m, int32_t configured_hold,
                     const char* rewrite_path, char* err, size_t err_cap, fw_loop_stats_t* st) {
  hedger_config_t hc;
  fw_loop_learner_config(c, &hc);
  hedger_t* hd = NULL;
  assert_int_equal(hedger_create(&hd, &hc), HEDGER_OK);
  static uint8_t payload[4096];  // an empty learned state of this configuration's shape
  size_t ps = 0;
  assert_int_equal(hedger_save(hd, payload, sizeof payload, &ps), HEDGER_OK);
  hedger_destroy(hd);
  uint8_t meta[FW_PROGRESS_BYTES];
  const size_t meta_n = fw_progress_encode(g, meta);
  assert_int_equal(fw_checkpoint_write(c->checkpoint_file, meta, meta_n, payload, ps, err, err_cap), 0);
  fw_config_t ci = *c;
  ci.pair_obstacle_clearance_m = configured_m;
  ci.obstacle_pass_hold_steps = configured_hold;
  assert_int_equal(harness_open(&g_h, &ci, false, 3), 0);
  err[0] = '\0';
  const int r = fw_loop_load_checkpoint(g_h.loop, err, err_cap);
  fw_loop_get_stats(g_h.loop, st);
  fw_ckpt_writer_t* w = NULL;
  if (r == 1 && rewrite_path != NULL) {
    size_t meta_cap = 0;
    size_t payload_cap = 0;
    fw_loop_checkpoint_capacity(g_h.loop, &meta_cap, &payload_cap);
    w = fw_ckpt_writer_create(rewrite_path, meta_cap, payload_cap, err, err_cap);
    assert_non_null(w);
    fw_loop_attach_checkpoints(g_h.loop, w);
    assert_int_equal(fw_loop_shutdown(g_h.loop), 0);
  }
  harness_close(&g_h);
  fw_ckpt_writer_destroy(w);
  return r;
}

// The obstacle task's shift is a policy only with the clearance its terms bent around
// (pair_obstacle_clearance_m): a checkpoint resumes its shift only with that clearance, and a
// refusal names the setting that resumes it and loads nothing. A file that does not record the
// clearance (written before the field) learned with 0.5 m; a shift still at 0 resumes under any
// clearance; the corridor records none and ignores the setting.
static int load_with_clearance(const fw_config_t* c, const fw_progress_t* g, double configured_m, char* err,
                               size_t err_cap, fw_loop_stats_t* st) {
  return load_with(c, g, configured_m, g->pass_hold_recorded ? g->obstacle_pass_hold_steps : c->obstacle_pass_hold_steps,
                   NULL, err, err_cap, st);
}

// The controller section of an obstacle session in phase two (40 training runs, run id 50) with
// no shift and nothing recorded: the cases below set the shift, the clearance and the hold.
static fw_progress_t obstacle_phase_two_progress(uint32_t state_dim) {
  fw_progress_t g;
  memset(&g, 0, sizeof g);
  g.task = FW_TASK_OBSTACLES;
  g.state_dim = state_dim;
  g.schedule.phase = 2;
  g.schedule.training_runs = 40;
  g.schedule.phase_one_runs = 30;
  g.schedule.phase_two_runs = 10;
  g.run_id = 50;
  return g;
}

static void test_loop_checkpoint_obstacle_clearance(void** state) {
  (void)state;
  char dir[] = "/tmp/b21r-loopclear-XXXXXX";
  assert_non_null(mkdtemp(dir));
  fw_config_t c;
  harness_config(&c);
  c.task = FW_TASK_OBSTACLES;
  snprintf(c.checkpoint_file, sizeof c.checkpoint_file, "%s/hedger.ckpt", dir);
  hedger_config_t hc;
  fw_loop_learner_config(&c, &hc);
  fw_progress_t g = obstacle_phase_two_progress(hc.state_dim);
  g.shift.imitation = -0.5;
  g.shift.pairs = 5;
  g.pass_hold_recorded = true;  // the configuration's hold: this test is about the clearance
  g.obstacle_pass_hold_steps = c.obstacle_pass_hold_steps;
  struct {
    double recorded_m;    // bytes 88-95 (0: not recorded)
    double configured_m;  // pair_obstacle_clearance_m
    double gain;          // the shift's a and b (0: nothing learned on the terms)
    int expect;           // fw_loop_load_checkpoint's result
  } const cases[] = {
      {0.45, 0.45, 1.25, 1}, {0.45, 0.5, 1.25, -1}, {0.0, 0.5, 1.25, 1}, {0.0, 0.45, 1.25, -1}, {0.5, 0.45, 0.0, 1},
  };
  char err[FW_LOOP_ERR_MAX];
  fw_loop_stats_t st;
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
    g.obstacle_clearance_m = cases[i].recorded_m;
    g.shift.gain = cases[i].gain;
    g.shift.centring = cases[i].gain;
    const int r = load_with_clearance(&c, &g, cases[i].configured_m, err, sizeof err, &st);
    if (r != cases[i].expect) {
      fail_msg("case %zu: recorded %g, configured %g, a %g: load gave %d (%s)", i, cases[i].recorded_m,
               cases[i].configured_m, cases[i].gain, r, err);
    }
    if (r == 1) {
      assert_true(st.shift.gain == g.shift.gain && st.shift.imitation == g.shift.imitation);
      assert_int_equal(st.training_runs, 40);
    } else {
      char want[96];
      snprintf(want, sizeof want, "set pair_obstacle_clearance_m = %g to go on with it",
               cases[i].recorded_m > 0.0 ? cases[i].recorded_m : 0.5);
      if (strstr(err, want) == NULL || strstr(err, c.checkpoint_file) == NULL) {
        fail_msg("case %zu: '%s' does not say '%s'", i, err, want);
      }
      assert_int_equal(st.training_runs, 0);  // nothing loaded
      assert_true(st.shift.gain == 0.0 && st.shift.imitation == 0.0);
    }
  }
  // The corridor's shift loads whatever pair_obstacle_clearance_m says.
  fw_config_t cc;
  harness_config(&cc);
  snprintf(cc.checkpoint_file, sizeof cc.checkpoint_file, "%s/hedger.ckpt", dir);
  fw_loop_learner_config(&cc, &hc);
  g.task = FW_TASK_CORRIDOR;
  g.state_dim = hc.state_dim;
  g.obstacle_clearance_m = 0.0;
  g.pass_hold_recorded = false;
  g.obstacle_pass_hold_steps = 0;
  g.shift.gain = 0.75;
  g.shift.centring = -1.0;
  assert_int_equal(load_with_clearance(&cc, &g, 0.45, err, sizeof err, &st), 1);
  assert_true(st.shift.gain == 0.75);
  assert_int_equal(remove(c.checkpoint_file), 0);
  assert_int_equal(remove(dir), 0);
}

// The obstacle task's shift is learned and vetted with the hold past the obstacle
// (obstacle_pass_hold_steps): a checkpoint resumes a shift that moved only with that hold, and a
// refusal names the setting and loads nothing. A file that does not record the hold (written
// before the field: with none or with 10, it cannot say) resumes under the configured hold with a
// note; a shift that never moved resumes under any hold without one. The
// controller's own checkpoint records the hold it ran with (104-byte section), and a shift that
// never moved keeps the 96-byte section.
static void test_loop_checkpoint_obstacle_pass_hold(void** state) {
  (void)state;
  char dir[] = "/tmp/b21r-loophold-XXXXXX";
  assert_non_null(mkdtemp(dir));
  fw_config_t c;
  harness_config(&c);
  c.task = FW_TASK_OBSTACLES;
  snprintf(c.checkpoint_file, sizeof c.checkpoint_file, "%s/hedger.ckpt", dir);
  char rewritten[sizeof c.checkpoint_file + 16];
  snprintf(rewritten, sizeof rewritten, "%s/again.ckpt", dir);
  hedger_config_t hc;
  fw_loop_learner_config(&c, &hc);
  fw_progress_t g = obstacle_phase_two_progress(hc.state_dim);
  g.shift.pairs = 5;
  struct {
    int32_t recorded;    // bytes 96-99 - 1 (-1: a 96-byte section, not recorded)
    int32_t configured;  // obstacle_pass_hold_steps
    double imitation;    // the shift's w (a = b = 0 throughout: the weight alone was vetted with the hold)
    int expect;          // fw_loop_load_checkpoint's result
  } const cases[] = {
      {10, 10, -0.5, 1}, {10, 6, -0.5, -1}, {0, 0, -0.5, 1}, {0, 10, -0.5, -1},
      {-1, 0, -0.5, 1},  {-1, 10, -0.5, 1}, {-1, 10, 0.0, 1},
  };
  char err[FW_LOOP_ERR_MAX];
  fw_loop_stats_t st;
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
    g.pass_hold_recorded = cases[i].recorded >= 0;
    g.obstacle_pass_hold_steps = cases[i].recorded >= 0 ? cases[i].recorded : 0;
    g.shift.imitation = cases[i].imitation;
    (void)remove(rewritten);
    const int r = load_with(&c, &g, c.pair_obstacle_clearance_m, cases[i].configured, rewritten, err, sizeof err, &st);
    if (r != cases[i].expect) {
      fail_msg("case %zu: recorded %d, configured %d, w %g: load gave %d (%s)", i, (int)cases[i].recorded,
               (int)cases[i].configured, cases[i].imitation, r, err);
    }
    if (r == 1) {
      assert_true(st.shift.imitation == g.shift.imitation);
      assert_int_equal(st.training_runs, 40);
      // A shift that moved with no hold recorded resumes under the configured one, with a note.
      const bool unknown = cases[i].recorded < 0 && cases[i].imitation != 0.0;
      char note[96];
      snprintf(note, sizeof note, "it goes on with obstacle_pass_hold_steps = %d", (int)cases[i].configured);
      if (unknown ? strstr(err, note) == NULL || strstr(err, "does not record the hold") == NULL : err[0] != '\0') {
        fail_msg("case %zu: note '%s'", i, err);
      }
      // The controller's own checkpoint records the hold it ran with where the shift moved.
      uint8_t meta[FW_PROGRESS_BYTES + 1];
      size_t ms = 0;
      static uint8_t payload[1 << 16];
      size_t ps = 0;
      assert_int_equal(fw_checkpoint_read(rewritten, meta, sizeof meta, &ms, payload, sizeof payload, &ps, err,
                                          sizeof err),
                       1);
      fw_progress_t again;
      assert_int_equal(fw_progress_decode(meta, ms, &again, NULL, 0), 0);
      const bool moved = cases[i].imitation != 0.0;
      if (ms != (moved ? FW_PROGRESS_BYTES : FW_PROGRESS_BYTES_BASE) || again.pass_hold_recorded != moved ||
          again.obstacle_pass_hold_steps != (moved ? cases[i].configured : 0)) {
        fail_msg("case %zu: the controller wrote a %zu-byte section, hold %s %d (shift w %g)", i, ms,
                 again.pass_hold_recorded ? "recorded" : "not recorded", (int)again.obstacle_pass_hold_steps,
                 again.shift.imitation);
      }
    } else {
      char want[96];
      snprintf(want, sizeof want, "set obstacle_pass_hold_steps = %d to go on with it", (int)cases[i].recorded);
      if (strstr(err, want) == NULL || strstr(err, c.checkpoint_file) == NULL) {
        fail_msg("case %zu: '%s' does not say '%s'", i, err, want);
      }
      assert_int_equal(st.training_runs, 0);  // nothing loaded
      assert_true(st.shift.imitation == 0.0);
    }
  }
  (void)remove(rewritten);
  assert_int_equal(remove(c.checkpoint_file), 0);
  assert_int_equal(remove(dir), 0);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_loop_learns_corridor_reaches_goal_from_all_poses),
      cmocka_unit_test(test_pair_run_tag_always_increases),
      cmocka_unit_test(test_pair_ranker_moves_the_shift),
      cmocka_unit_test(test_loop_pair_runs_share_start_and_rank),
      cmocka_unit_test(test_loop_phase_one_pairs),
      cmocka_unit_test(test_loop_shift_vet_runs_between_runs),
      cmocka_unit_test(test_loop_pair_runs_auto_off_where_it_does_not_apply),
      cmocka_unit_test(test_loop_pair_safety_keeps_pair_runs_off_the_walls),
      cmocka_unit_test(test_loop_pair_safety_vets_unknown_actions),
      cmocka_unit_test(test_loop_same_seed_bit_identical_experiences),
      cmocka_unit_test(test_loop_state_rotation_is_the_executed_command),
      cmocka_unit_test(test_loop_canopen_stream_independent_of_answer_lag),
      cmocka_unit_test(test_loop_tick_allocates_nothing),
      cmocka_unit_test(test_loop_checkpoint_restart_resumes),
      cmocka_unit_test(test_loop_checkpoint_obstacle_clearance),
      cmocka_unit_test(test_loop_checkpoint_obstacle_pass_hold),
  };
  return cmocka_run_group_tests_name("firmware.loop", tests, NULL, NULL);
}
