// SPDX-License-Identifier: MIT
// The environment core (sim/env.h): both tasks on both back-ends, determinism, errors, the clamp
// in force, no allocation per step.
#include "sim/env.h"

#include <b21r_test/alloc_counter.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

static sim_env_t* make(const tasks_decl_t* task, sim_env_backend_t backend) {
  sim_env_config_t cfg;
  sim_env_config_default(&cfg, task, backend);
  char err[256];
  sim_env_t* env = sim_env_create(&cfg, err, sizeof err);
  if (env == NULL) {
    fail_msg("sim_env_create: %s", err);
  }
  return env;
}

static const features_pose_t k_no_pose = {0.0, 0.0, 0.0};

// Runs n steps of a fixed action pattern with resets; returns a checksum-free trace in out.
static int run(sim_env_t* env, uint64_t seed, int n, double* out, int cap) {
  assert_int_equal(sim_env_seed(env, seed), SIM_ENV_OK);
  double s[TASKS_MAX_STATE_DIM];
  assert_int_equal(sim_env_reset(env, SIM_ENV_START_TRAINING, 0, k_no_pose, s), SIM_ENV_OK);
  int k = 0;
  for (int i = 0; i < n; ++i) {
    sim_env_transition_t t;
    assert_int_equal(sim_env_step(env, 0.8 * sin(0.3 * i), &t), SIM_ENV_OK);
    for (uint32_t j = 0; j < sim_env_episode(env)->state_dim && k < cap; ++j) out[k++] = t.state[j];
    if (k < cap) out[k++] = t.reward + t.action_radps;
    if (t.terminated || t.truncated) {
      assert_int_equal(sim_env_reset(env, SIM_ENV_START_TRAINING, 0, k_no_pose, s), SIM_ENV_OK);
    }
  }
  return k;
}

// Same seed, same actions: bit-identical results, on every task and back-end; another seed: not.
static void test_env_deterministic_per_seed(void** state) {
  (void)state;
  static double a[4000], b[4000];
  for (int task = 0; task < 2; ++task) {
    for (int be = 0; be < 2; ++be) {
      sim_env_t* e1 = make(task == 0 ? &tasks_corridor_decl : &tasks_obstacles_decl, (sim_env_backend_t)be);
      sim_env_t* e2 = make(task == 0 ? &tasks_corridor_decl : &tasks_obstacles_decl, (sim_env_backend_t)be);
      const int na = run(e1, 42, 600, a, 4000);
      const int nb = run(e2, 42, 600, b, 4000);
      assert_int_equal(na, nb);
      assert_memory_equal(a, b, sizeof a[0] * (size_t)na);
      (void)run(e2, 43, 600, b, 4000);
      assert_true(memcmp(a, b, sizeof a[0] * 8) != 0);
      sim_env_destroy(e1);
      sim_env_destroy(e2);
    }
  }
}

// The executed action is the controller's clamp of the request; the state bounds hold.
static void test_env_clamp_and_bounds(void** state) {
  (void)state;
  for (int task = 0; task < 2; ++task) {
    for (int be = 0; be < 2; ++be) {
      sim_env_t* env = make(task == 0 ? &tasks_corridor_decl : &tasks_obstacles_decl, (sim_env_backend_t)be);
      double s[TASKS_MAX_STATE_DIM], lo[TASKS_MAX_STATE_DIM], hi[TASKS_MAX_STATE_DIM];
      sim_env_state_bounds(env, lo, hi);
      assert_int_equal(sim_env_reset(env, SIM_ENV_START_EVAL, 0, k_no_pose, s), SIM_ENV_OK);
      sim_env_transition_t t;
      assert_int_equal(sim_env_step(env, 5.0, &t), SIM_ENV_OK);
      assert_true(fabs(t.action_radps - 0.286) < 1e-12);  // 2.86 rad/s^2 x 0.1 s from rest
      assert_int_equal(sim_env_step(env, 5.0, &t), SIM_ENV_OK);
      assert_true(fabs(t.action_radps - 0.572) < 1e-12);
      for (int i = 0; i < 300 && !t.terminated && !t.truncated; ++i) {
        assert_int_equal(sim_env_step(env, i % 20 < 10 ? 1.0 : -1.0, &t), SIM_ENV_OK);
        assert_true(fabs(t.action_radps) <= 1.0 && t.translation_mps <= 0.8);
        for (uint32_t j = 0; j < sim_env_episode(env)->state_dim; ++j) {
          assert_true(t.state[j] >= lo[j] && t.state[j] <= hi[j]);
        }
      }
      sim_env_destroy(env);
    }
  }
}

// Errors: step before a reset and after the end, bad actions and poses; nothing changes.
static void test_env_errors(void** state) {
  (void)state;
  sim_env_t* env = make(&tasks_corridor_decl, SIM_ENV_KINEMATIC);
  sim_env_transition_t t;
  double s[TASKS_MAX_STATE_DIM];
  assert_int_equal(sim_env_step(env, 0.0, &t), SIM_ENV_ERR_STATE);
  const features_pose_t in_wall = {0.1, 0.0, 0.0};
  assert_int_equal(sim_env_reset(env, SIM_ENV_START_POSE, 0, in_wall, s), SIM_ENV_ERR_INVALID_ARG);
  const features_pose_t nan_pose = {(double)NAN, 0.0, 0.0};
  assert_int_equal(sim_env_reset(env, SIM_ENV_START_POSE, 0, nan_pose, s), SIM_ENV_ERR_INVALID_ARG);
  assert_int_equal(sim_env_reset(env, (sim_env_start_t)9, 0, k_no_pose, s), SIM_ENV_ERR_INVALID_ARG);
  const features_pose_t p = {9.05, 0.0, 0.0};  // one step from the goal
  assert_int_equal(sim_env_reset(env, SIM_ENV_START_POSE, 0, p, s), SIM_ENV_OK);
  assert_int_equal(sim_env_step(env, (double)NAN, &t), SIM_ENV_ERR_INVALID_ARG);
  assert_int_equal(sim_env_step(env, 0.0, &t), SIM_ENV_OK);
  assert_true(t.terminated && t.reason == TASKS_END_GOAL && t.reward == 10.0);
  assert_int_equal(sim_env_step(env, 0.0, &t), SIM_ENV_ERR_STATE);
  assert_non_null(strstr(sim_env_status_str(SIM_ENV_ERR_STATE), "reset"));
  sim_env_destroy(env);
  sim_env_config_t bad;
  sim_env_config_default(&bad, &tasks_corridor_decl, SIM_ENV_ODE);
  bad.limits.max_rotation_radps = 0.0;
  char err[128] = "";
  assert_null(sim_env_create(&bad, err, sizeof err));
  assert_true(strlen(err) > 0);
  sim_env_config_default(&bad, &tasks_corridor_decl, SIM_ENV_ODE);
  tasks_spec_set_dt_s(&tasks_corridor_decl, bad.spec, 0.105);  // not a whole number of 0.01 s substeps
  assert_null(sim_env_create(&bad, err, sizeof err));
}

// A collision ends the episode: the ODE back-end through the bumper (DIO), the kinematic one by
// the geometry; the obstacle task pays -1.
static void test_env_collision_terminates(void** state) {
  (void)state;
  for (int be = 0; be < 2; ++be) {
    sim_env_t* env = make(&tasks_obstacles_decl, (sim_env_backend_t)be);
    const features_pose_t facing = {-2.5, 0.0, 0.0};  // obstacle at (-1.5, 0), radius 0.25
    double s[TASKS_MAX_STATE_DIM];
    assert_int_equal(sim_env_reset(env, SIM_ENV_START_POSE, 0, facing, s), SIM_ENV_OK);
    sim_env_transition_t t;
    int steps = 0;
    do {
      assert_int_equal(sim_env_step(env, 0.0, &t), SIM_ENV_OK);
    } while (!t.terminated && !t.truncated && ++steps < 100);
    assert_true(t.terminated && t.contact && t.reason == TASKS_END_COLLISION && t.reward == -1.0);
    sim_env_truth_t truth;
    sim_env_get_truth(env, &truth);
    assert_true(truth.collided);
    sim_env_destroy(env);
  }
}

// After the first steps, a step allocates nothing (ODE reuses its step arena).
static void test_env_step_allocation_free(void** state) {
  (void)state;
  for (int be = 0; be < 2; ++be) {
    sim_env_t* env = make(&tasks_corridor_decl, (sim_env_backend_t)be);
    double s[TASKS_MAX_STATE_DIM];
    sim_env_transition_t t;
    assert_int_equal(sim_env_reset(env, SIM_ENV_START_EVAL, 0, k_no_pose, s), SIM_ENV_OK);
    for (int i = 0; i < 5; ++i) assert_int_equal(sim_env_step(env, 0.1, &t), SIM_ENV_OK);
    alloc_counter_begin();
    for (int i = 0; i < 50 && !t.terminated && !t.truncated; ++i) {
      assert_int_equal(sim_env_step(env, 0.1 * sin(0.2 * i), &t), SIM_ENV_OK);
    }
    print_message("%s: %llu allocations in 50 steps\n", be == 0 ? "ode" : "kinematic",
                  (unsigned long long)alloc_counter_peek());
    assert_int_equal(alloc_counter_end(), 0);
    sim_env_destroy(env);
  }
}

// The obstacle task's state remembers the obstacle being passed on both back-ends (the ODE one
// from noisy scans, the kinematic one from the exact pose): after it leaves the view the state
// keeps a near obstacle beside and then behind the robot, its age growing by one period a step,
// instead of "no obstacle"; a reset starts without the memory.
static void test_env_obstacle_memory_on_both_backends(void** state) {
  (void)state;
  for (int be = 0; be < 2; ++be) {
    sim_env_t* env = make(&tasks_obstacles_decl, (sim_env_backend_t)be);
    double s[TASKS_MAX_STATE_DIM];
    // Straight past the obstacle (centre (-1.5, 0), radius 0.25) on its left, 0.3 m clear; the
    // second time only until it has been remembered for 5 steps.
    const features_pose_t past = {-3.5, -0.81, 0.0};
    for (int episode = 0; episode < 2; ++episode) {
      assert_int_equal(sim_env_reset(env, SIM_ENV_START_POSE, 0, past, s), SIM_ENV_OK);
      assert_true(s[3] < 2.5 && s[4] == 0.0);
      sim_env_transition_t t;
      int remembered = 0;
      double prev_age = 0.0, worst = 0.0;
      for (int i = 0; i < 120 && !(episode == 1 && remembered == 5); ++i) {
        assert_int_equal(sim_env_step(env, 0.0, &t), SIM_ENV_OK);
        assert_false(t.terminated);
        if (t.state[4] > 0.0 && t.state[3] < 8.0) {
          ++remembered;
          assert_true(fabs(t.state[4] - prev_age - 0.1) < 1e-9);
          assert_true(t.state[2] > 0.9);
          // As far as the true obstacle: exactly on the kinematic model, within the scan's and
          // odometry's errors on the emulator.
          sim_env_truth_t truth;
          sim_env_get_truth(env, &truth);
          const double surface = hypot(truth.pose.x_m + 1.5, truth.pose.y_m) - 0.25;
          worst = fmax(worst, fabs(t.state[3] - surface));
          assert_true(fabs(t.state[3] - surface) < (be == SIM_ENV_KINEMATIC ? 1e-9 : 0.06));
        }
        prev_age = t.state[4];
      }
      print_message("%s: remembered for %d steps, distance within %.4f m of the truth\n",
                    be == 0 ? "ode" : "kinematic", remembered, worst);
      assert_int_equal(remembered, episode == 0 ? 30 : 5);
    }
    // Beside the obstacle, facing away from it: nothing seen, nothing remembered from before.
    const features_pose_t beside = {-1.2, -0.81, 0.0};
    assert_int_equal(sim_env_reset(env, SIM_ENV_START_POSE, 0, beside, s), SIM_ENV_OK);
    assert_true(s[3] == 8.0 && fabs(s[4] - 3.0) < 1e-9);
    sim_env_destroy(env);
  }
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_env_deterministic_per_seed),
      cmocka_unit_test(test_env_clamp_and_bounds),
      cmocka_unit_test(test_env_errors),
      cmocka_unit_test(test_env_collision_terminates),
      cmocka_unit_test(test_env_obstacle_memory_on_both_backends),
      cmocka_unit_test(test_env_step_allocation_free),
  };
  return cmocka_run_group_tests_name("sim.env", tests, NULL, NULL);
}
