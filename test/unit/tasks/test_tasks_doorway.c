// SPDX-License-Identifier: MIT
// The doorway task's own rules, beside the registry's generic checks: its room and door, the
// reward and termination (goal, collision, step limit), the training starts, and its drivers
// driving whole episodes in the synthetic world (kinematic synchro drive at 10 Hz, features from
// synthetic LMS200 scans): the sloppy example reaches the goal from most starts but clearly
// slower than the reference, which reaches it from every start with a margin.
#include <b21r_test/alloc_counter.h>
#include <tasks/decl.h>
#include <tasks/doorway.h>
#include <tasks/episode.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#include "task_sim.h"

typedef struct world_count {
  int arena, walls, starts, goals, names;
  double wall_t, goal_x, goal_r;
  double wall_y[4];
} world_count_t;

static int w_corridor(void* u, double a, double b, int e) {
  (void)u, (void)a, (void)b, (void)e;
  return 1;  // the doorway has no corridor
}
static int w_arena(void* u, double a, double b, double c, double d) {
  (void)a, (void)b, (void)c, (void)d;
  ++((world_count_t*)u)->arena;
  return 0;
}
static int w_wall(void* u, double x0, double y0, double x1, double y1, double t) {
  world_count_t* w = (world_count_t*)u;
  assert_true(x0 == x1);  // across the room at the wall's centre plane
  if (w->walls < 2) {
    w->wall_y[2 * w->walls] = y0;
    w->wall_y[2 * w->walls + 1] = y1;
  }
  ++w->walls;
  w->wall_t = t;
  return 0;
}
static int w_cylinder(void* u, double a, double b, double r) {
  (void)u, (void)a, (void)b, (void)r;
  return 1;  // nor cylinders
}
static int w_goal(void* u, double x, double y, double r) {
  world_count_t* w = (world_count_t*)u;
  (void)y;
  ++w->goals;
  w->goal_x = x;
  w->goal_r = r;
  return 0;
}
static int w_start(void* u, features_pose_t p) {
  (void)p;
  ++((world_count_t*)u)->starts;
  return 0;
}
static int w_name(void* u, const char* n) {
  assert_string_equal(n, "doorway");
  ++((world_count_t*)u)->names;
  return 0;
}

// The world: the room, the dividing wall on either side of a 1 m door, the goal beyond it, the
// ten evaluation poses; the evaluation poses are clear of every wall on the robot's side.
static void test_doorway_world_and_poses(void** state) {
  (void)state;
  tasks_doorway_spec_t s;
  tasks_doorway_spec_default(&s);
  world_count_t c;
  memset(&c, 0, sizeof c);
  const tasks_world_sink_t sink = {&c, w_corridor, w_arena, w_wall, w_cylinder, w_goal, w_start, w_name};
  assert_int_equal(tasks_doorway_decl.world(&s, &sink), 0);
  assert_int_equal(c.arena, 1);
  assert_int_equal(c.walls, 2);
  assert_int_equal(c.goals, 1);
  assert_int_equal(c.starts, TASKS_N_EVAL_STARTS);
  assert_int_equal(c.names, 1);
  assert_true(c.wall_t == s.wall_thickness_m);
  // The gap between the two walls is the door.
  assert_true(fabs((c.wall_y[2] - c.wall_y[1]) - s.door_width_m) < 1e-12);
  assert_true(c.goal_x > s.wall_x_m && c.goal_r == s.goal_radius_m);
  for (uint32_t i = 0; i < TASKS_N_EVAL_STARTS; ++i) {
    const features_pose_t p = tasks_doorway_eval_start(&s, i);
    assert_true(p.x_m < s.wall_x_m - 1.5);
    assert_false(tasks_doorway_disc_collides(&s, p.x_m, p.y_m, s.robot_radius_m + 0.1));
  }
  // Collision geometry: in the door's middle the body fits; against a jamb or a wall it does not.
  assert_false(tasks_doorway_disc_collides(&s, s.wall_x_m, s.door_y_m, s.robot_radius_m));
  assert_true(tasks_doorway_disc_collides(&s, s.wall_x_m, s.door_y_m + 0.3, s.robot_radius_m));
  assert_true(tasks_doorway_disc_collides(&s, s.wall_x_m - 0.3, s.door_y_m + 1.0, s.robot_radius_m));
  assert_false(tasks_doorway_disc_collides(&s, s.wall_x_m - 0.35, s.door_y_m + 1.0, s.robot_radius_m));
  assert_true(tasks_doorway_disc_collides(&s, s.room_min_x_m + 0.2, 0.0, s.robot_radius_m));
  // A door that does not fit in the room is refused.
  s.door_y_m = s.room_max_y_m;
  memset(&c, 0, sizeof c);
  assert_int_not_equal(tasks_doorway_decl.world(&s, &sink), 0);
}

// Reward and termination: the goal's +1 ends the run, a collision's -1 ends it and takes
// precedence, the step limit stops it without a terminal state; an invalid state is no goal.
static void test_doorway_outcome(void** state) {
  (void)state;
  tasks_doorway_spec_t s;
  tasks_doorway_spec_default(&s);
  features_doorway_config_t cfg;
  tasks_doorway_features_config(&s, &cfg);
  features_doorway_t at_goal, before;
  const features_pose_t near_goal = {s.goal_x_m - 0.2, s.goal_y_m, 0.0};
  assert_int_equal(features_doorway_from_pose(&cfg, near_goal, &at_goal), FEATURES_OK);
  assert_int_equal(features_doorway_from_pose(&cfg, (features_pose_t){-2.0, 0.5, 0.0}, &before), FEATURES_OK);
  tasks_outcome_t o = tasks_doorway_outcome(&s, &at_goal, 0U, 10U);
  assert_true(o.reward == s.goal_reward && o.terminal == 1 && o.end_run == 1 && o.reason == TASKS_END_GOAL);
  o = tasks_doorway_outcome(&s, &at_goal, 1U, 10U);
  assert_true(o.reward == s.collision_reward && o.terminal == 1 && o.reason == TASKS_END_COLLISION);
  o = tasks_doorway_outcome(&s, &before, 1U, 10U);
  assert_true(o.reward == -1.0 && o.terminal == 1 && o.end_run == 1 && o.reason == TASKS_END_COLLISION);
  o = tasks_doorway_outcome(&s, &before, 0U, 10U);
  assert_true(o.reward == 0.0 && o.terminal == 0 && o.end_run == 0 && o.reason == TASKS_END_NONE);
  o = tasks_doorway_outcome(&s, &before, 0U, s.step_limit);
  assert_true(o.reward == 0.0 && o.terminal == 0 && o.end_run == 1 && o.reason == TASKS_END_STEP_LIMIT);
  at_goal.valid = 0U;
  o = tasks_doorway_outcome(&s, &at_goal, 0U, 10U);
  assert_int_equal(o.reason, TASKS_END_NONE);
  // The goal's distance and bearing from the door frame.
  assert_true(fabs(tasks_doorway_goal_distance(&s, &before) - hypot(3.5, 0.5)) < 1e-12);
  assert_true(fabs(tasks_doorway_goal_bearing(&s, &before) - atan2(-0.5, 3.5)) < 1e-12);
}

// Training starts: near their evaluation pose but never it, clear of the walls, on the robot's
// side of the wall; a function of the generator's state.
static void test_doorway_training_starts(void** state) {
  (void)state;
  tasks_doorway_spec_t s;
  tasks_doorway_spec_default(&s);
  rng_t a, b;
  rng_seed(&a, 42U);
  rng_seed(&b, 42U);
  for (int k = 0; k < 500; ++k) {
    const uint32_t i = (uint32_t)k % TASKS_N_EVAL_STARTS;
    const features_pose_t p = tasks_doorway_training_start_near(&s, i, &a);
    const features_pose_t q = tasks_doorway_training_start_near(&s, i, &b);
    assert_memory_equal(&p, &q, sizeof p);
    const features_pose_t e = tasks_doorway_eval_start(&s, i);
    assert_true(fabs(p.x_m - e.x_m) <= s.train_jitter_x_m && fabs(p.y_m - e.y_m) <= s.train_jitter_y_m &&
                fabs(features_angle_wrap(p.theta_rad - e.theta_rad)) <= s.train_jitter_theta_rad + 1e-12);
    assert_false(p.x_m == e.x_m && p.y_m == e.y_m && p.theta_rad == e.theta_rad);
    assert_false(tasks_doorway_disc_collides(&s, p.x_m, p.y_m, s.robot_radius_m + 0.1));
    assert_true(p.x_m < s.wall_x_m);
  }
}

typedef struct batch {
  int n, goals, collisions;
  double steps_sum, min_clearance;
} batch_t;

static void run_batch(tasks_driver_kind_t kind, int seeds, batch_t* b) {
  tasks_doorway_spec_t s;
  tasks_doorway_spec_default(&s);
  task_sim_opts_t opts;
  task_sim_opts_default(&opts);
  memset(b, 0, sizeof *b);
  b->min_clearance = INFINITY;
  for (int k = 0; k < seeds; ++k) {
    opts.sensor_seed = 1U + (uint64_t)k;
    for (uint32_t i = 0; i < TASKS_N_EVAL_STARTS; ++i) {
      tasks_driver_t d;
      tasks_driver_begin_run(&d, kind, &tasks_doorway_decl, s.omega_max_radps, 1000U * (uint64_t)k + i);
      const task_sim_result_t r = task_sim_doorway(&s, tasks_doorway_eval_start(&s, i), &d, &opts);
      ++b->n;
      if (r.reason == TASKS_END_GOAL) {
        ++b->goals;
        b->steps_sum += (double)r.steps;
        b->min_clearance = fmin(b->min_clearance, r.min_clearance_m);
        assert_true(r.return_sum == s.goal_reward);
      } else if (r.reason == TASKS_END_COLLISION) {
        ++b->collisions;
        assert_true(r.return_sum == s.collision_reward);
      }
    }
  }
  printf("[ doorway ] kind %d: runs %d, goals %d, collisions %d, mean steps to the goal %.1f, closest %.3f m\n",
         kind, b->n, b->goals, b->collisions, b->goals > 0 ? b->steps_sum / b->goals : 0.0, b->min_clearance);
}

// The sloppy example (gain drawn per run) reaches the goal from most starts and clips a jamb now
// and then; the reference reaches it from every start, keeping the search's 0.10 m margin, and
// is clearly faster (at least 5 % fewer steps) than the example's successful runs.
static void test_doorway_drivers_reach_the_goal(void** state) {
  (void)state;
  batch_t p, o, h;
  run_batch(TASKS_DRIVER_PROPORTIONAL, 5, &p);
  run_batch(TASKS_DRIVER_OPTIMAL, 3, &o);
  run_batch(TASKS_DRIVER_HUMAN, 5, &h);
  assert_true(p.goals >= (9 * p.n) / 10);
  assert_int_equal(p.goals + p.collisions, p.n);
  assert_int_equal(o.goals, o.n);
  assert_true(o.min_clearance >= 0.10);
  assert_true(o.steps_sum / o.goals <= 0.95 * (p.steps_sum / p.goals));
  // A person reaches it from most starts, slower and less safely than the example.
  assert_true(h.goals >= (7 * h.n) / 10);
  assert_true(h.steps_sum / h.goals > p.steps_sum / p.goals);
}

// The reference's constants are the grid search's winner: the gains next to it on the grid are
// no faster with the same margin (tasks_optimal_search.c doorway).
static void test_doorway_reference_is_a_local_optimum(void** state) {
  (void)state;
  tasks_doorway_spec_t s;
  tasks_doorway_spec_default(&s);
  task_sim_opts_t opts;
  task_sim_opts_default(&opts);
  tasks_driver_t d;
  tasks_driver_begin_run(&d, TASKS_DRIVER_OPTIMAL, &tasks_doorway_decl, 1.0, 1U);
  const double law[2] = {d.law[0], d.law[1]};
  double best = INFINITY;
  double at_law = INFINITY;
  for (int dg = -1; dg <= 1; ++dg) {
    for (int dl = -1; dl <= 1; ++dl) {
      double sum = 0.0;
      int ok = 1;
      for (uint64_t seed = 1U; seed <= 3U && ok; ++seed) {
        opts.sensor_seed = seed;
        for (uint32_t i = 0; i < TASKS_N_EVAL_STARTS; ++i) {
          tasks_driver_begin_run(&d, TASKS_DRIVER_OPTIMAL, &tasks_doorway_decl, 1.0, seed);
          d.law[0] = law[0] + 0.25 * dg;
          d.law[1] = law[1] + 0.25 * dl;
          const task_sim_result_t r = task_sim_doorway(&s, tasks_doorway_eval_start(&s, i), &d, &opts);
          if (r.reason != TASKS_END_GOAL || r.min_clearance_m < 0.10) {
            ok = 0;
            break;
          }
          sum += (double)r.steps;
        }
      }
      const double mean = ok ? sum / 30.0 : HUGE_VAL;
      best = fmin(best, mean);
      if (dg == 0 && dl == 0) at_law = mean;
    }
  }
  assert_true(isfinite(at_law));
  assert_true(at_law <= best);
}

// A whole run through the declaration (episode API, the exact state of the kinematic model)
// allocates nothing, and the state stays within the declared bounds.
static void test_doorway_episode_bounds_and_no_allocation(void** state) {
  (void)state;
  tasks_episode_t ep;
  tasks_episode_init(&ep, &tasks_doorway_decl, NULL);
  const tasks_doorway_spec_t* s = (const tasks_doorway_spec_t*)tasks_episode_spec_const(&ep);
  double lo[TASKS_MAX_STATE_DIM], hi[TASKS_MAX_STATE_DIM];
  tasks_episode_state_bounds(&ep, lo, hi);
  tasks_driver_t d;
  alloc_counter_begin();
  for (uint32_t i = 0; i < TASKS_N_EVAL_STARTS; ++i) {
    features_pose_t p = tasks_episode_eval_start(&ep, i);
    tasks_episode_begin(&ep, p, p);
    tasks_episode_driver_begin(&ep, &d, TASKS_DRIVER_OPTIMAL, 1.0, i);
    double st[TASKS_MAX_STATE_DIM];
    assert_int_equal(tasks_episode_observe_pose(&ep, p, st), 1);
    for (uint32_t step = 1U; step <= s->step_limit; ++step) {
      const double w = tasks_episode_driver_action(&ep, &d);
      p.theta_rad = features_angle_wrap(p.theta_rad + w * s->dt_s);
      p.x_m += s->v_mps * s->dt_s * cos(p.theta_rad);
      p.y_m += s->v_mps * s->dt_s * sin(p.theta_rad);
      assert_int_equal(tasks_episode_observe_pose(&ep, p, st), 1);
      for (uint32_t k = 0; k < tasks_doorway_decl.state_dim; ++k) assert_true(st[k] >= lo[k] && st[k] <= hi[k]);
      const uint8_t contact = (uint8_t)tasks_doorway_disc_collides(s, p.x_m, p.y_m, s->robot_radius_m);
      const tasks_outcome_t o = tasks_episode_outcome(&ep, contact, step);
      if (o.end_run) {
        assert_int_equal(o.reason, TASKS_END_GOAL);
        break;
      }
    }
  }
  assert_int_equal(alloc_counter_end(), 0);
  assert_non_null(tasks_doorway_state(&ep));
  assert_null(tasks_corridor_state(&ep));
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_doorway_world_and_poses),
      cmocka_unit_test(test_doorway_outcome),
      cmocka_unit_test(test_doorway_training_starts),
      cmocka_unit_test(test_doorway_drivers_reach_the_goal),
      cmocka_unit_test(test_doorway_reference_is_a_local_optimum),
      cmocka_unit_test(test_doorway_episode_bounds_and_no_allocation),
  };
  return cmocka_run_group_tests_name("tasks.doorway", tests, NULL, NULL);
}
