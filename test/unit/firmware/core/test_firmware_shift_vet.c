// SPDX-License-Identifier: MIT
// The vet of a step of the learned policy's shift (fw/shift_vet.h), with a policy whose behaviour
// on the model is known: the recovery law (2 x target angle) as the "greedy" action. A shift that
// keeps the law turning toward the axis is taken; one that makes it turn away is cut to a half, a
// quarter or an eighth, the first of them that is safe, and refused when none is; a step is judged start by start against the shift in force
// (mirrored starts included), and one that rescues more starts than it loses is taken; where the
// model sees no difference the step is taken; the verdict
// does not depend on how the work is sliced; the rollouts weigh the greedy action by 1 + the
// imitation's weight; the start ring keeps the last starts.
#include <b21r_test/alloc_counter.h>
#include <features/features.h>
#include <fw/config.h>
#include <fw/shift_vet.h>
#include <fw/loop.h>
#include <tasks/episode.h>
#include <tasks/tasks.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

static fw_shift_vet_env_t g_env;
static fw_shift_vet_starts_t g_starts;
static int g_calls;

static int setup(void** state) {
  (void)state;
  fw_config_t cfg;
  fw_config_defaults(&cfg);
  fw_shift_vet_env_init(&g_env, &cfg);
  memset(&g_starts, 0, sizeof g_starts);
  g_calls = 0;
  return 0;
}

// The learner's state at a pose: x from the start wall, y offset (+ left), psi heading [rad];
// then the rotation in force (state_rotation), 0.
static void add_start(double x, double y, double psi) {
  const tasks_corridor_spec_t* sp = &g_env.spec;
  const double s[4] = {sp->length_m - x, 0.5 - y / sp->width_m, -psi - atan2(y, sp->lookahead_m), 0.0};
  fw_shift_vet_starts_add(&g_starts, &g_env, s);
}

// Poses like the evaluation's: near the start wall, off the axis, turned by up to 0.5 rad.
static void add_typical_starts(void) {
  add_start(1.0, 0.3, 0.4);
  add_start(1.2, -0.3, -0.4);
  add_start(1.4, 0.0, 0.5);
  add_start(1.1, -0.2, 0.3);
}

// The "learned" policy: the recovery law, known everywhere.
static bool law(void* ctx, const double* s, double* action) {
  (void)ctx;
  g_calls++;
  *action = 2.0 * s[2];
  return true;
}

static bool nothing_known(void* ctx, const double* s, double* action) {
  (void)ctx;
  (void)s;
  g_calls++;
  *action = 0.0;
  return false;
}

static fw_shift_vet_t vet_of(fw_shift_vet_greedy_fn greedy, double gain, double centring, uint32_t periods) {
  const fw_pair_shift_t in_force = {.gain = 0.0, .centring = 0.0, .pairs = 3U};
  const fw_pair_shift_t proposed = {.gain = gain, .centring = centring, .pairs = 4U};
  fw_shift_vet_t vet;
  fw_shift_vet_begin(&vet, &in_force, &proposed);
  while (!fw_shift_vet_step(&vet, greedy, NULL, &g_env, &g_starts, periods)) {
  }
  assert_true(fw_shift_vet_done(&vet));
  return vet;
}

// A small step of a policy that reaches the goal from every start: taken, after one rollout from
// each start and from its mirror image (about 140 periods each), and the pair counts.
static void test_vet_takes_a_safe_step(void** state) {
  (void)state;
  add_typical_starts();
  alloc_counter_begin();
  const fw_shift_vet_t vet = vet_of(law, 0.2, 0.3, UINT32_MAX);
  assert_int_equal(alloc_counter_end(), 0);
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_TAKEN);
  assert_true(vet.result.gain == 0.2 && vet.result.centring == 0.3 && vet.result.pairs == 4U);
  assert_int_equal(vet.failures[0], 0);
  assert_int_equal(vet.failures[1], 0);  // the shift in force was never needed
  assert_true(g_calls > 8 * 120 && g_calls < 8 * 200);
  assert_int_equal((int)vet.periods, g_calls);
}

// Gain -2.6 turns the law away from the axis (-0.6 x target angle): the first start ends on a
// wall where the shift in force reaches the goal, and the proposed shift is dropped at once (after
// the shift in force is driven from the other starts: it fails from none, so nothing can be
// rescued). Half
// of it (-1.3: 0.7 x target angle) still turns toward the axis from every start: halved.
static void test_vet_halves_a_step_that_reaches_a_wall(void** state) {
  (void)state;
  add_typical_starts();
  const fw_shift_vet_t vet = vet_of(law, -2.6, 0.0, UINT32_MAX);
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_HALVED);
  assert_int_equal(vet.failures[0], 1);
  assert_int_equal(vet.failures[1], 0);
  assert_int_equal(vet.failures[2], 0);
  assert_int_equal(vet.in_force_failed[0], -1);
  assert_true(vet.result.gain == -1.3 && vet.result.centring == 0.0 && vet.result.pairs == 4U);
}

// Gain -5: half of it (-2.5) turns away too, a quarter (-1.25: 0.75 x target angle) does not:
// a quarter of the step is taken. Gain -12: the half (-6) and the quarter (-3) turn away, the
// eighth (-1.5) does not.
static void test_vet_tries_a_quarter_and_an_eighth(void** state) {
  (void)state;
  add_typical_starts();
  fw_shift_vet_t vet = vet_of(law, -5.0, 0.0, UINT32_MAX);
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_HALVED);
  assert_true(vet.result.gain == -1.25 && vet.result.centring == 0.0 && vet.result.pairs == 4U);
  assert_int_equal(vet.failures[0], 1);
  assert_int_equal(vet.failures[2], 1);  // the half, dropped at its first failing start
  vet = vet_of(law, -12.0, 0.0, UINT32_MAX);
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_HALVED);
  assert_true(vet.result.gain == -1.5 && vet.result.pairs == 4U);
  assert_int_equal(vet.failures[2], 2);  // the half and the quarter
  assert_int_equal(vet.failures[1], 0);  // the shift in force, driven once per start for the whole vet
}

// Gain -20: even an eighth of it (-2.5) turns away: the shift stays, and the pair still counts.
static void test_vet_refuses_a_step_whose_eighth_reaches_a_wall(void** state) {
  (void)state;
  add_typical_starts();
  const fw_shift_vet_t vet = vet_of(law, -20.0, 0.0, UINT32_MAX);
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_REFUSED);
  assert_int_equal(vet.failures[2], FW_SHIFT_VET_HALVINGS);
  assert_true(vet.result.gain == 0.0 && vet.result.centring == 0.0 && vet.result.pairs == 4U);
}

// A step that the model cannot tell from the shift in force is taken: with no starts at all, or
// with a policy that knows nothing anywhere (it holds course, the shift does not act), even
// though every rollout fails (from each start and its mirror, with both shifts). A step that
// moves nothing is taken without a rollout.
static void test_vet_takes_what_it_cannot_tell_apart(void** state) {
  (void)state;
  fw_shift_vet_t vet = vet_of(law, -5.0, 0.0, UINT32_MAX);
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_TAKEN);
  assert_int_equal(g_calls, 0);
  add_typical_starts();
  vet = vet_of(nothing_known, -5.0, 0.0, UINT32_MAX);
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_TAKEN);
  assert_true(vet.failures[0] == 8 && vet.failures[1] == 8);
  g_calls = 0;
  vet = vet_of(law, 0.0, 0.0, UINT32_MAX);
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_TAKEN);
  assert_int_equal(g_calls, 0);
}

// The imitation's weight: the vet's rollouts drive (1 + w) x the greedy action plus the shift, as
// the controller does. w = -1 leaves the law out: holding course from starts turned by up to
// 0.5 rad reaches a wall where the law does not, and the half (w = -0.5: 1 x target angle) turns
// toward the axis from every start: halved. w = -1 with gain 2 is the law itself again: taken.
// Doubling the law (w = +1: 4 x target angle) is safe too.
static void test_vet_weighs_the_greedy_action(void** state) {
  (void)state;
  add_typical_starts();
  const fw_pair_shift_t in_force = {.gain = 0.0, .centring = 0.0, .imitation = 0.0, .pairs = 3U};
  const double step[3][2] = {{-1.0, 0.0}, {-1.0, 2.0}, {1.0, 0.0}};  // (imitation, gain)
  const fw_shift_verdict_t expected[3] = {FW_SHIFT_STEP_HALVED, FW_SHIFT_STEP_TAKEN, FW_SHIFT_STEP_TAKEN};
  for (int i = 0; i < 3; ++i) {
    const fw_pair_shift_t proposed = {.gain = step[i][1], .centring = 0.0, .imitation = step[i][0], .pairs = 4U};
    fw_shift_vet_t vet;
    fw_shift_vet_begin(&vet, &in_force, &proposed);
    while (!fw_shift_vet_step(&vet, law, NULL, &g_env, &g_starts, UINT32_MAX)) {
    }
    assert_int_equal(vet.verdict, expected[i]);
    const double fraction = expected[i] == FW_SHIFT_STEP_HALVED ? 0.5 : 1.0;
    assert_true(vet.result.imitation == fraction * step[i][0] && vet.result.gain == fraction * step[i][1]);
    assert_int_equal(vet.failures[0], i == 0 ? 1 : 0);
  }
}

// The work in slices (one period per call, as a tick with the budget 1) reaches the same verdict
// and shift with the same number of policy calls, and never does more than its budget per call.
static void check_slices(double gain, double centring, fw_shift_verdict_t verdict) {
  g_calls = 0;
  const fw_shift_vet_t whole = vet_of(law, gain, centring, UINT32_MAX);
  assert_int_equal(whole.verdict, verdict);
  const int whole_calls = g_calls;
  g_calls = 0;
  const fw_pair_shift_t in_force = {.gain = 0.0, .centring = 0.0, .pairs = 3U};
  const fw_pair_shift_t proposed = {.gain = gain, .centring = centring, .pairs = 4U};
  fw_shift_vet_t sliced;
  fw_shift_vet_begin(&sliced, &in_force, &proposed);
  int slices = 0;
  for (;;) {
    const int before = g_calls;
    const bool done = fw_shift_vet_step(&sliced, law, NULL, &g_env, &g_starts, 3U);
    assert_true(g_calls - before <= 3);
    slices++;
    if (done) {
      break;
    }
  }
  assert_int_equal(g_calls, whole_calls);
  assert_true(slices >= whole_calls / 3);
  assert_int_equal(sliced.verdict, whole.verdict);
  assert_true(sliced.result.gain == whole.result.gain && sliced.result.centring == whole.result.centring &&
              sliced.result.imitation == whole.result.imitation);
  assert_int_equal(sliced.result.pairs, whole.result.pairs);
}

// Sliced into 3 periods a slice, the vet decides as in one go: a step it halves, and one it cuts
// to an eighth (the half and the quarter dropped in the middle of slices).
static void test_vet_in_slices_decides_the_same(void** state) {
  (void)state;
  add_typical_starts();
  check_slices(-2.6, 0.4, FW_SHIFT_STEP_HALVED);
  check_slices(-12.0, 0.0, FW_SHIFT_STEP_HALVED);
}

// The fractions are of the step from the shift in force, not of the proposed shift: from gain
// -0.5 (the law at 1.5 x target angle) a step to -4.5: its half (-2.5) turns away, its quarter
// (-1.5, not a quarter of -4.5) does not.
static void test_vet_cuts_the_step_from_the_shift_in_force(void** state) {
  (void)state;
  add_typical_starts();
  const fw_pair_shift_t in_force = {.gain = -0.5, .centring = 0.0, .pairs = 3U};
  const fw_pair_shift_t proposed = {.gain = -4.5, .centring = 0.0, .pairs = 4U};
  fw_shift_vet_t vet;
  fw_shift_vet_begin(&vet, &in_force, &proposed);
  while (!fw_shift_vet_step(&vet, law, NULL, &g_env, &g_starts, UINT32_MAX)) {
  }
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_HALVED);
  assert_true(vet.result.gain == -1.5 && vet.result.centring == 0.0 && vet.result.pairs == 4U);
  assert_int_equal(vet.failures[0], 1);
  assert_int_equal(vet.failures[2], 1);  // the half
}

// ---------------------------------------------------------------------------------------------
// Rescues against losses: which rollouts fail is set by a table, per start and per shift. The
// "greedy" action reads from the vet under way which shift its rollout drives and from which
// start, and returns the law (which reaches the goal from every typical start) or its opposite
// (-2 x target angle, which turns away and reaches a wall from each of them); the step is 1e-9 in
// gain, so the shift itself changes nothing on the model.

typedef struct verdict_table {
  const fw_shift_vet_t* vet;
  uint32_t in_force_fails;   // bit k: the shift in force fails from rollout start k
  uint32_t candidate_fails;  // bit k: the proposed shift (and each fraction) fails from start k
} verdict_table_t;

static bool tabled(void* ctx, const double* s, double* action) {
  const verdict_table_t* t = (const verdict_table_t*)ctx;
  const fw_shift_vet_t* v = t->vet;
  const bool in_force = v->driving != FW_SHIFT_VET_DRIVING_CANDIDATE;
  const uint32_t k = v->driving == FW_SHIFT_VET_DRIVING_ALL_IN_FORCE ? v->in_force_next : v->start;
  const bool fails = (((in_force ? t->in_force_fails : t->candidate_fails) >> k) & 1U) != 0U;
  g_calls++;
  *action = (fails ? -2.0 : 2.0) * s[2];
  return true;
}

static fw_shift_vet_t tabled_vet(uint32_t in_force_fails, uint32_t candidate_fails) {
  const fw_pair_shift_t in_force = {.gain = 0.0, .centring = 0.0, .pairs = 3U};
  const fw_pair_shift_t proposed = {.gain = 1e-9, .centring = 0.0, .pairs = 4U};
  fw_shift_vet_t vet;
  verdict_table_t table = {.vet = &vet, .in_force_fails = in_force_fails, .candidate_fails = candidate_fails};
  fw_shift_vet_begin(&vet, &in_force, &proposed);
  while (!fw_shift_vet_step(&vet, tabled, &table, &g_env, &g_starts, 7U)) {
  }
  return vet;
}

// A step that rescues more starts than it loses is taken: the shift in force fails from starts
// 0, 1 and 2 (of 8: four starts and their mirror images), the proposed shift from 5 alone. The
// shift in force is driven once from every start, after the first lost one.
static void test_vet_takes_a_step_that_rescues_more_than_it_loses(void** state) {
  (void)state;
  add_typical_starts();
  const fw_shift_vet_t vet = tabled_vet(0x07U, 0x20U);
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_TAKEN);
  assert_true(vet.result.gain == 1e-9 && vet.result.pairs == 4U);
  assert_int_equal(vet.lost, 1);
  assert_int_equal(vet.failures[0], 1);
  assert_int_equal(vet.failures[1], 3);
  for (int k = 0; k < 8; ++k) {
    assert_int_equal(vet.in_force_failed[k], k < 3 ? 1 : -1);
    assert_int_equal(vet.candidate_failed[k], k == 5 ? 1 : -1);
  }
  // Where the shift in force fails too, the candidate's failure is no loss: no other start is
  // needed, and the shift in force is driven from that start alone.
  const fw_shift_vet_t same = tabled_vet(0x10U, 0x10U);
  assert_int_equal(same.verdict, FW_SHIFT_STEP_TAKEN);
  assert_int_equal(same.lost, 0);
  assert_int_equal(same.failures[1], 1);
  assert_int_equal(same.in_force_failed[0], 0);
}

// As many rescues as losses, or fewer, do not pay: each fraction is dropped as soon as it has lost
// as many starts as the shift in force fails from (it cannot rescue more), and the step is
// refused. The shift in force is driven from each start once for the whole vet, not once per
// fraction.
static void test_vet_refuses_a_step_that_loses_as_many_as_it_rescues(void** state) {
  (void)state;
  add_typical_starts();
  const uint32_t cases[3][2] = {{0x03U, 0x30U}, {0x01U, 0x02U}, {0x01U, 0x06U}};  // (in force, candidate) fails
  const int32_t lost_at_drop[3] = {2, 1, 1};
  for (int i = 0; i < 3; ++i) {
    const fw_shift_vet_t vet = tabled_vet(cases[i][0], cases[i][1]);
    assert_int_equal(vet.verdict, FW_SHIFT_STEP_REFUSED);
    assert_true(vet.result.gain == 0.0 && vet.result.pairs == 4U);
    assert_int_equal(vet.lost, lost_at_drop[i]);
    assert_int_equal(vet.failures[1], __builtin_popcount(cases[i][0]));
    assert_int_equal(vet.failures[0], lost_at_drop[i]);
    assert_int_equal(vet.failures[2], FW_SHIFT_VET_HALVINGS * lost_at_drop[i]);
    assert_true(vet.stage < 0);
  }
  // The same losses against more rescues: taken (two lost, three rescued).
  const fw_shift_vet_t vet = tabled_vet(0x07U, 0x30U);
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_TAKEN);
  assert_int_equal(vet.lost, 2);
}

// The ring keeps the last pair_shift_vet_starts starts (20 by default), oldest out first, and
// drops non-finite states.
static void test_vet_starts_keep_the_last_runs(void** state) {
  (void)state;
  assert_int_equal(g_env.capacity, 20);
  for (int i = 0; i < 23; ++i) {
    add_start(1.0 + 0.01 * i, 0.0, 0.0);
  }
  assert_int_equal(g_starts.n, 20);
  double lowest = INFINITY;
  for (uint32_t i = 0; i < g_starts.n; ++i) {
    lowest = fmin(lowest, g_env.spec.length_m - g_starts.state[i][0]);
  }
  assert_true(fabs(lowest - 1.03) < 1e-12);  // runs 0, 1 and 2 were pushed out
  const double bad[4] = {5.0, NAN, 0.0, 0.0};
  fw_shift_vet_starts_add(&g_starts, &g_env, bad);
  assert_int_equal(g_starts.next, 3);
  for (uint32_t i = 0; i < g_starts.n; ++i) {
    assert_true(isfinite(g_starts.state[i][1]));
  }
}

// ---------------------------------------------------------------------------------------------
// The obstacle task: its rollouts (tasks_obstacles_rollout_*), its pair terms and its mirror.

static fw_shift_vet_env_t g_obstacles_env;

static int setup_obstacles(void** state) {
  (void)state;
  fw_config_t cfg;
  fw_config_defaults(&cfg);
  cfg.task = FW_TASK_OBSTACLES;
  cfg.obstacle_pass_hold_steps = 0;  // the policy of the state alone (the hold: its own test)
  fw_shift_vet_env_init(&g_obstacles_env, &cfg);
  memset(&g_starts, 0, sizeof g_starts);
  g_calls = 0;
  return 0;
}

// The "learned" policy among obstacles: 1.5 x the goal direction bent around a near obstacle (the
// first term of fw_pair_basis), a goal-seeking law that turns to the edge of the obstacle's cone
// on the goal's side, at a gentle gain. On the model it reaches the goal from all ten evaluation
// poses and their mirror images; moved by the shift it does so or not as follows (measured on the
// model; a turn harder toward the goal bearing alone, g, is a shift (+x, -x): x (g + bend) - x bend):
// (+0.2, -0.2) hits the obstacle from 2 poses and their mirror images, (+0.1, -0.1) from none,
// (-1, +1) from none; centring -2 (bending the goal direction toward the obstacle) from 8, -1
// from 6, -0.5 from 4, -0.25 from at least one (the vet refuses -2), +4 from none; gain +1 on
// the bent direction alone (a harder turn toward the course that keeps the clearance) from none.
static bool avoid_law(void* ctx, const double* s, double* action) {
  (void)ctx;
  g_calls++;
  double basis[2];
  fw_pair_basis(FW_TASK_OBSTACLES, 0.5, s, basis);  // pair_obstacle_clearance_m's default, as the vet's
  *action = 1.5 * basis[0];
  return true;
}

static fw_shift_vet_t obstacles_vet_in(const fw_shift_vet_env_t* env, double gain, double centring) {
  const fw_pair_shift_t in_force = {.gain = 0.0, .centring = 0.0, .pairs = 3U};
  const fw_pair_shift_t proposed = {.gain = gain, .centring = centring, .pairs = 4U};
  fw_shift_vet_t vet;
  fw_shift_vet_begin(&vet, &in_force, &proposed);
  while (!fw_shift_vet_step(&vet, avoid_law, NULL, env, &g_starts, 64U)) {
  }
  return vet;
}

static fw_shift_vet_t obstacles_vet_of(double gain, double centring) {
  return obstacles_vet_in(&g_obstacles_env, gain, centring);
}

// The learner's states at the ten evaluation poses (state_rotation: the rotation in force, 0),
// from the ideal laser of tasks_episode_observe_pose.
static void add_obstacle_eval_starts(void) {
  tasks_corridor_spec_t corridor;
  tasks_corridor_spec_default(&corridor);
  tasks_episode_t ep;
  tasks_episode_init(&ep, TASKS_TASK_OBSTACLES, &corridor, &g_obstacles_env.obstacles);
  for (uint32_t i = 0; i < TASKS_N_EVAL_STARTS; ++i) {
    double s[5] = {0.0, 0.0, 0.0, 0.0, 0.0};
    assert_int_equal(tasks_episode_observe_pose(&ep, tasks_obstacles_eval_start(&g_obstacles_env.obstacles, i), s), 1);
    fw_shift_vet_starts_add(&g_starts, &g_obstacles_env, s);
  }
}

// Among obstacles the vet drives the obstacle model from each start and its mirror image (the
// default arena is symmetric), fails at contact, and judges a step as in the corridor: taken
// where nothing new fails, cut where a half (a quarter, an eighth) of the step is safe, refused
// where none is. A mirrored
// start fails exactly where its original does for this symmetric law. A start without a visible
// obstacle (no pose to drive from) fails with every shift, so it blocks nothing.
static void test_vet_among_obstacles(void** state) {
  (void)state;
  assert_true(g_obstacles_env.task == FW_TASK_OBSTACLES && g_obstacles_env.task_dim == 4U);
  assert_true(g_obstacles_env.mirror && g_obstacles_env.margin_m == FW_SHIFT_VET_OBSTACLES_MARGIN_M);
  add_obstacle_eval_starts();
  assert_int_equal((int)g_starts.n, TASKS_N_EVAL_STARTS);
  alloc_counter_begin();
  fw_shift_vet_t vet = obstacles_vet_of(-1.0, 1.0);
  assert_int_equal(alloc_counter_end(), 0);
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_TAKEN);
  assert_int_equal(vet.failures[0], 0);
  // 20 rollouts of about 100-120 periods (0.3 m/s over about 3 m).
  assert_true(vet.periods > 20 * 90 && vet.periods < 20 * 130);

  vet = obstacles_vet_of(1.0, 0.0);  // harder toward the bent direction: safe from every start
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_TAKEN);
  assert_int_equal(vet.failures[0], 0);

  vet = obstacles_vet_of(0.2, -0.2);  // harder toward the goal bearing itself
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_HALVED);
  assert_true(vet.result.gain == 0.1 && vet.result.centring == -0.1 && vet.result.pairs == 4U);
  assert_int_equal(vet.failures[0], 1);  // dropped at its first failing start
  assert_int_equal(vet.failures[2], 0);

  vet = obstacles_vet_of(0.0, -2.0);  // the half, the quarter and the eighth hit it too
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_REFUSED);
  assert_true(vet.failures[2] >= FW_SHIFT_VET_HALVINGS);
  assert_true(vet.result.gain == 0.0 && vet.result.centring == 0.0 && vet.result.pairs == 4U);
  assert_true(vet.failures[2] > 0);

  // The mirror image the vet drives is the mirrored pose's state: each start and its mirror
  // image driven alone (without the vet's own mirroring) fail alike for this symmetric law, a
  // shift of (+0.2, -0.2) from the same 2 poses.
  fw_shift_vet_env_t alone = g_obstacles_env;
  alone.mirror = false;
  int fails[2] = {0, 0};
  for (uint32_t i = 0; i < g_starts.n; ++i) {
    bool failed[2];
    for (int m = 0; m < 2; ++m) {
      fw_shift_vet_starts_t one;
      memset(&one, 0, sizeof one);
      double s[5];
      memcpy(s, g_starts.state[i], 4 * sizeof s[0]);
      s[4] = 0.0;
      if (m == 1) {
        s[0] = -s[0];  // goal bearing
        s[2] = -s[2];  // obstacle bearing (visible from every evaluation pose)
      }
      fw_shift_vet_starts_add(&one, &alone, s);
      const fw_pair_shift_t in_force = {.gain = 0.0, .centring = 0.0, .pairs = 3U};
      const fw_pair_shift_t proposed = {.gain = 0.2, .centring = -0.2, .pairs = 4U};
      fw_shift_vet_begin(&vet, &in_force, &proposed);
      (void)fw_shift_vet_step(&vet, avoid_law, NULL, &alone, &one, UINT32_MAX);
      failed[m] = vet.failures[0] > 0;  // the proposed shift's one rollout
      fails[m] += failed[m] ? 1 : 0;
    }
    assert_true(failed[0] == failed[1]);
  }
  assert_int_equal(fails[0], 2);
  assert_int_equal(fails[1], 2);

  // A start without a visible obstacle (facing away from it, the disc behind): every shift fails
  // there, so it does not block a step the other starts allow.
  memset(&g_starts, 0, sizeof g_starts);
  const double hidden[5] = {3.0, 3.0, 3.141592653589793, 8.0, 0.0};
  fw_shift_vet_starts_add(&g_starts, &g_obstacles_env, hidden);
  add_obstacle_eval_starts();
  vet = obstacles_vet_of(-1.0, 1.0);
  assert_int_equal(vet.verdict, FW_SHIFT_STEP_TAKEN);
  assert_int_equal(vet.failures[0], 2);  // the hidden start and its mirror image
  assert_int_equal(vet.failures[1], 2);
}

// The vet's rollouts hold past an obstacle as the controller does (obstacle_pass_hold_steps, the
// default): the law above turned harder toward the goal, or its bend narrowed, clipped the
// obstacle from some evaluation pose only where it slipped out of the laser's view beside the
// robot and the policy of the state alone turned to the goal at once (measured on the model: each
// shift below fails from at least one pose without the hold, from none with it). Bending the
// goal direction into the obstacle (centring -2) still fails.
static void test_vet_holds_past_an_obstacle(void** state) {
  (void)state;
  add_obstacle_eval_starts();
  fw_shift_vet_env_t held = g_obstacles_env;
  fw_config_t cfg;
  fw_config_defaults(&cfg);
  cfg.task = FW_TASK_OBSTACLES;
  fw_shift_vet_env_init(&held, &cfg);
  assert_int_equal(held.pass_hold_steps, TASKS_OBSTACLES_PASS_HOLD_STEPS);  // the default
  assert_int_equal(g_obstacles_env.pass_hold_steps, 0);
  const double clipped[][2] = {{0.2, -0.2}, {1.0, -1.0}, {0.0, -0.5}, {4.0, 0.0}};
  for (size_t i = 0; i < sizeof clipped / sizeof clipped[0]; ++i) {
    fw_shift_vet_t alone = obstacles_vet_in(&g_obstacles_env, clipped[i][0], clipped[i][1]);
    assert_int_equal(alone.verdict, FW_SHIFT_STEP_HALVED);
    assert_int_equal(alone.failures[0], 1);
    fw_shift_vet_t vet = obstacles_vet_in(&held, clipped[i][0], clipped[i][1]);
    assert_int_equal(vet.verdict, FW_SHIFT_STEP_TAKEN);
    assert_int_equal(vet.failures[0], 0);
    assert_true(vet.result.gain == clipped[i][0] && vet.result.centring == clipped[i][1]);
  }
  fw_shift_vet_t into = obstacles_vet_in(&held, 0.0, -2.0);
  assert_int_equal(into.verdict, FW_SHIFT_STEP_HALVED);
  assert_true(into.failures[0] > 0 && into.result.centring > -2.0);
}

// The hold past an obstacle (obstacle_pass_hold_steps): after a near obstacle in view slips out of
// view the learned policy holds course for exactly hold_steps states, wherever it was last seen;
// an obstacle that leaves the view from beyond FW_PAIR_OBSTACLE_RANGE_M holds nothing; one back in
// view ends the hold; the mirror image (bearing -pi) holds alike; the corridor and hold_steps 0
// never hold.
static void test_pass_hold_counts_states(void** state) {
  (void)state;
  const double pi = 3.141592653589793;
  const double near[4] = {0.2, 2.0, -1.2, 0.3};        // beside the robot, 0.3 m away
  const double hidden[4] = {-0.6, 1.9, pi, 8.0};       // out of view (features' empty slot)
  const double hidden_mirror[4] = {0.6, 1.9, -pi, 8.0};
  const double far[4] = {0.2, 2.0, -1.2, 1.6};         // in view beyond the range
  const double ahead[4] = {0.2, 2.0, 0.5, 0.6};        // in view, near, 0.5 rad off the heading
  fw_pass_hold_t h;
  fw_pass_hold_reset(&h);
  assert_false(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, hidden, 3U));  // never seen
  assert_false(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, near, 3U));
  for (int i = 0; i < 3; ++i) {
    assert_true(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, i % 2 == 0 ? hidden : hidden_mirror, 3U));
    assert_true(fw_pass_hold_active(&h));  // the verdict at the latest state, as the controller reads it
  }
  assert_false(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, hidden, 3U));
  assert_false(fw_pass_hold_active(&h));
  // Back in view during the hold: the state says where it is, and the hold ends.
  assert_false(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, near, 3U));
  assert_true(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, hidden, 3U));
  assert_false(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, far, 3U));
  // Leaving the view from beyond the range: nothing to hold for.
  assert_false(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, hidden, 3U));
  // Lost from view nearer the heading (its returns dropped from a scan): held as well.
  assert_false(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, ahead, 3U));
  assert_true(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, hidden, 3U));
  fw_pass_hold_reset(&h);
  // A new run forgets the obstacle of the last one.
  assert_false(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, near, 3U));
  assert_true(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, hidden, 3U));
  fw_pass_hold_reset(&h);
  assert_false(fw_pass_hold_active(&h));
  assert_false(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, hidden, 3U));
  // hold_steps 0 and the corridor never hold.
  assert_false(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, near, 0U));
  assert_false(fw_pass_hold_observe(&h, FW_TASK_OBSTACLES, hidden, 0U));
  const double corridor[3] = {5.0, 0.5, 3.0};
  assert_false(fw_pass_hold_observe(&h, FW_TASK_CORRIDOR, corridor, 3U));
  // The learned policy is 0 (hold course) wherever it holds.
  const fw_pair_shift_t shift = {.gain = 2.0, .centring = 0.5, .imitation = -0.5, .pairs = 3U};
  assert_true(fw_pair_policy_action(&shift, FW_TASK_OBSTACLES, 0.45, hidden, 0.8, true) == 0.0);
  assert_true(fabs(fw_pair_policy_action(&shift, FW_TASK_OBSTACLES, 0.45, hidden, 0.8, false) - (0.4 - 1.2)) < 1e-15);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test_setup(test_vet_takes_a_safe_step, setup),
      cmocka_unit_test_setup(test_vet_halves_a_step_that_reaches_a_wall, setup),
      cmocka_unit_test_setup(test_vet_tries_a_quarter_and_an_eighth, setup),
      cmocka_unit_test_setup(test_vet_refuses_a_step_whose_eighth_reaches_a_wall, setup),
      cmocka_unit_test_setup(test_vet_takes_what_it_cannot_tell_apart, setup),
      cmocka_unit_test_setup(test_vet_weighs_the_greedy_action, setup),
      cmocka_unit_test_setup(test_vet_in_slices_decides_the_same, setup),
      cmocka_unit_test_setup(test_vet_cuts_the_step_from_the_shift_in_force, setup),
      cmocka_unit_test_setup(test_vet_takes_a_step_that_rescues_more_than_it_loses, setup),
      cmocka_unit_test_setup(test_vet_refuses_a_step_that_loses_as_many_as_it_rescues, setup),
      cmocka_unit_test_setup(test_vet_starts_keep_the_last_runs, setup),
      cmocka_unit_test_setup(test_vet_among_obstacles, setup_obstacles),
      cmocka_unit_test(test_pass_hold_counts_states),
      cmocka_unit_test_setup(test_vet_holds_past_an_obstacle, setup_obstacles),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
