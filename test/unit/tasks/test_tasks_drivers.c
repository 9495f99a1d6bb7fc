// SPDX-License-Identifier: MIT
// Example drivers and optimal references driving whole episodes in the synthetic world
// (kinematic synchro drive at 10 Hz, features from synthetic LMS200 scans): every evaluation
// start reaches the goal within the step limit; the simulated human is far more varied than the
// proportional controller; runs are a function of their seeds; no allocation.
#include <b21r_test/alloc_counter.h>
#include <tasks/decl.h>
#include <tasks/tasks.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#include "task_sim.h"

#define MAX_RUNS 64

// Steps and path lengths of a batch of runs.
typedef struct batch {
  int n, goals;
  double steps[MAX_RUNS];
  double path[MAX_RUNS];
} batch_t;

static double mean(const double* v, int n) {
  double s = 0.0;
  for (int i = 0; i < n; ++i) s += v[i];
  return n > 0 ? s / n : 0.0;
}

static double stddev(const double* v, int n) {
  const double m = mean(v, n);
  double s = 0.0;
  for (int i = 0; i < n; ++i) s += (v[i] - m) * (v[i] - m);
  return n > 1 ? sqrt(s / (n - 1)) : 0.0;
}

static double minimum(const double* v, int n) {
  double m = INFINITY;
  for (int i = 0; i < n; ++i) m = fmin(m, v[i]);
  return m;
}

static double maximum(const double* v, int n) {
  double m = -INFINITY;
  for (int i = 0; i < n; ++i) m = fmax(m, v[i]);
  return m;
}

// Runs `seeds` runs from each evaluation start (run seed = 1000 * s + start) and checks that each
// reaches the goal within the step limit.
static void run_batch(const tasks_decl_t* task, tasks_driver_kind_t kind, int seeds,
                      const task_sim_opts_t* opts, batch_t* b) {
  memset(b, 0, sizeof *b);
  tasks_corridor_spec_t cs;
  tasks_corridor_spec_default(&cs);
  tasks_obstacles_spec_t os;
  tasks_obstacles_spec_default(&os);
  for (int s = 0; s < seeds; ++s) {
    for (uint32_t i = 0U; i < TASKS_N_EVAL_STARTS; ++i) {
      tasks_driver_t d;
      tasks_driver_begin_run(&d, kind, task, 1.0, 1000U * (uint64_t)s + i);
      const task_sim_result_t r =
          task == &tasks_corridor_decl
              ? task_sim_corridor(&cs, tasks_corridor_eval_start(&cs, i), &d, opts)
              : task_sim_obstacles(&os, tasks_obstacles_eval_start(&os, i), &d, opts);
      if (r.reason != TASKS_END_GOAL) {
        printf("  run seed %d start %u: reason %u after %u steps at (%.2f, %.2f)\n", s, i,
               r.reason, r.steps, r.final_x_m, r.final_y_m);
      }
      assert_int_equal(r.reason, TASKS_END_GOAL);
      if (task == &tasks_corridor_decl) {
        // No driver beats the kinematic bound from its pose (tasks_corridor_steps_lower_bound).
        assert_true(r.steps >= tasks_corridor_steps_lower_bound(&cs, tasks_corridor_eval_start(&cs, i)));
      }
      assert_true(r.steps <= (task == &tasks_corridor_decl ? cs.step_limit : os.step_limit));
      assert_true(r.return_sum == (task == &tasks_corridor_decl ? cs.goal_reward : os.goal_reward));
      assert_true(b->n < MAX_RUNS);
      b->steps[b->n] = (double)r.steps;
      b->path[b->n] = r.path_m;
      ++b->n;
      ++b->goals;
    }
  }
}

static void print_batch(const char* task, const char* who, const batch_t* b) {
  printf("[ drivers ] %-9s %-12s runs %2d goals %2d | steps to goal min %4.0f mean %6.1f max %4.0f "
         "sd %5.1f | path sd %.3f m\n",
         task, who, b->n, b->goals, minimum(b->steps, b->n), mean(b->steps, b->n),
         maximum(b->steps, b->n), stddev(b->steps, b->n), stddev(b->path, b->n));
}

// The three drivers on one task: all reach the goal from every evaluation start; the human's
// runs spread far more than the proportional controller's; the optimal reference is at least
// as good on average as the example policy.
static void drivers_on_task(const tasks_decl_t* task, const char* name) {
  task_sim_opts_t opts;
  task_sim_opts_default(&opts);
  batch_t p, h, o;
  run_batch(task, TASKS_DRIVER_PROPORTIONAL, 2, &opts, &p);
  run_batch(task, TASKS_DRIVER_HUMAN, 3, &opts, &h);
  run_batch(task, TASKS_DRIVER_OPTIMAL, 1, &opts, &o);
  print_batch(name, "proportional", &p);
  print_batch(name, "human", &h);
  print_batch(name, "optimal", &o);
  assert_true(stddev(h.steps, h.n) > 2.0 * stddev(p.steps, p.n));
  assert_true(stddev(h.path, h.n) > 1.5 * stddev(p.path, p.n));
  assert_true(mean(h.steps, h.n) > mean(p.steps, p.n));
  assert_true(mean(o.steps, o.n) <= mean(p.steps, p.n));
}

// Corridor: proportional (gain varied per run), human and optimal drivers.
static void test_drivers_corridor_all_reach_goal(void** state) {
  (void)state;
  drivers_on_task(&tasks_corridor_decl, "corridor");
}

// Obstacles: proportional with avoidance bend, human and optimal drivers.
static void test_drivers_obstacles_all_reach_goal(void** state) {
  (void)state;
  drivers_on_task(&tasks_obstacles_decl, "obstacles");
}

// The corridor drivers also cope with 0.5° scans, dropouts, a person by the wall and odometry
// whose heading drifts by 0.01 rad per metre.
static void test_drivers_corridor_robust_to_clutter_and_drift(void** state) {
  (void)state;
  task_sim_opts_t opts;
  task_sim_opts_default(&opts);
  assert_int_equal(synth_lidar_config_lms200(&opts.lidar, 180, 0.5), 0);
  opts.lidar.dropout_prob = 0.05;
  opts.lidar.error_code_prob = 0.01;
  opts.person = 1;
  opts.odom_heading_drift = 0.01;
  opts.sensor_seed = 9U;
  opts.limits.acc_mps2 = 0.7;    // B21r accelerations (protocols.md C)
  opts.limits.acc_radps2 = 2.86;
  batch_t p, o;
  run_batch(&tasks_corridor_decl, TASKS_DRIVER_PROPORTIONAL, 1, &opts, &p);
  run_batch(&tasks_corridor_decl, TASKS_DRIVER_OPTIMAL, 1, &opts, &o);
  print_batch("corridor*", "proportional", &p);
  print_batch("corridor*", "optimal", &o);
}

// The obstacle drivers also cope with 0.5° scans, dropouts, error codes and drifting odometry.
static void test_drivers_obstacles_robust_to_dropouts_and_drift(void** state) {
  (void)state;
  task_sim_opts_t opts;
  task_sim_opts_default(&opts);
  assert_int_equal(synth_lidar_config_lms200(&opts.lidar, 180, 0.5), 0);
  opts.lidar.dropout_prob = 0.05;
  opts.lidar.error_code_prob = 0.01;
  opts.odom_heading_drift = 0.01;
  opts.sensor_seed = 10U;
  opts.limits.acc_mps2 = 0.7;
  opts.limits.acc_radps2 = 2.86;
  batch_t p, o;
  run_batch(&tasks_obstacles_decl, TASKS_DRIVER_PROPORTIONAL, 1, &opts, &p);
  run_batch(&tasks_obstacles_decl, TASKS_DRIVER_OPTIMAL, 1, &opts, &o);
  print_batch("obstacles*", "proportional", &p);
  print_batch("obstacles*", "optimal", &o);
}

// A run is a function of its seeds: bit-identical results for the same seeds; the gain of the
// example policy differs between runs and stays in its documented range.
static void test_drivers_runs_deterministic_per_seed(void** state) {
  (void)state;
  tasks_corridor_spec_t cs;
  tasks_corridor_spec_default(&cs);
  task_sim_opts_t opts;
  task_sim_opts_default(&opts);
  for (int kind = 0; kind < 3; ++kind) {
    tasks_driver_t a, b;
    tasks_driver_begin_run(&a, (tasks_driver_kind_t)kind, &tasks_corridor_decl, 1.0, 77U);
    tasks_driver_begin_run(&b, (tasks_driver_kind_t)kind, &tasks_corridor_decl, 1.0, 77U);
    const task_sim_result_t ra = task_sim_corridor(&cs, tasks_corridor_eval_start(&cs, 4U), &a, &opts);
    const task_sim_result_t rb = task_sim_corridor(&cs, tasks_corridor_eval_start(&cs, 4U), &b, &opts);
    assert_int_equal(ra.steps, rb.steps);
    assert_memory_equal(&ra.path_m, &rb.path_m, sizeof(double));
    assert_memory_equal(&ra.sum_abs_omega, &rb.sum_abs_omega, sizeof(double));
    assert_memory_equal(&a, &b, sizeof a);
  }
  double lo = INFINITY, hi = -INFINITY;
  for (uint64_t seed = 0U; seed < 200U; ++seed) {
    tasks_driver_t d;
    tasks_driver_begin_run(&d, TASKS_DRIVER_PROPORTIONAL, &tasks_corridor_decl, 1.0, seed);
    lo = fmin(lo, d.gain);
    hi = fmax(hi, d.gain);
    assert_true(d.gain >= TASKS_PROPORTIONAL_CORRIDOR_GAIN_MIN &&
                d.gain < TASKS_PROPORTIONAL_CORRIDOR_GAIN_MAX);
  }
  assert_true(hi - lo > 0.8 * (TASKS_PROPORTIONAL_CORRIDOR_GAIN_MAX - TASKS_PROPORTIONAL_CORRIDOR_GAIN_MIN));
}

// Outputs are bounded and finite for any state, including invalid and absurd ones; the
// proportional controller is exactly omega = k * theta below saturation.
static void test_drivers_outputs_bounded_and_safe(void** state) {
  (void)state;
  features_corridor_t fc;
  memset(&fc, 0, sizeof fc);
  features_obstacles_t fo;
  memset(&fo, 0, sizeof fo);
  for (int kind = 0; kind < 3; ++kind) {
    for (int task = 0; task < 2; ++task) {
      tasks_driver_t d;
      tasks_driver_begin_run(&d, (tasks_driver_kind_t)kind, task == 0 ? &tasks_corridor_decl : &tasks_obstacles_decl, 0.5, 3U);
      for (int i = 0; i < 200; ++i) {
        fc.valid = (uint8_t)(i % 3 != 0);
        fc.target_angle_rad = 3.0 * sin(0.37 * i);
        fc.heading_rad = 2.0 * cos(0.11 * i);
        fc.offset_m = sin(0.05 * i);
        fc.lateral_frac = 0.5 - 0.5 * fc.offset_m;
        fo.valid = fc.valid;
        fo.goal_bearing_rad = fc.target_angle_rad;
        fo.goal_distance_m = 2.0;
        fo.obstacle[0].visible = (uint8_t)(i % 2);
        fo.obstacle[0].distance_m = 0.1 + 0.01 * i;
        fo.obstacle[0].bearing_rad = 0.5 * sin(0.2 * i);
        const double w = task == 0 ? tasks_driver_corridor(&d, &fc) : tasks_driver_obstacles(&d, &fo);
        assert_true(isfinite(w));
        assert_true(fabs(w) <= 0.5);
      }
    }
  }
  tasks_driver_t d;
  tasks_driver_begin_run(&d, TASKS_DRIVER_PROPORTIONAL, &tasks_corridor_decl, 1.0, 5U);
  fc.valid = 1U;
  fc.target_angle_rad = 0.1;
  assert_true(fabs(tasks_driver_corridor(&d, &fc) - d.gain * 0.1) < 1e-15);
  fc.valid = 0U;
  assert_true(tasks_driver_corridor(&d, &fc) == 0.0);
  assert_true(tasks_driver_corridor(&d, NULL) == 0.0);
  assert_true(tasks_driver_obstacles(NULL, &fo) == 0.0);
  // Out-of-range kind, task and bound fall back to the documented defaults.
  tasks_driver_begin_run(&d, (tasks_driver_kind_t)9, NULL, NAN, 5U);
  assert_int_equal(d.kind, TASKS_DRIVER_PROPORTIONAL);
  assert_int_equal(d.task, tasks_corridor_decl.id);
  assert_true(d.omega_max_radps == 1.0);
}

// A whole episode, scans and features included, allocates nothing.
static void test_drivers_episode_allocation_free(void** state) {
  (void)state;
  tasks_corridor_spec_t cs;
  tasks_corridor_spec_default(&cs);
  tasks_obstacles_spec_t os;
  tasks_obstacles_spec_default(&os);
  task_sim_opts_t opts;
  task_sim_opts_default(&opts);
  tasks_driver_t d;
  tasks_driver_begin_run(&d, TASKS_DRIVER_HUMAN, &tasks_corridor_decl, 1.0, 1U);
  alloc_counter_begin();
  const task_sim_result_t rc = task_sim_corridor(&cs, tasks_corridor_eval_start(&cs, 0U), &d, &opts);
  tasks_driver_begin_run(&d, TASKS_DRIVER_HUMAN, &tasks_obstacles_decl, 1.0, 1U);
  const task_sim_result_t ro = task_sim_obstacles(&os, tasks_obstacles_eval_start(&os, 0U), &d, &opts);
  assert_int_equal(alloc_counter_end(), 0);
  assert_int_equal(rc.reason, TASKS_END_GOAL);
  assert_int_equal(ro.reason, TASKS_END_GOAL);
}

// One executable, three CTest entries (tasks.drivers_corridor, tasks.drivers_obstacles,
// tasks.drivers_misc), so that each stays well inside the time budget under the sanitizers.
int main(int argc, char** argv) {
  const struct CMUnitTest corridor[] = {
      cmocka_unit_test(test_drivers_corridor_all_reach_goal),
  };
  const struct CMUnitTest obstacles[] = {
      cmocka_unit_test(test_drivers_obstacles_all_reach_goal),
      cmocka_unit_test(test_drivers_obstacles_robust_to_dropouts_and_drift),
  };
  const struct CMUnitTest misc[] = {
      cmocka_unit_test(test_drivers_corridor_robust_to_clutter_and_drift),
      cmocka_unit_test(test_drivers_runs_deterministic_per_seed),
      cmocka_unit_test(test_drivers_outputs_bounded_and_safe),
      cmocka_unit_test(test_drivers_episode_allocation_free),
  };
  const char* only = argc > 1 ? argv[1] : "";
  int failed = 0;
  if (only[0] == '\0' || strcmp(only, "corridor") == 0) {
    failed += cmocka_run_group_tests_name("tasks.drivers_corridor", corridor, NULL, NULL);
  }
  if (only[0] == '\0' || strcmp(only, "obstacles") == 0) {
    failed += cmocka_run_group_tests_name("tasks.drivers_obstacles", obstacles, NULL, NULL);
  }
  if (only[0] == '\0' || strcmp(only, "misc") == 0) {
    failed += cmocka_run_group_tests_name("tasks.drivers_misc", misc, NULL, NULL);
  }
  return failed;
}
