// SPDX-License-Identifier: MIT
// policy = select: phase two's training runs come in pairs from one start pose, one run of each
// pair the greedy policy's and the other the actor's (alternating which goes first), with one
// exploration stream; the pair's steps (a miss at the step limit) rank them, and every other run
// has the policy the pairs favour. An aborted second run leaves its pair open (it is repeated as
// the second); a restart restores the ranking but not a half-finished pair.
#include "learn/learn.h"
#include "learn_test_task.h"

#include <math.h>
#include <stdbool.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>


typedef struct {
  void* mem;
  learn_t* a;
} agent_t;

static agent_t make_agent(int32_t policy) {
  const learn_task_t task = learn_test_line_task();
  learn_config_t cfg = learn_config_default();
  cfg.policy = policy;
  cfg.state_last_action = false;
  cfg.capacity = 2000;
  cfg.actor.capacity = 2000;
  cfg.actor.max_queries = 200;
  cfg.actor_guard_se = 1.0;
  cfg.actor_guard_range = true;
  cfg.decision_ticks = 1;
  cfg.explore_probability = 0.5;
  cfg.explore_sigma = 0.2;
  cfg.example_dither_sigma = 0.3;
  cfg.schedule.phase_one_runs = 2;
  cfg.schedule.phase_two_runs = 5;
  cfg.schedule.eval_every = 100;  // one block, after the last training run
  cfg.schedule.eval_starts = 1;
  cfg.schedule.switch_mode = LEARN_SWITCH_RUNS;
  const size_t bytes = learn_storage_size(&task, &cfg);
  assert_true(bytes > 0);
  agent_t g;
  g.mem = aligned_alloc(LEARN_STORAGE_ALIGN, (bytes + LEARN_STORAGE_ALIGN - 1) / LEARN_STORAGE_ALIGN *
                                                 LEARN_STORAGE_ALIGN);
  assert_non_null(g.mem);
  char err[LEARN_ERR_MAX];
  g.a = learn_init(g.mem, bytes, &task, &cfg, err, sizeof err);
  assert_non_null(g.a);
  return g;
}

#define MAX_STEPS 64

// Drives the planned run for `steps` actions (the state walks from -0.5 towards the goal), ending
// at the goal, or aborted before its last action when `abort_run`; then the between-run work.
// sources[i] receives the source of action i.
static learn_run_end_t drive(learn_t* a, int32_t steps, bool abort_run, int8_t* sources) {
  learn_begin_run(a);
  learn_run_end_t end;
  memset(&end, 0, sizeof end);
  learn_experience_t exp;
  double last = 0.0;
  for (int32_t i = 0;; ++i) {
    const double s = -0.5 + 0.9 * (double)i / (double)steps;
    assert_true(learn_observe(a, &s, last));
    if (learn_has_transition(a)) {
      const bool at_goal = i == steps;
      const learn_outcome_t o = {.reward = at_goal ? 1.0 : 0.0, .terminal = at_goal, .end_run = at_goal,
                                 .goal = at_goal, .reason = 0};
      if (learn_transition(a, &o, &end)) {
        break;
      }
    }
    if (abort_run && i == steps - 1) {
      assert_true(learn_abort_run(a, &end));
      break;
    }
    double act = 0.0;
    int8_t src = 0;
    learn_act(a, 0.5 * s, 0.0, &act, &src);  // phase one's teacher: a = 0.5 s (with dither)
    assert_true(i < MAX_STEPS);
    sources[i] = src;
    learn_executed(a, act, 0.3);
    (void)learn_after_command(a, &exp);
    last = act;
  }
  (void)learn_finish_now(a, &exp);
  return end;
}

static void test_pairs_alternate_repeat_and_rank(void** state) {
  (void)state;
  agent_t g = make_agent(LEARN_POLICY_SELECT);
  learn_t* a = g.a;
  int8_t src[6][MAX_STEPS];
  memset(src, 0, sizeof src);
  int8_t scratch[MAX_STEPS];
  // Phase one: the teacher drives; nothing is ranked, the greedy policy is the one in force.
  for (int r = 0; r < 2; ++r) {
    assert_false(learn_run_repeats_start(a));
    const learn_run_end_t e = drive(a, 30, false, scratch);
    assert_int_equal(e.plan.phase, 1);
    assert_int_equal(e.policy, LEARN_POLICY_GREEDY);
  }
  // Pair 0: the greedy policy first (10 steps), then the actor from the same start (20 steps).
  assert_false(learn_run_repeats_start(a));
  learn_run_end_t e = drive(a, 10, false, src[0]);
  assert_int_equal(e.plan.phase, 2);
  assert_int_equal(e.policy, LEARN_POLICY_GREEDY);
  assert_true(learn_run_repeats_start(a));
  e = drive(a, 20, false, src[1]);
  assert_int_equal(e.policy, LEARN_POLICY_ACTOR);
  learn_selection_t sel = learn_selection_get(a);
  assert_int_equal(sel.pairs, 1);
  assert_true(sel.greedy_saved_steps == 10.0);
  // The pair shared one exploration stream: which steps explored is the same in both runs (the
  // first 10 steps), and differs from the next pair's.
  assert_memory_equal(src[0], src[1], 10);
  // Pair 1: the actor first (30 steps); the greedy policy's run is cut short by a safety stop and
  // repeated as the pair's second, from the same start, then takes 50 steps.
  assert_false(learn_run_repeats_start(a));
  e = drive(a, 30, false, src[2]);
  assert_int_equal(e.policy, LEARN_POLICY_ACTOR);
  assert_memory_not_equal(src[0], src[2], 10);
  assert_true(learn_run_repeats_start(a));
  e = drive(a, 40, true, src[3]);
  assert_true(e.aborted);
  assert_int_equal(e.policy, LEARN_POLICY_GREEDY);
  assert_int_equal(learn_selection_get(a).pairs, 1);
  assert_true(learn_run_repeats_start(a));
  e = drive(a, 50, false, src[4]);
  assert_int_equal(e.policy, LEARN_POLICY_GREEDY);
  assert_memory_equal(src[2], src[4], 30);
  sel = learn_selection_get(a);
  assert_int_equal(sel.pairs, 2);
  assert_true(sel.greedy_saved_steps == -10.0);  // 10 saved in pair 0, 20 lost in pair 1
  // Pair 2's first run (the greedy policy's again) is the schedule's last training run: no second.
  assert_false(learn_run_repeats_start(a));
  e = drive(a, 10, false, src[5]);
  assert_int_equal(e.policy, LEARN_POLICY_GREEDY);
  // The evaluation block: the actor, which the pairs favour.
  const learn_plan_t p = learn_plan(a);
  assert_int_equal(p.kind, LEARN_RUN_EVAL);
  assert_false(learn_run_repeats_start(a));
  e = drive(a, 10, false, scratch);
  assert_int_equal(e.policy, LEARN_POLICY_ACTOR);
  assert_int_equal(learn_selection_get(a).pairs, 2);
  free(g.mem);
}

// A pair's first run resumed from a journal after a restart (learn_resume_run): the caller cannot
// repeat its start pose, so the next live run is no pair's second; two resumed runs still pair.
static void test_resumed_first_run_opens_no_pair(void** state) {
  (void)state;
  agent_t g = make_agent(LEARN_POLICY_SELECT);
  learn_t* a = g.a;
  int8_t scratch[MAX_STEPS];
  for (int r = 0; r < 2; ++r) {
    (void)drive(a, 30, false, scratch);
  }
  learn_plan_t p = learn_plan(a);
  assert_true(learn_resume_run(a, &p, 10, true, false, NULL));  // pair 0's first, the greedy policy's
  p = learn_plan(a);
  assert_false(learn_run_repeats_start(a));
  const learn_run_end_t e = drive(a, 20, false, scratch);
  assert_int_equal(e.policy, LEARN_POLICY_GREEDY);  // not a second: the policy in force (none ranked)
  assert_int_equal(learn_selection_get(a).pairs, 0);
  // Both runs of pair 1 resumed: ranked as they ran (the actor first, 30 steps; the greedy 50).
  p = learn_plan(a);
  assert_true(learn_resume_run(a, &p, 30, true, false, NULL));
  p = learn_plan(a);
  assert_true(learn_run_repeats_start(a) == false);  // (asked live: a resumed first)
  assert_true(learn_resume_run(a, &p, 50, true, false, NULL));
  assert_int_equal(learn_selection_get(a).pairs, 1);
  assert_true(learn_selection_get(a).greedy_saved_steps == -20.0);
  free(g.mem);
}

static void test_resume_selection(void** state) {
  (void)state;
  agent_t g = make_agent(LEARN_POLICY_SELECT);
  const learn_selection_t saved = {.greedy_saved_steps = -42.0, .pairs = 7};
  assert_true(learn_resume_selection(g.a, &saved));
  assert_true(learn_selection_get(g.a).greedy_saved_steps == -42.0);
  assert_int_equal(learn_selection_get(g.a).pairs, 7);
  const learn_selection_t bad = {.greedy_saved_steps = NAN, .pairs = 1};
  assert_false(learn_resume_selection(g.a, &bad));
  const learn_selection_t negative = {.greedy_saved_steps = 0.0, .pairs = -1};
  assert_false(learn_resume_selection(g.a, &negative));
  assert_int_equal(learn_selection_get(g.a).pairs, 7);
  free(g.mem);
  // Another policy has no ranking to restore; it acts with its own policy throughout.
  agent_t h = make_agent(LEARN_POLICY_ACTOR);
  assert_false(learn_resume_selection(h.a, &saved));
  assert_int_equal(learn_selection_get(h.a).pairs, 0);
  assert_false(learn_run_greedy(h.a));
  free(h.mem);
}

static void test_storage_as_the_actor(void** state) {
  (void)state;
  const learn_task_t task = learn_test_line_task();
  learn_config_t cfg = learn_config_default();
  cfg.policy = LEARN_POLICY_SELECT;
  const size_t select = learn_storage_size(&task, &cfg);
  cfg.policy = LEARN_POLICY_ACTOR;
  assert_true(select > 0);
  assert_int_equal(select, learn_storage_size(&task, &cfg));
  cfg.policy = 3;
  assert_int_equal(learn_storage_size(&task, &cfg), 0);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_pairs_alternate_repeat_and_rank),
      cmocka_unit_test(test_resumed_first_run_opens_no_pair),
      cmocka_unit_test(test_resume_selection),
      cmocka_unit_test(test_storage_as_the_actor),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
