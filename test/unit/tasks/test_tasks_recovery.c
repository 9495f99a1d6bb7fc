// SPDX-License-Identifier: MIT
// The corridor's recovery rollout (tasks/recovery.h): what it predicts matches an independent
// integration of the same commands (sim/kinematic.h at fine sub-steps), it ranks commands the
// way the geometry does, it is symmetric, it stops at the goal, and it refuses what it cannot
// predict. The whole-run rollouts of both tasks: the same, and (obstacles) the pose a state
// describes comes back from it.
#include <b21r_test/alloc_counter.h>
#include <features/features.h>
#include <sim/kinematic.h>
#include <tasks/episode.h>
#include <tasks/recovery.h>
#include <tasks/tasks.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

static tasks_corridor_spec_t g_spec;
static tasks_command_limits_t g_lim;

static int setup(void** state) {
  (void)state;
  tasks_corridor_spec_default(&g_spec);
  tasks_command_limits_default(&g_lim);
  return 0;
}

// The features of an exact pose (what a perfect laser reports): y lateral offset [m], psi heading
// to the corridor axis [rad], x from the start wall [m].
static features_corridor_t at_pose(double x, double y, double psi) {
  features_corridor_t f;
  memset(&f, 0, sizeof f);
  f.valid = 1;
  f.end_distance_m = g_spec.length_m - x;
  f.offset_m = y;
  f.heading_rad = psi;
  f.lateral_frac = 0.5 - y / g_spec.width_m;
  f.target_angle_rad = -psi - atan2(y, g_spec.lookahead_m);
  return f;
}

static bool refused(double c) { return isinf(c) && c < 0.0; }

static double clearance(const features_corridor_t* f, double v0, double w0, double w, double horizon_s) {
  return tasks_corridor_recovery_clearance_m(&g_spec, &g_lim, g_spec.dt_s, f, v0, w0, w, horizon_s);
}

// The same scenario integrated independently: the controller's commands each period (the vetted
// one, then the recovery law's from the true pose), each clamped as the controller clamps it, and
// a synchro-drive body at 100 sub-steps per period whose axes follow the commands under the same
// acceleration limits (so they ramp over the period). Returns the least clearance seen at the
// periods' ends, the instants the rollout predicts. This checks the rollout's integration of its
// own model (the controller's limits, nominal width, no coast: the poses are far from the goal);
// a base slower than the limits, or a measured width, is the margin's business.
static double integrated(double x, double y, double psi, double v0, double w0, double w, double horizon_s) {
  const double dt = g_spec.dt_s;
  const int sub = 100;
  sim_kin_limits_t kl = {g_lim.max_translation_accel_mps2, g_lim.max_rotation_accel_radps2};
  sim_kin_state_t s;
  sim_kin_reset(&s, x, y, psi);
  s.v_mps = v0;
  s.omega_radps = w0;
  double v_prev = v0;
  double w_prev = w0;
  double least = INFINITY;
  const int n = (int)ceil(horizon_s / dt - 1e-9);
  for (int k = 0; k < n; ++k) {
    const features_corridor_t f = at_pose(s.x_m, s.y_m, s.theta_rad);
    double v_cmd = tasks_corridor_speed_mps(&g_spec, &f);
    double w_cmd = k == 0 ? w : tasks_corridor_recovery_action(&g_spec, &f);
    (void)tasks_command_clamp(&g_lim, dt, v_prev, w_prev, &v_cmd, &w_cmd);
    sim_kin_run(&s, &kl, v_cmd, w_cmd, dt / sub, (uint64_t)sub);
    v_prev = v_cmd;
    w_prev = w_cmd;
    least = fmin(least, 0.5 * g_spec.width_m - g_spec.robot_radius_m - fabs(s.y_m));
    if (g_spec.length_m - s.x_m <= g_spec.goal_distance_m) {
      break;
    }
  }
  return least;
}

// Centred and straight at cruising speed, holding course: the clearance stays what it is, the
// free half-width 1.0 - 0.26 = 0.74 m.
static void test_recovery_centred_straight_keeps_half_width(void** state) {
  (void)state;
  const features_corridor_t f = at_pose(2.0, 0.0, 0.0);
  assert_true(fabs(clearance(&f, g_spec.v_centre_mps, 0.0, 0.0, 3.0) - 0.74) < 1e-12);
}

// Over a grid of poses (offsets to 0.6 m, headings to 1.1 rad either way), previous commands and
// vetted commands, the prediction is within 1 cm of the independent integration: the margin
// the controller keeps (0.1 m by default) is for sensing and latency, not for the model.
static void test_recovery_matches_independent_integration(void** state) {
  (void)state;
  double worst = 0.0;
  int n = 0;
  for (double y = -0.6; y <= 0.6001; y += 0.2) {
    for (double psi = -1.1; psi <= 1.1001; psi += 0.275) {
      for (double w0 = -0.5; w0 <= 0.5001; w0 += 0.5) {
        for (double w = -1.0; w <= 1.0001; w += 0.25) {
          const features_corridor_t f = at_pose(3.0, y, psi);
          const double p = clearance(&f, 0.4, w0, w, 3.0);
          const double q = integrated(3.0, y, psi, 0.4, w0, w, 3.0);
          worst = fmax(worst, fabs(p - q));
          n++;
        }
      }
    }
  }
  print_message("rollout vs integration over %d cases: largest difference %.4f m\n", n, worst);
  assert_true(worst < 0.01);
}

// Near the left wall and heading towards it: within the band the acceleration limit lets the
// command reach from the one in force (0 +- 0.286 rad/s), turning further left is predicted to
// touch the wall and turning right is not, and the clearance falls strictly as the command turns
// further left.
static void test_recovery_ranks_commands_by_the_geometry(void** state) {
  (void)state;
  const features_corridor_t f = at_pose(3.0, 0.5, 0.9);
  double prev = INFINITY;
  for (double w = -0.28; w <= 0.2801; w += 0.07) {
    const double c = clearance(&f, 0.6, 0.0, w, 3.0);
    assert_true(c < prev);
    prev = c;
  }
  assert_true(clearance(&f, 0.6, 0.0, 0.28, 3.0) < 0.0);
  assert_true(clearance(&f, 0.6, 0.0, -0.28, 3.0) > 0.0);
}

// Mirroring the pose, the previous command and the vetted command about the centre line gives
// the same clearance (to rounding).
static void test_recovery_is_mirror_symmetric(void** state) {
  (void)state;
  for (double y = -0.5; y <= 0.5001; y += 0.25) {
    for (double psi = -0.9; psi <= 0.9001; psi += 0.3) {
      for (double w = -1.0; w <= 1.0001; w += 0.5) {
        const features_corridor_t a = at_pose(2.0, y, psi);
        const features_corridor_t b = at_pose(2.0, -y, -psi);
        assert_true(fabs(clearance(&a, 0.5, 0.2, w, 3.0) - clearance(&b, 0.5, -0.2, -w, 3.0)) < 1e-12);
      }
    }
  }
}

// The run ends at the goal, where the base is told to stop and coasts to a stand: the same pose
// and commands that touch the wall 6 m before the goal are safe 5 cm before it; and the coast
// counts: a one-period rollout that reaches the goal while heading for a wall keeps less
// clearance once the base stands than at the goal (0.31 m at the goal, 0.19 m standing).
static void test_recovery_stops_at_the_goal_after_the_coast(void** state) {
  (void)state;
  const double x_goal = g_spec.length_m - g_spec.goal_distance_m;
  const features_corridor_t near_goal = at_pose(x_goal - 0.05, 0.5, 0.6);
  const features_corridor_t far = at_pose(3.0, 0.5, 0.6);
  assert_true(clearance(&far, 0.6, 1.0, 1.0, 3.0) < 0.0);
  assert_true(clearance(&near_goal, 0.6, 1.0, 1.0, 3.0) > 0.0);
  const features_corridor_t at_goal = at_pose(x_goal + 0.01, 0.4, 0.6);
  const double c = clearance(&at_goal, 0.6, 0.0, 0.0, g_spec.dt_s);
  const double at_the_goal = 0.74 - (0.4 + 0.06 * sin(0.6));
  print_message("at the goal: %.3f m after one period, %.3f m once standing\n", at_the_goal, c);
  assert_true(c < at_the_goal - 0.1);
  // A base that could not stand within 20 s cannot be predicted.
  tasks_command_limits_t slow = g_lim;
  slow.max_translation_accel_mps2 = 0.01;
  assert_true(refused(tasks_corridor_recovery_clearance_m(&g_spec, &slow, g_spec.dt_s, &at_goal, 0.6, 0.0, 0.0,
                                                          g_spec.dt_s)));
}

// The walls are where the features measured them: a measured width below the nominal one moves
// them in (the offset is measured from the measured centre line), one above it does not move
// them out.
static void test_recovery_uses_the_measured_width(void** state) {
  (void)state;
  features_corridor_t f = at_pose(2.0, 0.0, 0.0);
  f.width_m = 1.8;
  assert_true(fabs(clearance(&f, g_spec.v_centre_mps, 0.0, 0.0, 3.0) - 0.64) < 1e-12);
  f.width_m = 2.3;
  assert_true(fabs(clearance(&f, g_spec.v_centre_mps, 0.0, 0.0, 3.0) - 0.74) < 1e-12);
}

// Dead reckoning moves the features one period as the rollout does: chained predictions with the
// recovery law reproduce the rollout's clearance, and a prediction that holds course while
// centred and straight moves only the end distance.
static void test_recovery_predict_follows_the_rollout(void** state) {
  (void)state;
  const features_corridor_t f0 = at_pose(3.0, 0.3, 0.5);
  features_corridor_t f = f0;
  double v = 0.5;
  double w = 0.2;
  double least = INFINITY;
  for (int k = 0; k < 30; ++k) {
    const double w_cmd = k == 0 ? 0.4 : tasks_corridor_recovery_action(&g_spec, &f);
    double v_cmd = tasks_corridor_speed_mps(&g_spec, &f);
    double w_sent = w_cmd;
    double v_sent = v_cmd;
    (void)tasks_command_clamp(&g_lim, g_spec.dt_s, v, w, &v_sent, &w_sent);
    features_corridor_t next;
    assert_int_equal(tasks_corridor_recovery_predict(&g_spec, &g_lim, g_spec.dt_s, &f, v, w, v_cmd, w_cmd, &next), 1);
    f = next;
    v = v_sent;
    w = w_sent;
    least = fmin(least, 0.74 - fabs(f.offset_m));
  }
  assert_true(fabs(least - clearance(&f0, 0.5, 0.2, 0.4, 3.0)) < 1e-9);
  const features_corridor_t c = at_pose(2.0, 0.0, 0.0);
  features_corridor_t n;
  assert_int_equal(tasks_corridor_recovery_predict(&g_spec, &g_lim, 0.1, &c, 0.6, 0.0, 0.6, 0.0, &n), 1);
  assert_true(n.offset_m == 0.0 && n.heading_rad == 0.0 && fabs(n.end_distance_m - (c.end_distance_m - 0.06)) < 1e-12);
  assert_int_equal(tasks_corridor_recovery_predict(&g_spec, &g_lim, 0.1, &c, 0.6, 0.0, NAN, 0.0, &n), 0);
  assert_int_equal(tasks_corridor_recovery_predict(&g_spec, &g_lim, 0.1, &c, 0.6, 0.0, 0.6, 0.0, NULL), 0);
}

// A longer horizon never predicts more clearance; the horizon is kept within [dt, 20 s].
static void test_recovery_horizon(void** state) {
  (void)state;
  const features_corridor_t f = at_pose(2.0, 0.3, 0.4);
  double prev = INFINITY;
  for (double h = 0.1; h <= 6.0; h += 0.5) {
    const double c = clearance(&f, 0.5, 0.0, 0.5, h);
    assert_true(c <= prev);
    prev = c;
  }
  assert_true(clearance(&f, 0.5, 0.0, 0.5, 0.0) == clearance(&f, 0.5, 0.0, 0.5, g_spec.dt_s));
  assert_true(clearance(&f, 0.5, 0.0, 0.5, 1e6) == clearance(&f, 0.5, 0.0, 0.5, 20.0));
}

// Nothing can be predicted from invalid features or a non-finite input: -INFINITY, so nothing
// passes; the recovery law then holds course. No call allocates.
static void test_recovery_refuses_what_it_cannot_predict(void** state) {
  (void)state;
  features_corridor_t f = at_pose(2.0, 0.0, 0.0);
  alloc_counter_begin();
  assert_true(refused(clearance(&f, 0.5, 0.0, NAN, 3.0)));
  assert_true(refused(clearance(&f, NAN, 0.0, 0.0, 3.0)));
  assert_true(refused(clearance(&f, 0.5, INFINITY, 0.0, 3.0)));
  assert_true(refused(clearance(&f, 0.5, 0.0, 0.0, NAN)));
  assert_true(refused(tasks_corridor_recovery_clearance_m(&g_spec, &g_lim, 0.0, &f, 0.5, 0.0, 0.0, 3.0)));
  assert_true(refused(tasks_corridor_recovery_clearance_m(&g_spec, &g_lim, 1e-12, &f, 0.5, 0.0, 0.0, 3.0)));
  assert_true(refused(tasks_corridor_recovery_clearance_m(&g_spec, &g_lim, 0.1, NULL, 0.5, 0.0, 0.0, 3.0)));
  assert_true(refused(tasks_corridor_recovery_clearance_m(NULL, &g_lim, 0.1, &f, 0.5, 0.0, 0.0, 3.0)));
  assert_true(refused(tasks_corridor_recovery_clearance_m(&g_spec, NULL, 0.1, &f, 0.5, 0.0, 0.0, 3.0)));
  f.offset_m = NAN;
  assert_true(refused(clearance(&f, 0.5, 0.0, 0.0, 3.0)));
  f = at_pose(2.0, 0.3, 0.2);
  f.valid = 0;
  assert_true(refused(clearance(&f, 0.5, 0.0, 0.0, 3.0)));
  assert_true(tasks_corridor_recovery_action(&g_spec, &f) == 0.0);
  assert_true(tasks_corridor_recovery_action(&g_spec, NULL) == 0.0);
  assert_true(tasks_corridor_recovery_action(NULL, &f) == 0.0);
  assert_int_equal(alloc_counter_end(), 0);
}

// The recovery law is the example policy at gain 2 on the target angle, within the action bound.
static void test_recovery_action_is_the_gain_two_law(void** state) {
  (void)state;
  const features_corridor_t f = at_pose(2.0, 0.2, 0.1);
  assert_true(tasks_corridor_recovery_action(&g_spec, &f) == 2.0 * f.target_angle_rad);
  const features_corridor_t g = at_pose(2.0, 0.6, 1.0);
  assert_true(tasks_corridor_recovery_action(&g_spec, &g) == -g_spec.omega_max_radps);
}

// A whole run on the model (tasks_corridor_rollout_*): it starts at the pose the learner's state
// describes, then moves period by period exactly as chained dead reckoning does, and ends at the
// goal when the end distance is reached.
static void test_rollout_follows_the_prediction_to_the_goal(void** state) {
  (void)state;
  const features_corridor_t f0 = at_pose(1.2, 0.3, 0.4);
  double s0[3];
  features_corridor_state(&f0, s0);
  tasks_corridor_rollout_t ro;
  assert_int_equal(tasks_corridor_rollout_begin(&ro, &g_spec, s0, 0.1), TASKS_ROLLOUT_RUNNING);
  assert_true(fabs(ro.f.offset_m - 0.3) < 1e-12 && fabs(ro.f.heading_rad - 0.4) < 1e-12);
  assert_true(ro.f.end_distance_m == f0.end_distance_m && ro.v_mps == 0.0 && ro.omega_radps == 0.1);
  features_corridor_t f = f0;
  double v = 0.0;
  double w = 0.1;
  double least = 0.74 - 0.3;
  uint32_t periods = 0;
  alloc_counter_begin();
  while (ro.status == TASKS_ROLLOUT_RUNNING) {
    const double w_cmd = tasks_corridor_recovery_action(&g_spec, &ro.f);
    double v_sent = tasks_corridor_speed_mps(&g_spec, &f);
    double w_sent = w_cmd;
    (void)tasks_command_clamp(&g_lim, g_spec.dt_s, v, w, &v_sent, &w_sent);
    features_corridor_t next;
    assert_int_equal(tasks_corridor_recovery_predict(&g_spec, &g_lim, g_spec.dt_s, &f, v, w,
                                                     tasks_corridor_speed_mps(&g_spec, &f), w_cmd, &next), 1);
    (void)tasks_corridor_rollout_step(&ro, &g_spec, &g_lim, g_spec.dt_s, w_cmd, 0.1, g_spec.step_limit);
    f = next;
    v = v_sent;
    w = w_sent;
    least = fmin(least, 0.74 - fabs(f.offset_m));
    periods++;
    if (ro.status == TASKS_ROLLOUT_RUNNING) {
      assert_true(fabs(ro.f.offset_m - f.offset_m) < 1e-12 && fabs(ro.f.heading_rad - f.heading_rad) < 1e-12);
      assert_true(fabs(ro.f.end_distance_m - f.end_distance_m) < 1e-12 && ro.omega_radps == w);
    }
  }
  assert_int_equal(alloc_counter_end(), 0);
  assert_int_equal(ro.status, TASKS_ROLLOUT_GOAL);
  assert_true(f.end_distance_m <= g_spec.goal_distance_m);
  assert_int_equal(ro.periods, periods);
  // 7.8 m to the goal at no more than 0.6 m/s take at least 130 periods; the recovery law
  // settles within a few seconds, so not many more.
  assert_true(periods >= 130 && periods < 160);
  assert_true(ro.least_clearance_m <= least && ro.least_clearance_m > 0.1);
  // A finished rollout stays as it ended.
  assert_int_equal(tasks_corridor_rollout_step(&ro, &g_spec, &g_lim, g_spec.dt_s, 1.0, 0.1, 1000),
                   TASKS_ROLLOUT_GOAL);
  assert_int_equal(ro.periods, periods);
}

// Holding course at 0.6 rad off the axis meets the wall (with or without a margin, the margin
// sooner); a run that needs more periods than the limit ends at the limit; non-finite inputs are
// refused as unpredictable.
static void test_rollout_ends_at_a_wall_the_limit_or_bad_input(void** state) {
  (void)state;
  const features_corridor_t f0 = at_pose(1.0, 0.0, 0.6);
  double s0[3];
  features_corridor_state(&f0, s0);
  uint32_t to_contact = 0;
  uint32_t to_margin = 0;
  for (int pass = 0; pass < 2; ++pass) {
    tasks_corridor_rollout_t ro;
    (void)tasks_corridor_rollout_begin(&ro, &g_spec, s0, 0.0);
    const double margin = pass == 0 ? 0.0 : 0.2;
    while (tasks_corridor_rollout_step(&ro, &g_spec, &g_lim, g_spec.dt_s, 0.0, margin, 1000) == TASKS_ROLLOUT_RUNNING) {
    }
    assert_int_equal(ro.status, TASKS_ROLLOUT_WALL);
    assert_true(ro.least_clearance_m < margin && ro.f.end_distance_m > g_spec.goal_distance_m);
    *(pass == 0 ? &to_contact : &to_margin) = ro.periods;
  }
  assert_true(to_margin < to_contact);
  const features_corridor_t c = at_pose(1.0, 0.0, 0.0);
  double sc[3];
  features_corridor_state(&c, sc);
  tasks_corridor_rollout_t ro;
  (void)tasks_corridor_rollout_begin(&ro, &g_spec, sc, 0.0);
  while (tasks_corridor_rollout_step(&ro, &g_spec, &g_lim, g_spec.dt_s, 0.0, 0.1, 25) == TASKS_ROLLOUT_RUNNING) {
  }
  assert_int_equal(ro.status, TASKS_ROLLOUT_STEP_LIMIT);
  assert_int_equal(ro.periods, 25);
  (void)tasks_corridor_rollout_begin(&ro, &g_spec, sc, 0.0);
  assert_int_equal(tasks_corridor_rollout_step(&ro, &g_spec, &g_lim, g_spec.dt_s, NAN, 0.1, 25), TASKS_ROLLOUT_INVALID);
  sc[1] = NAN;
  assert_int_equal(tasks_corridor_rollout_begin(&ro, &g_spec, sc, 0.0), TASKS_ROLLOUT_INVALID);
  assert_int_equal(tasks_corridor_rollout_step(&ro, &g_spec, &g_lim, g_spec.dt_s, 0.0, 0.1, 25), TASKS_ROLLOUT_INVALID);
  assert_int_equal(tasks_corridor_rollout_begin(NULL, &g_spec, sc, 0.0), TASKS_ROLLOUT_INVALID);
  assert_int_equal(tasks_corridor_rollout_begin(&ro, NULL, s0, 0.0), TASKS_ROLLOUT_INVALID);
}

// ---------------------------------------------------------------------------------------------
// The obstacle task's whole-run rollout.

// The default obstacle task and its features' configuration.
static void obstacles_defaults(tasks_obstacles_spec_t* spec, features_obstacles_config_t* fcfg) {
  tasks_obstacles_spec_default(spec);
  tasks_obstacles_features_config(spec, fcfg);
}

// The state an ideal laser gives at an arena pose (the emulator's idealised model).
static bool obstacles_state_at(const tasks_obstacles_spec_t* spec, features_pose_t p, double s[4]) {
  tasks_episode_t ep;
  tasks_corridor_spec_t corridor;
  tasks_corridor_spec_default(&corridor);
  tasks_episode_init(&ep, TASKS_TASK_OBSTACLES, &corridor, spec);
  return tasks_episode_observe_pose(&ep, p, s) == 1;
}

// Every pose the obstacle is visible from comes back from its state (to rounding), over a grid
// of the arena around the obstacle and of headings; with the laser's errors added (0.02 m, 0.01
// rad) within 0.35 m (0.30 m measured: a bearing error turns the whole triangle, so the error
// grows with the distance, to 6 m here). A state without a visible obstacle, or one whose
// obstacle distance matches no disc, gives no pose.
static void test_obstacles_pose_from_state_inverts_the_features(void** state) {
  (void)state;
  tasks_obstacles_spec_t spec;
  features_obstacles_config_t fcfg;
  obstacles_defaults(&spec, &fcfg);
  int visible = 0;
  int hidden = 0;
  double worst = 0.0;
  double worst_noisy = 0.0;
  for (double x = -4.5; x <= 1.5001; x += 0.25) {
    for (double y = -3.0; y <= 3.0001; y += 0.25) {
      for (double th = -3.0; th <= 3.0001; th += 0.5) {
        const features_pose_t p = {x, y, th};
        if (hypot(x + 1.5, y) < 0.3 || hypot(x, y) < 0.3) {
          continue;  // inside the disc, or at the goal (where a distance error can make it negative)
        }
        double s[4];
        assert_true(obstacles_state_at(&spec, p, s));
        features_pose_t q;
        const int got = tasks_obstacles_pose_from_state(&spec, &fcfg, s, &q);
        if (s[3] >= fcfg.no_obstacle_distance_m) {
          assert_int_equal(got, 0);
          hidden++;
          continue;
        }
        assert_int_equal(got, 1);
        visible++;
        worst = fmax(worst, fmax(hypot(q.x_m - x, q.y_m - y), fabs(remainder(q.theta_rad - th, 6.283185307179586))));
        const double noisy[4] = {s[0] + 0.01, s[1] - 0.02, s[2] - 0.01, s[3] + 0.02};
        assert_int_equal(tasks_obstacles_pose_from_state(&spec, &fcfg, noisy, &q), 1);
        worst_noisy = fmax(worst_noisy, hypot(q.x_m - x, q.y_m - y));
      }
    }
  }
  print_message("obstacle poses: %d visible (largest error %.2g), %d hidden; with sensing errors %.3f m\n", visible,
                worst, hidden, worst_noisy);
  assert_true(visible > 1000 && hidden > 1000);
  assert_true(worst < 1e-9);
  assert_true(worst_noisy < 0.35);
  // Two discs at the same distance from the goal: the distance alone matches both, and the pose
  // taken is the one whose features reproduce the state's obstacle, so the pose recovered always
  // reproduces the state (where the second disc is out of view the state cannot tell the two
  // poses apart; poses equally far from both discs are left out: which one the state names there
  // is a matter of rounding).
  tasks_obstacles_spec_t two = spec;
  two.n_obstacles = 2;
  two.obstacles[1] = (tasks_circle_t){0.0, 1.5, 0.25};
  int checked = 0;
  for (double x = -4.0; x <= 1.5001; x += 0.5) {
    for (double y = -3.0; y <= 3.0001; y += 0.5) {
      for (double th = -3.0; th <= 3.0001; th += 0.75) {
        double s[4];
        double r[4];
        features_pose_t q;
        if (hypot(x + 1.5, y) < 0.6 || hypot(x, y - 1.5) < 0.6 || hypot(x, y) < 0.3 ||
            fabs(hypot(x + 1.5, y) - hypot(x, y - 1.5)) < 0.01 ||
            !obstacles_state_at(&two, (features_pose_t){x, y, th}, s) || s[3] >= fcfg.no_obstacle_distance_m) {
          continue;
        }
        assert_int_equal(tasks_obstacles_pose_from_state(&two, &fcfg, s, &q), 1);
        assert_true(obstacles_state_at(&two, q, r));
        for (int i = 0; i < 4; ++i) {
          assert_true(fabs(r[i] - s[i]) < 1e-9);
        }
        checked++;
      }
    }
  }
  assert_true(checked > 300);
  features_pose_t q;
  const double mismatched[4] = {0.0, 3.0, 0.0, 0.5};  // the obstacle 0.75 m from the goal: no disc is
  assert_int_equal(tasks_obstacles_pose_from_state(&spec, &fcfg, mismatched, &q), 0);
  const double bad[4] = {0.0, NAN, 0.1, 1.0};
  assert_int_equal(tasks_obstacles_pose_from_state(&spec, &fcfg, bad, &q), 0);
  assert_int_equal(tasks_obstacles_pose_from_state(NULL, &fcfg, mismatched, &q), 0);
}

// From every evaluation start the "optimal" reference law drives the rollout to the goal, and
// the rollout follows an independent integration of the same commands (a synchro-drive body at
// 100 sub-steps per period under the same limits) to within 5 cm over the whole run (about 3 m,
// 0.04 m measured); no
// allocation. Its periods are close to the steps the reference takes in the emulator (97.4 on
// average from these starts, with a noisy laser): 97.6 on the model.
static void test_obstacles_rollout_follows_the_integration_to_the_goal(void** state) {
  (void)state;
  tasks_obstacles_spec_t spec;
  features_obstacles_config_t fcfg;
  obstacles_defaults(&spec, &fcfg);
  const double dt = spec.dt_s;
  const int sub = 100;
  sim_kin_limits_t kl = {g_lim.max_translation_accel_mps2, g_lim.max_rotation_accel_radps2};
  double worst = 0.0;
  uint32_t total = 0;
  for (uint32_t i = 0; i < TASKS_N_EVAL_STARTS; ++i) {
    const features_pose_t p0 = tasks_obstacles_eval_start(&spec, i);
    double s[4];
    assert_true(obstacles_state_at(&spec, p0, s));
    tasks_obstacles_rollout_t ro;
    assert_int_equal(tasks_obstacles_rollout_begin(&ro, &spec, &fcfg, s, 0.0), TASKS_ROLLOUT_RUNNING);
    assert_true(hypot(ro.pose.x_m - p0.x_m, ro.pose.y_m - p0.y_m) < 1e-9);
    tasks_driver_t d;
    tasks_driver_begin_run(&d, TASKS_DRIVER_OPTIMAL, TASKS_TASK_OBSTACLES, spec.omega_max_radps, 1U);
    sim_kin_state_t body;
    sim_kin_reset(&body, p0.x_m, p0.y_m, p0.theta_rad);
    double v_prev = 0.0;
    double w_prev = 0.0;
    alloc_counter_begin();
    while (ro.status == TASKS_ROLLOUT_RUNNING) {
      const double w = tasks_driver_obstacles(&d, &ro.f);
      (void)tasks_obstacles_rollout_step(&ro, &spec, &fcfg, &g_lim, dt, w, 0.0, spec.step_limit);
      double v_cmd = spec.v_mps;
      double w_cmd = w;
      (void)tasks_command_clamp(&g_lim, dt, v_prev, w_prev, &v_cmd, &w_cmd);
      sim_kin_run(&body, &kl, v_cmd, w_cmd, dt / sub, (uint64_t)sub);
      v_prev = v_cmd;
      w_prev = w_cmd;
      worst = fmax(worst, hypot(ro.pose.x_m - body.x_m, ro.pose.y_m - body.y_m));
    }
    assert_int_equal(alloc_counter_end(), 0);
    assert_int_equal(ro.status, TASKS_ROLLOUT_GOAL);
    // The reference law passes the disc closely: 0.07 m at the least, from start 9.
    assert_true(ro.f.goal_distance_m <= spec.goal_radius_m && ro.least_clearance_m > 0.05);
    total += ro.periods;
    // A finished rollout stays as it ended.
    const uint32_t periods = ro.periods;
    assert_int_equal(tasks_obstacles_rollout_step(&ro, &spec, &fcfg, &g_lim, dt, 1.0, 0.1, 1000), TASKS_ROLLOUT_GOAL);
    assert_int_equal(ro.periods, periods);
  }
  print_message("optimal law on the model: %.1f periods on average; largest distance from the integration %.4f m\n",
                (double)total / TASKS_N_EVAL_STARTS, worst);
  assert_true(worst < 0.05);
  assert_true(total >= 90U * TASKS_N_EVAL_STARTS && total <= 105U * TASKS_N_EVAL_STARTS);
}

// Holding course from straight behind the obstacle, facing the goal, meets the disc (the margin
// sooner than contact); toward a wall, the wall; a run that needs more periods than the limit
// ends at the limit; non-finite inputs are refused; a start without a visible obstacle has no
// pose to start from.
static void test_obstacles_rollout_ends_at_contact_the_limit_or_bad_input(void** state) {
  (void)state;
  tasks_obstacles_spec_t spec;
  features_obstacles_config_t fcfg;
  obstacles_defaults(&spec, &fcfg);
  const double dt = spec.dt_s;
  double s[4];
  assert_true(obstacles_state_at(&spec, (features_pose_t){-3.0, 0.05, 0.0}, s));
  uint32_t to_contact = 0;
  uint32_t to_margin = 0;
  for (int pass = 0; pass < 2; ++pass) {
    tasks_obstacles_rollout_t ro;
    (void)tasks_obstacles_rollout_begin(&ro, &spec, &fcfg, s, 0.0);
    const double margin = pass == 0 ? 0.0 : 0.2;
    while (tasks_obstacles_rollout_step(&ro, &spec, &fcfg, &g_lim, dt, 0.0, margin, 1000) == TASKS_ROLLOUT_RUNNING) {
    }
    assert_int_equal(ro.status, TASKS_ROLLOUT_WALL);
    assert_true(ro.least_clearance_m < margin && ro.pose.x_m < -1.5);
    *(pass == 0 ? &to_contact : &to_margin) = ro.periods;
  }
  print_message("holding course into the disc: contact after %u periods, the 0.2 m margin after %u\n", to_contact, to_margin);
  assert_true(to_margin < to_contact);
  // (1.5 - 0.25 - 0.26) m at 0.03 m per period, plus the ramp to speed: about 35 periods.
  assert_true(to_contact >= 34 && to_contact <= 38);
  tasks_obstacles_rollout_t ro;
  assert_true(obstacles_state_at(&spec, (features_pose_t){-1.0, 0.0, 1.5}, s));  // the disc behind on the right
  assert_true(s[3] < fcfg.no_obstacle_distance_m || tasks_obstacles_rollout_begin(&ro, &spec, &fcfg, s, 0.0) ==
                                                        TASKS_ROLLOUT_INVALID);
  // Toward the wall at x = -5, past the disc 1 m to the side (visible ahead on the left at the
  // start): the skirt clears the disc by 0.49 m and meets the wall's margin.
  assert_true(obstacles_state_at(&spec, (features_pose_t){-1.0, 1.0, 3.141592653589793}, s));
  assert_int_equal(tasks_obstacles_rollout_begin(&ro, &spec, &fcfg, s, 0.0), TASKS_ROLLOUT_RUNNING);
  while (tasks_obstacles_rollout_step(&ro, &spec, &fcfg, &g_lim, dt, 0.0, 0.1, 1000) == TASKS_ROLLOUT_RUNNING) {
  }
  assert_int_equal(ro.status, TASKS_ROLLOUT_WALL);
  assert_true(ro.pose.x_m < -5.0 + 0.26 + 0.1 && ro.pose.x_m > -5.0 + 0.26 + 0.1 - 0.05);
  assert_true(fabs(ro.pose.y_m - 1.0) < 1e-9);
  assert_true(obstacles_state_at(&spec, (features_pose_t){-3.0, 1.0, 0.0}, s));
  (void)tasks_obstacles_rollout_begin(&ro, &spec, &fcfg, s, 0.0);
  while (tasks_obstacles_rollout_step(&ro, &spec, &fcfg, &g_lim, dt, 0.0, 0.1, 25) == TASKS_ROLLOUT_RUNNING) {
  }
  assert_int_equal(ro.status, TASKS_ROLLOUT_STEP_LIMIT);
  assert_int_equal(ro.periods, 25);
  (void)tasks_obstacles_rollout_begin(&ro, &spec, &fcfg, s, 0.0);
  assert_int_equal(tasks_obstacles_rollout_step(&ro, &spec, &fcfg, &g_lim, dt, NAN, 0.1, 25), TASKS_ROLLOUT_INVALID);
  assert_int_equal(tasks_obstacles_rollout_begin(&ro, &spec, &fcfg, s, INFINITY), TASKS_ROLLOUT_INVALID);
  const double hidden[4] = {0.0, 3.0, 3.141592653589793, fcfg.no_obstacle_distance_m};
  assert_int_equal(tasks_obstacles_rollout_begin(&ro, &spec, &fcfg, hidden, 0.0), TASKS_ROLLOUT_INVALID);
  assert_int_equal(tasks_obstacles_rollout_step(&ro, &spec, &fcfg, &g_lim, dt, 0.0, 0.1, 25), TASKS_ROLLOUT_INVALID);
  assert_int_equal(tasks_obstacles_rollout_begin(NULL, &spec, &fcfg, s, 0.0), TASKS_ROLLOUT_INVALID);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test_setup(test_recovery_centred_straight_keeps_half_width, setup),
      cmocka_unit_test_setup(test_recovery_matches_independent_integration, setup),
      cmocka_unit_test_setup(test_recovery_ranks_commands_by_the_geometry, setup),
      cmocka_unit_test_setup(test_recovery_is_mirror_symmetric, setup),
      cmocka_unit_test_setup(test_recovery_stops_at_the_goal_after_the_coast, setup),
      cmocka_unit_test_setup(test_recovery_uses_the_measured_width, setup),
      cmocka_unit_test_setup(test_recovery_predict_follows_the_rollout, setup),
      cmocka_unit_test_setup(test_recovery_horizon, setup),
      cmocka_unit_test_setup(test_recovery_refuses_what_it_cannot_predict, setup),
      cmocka_unit_test_setup(test_recovery_action_is_the_gain_two_law, setup),
      cmocka_unit_test_setup(test_rollout_follows_the_prediction_to_the_goal, setup),
      cmocka_unit_test_setup(test_rollout_ends_at_a_wall_the_limit_or_bad_input, setup),
      cmocka_unit_test_setup(test_obstacles_pose_from_state_inverts_the_features, setup),
      cmocka_unit_test_setup(test_obstacles_rollout_follows_the_integration_to_the_goal, setup),
      cmocka_unit_test_setup(test_obstacles_rollout_ends_at_contact_the_limit_or_bad_input, setup),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
