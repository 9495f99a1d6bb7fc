// SPDX-License-Identifier: MIT
// Task specifications, start poses, rewards/termination on hand-built situations, speed policies.
#include <b21r_test/alloc_counter.h>
#include <b21r_test/synthetic_world.h>
#include <features/features.h>
#include <tasks/tasks.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#define PI 3.14159265358979323846

static features_corridor_t corridor_at(const tasks_corridor_spec_t* spec, double x, double y,
                                       double th) {
  features_corridor_config_t cfg;
  tasks_corridor_features_config(spec, &cfg);
  features_corridor_t f;
  const features_pose_t p = {x, y, th};
  assert_int_equal(features_corridor_from_pose(&cfg, p, &f), FEATURES_OK);
  return f;
}

static features_obstacles_t obstacles_at(const tasks_obstacles_spec_t* spec, double x, double y,
                                         double th) {
  features_obstacles_config_t cfg;
  tasks_obstacles_features_config(spec, &cfg);
  static features_scan_t scan;  // no returns: only the goal part matters here
  memset(&scan, 0, sizeof scan);
  assert_int_equal(features_scan_set_lms200_geometry(&scan, 180, 1.0), FEATURES_OK);
  for (int i = 0; i < scan.n_beams; ++i) scan.no_return[i] = 1U;
  const features_pose_t p = {x, y, th};
  features_obstacles_t f;
  assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, spec->goal_x_m, spec->goal_y_m, &f),
                   FEATURES_OK);
  return f;
}

// The defaults are the documented numbers (paper values where the paper gives them).
static void test_specs_defaults_documented_values(void** state) {
  (void)state;
  tasks_corridor_spec_t c;
  tasks_corridor_spec_default(&c);
  assert_true(c.length_m == 10.0 && c.width_m == 2.0 && c.goal_distance_m == 1.0);
  assert_true(c.goal_reward == 10.0 && c.gamma == 0.99 && c.omega_max_radps == 1.0);
  assert_true(c.v_centre_mps == 0.6 && c.v_wall_mps == 0.2 && c.dt_s == 0.1);
  assert_true(c.lookahead_m == 2.0 && c.step_limit == 1000U);
  tasks_obstacles_spec_t o;
  tasks_obstacles_spec_default(&o);
  assert_true(o.goal_reward == 1.0 && o.collision_reward == -1.0 && o.gamma == 0.9);
  assert_true(o.n_obstacles == 1U && o.v_mps == 0.3 && o.omega_max_radps == 1.0);
  assert_true(TASKS_ALPHA == 0.2);
  features_corridor_config_t fc;
  tasks_corridor_features_config(&c, &fc);
  assert_true(fc.width_m == c.width_m && fc.length_m == c.length_m && fc.lookahead_m == 2.0);
}

// Corridor evaluation starts: ten distinct poses, clear of the walls, facing down the corridor.
static void test_specs_corridor_eval_starts_valid(void** state) {
  (void)state;
  tasks_corridor_spec_t c;
  tasks_corridor_spec_default(&c);
  for (uint32_t i = 0U; i < TASKS_N_EVAL_STARTS; ++i) {
    const features_pose_t p = tasks_corridor_eval_start(&c, i);
    assert_true(fabs(p.y_m) + c.robot_radius_m + 0.1 <= 0.5 * c.width_m);
    assert_true(p.x_m >= c.robot_radius_m + 0.1 && p.x_m < 2.0);
    assert_true(fabs(p.theta_rad) <= 1.0 + 1e-12);
    for (uint32_t j = 0U; j < i; ++j) {
      const features_pose_t q = tasks_corridor_eval_start(&c, j);
      assert_false(p.x_m == q.x_m && p.y_m == q.y_m && p.theta_rad == q.theta_rad);
    }
  }
  const features_pose_t wrap = tasks_corridor_eval_start(&c, 13U);
  assert_true(wrap.x_m == c.eval_starts[3].x_m);
}

// Obstacle evaluation starts: about 3 m from the goal, clear of the obstacle, heading roughly at
// the goal, and for most of them the straight line to the goal passes the obstacle closely.
static void test_specs_obstacles_eval_starts_valid(void** state) {
  (void)state;
  tasks_obstacles_spec_t o;
  tasks_obstacles_spec_default(&o);
  int blocked = 0;
  for (uint32_t i = 0U; i < TASKS_N_EVAL_STARTS; ++i) {
    const features_pose_t p = tasks_obstacles_eval_start(&o, i);
    const double dg = hypot(p.x_m - o.goal_x_m, p.y_m - o.goal_y_m);
    assert_true(dg >= 2.8 - 1e-9 && dg <= 3.2 + 1e-9);
    const tasks_circle_t* c = &o.obstacles[0];
    assert_true(hypot(p.x_m - c->x_m, p.y_m - c->y_m) > c->radius_m + o.robot_radius_m + 0.5);
    const double to_goal = atan2(o.goal_y_m - p.y_m, o.goal_x_m - p.x_m);
    assert_true(fabs(features_angle_wrap(p.theta_rad - to_goal)) <= 0.6 + 1e-9);
    // Distance from the obstacle centre to the start-goal segment.
    const double ux = (o.goal_x_m - p.x_m) / dg, uy = (o.goal_y_m - p.y_m) / dg;
    const double t = (c->x_m - p.x_m) * ux + (c->y_m - p.y_m) * uy;
    const double lateral = fabs(-(c->x_m - p.x_m) * uy + (c->y_m - p.y_m) * ux);
    blocked += t > 0.0 && t < dg && lateral < c->radius_m + o.robot_radius_m + 0.2;
  }
  printf("[ specs ] obstacle evaluation starts whose straight path passes the obstacle: %d/10\n",
         blocked);
  assert_true(blocked >= 6);
}

// Training starts are near an evaluation start but never equal to one, clear of walls and
// obstacles, and a function of the seed.
static void test_specs_training_starts_similar_not_same(void** state) {
  (void)state;
  tasks_corridor_spec_t c;
  tasks_corridor_spec_default(&c);
  tasks_obstacles_spec_t o;
  tasks_obstacles_spec_default(&o);
  rng_t r1, r2;
  rng_seed(&r1, 99U);
  rng_seed(&r2, 99U);
  for (int k = 0; k < 500; ++k) {
    const features_pose_t p = tasks_corridor_training_start(&c, &r1);
    const features_pose_t q = tasks_corridor_training_start(&c, &r2);
    assert_memory_equal(&p, &q, sizeof p);
    double nearest = INFINITY;
    for (uint32_t i = 0U; i < TASKS_N_EVAL_STARTS; ++i) {
      const features_pose_t e = c.eval_starts[i];
      const double n = fmax(fmax(fabs(p.x_m - e.x_m) / c.train_jitter_x_m,
                                 fabs(p.y_m - e.y_m) / c.train_jitter_y_m),
                            fabs(features_angle_wrap(p.theta_rad - e.theta_rad)) /
                                c.train_jitter_theta_rad);
      nearest = fmin(nearest, n);
    }
    assert_true(nearest <= 1.0 + 1e-9);  // similar: inside the jitter box of some start
    assert_true(nearest > 0.0);          // not the same as any evaluation start
    assert_true(fabs(p.y_m) + c.robot_radius_m + 0.1 <= 0.5 * c.width_m + 1e-12);
    assert_true(p.x_m >= c.robot_radius_m + 0.1 - 1e-12);

    const features_pose_t s = tasks_obstacles_training_start(&o, &r1);
    (void)tasks_obstacles_training_start(&o, &r2);
    const tasks_circle_t* ob = &o.obstacles[0];
    assert_true(hypot(s.x_m - ob->x_m, s.y_m - ob->y_m) >= ob->radius_m + o.robot_radius_m + 0.1);
    const double dg = hypot(s.x_m - o.goal_x_m, s.y_m - o.goal_y_m);
    assert_true(dg > 2.3 && dg < 3.7);
    int same = 0;
    for (uint32_t i = 0U; i < TASKS_N_EVAL_STARTS; ++i) {
      same += s.x_m == o.eval_starts[i].x_m && s.y_m == o.eval_starts[i].y_m &&
              s.theta_rad == o.eval_starts[i].theta_rad;
    }
    assert_int_equal(same, 0);
  }
}

// Corridor reward: +10 and terminal at the end, 0 elsewhere; contact ends the run (terminal,
// reward 0); the step limit ends the run without making the state terminal.
static void test_specs_corridor_outcome_hand_built(void** state) {
  (void)state;
  tasks_corridor_spec_t c;
  tasks_corridor_spec_default(&c);
  const features_corridor_t mid = corridor_at(&c, 5.0, 0.0, 0.0);
  tasks_outcome_t o = tasks_corridor_outcome(&c, &mid, 0U, 10U);
  assert_true(o.reward == 0.0);
  assert_int_equal(o.terminal, 0);
  assert_int_equal(o.end_run, 0);
  assert_int_equal(o.reason, TASKS_END_NONE);
  const features_corridor_t end = corridor_at(&c, 9.0, 0.3, 0.2);  // exactly 1.0 m from the end
  o = tasks_corridor_outcome(&c, &end, 0U, 150U);
  assert_true(o.reward == 10.0);
  assert_int_equal(o.terminal, 1);
  assert_int_equal(o.end_run, 1);
  assert_int_equal(o.reason, TASKS_END_GOAL);
  const features_corridor_t near = corridor_at(&c, 8.99, 0.0, 0.0);  // 1.01 m: not yet
  o = tasks_corridor_outcome(&c, &near, 0U, 150U);
  assert_true(o.reward == 0.0 && o.terminal == 0);
  o = tasks_corridor_outcome(&c, &mid, 1U, 20U);
  assert_true(o.reward == 0.0);
  assert_int_equal(o.terminal, 1);
  assert_int_equal(o.reason, TASKS_END_COLLISION);
  o = tasks_corridor_outcome(&c, &end, 1U, 20U);  // goal wins over a simultaneous contact
  assert_int_equal(o.reason, TASKS_END_GOAL);
  o = tasks_corridor_outcome(&c, &mid, 0U, c.step_limit);
  assert_true(o.reward == 0.0);
  assert_int_equal(o.terminal, 0);
  assert_int_equal(o.end_run, 1);
  assert_int_equal(o.reason, TASKS_END_STEP_LIMIT);
  o = tasks_corridor_outcome(&c, &mid, 0U, c.step_limit - 1U);
  assert_int_equal(o.end_run, 0);
  features_corridor_t invalid = end;
  invalid.valid = 0U;  // an invalid state never pays the goal reward
  o = tasks_corridor_outcome(&c, &invalid, 0U, 5U);
  assert_true(o.reward == 0.0 && o.end_run == 0);
  tasks_corridor_spec_t unlimited = c;
  unlimited.step_limit = 0U;
  o = tasks_corridor_outcome(&unlimited, &mid, 0U, 4000000000U);
  assert_int_equal(o.end_run, 0);
}

// Obstacle reward: +1 at the goal, -1 on contact (which wins), 0 otherwise; step limit.
static void test_specs_obstacles_outcome_hand_built(void** state) {
  (void)state;
  tasks_obstacles_spec_t s;
  tasks_obstacles_spec_default(&s);
  const features_obstacles_t far = obstacles_at(&s, -3.0, 0.0, 0.0);
  tasks_outcome_t o = tasks_obstacles_outcome(&s, &far, 0U, 1U);
  assert_true(o.reward == 0.0 && o.terminal == 0 && o.end_run == 0);
  const features_obstacles_t at = obstacles_at(&s, -0.29, 0.0, 1.0);
  o = tasks_obstacles_outcome(&s, &at, 0U, 90U);
  assert_true(o.reward == 1.0);
  assert_int_equal(o.terminal, 1);
  assert_int_equal(o.reason, TASKS_END_GOAL);
  const features_obstacles_t outside = obstacles_at(&s, -0.31, 0.0, 1.0);
  o = tasks_obstacles_outcome(&s, &outside, 0U, 90U);
  assert_true(o.reward == 0.0 && o.terminal == 0);
  o = tasks_obstacles_outcome(&s, &far, 1U, 30U);
  assert_true(o.reward == -1.0);
  assert_int_equal(o.terminal, 1);
  assert_int_equal(o.reason, TASKS_END_COLLISION);
  o = tasks_obstacles_outcome(&s, &at, 1U, 30U);  // contact wins over the goal
  assert_true(o.reward == -1.0);
  o = tasks_obstacles_outcome(&s, &far, 0U, s.step_limit);
  assert_true(o.reward == 0.0 && o.terminal == 0 && o.end_run == 1);
  assert_int_equal(o.reason, TASKS_END_STEP_LIMIT);
}

// Corridor speed: fast on the centre line, v_wall where the robot touches a wall, symmetric,
// monotonic in between; obstacle speed constant; omega clamped and never NaN.
static void test_specs_speed_policies_follow_documented_curve(void** state) {
  (void)state;
  tasks_corridor_spec_t c;
  tasks_corridor_spec_default(&c);
  const double touch_y = 0.5 * c.width_m - c.robot_radius_m;
  features_corridor_t f = corridor_at(&c, 5.0, 0.0, 0.0);
  assert_true(fabs(tasks_corridor_speed_mps(&c, &f) - 0.6) < 1e-12);
  f = corridor_at(&c, 5.0, touch_y, 0.0);
  assert_true(fabs(tasks_corridor_speed_mps(&c, &f) - 0.2) < 1e-12);
  f = corridor_at(&c, 5.0, -touch_y, 0.0);
  assert_true(fabs(tasks_corridor_speed_mps(&c, &f) - 0.2) < 1e-12);
  const features_corridor_t half = corridor_at(&c, 5.0, 0.5, 0.0);
  f = corridor_at(&c, 5.0, 0.25, 0.0);
  printf("[ specs ] corridor speed: centre 0.600, 0.25 m off %.3f, 0.5 m off %.3f, touching a "
         "wall 0.200 m/s\n", tasks_corridor_speed_mps(&c, &f), tasks_corridor_speed_mps(&c, &half));
  assert_true(fabs(tasks_corridor_speed_mps(&c, &f) - (0.2 + 0.4 * (1.0 - pow(0.25 / touch_y, 2.0)))) < 1e-12);
  double prev = 1.0;
  for (int i = 0; i <= 50; ++i) {
    const features_corridor_t g = corridor_at(&c, 5.0, touch_y * i / 50.0, 0.0);
    const features_corridor_t h = corridor_at(&c, 5.0, -touch_y * i / 50.0, 0.0);
    const double v = tasks_corridor_speed_mps(&c, &g);
    assert_true(v <= prev + 1e-15);
    assert_true(fabs(v - tasks_corridor_speed_mps(&c, &h)) < 1e-12);
    prev = v;
  }
  features_corridor_t invalid = corridor_at(&c, 5.0, 0.0, 0.0);
  invalid.valid = 0U;
  assert_true(tasks_corridor_speed_mps(&c, &invalid) == c.v_wall_mps);
  assert_true(tasks_corridor_speed_mps(&c, NULL) == c.v_wall_mps);
  tasks_obstacles_spec_t o;
  tasks_obstacles_spec_default(&o);
  assert_true(tasks_obstacles_speed_mps(&o) == 0.3);
  assert_true(tasks_clamp_omega(2.0, 1.0) == 1.0);
  assert_true(tasks_clamp_omega(-2.0, 1.0) == -1.0);
  assert_true(tasks_clamp_omega(0.3, 1.0) == 0.3);
  assert_true(tasks_clamp_omega(NAN, 1.0) == 0.0);
  assert_true(tasks_clamp_omega(0.5, NAN) == 0.0);
}

// Everything here is allocation-free.
// The corridor's kinematic bound by hand: straight on the axis from x = 0, 9 m at 0.06 m per step
// is 150 steps; a heading of 0.5 rad costs more, whatever its sign; at the goal it is 0.
static void test_specs_corridor_lower_bound_by_hand(void** state) {
  (void)state;
  tasks_corridor_spec_t cs;
  tasks_corridor_spec_default(&cs);
  const features_pose_t straight = {0.0, 0.0, 0.0};
  assert_int_equal(tasks_corridor_steps_lower_bound(&cs, straight), 150U);
  const features_pose_t left = {0.0, 0.3, 0.5}, right = {0.0, -0.3, -0.5};
  const uint32_t bl = tasks_corridor_steps_lower_bound(&cs, left);
  assert_true(bl > 150U && bl < 155U);
  assert_int_equal(tasks_corridor_steps_lower_bound(&cs, right), bl);
  const features_pose_t at_goal = {cs.length_m - cs.goal_distance_m, 0.0, 1.0};
  assert_int_equal(tasks_corridor_steps_lower_bound(&cs, at_goal), 0U);
  for (uint32_t i = 0U; i < TASKS_N_EVAL_STARTS; ++i) {
    const features_pose_t p = tasks_corridor_eval_start(&cs, i);
    assert_true(tasks_corridor_steps_lower_bound(&cs, p) <=
                (uint32_t)ceil((cs.length_m - cs.goal_distance_m - p.x_m) / (cs.v_centre_mps * cs.dt_s)) + 1U);
  }
}

static void test_specs_no_allocation(void** state) {
  (void)state;
  tasks_corridor_spec_t c;
  tasks_obstacles_spec_t o;
  rng_t r;
  alloc_counter_begin();
  tasks_corridor_spec_default(&c);
  tasks_obstacles_spec_default(&o);
  rng_seed(&r, 1U);
  for (int i = 0; i < 1000; ++i) {
    (void)tasks_corridor_training_start(&c, &r);
    (void)tasks_obstacles_training_start(&o, &r);
  }
  assert_int_equal(alloc_counter_end(), 0);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_specs_defaults_documented_values),
      cmocka_unit_test(test_specs_corridor_eval_starts_valid),
      cmocka_unit_test(test_specs_obstacles_eval_starts_valid),
      cmocka_unit_test(test_specs_training_starts_similar_not_same),
      cmocka_unit_test(test_specs_corridor_outcome_hand_built),
      cmocka_unit_test(test_specs_obstacles_outcome_hand_built),
      cmocka_unit_test(test_specs_speed_policies_follow_documented_curve),
      cmocka_unit_test(test_specs_corridor_lower_bound_by_hand),
      cmocka_unit_test(test_specs_no_allocation),
  };
  return cmocka_run_group_tests_name("tasks.specs", tests, NULL, NULL);
}
