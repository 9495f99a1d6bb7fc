// SPDX-License-Identifier: MIT
// A task as a robot runs it (tasks/episode.h): the command clamp, the run frame, the state from a
// scan and odometry, the exact state of a pose, outcome, speed and drivers through one interface.
#include <b21r_test/alloc_counter.h>
#include <b21r_test/synthetic_world.h>
#include <features/features.h>
#include <tasks/episode.h>
#include <tasks/tasks.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#define PI 3.14159265358979323846

static features_pose_t pose(double x, double y, double th) {
  features_pose_t p = {x, y, th};
  return p;
}

// The defaults are the controller's documented defaults.
static void test_episode_command_limits_defaults(void** state) {
  (void)state;
  tasks_command_limits_t l;
  tasks_command_limits_default(&l);
  assert_true(l.max_translation_mps == 0.8 && l.max_rotation_radps == 1.0);
  assert_true(l.max_translation_accel_mps2 == 0.7 && l.max_rotation_accel_radps2 == 2.86);
}

// Velocity limits first, then within acceleration x dt of the previous command; non-finite
// anything gives the zero command.
static void test_episode_command_clamp_limits_and_non_finite(void** state) {
  (void)state;
  tasks_command_limits_t l;
  tasks_command_limits_default(&l);
  double v = 5.0, w = -3.0;
  assert_int_equal(tasks_command_clamp(&l, 0.1, 0.8, -1.0, &v, &w), 1);
  assert_true(v == 0.8 && w == -1.0);  // velocity limits only (the previous command is there)
  v = 0.6;
  w = 1.0;
  assert_int_equal(tasks_command_clamp(&l, 0.1, 0.0, 0.0, &v, &w), 1);
  assert_true(v == 0.7 * 0.1 && w == 2.86 * 0.1);  // acceleration limits from standstill
  v = 0.3;
  w = 0.05;
  assert_int_equal(tasks_command_clamp(&l, 0.1, 0.3, 0.0, &v, &w), 1);
  assert_true(v == 0.3 && w == 0.05);  // within the limits: unchanged, bit for bit
  v = (double)NAN;
  w = 0.1;
  assert_int_equal(tasks_command_clamp(&l, 0.1, 0.3, 0.0, &v, &w), 0);
  assert_true(v == 0.0 && w == 0.0);
  v = 0.1;
  w = 0.1;
  assert_int_equal(tasks_command_clamp(&l, 0.1, (double)INFINITY, 0.0, &v, &w), 0);
  assert_true(v == 0.0 && w == 0.0);
}

// The state from a scan at an odometry pose equals the features of that scan at the pose mapped
// into the run's frame (the controller's computation); the exact state of a pose equals
// features_corridor_from_pose; outcome and speed are the task's.
static void test_episode_corridor_observe_outcome_speed(void** state) {
  (void)state;
  tasks_episode_t ep;
  tasks_episode_init(&ep, &tasks_corridor_decl, NULL);
  assert_int_equal(ep.state_dim, 3);
  assert_true(tasks_episode_step_limit(&ep) == 1000U && tasks_episode_gamma(&ep) == 0.99);
  assert_true(tasks_episode_robot_radius(&ep) == TASKS_B21R_RADIUS_M);
  const features_pose_t start = pose(1.2, 0.3, 0.2);
  const features_pose_t odom0 = pose(5.0, -2.0, 1.0);
  tasks_episode_begin(&ep, start, odom0);
  // Odometry moved 1 m along its heading: the robot is 1 m further along its start heading.
  const features_pose_t odom1 = pose(5.0 + cos(1.0), -2.0 + sin(1.0), 1.0);
  const features_pose_t truth = tasks_episode_pose_in_task(&ep, odom1);
  assert_true(fabs(truth.x_m - (1.2 + cos(0.2))) < 1e-12 && fabs(truth.y_m - (0.3 + sin(0.2))) < 1e-12);

  synth_world_t w;
  synth_world_init(&w);
  assert_int_equal(synth_world_add_corridor(&w, 10.0, 2.0), 0);
  synth_lidar_config_t lidar;
  assert_int_equal(synth_lidar_config_lms200(&lidar, 180, 1.0), 0);
  synth_rng_t rng;
  synth_rng_seed(&rng, 3);
  static features_scan_t scan;
  scan.angle_min_rad = lidar.angle_min_rad;
  scan.angle_increment_rad = lidar.angle_increment_rad;
  scan.n_beams = lidar.n_beams;
  assert_true(synth_lidar_scan(&w, &lidar, &rng, truth.x_m, truth.y_m, truth.theta_rad, scan.ranges_m, scan.no_return,
                               FEATURES_MAX_BEAMS) > 0);
  double s[TASKS_MAX_STATE_DIM];
  assert_int_equal(tasks_episode_observe(&ep, &scan, odom1, s), 1);
  features_corridor_t direct;
  assert_int_equal(features_corridor_compute(tasks_corridor_features(&ep), &scan, &truth, &direct), FEATURES_OK);
  const features_corridor_t* cs = tasks_corridor_state(&ep);
  assert_true(cs->offset_m == direct.offset_m && cs->heading_rad == direct.heading_rad &&
              cs->walls_seen == direct.walls_seen && cs->end_source == direct.end_source);
  assert_true(s[0] == direct.end_distance_m && s[1] == direct.lateral_frac && s[2] == direct.target_angle_rad);
  assert_true(tasks_episode_speed_mps(&ep) == tasks_corridor_speed_mps((const tasks_corridor_spec_t*)tasks_episode_spec(&ep), &direct));

  double e[TASKS_MAX_STATE_DIM];
  assert_int_equal(tasks_episode_observe_pose(&ep, truth, e), 1);
  features_corridor_t exact;
  assert_int_equal(features_corridor_from_pose(tasks_corridor_features(&ep), truth, &exact), FEATURES_OK);
  assert_true(e[0] == exact.end_distance_m && e[1] == exact.lateral_frac && e[2] == exact.target_angle_rad);
  // The measured state is within the features' stated accuracy of the exact one.
  assert_true(fabs(s[1] - e[1]) < 0.01 && fabs(s[2] - e[2]) < 0.025);

  tasks_outcome_t o = tasks_episode_outcome(&ep, 0U, 10U);
  assert_true(o.reward == 0.0 && o.end_run == 0U);
  assert_int_equal(tasks_episode_observe_pose(&ep, pose(9.2, 0.0, 0.0), e), 1);
  o = tasks_episode_outcome(&ep, 0U, 11U);
  assert_true(o.reward == 10.0 && o.terminal == 1U && o.reason == TASKS_END_GOAL);
  tasks_spec_set_step_limit(ep.decl, tasks_episode_spec(&ep), 5U);  // a spec's step limit may change between runs
  assert_int_equal(tasks_episode_observe_pose(&ep, pose(3.0, 0.0, 0.0), e), 1);
  o = tasks_episode_outcome(&ep, 0U, 5U);
  assert_true(o.end_run == 1U && o.terminal == 0U && o.reason == TASKS_END_STEP_LIMIT);
  o = tasks_episode_outcome(&ep, 1U, 2U);
  assert_true(o.terminal == 1U && o.reason == TASKS_END_COLLISION && o.reward == 0.0);
  // An unusable state leaves the vector as it was.
  double keep[3] = {7.0, 7.0, 7.0};
  assert_int_equal(tasks_episode_observe_pose(&ep, pose((double)NAN, 0.0, 0.0), keep), 0);
  assert_true(keep[0] == 7.0 && keep[2] == 7.0);
}

// Obstacles: the exact state of a pose is features_obstacles_from_pose with the spec's obstacles;
// starts and drivers are the task's; no declaration is the corridor.
static void test_episode_obstacles_pose_starts_drivers(void** state) {
  (void)state;
  tasks_obstacles_spec_t spec;
  tasks_obstacles_spec_default(&spec);
  spec.n_obstacles = 2U;
  spec.obstacles[1].x_m = -1.0;
  spec.obstacles[1].y_m = 1.0;
  spec.obstacles[1].radius_m = 0.2;
  tasks_episode_t ep;
  tasks_episode_init(&ep, &tasks_obstacles_decl, &spec);
  assert_int_equal(ep.state_dim, 5);
  assert_true(tasks_episode_gamma(&ep) == 0.9 && tasks_episode_step_limit(&ep) == 500U);
  const features_pose_t p = tasks_episode_eval_start(&ep, 3);
  assert_memory_equal(&p, &spec.eval_starts[3], sizeof p);
  double s[TASKS_MAX_STATE_DIM];
  assert_int_equal(tasks_episode_observe_pose(&ep, p, s), 1);
  const features_disc_t discs[2] = {{-1.5, 0.0, 0.25}, {-1.0, 1.0, 0.2}};
  features_obstacles_t f;
  assert_int_equal(features_obstacles_from_pose(tasks_obstacles_features(&ep), p, 0.0, 0.0, discs, 2U, PI, &f), FEATURES_OK);
  assert_true(f.obstacle[0].visible);
  assert_true(s[0] == f.goal_bearing_rad && s[1] == f.goal_distance_m && s[2] == f.obstacle[0].bearing_rad &&
              s[3] == f.obstacle[0].distance_m && s[4] == 0.0);
  assert_true(tasks_episode_speed_mps(&ep) == spec.v_mps);
  rng_t a, b;
  rng_seed(&a, 9);
  rng_seed(&b, 9);
  // The episode's training starts go round the evaluation poses in shuffled cycles.
  tasks_start_cycle_t cycle;
  memset(&cycle, 0, sizeof cycle);
  for (int k = 0; k < 2 * TASKS_N_EVAL_STARTS; ++k) {
    const features_pose_t t1 = tasks_episode_training_start(&ep, &a);
    const uint32_t base = tasks_start_cycle_next(&cycle, &b);
    const features_pose_t t2 = tasks_obstacles_training_start_near(&spec, base, &b);
    assert_memory_equal(&t1, &t2, sizeof t1);
  }
  tasks_driver_t d1, d2;
  tasks_episode_driver_begin(&ep, &d1, TASKS_DRIVER_PROPORTIONAL, 1.0, 5U);
  tasks_driver_begin_run(&d2, TASKS_DRIVER_PROPORTIONAL, &tasks_obstacles_decl, 1.0, 5U);
  assert_true(tasks_episode_driver_action(&ep, &d1) == tasks_driver_obstacles(&d2, tasks_obstacles_state(&ep)));
  tasks_episode_init(&ep, NULL, NULL);
  assert_true(ep.decl == &tasks_corridor_decl);
  assert_null(tasks_obstacles_state(&ep));
  // Every call above is allocation-free.
  alloc_counter_begin();
  for (int i = 0; i < 100; ++i) {
    (void)tasks_episode_observe_pose(&ep, pose(2.0, 0.1 * (i % 5), 0.0), s);
    (void)tasks_episode_outcome(&ep, 0U, (uint32_t)i);
  }
  assert_int_equal(alloc_counter_end(), 0);
}

// The obstacle task's state remembers the obstacle it passes: measured (a scan at an odometry
// pose) and exact (a pose) alike, the obstacle's entries stay the remembered one's after it left
// the view, the fifth value counts the time since it was seen (one control period a step), the
// memory ends after memory_s and every run starts without it (tasks_episode_begin). memory_s = 0
// gives the state without memory. Every value stays inside the declared bounds.
static void test_episode_obstacles_state_remembers_obstacle(void** state) {
  (void)state;
  tasks_obstacles_spec_t spec;
  tasks_obstacles_spec_default(&spec);
  assert_true(spec.memory_s == 3.0 && spec.dt_s == 0.1);
  synth_world_t w;
  synth_world_init(&w);
  assert_int_equal(synth_world_add_box(&w, spec.arena_min_x_m, spec.arena_min_y_m, spec.arena_max_x_m,
                                       spec.arena_max_y_m), 0);
  assert_int_equal(synth_world_add_circle(&w, spec.obstacles[0].x_m, spec.obstacles[0].y_m,
                                          spec.obstacles[0].radius_m), 0);
  synth_lidar_config_t lidar;
  assert_int_equal(synth_lidar_config_lms200(&lidar, 180, 1.0), 0);
  lidar.noise_sigma_m = 0.0;
  static features_scan_t scan;
  for (int memory = 1; memory >= 0; --memory) {
    for (int measured = 0; measured < 2; ++measured) {
      tasks_obstacles_spec_t sp = spec;
      if (!memory) sp.memory_s = 0.0;
      tasks_episode_t ep;
      tasks_episode_init(&ep, &tasks_obstacles_decl, &sp);
      assert_int_equal(tasks_obstacles_features(&ep)->memory_max_age, memory ? 30U : 0U);
      double lo[TASKS_MAX_STATE_DIM], hi[TASKS_MAX_STATE_DIM];
      tasks_episode_state_bounds(&ep, lo, hi);
      const double none_age = memory ? 3.0 : 0.0;
      // The robot passes the obstacle (centre (-1.5, 0), radius 0.25) on its left, 0.3 m clear
      // of the skirt; odometry reads another frame than the task's. The second run stops while
      // the obstacle is remembered, and a third starts beside it, where it cannot be seen.
      const features_pose_t odom0 = pose(1.0, 2.0, -0.5);
      for (int run = 0; run < 3; ++run) {
        const features_pose_t start = run < 2 ? pose(-3.5, -0.81, 0.0) : pose(-1.2, -0.81, 0.0);
        tasks_episode_begin(&ep, start, odom0);
        int seen = 0, remembered = 0, none = 0;
        double s[TASKS_MAX_STATE_DIM];
        for (int k = 0; k < 120; ++k) {
          const features_pose_t truth = pose(start.x_m + 0.03 * k, start.y_m, 0.0);
          const features_pose_t odom = features_pose_compose(odom0, features_pose_between(start, truth));
          if (measured) {
            scan.angle_min_rad = lidar.angle_min_rad;
            scan.angle_increment_rad = lidar.angle_increment_rad;
            scan.n_beams = lidar.n_beams;
            assert_true(synth_lidar_scan(&w, &lidar, NULL, truth.x_m, truth.y_m, truth.theta_rad, scan.ranges_m,
                                         scan.no_return, FEATURES_MAX_BEAMS) > 0);
            assert_int_equal(tasks_episode_observe(&ep, &scan, odom, s), 1);
          } else {
            assert_int_equal(tasks_episode_observe_pose(&ep, truth, s), 1);
          }
          for (uint32_t i = 0; i < 5U; ++i) assert_true(s[i] >= lo[i] && s[i] <= hi[i]);
          const features_obstacles_t* f = tasks_obstacles_state(&ep);
          if (run == 2) {
            // The previous run's memory is gone: nothing known.
            assert_int_equal(f->obstacle[0].visible, 0);
            assert_true(s[2] == PI && s[3] == 8.0 && fabs(s[4] - none_age) < 1e-9);
            break;
          }
          if (f->obstacle[0].visible) {
            ++seen;
            assert_true(s[2] == f->obstacle[0].bearing_rad && s[3] == f->obstacle[0].distance_m && s[4] == 0.0);
          } else if (s[3] < 8.0) {
            ++remembered;
            assert_true(memory);
            assert_true(fabs(s[4] - 0.1 * remembered) < 1e-9);
            assert_true(s[2] > 0.9);  // on the left, then behind
            // The remembered obstacle is as far as the true one (exactly from the exact state).
            const double surface = hypot(truth.x_m + 1.5, truth.y_m) - 0.25;
            assert_true(fabs(s[3] - surface) < (measured ? 0.05 : 1e-9));
            if (run == 1 && remembered == 5) break;
          } else {
            ++none;
            assert_true(seen > 0);
            assert_true(s[2] == PI && fabs(s[4] - none_age) < 1e-9);
            if (run == 1) break;
          }
        }
        if (run == 0) {
          print_message("memory %d measured %d: seen %d, remembered %d, none %d\n", memory, measured, seen, remembered,
                        none);
          assert_true(seen > 20);
          assert_int_equal(remembered, memory ? 30 : 0);
          assert_true(none > 10);
        }
      }
    }
  }
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_episode_command_limits_defaults),
      cmocka_unit_test(test_episode_command_clamp_limits_and_non_finite),
      cmocka_unit_test(test_episode_corridor_observe_outcome_speed),
      cmocka_unit_test(test_episode_obstacles_pose_starts_drivers),
      cmocka_unit_test(test_episode_obstacles_state_remembers_obstacle),
  };
  return cmocka_run_group_tests_name("tasks.episode", tests, NULL, NULL);
}
