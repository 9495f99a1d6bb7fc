// SPDX-License-Identifier: MIT
// The kinematic synchro-drive model against the closed-form model (continuous and discrete).
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>

#include "b21r_test/alloc_counter.h"
#include "sim/kinematic.h"

static const double k_pi = 3.14159265358979323846;

static sim_kin_limits_t unlimited(void) { return (sim_kin_limits_t){0.0, 0.0}; }

// Closed form of the continuous model under constant (v, w) from (0, 0, th0) after t seconds.
static void arc_closed_form(double v, double w, double th0, double t, double* x, double* y,
                            double* th) {
  *th = th0 + w * t;
  if (fabs(w) < 1e-15) {
    *x = v * t * cos(th0);
    *y = v * t * sin(th0);
  } else {
    *x = v / w * (sin(*th) - sin(th0));
    *y = -v / w * (cos(*th) - cos(th0));
  }
}

// Straight line at constant speed: x = v t exactly (to rounding), y stays 0.
static void test_kin_straight_line_matches_closed_form(void** state) {
  (void)state;
  sim_kin_state_t s;
  sim_kin_reset(&s, 0.0, 0.0, 0.0);
  const sim_kin_limits_t lim = unlimited();
  sim_kin_run(&s, &lim, 0.5, 0.0, 0.01, 1000);
  assert_true(fabs(s.x_m - 5.0) < 1e-9);
  assert_true(fabs(s.y_m) < 1e-12);
  assert_true(fabs(s.theta_rad) < 1e-15);
  assert_true(fabs(s.v_mps - 0.5) < 1e-15);
}

// Pure rotation: theta = w t (wrapped), position unchanged.
static void test_kin_pure_rotation_matches_closed_form(void** state) {
  (void)state;
  sim_kin_state_t s;
  sim_kin_reset(&s, 1.0, 2.0, 0.0);
  const sim_kin_limits_t lim = unlimited();
  sim_kin_run(&s, &lim, 0.0, 0.5, 0.01, 1000);  // 5 rad
  assert_true(fabs(s.theta_rad - (5.0 - 2.0 * k_pi)) < 1e-9);
  assert_true(fabs(s.x_m - 1.0) < 1e-15 && fabs(s.y_m - 2.0) < 1e-15);
}

// The discrete heading-first model has a closed form too: x_n = v dt sum_{k=1..n} cos(k w dt)
// = v dt sin(n w dt / 2) / sin(w dt / 2) cos((n + 1) w dt / 2); the model must equal it.
static void test_kin_arc_matches_discrete_closed_form(void** state) {
  (void)state;
  const double v = 0.4, w = 0.3, dt = 0.1;
  const uint64_t n = 97;
  sim_kin_state_t s;
  sim_kin_reset(&s, 0.0, 0.0, 0.0);
  const sim_kin_limits_t lim = unlimited();
  sim_kin_run(&s, &lim, v, w, dt, n);
  const double h = 0.5 * w * dt;
  const double ratio = sin((double)n * h) / sin(h);
  const double x = v * dt * ratio * cos((double)(n + 1) * h);
  const double y = v * dt * ratio * sin((double)(n + 1) * h);
  assert_true(fabs(s.x_m - x) < 1e-12);
  assert_true(fabs(s.y_m - y) < 1e-12);
  assert_true(fabs(s.theta_rad - sim_angle_wrap((double)n * w * dt)) < 1e-12);
}

// Against the continuous arc the model is first order: the error is below v*dt and halves
// (within 10 %) when dt halves.
static void test_kin_arc_converges_to_continuous_closed_form(void** state) {
  (void)state;
  const double v = 0.5, w = -0.7, t = 6.0;
  double err[3];
  const double dts[3] = {0.02, 0.01, 0.005};
  for (int k = 0; k < 3; ++k) {
    sim_kin_state_t s;
    sim_kin_reset(&s, 0.0, 0.0, 0.3);
    const sim_kin_limits_t lim = unlimited();
    sim_kin_run(&s, &lim, v, w, dts[k], (uint64_t)llround(t / dts[k]));
    double x, y, th;
    arc_closed_form(v, w, 0.3, t, &x, &y, &th);
    err[k] = hypot(s.x_m - x, s.y_m - y);
    assert_true(err[k] < v * dts[k]);
    assert_true(fabs(sim_angle_wrap(s.theta_rad - th)) < 1e-9);
  }
  assert_true(fabs(err[0] / err[1] - 2.0) < 0.2);
  assert_true(fabs(err[1] / err[2] - 2.0) < 0.2);
}

// Acceleration limit: v ramps at a until the command, distance = sum of the ramp (trapezoid).
static void test_kin_accel_limit_ramps_to_command(void** state) {
  (void)state;
  const double a = 0.5, dt = 0.01, v_cmd = 1.0;
  sim_kin_limits_t lim = {a, 0.0};
  sim_kin_state_t s;
  sim_kin_reset(&s, 0.0, 0.0, 0.0);
  sim_kin_run(&s, &lim, v_cmd, 0.0, dt, 100);
  assert_true(fabs(s.v_mps - 0.5) < 1e-12);  // half-way after 1 s
  sim_kin_run(&s, &lim, v_cmd, 0.0, dt, 100);
  assert_true(fabs(s.v_mps - 1.0) < 1e-12);  // at the command after 2 s
  sim_kin_run(&s, &lim, v_cmd, 0.0, dt, 200);
  // Discrete ramp: sum_{k=1..200} k a dt * dt = a dt^2 * 200*201/2; then 2 s at 1 m/s.
  const double expected = a * dt * dt * 200.0 * 201.0 / 2.0 + 2.0;
  assert_true(fabs(s.x_m - expected) < 1e-9);
  // And close to the continuous trapezoid a t^2 / 2 + v (t - t_ramp) = 1 + 2.
  assert_true(fabs(s.x_m - 3.0) < v_cmd * dt);
}

// Rotation axis limit: omega ramps at the rotational limit, also when braking to zero.
static void test_kin_rot_accel_limit_applies_both_ways(void** state) {
  (void)state;
  sim_kin_limits_t lim;
  sim_kin_limits_default(&lim);
  sim_kin_state_t s;
  sim_kin_reset(&s, 0.0, 0.0, 0.0);
  sim_kin_step(&s, &lim, 0.0, 1.0, 0.1);
  assert_true(fabs(s.omega_radps - lim.accel_rot_radps2 * 0.1) < 1e-12);
  sim_kin_run(&s, &lim, 0.0, 1.0, 0.1, 10);
  assert_true(fabs(s.omega_radps - 1.0) < 1e-12);
  sim_kin_step(&s, &lim, 0.0, 0.0, 0.1);
  assert_true(fabs(s.omega_radps - (1.0 - lim.accel_rot_radps2 * 0.1)) < 1e-12);
}

// NaN or infinite commands act as zero: the state stays finite.
static void test_kin_nonfinite_command_treated_as_zero(void** state) {
  (void)state;
  sim_kin_limits_t lim;
  sim_kin_limits_default(&lim);
  sim_kin_state_t s;
  sim_kin_reset(&s, 0.0, 0.0, 0.0);
  sim_kin_run(&s, &lim, NAN, INFINITY, 0.1, 10);
  assert_true(s.x_m == 0.0 && s.y_m == 0.0 && s.theta_rad == 0.0);
  assert_true(isfinite(s.v_mps) && isfinite(s.omega_radps));
}

// Angle wrapping returns (-pi, pi] and 0 for non-finite input.
static void test_kin_angle_wrap_range_is_half_open(void** state) {
  (void)state;
  assert_true(sim_angle_wrap(k_pi) == k_pi);
  assert_true(fabs(sim_angle_wrap(-k_pi) - k_pi) < 1e-15);
  assert_true(fabs(sim_angle_wrap(7.0) - (7.0 - 2.0 * k_pi)) < 1e-12);
  assert_true(fabs(sim_angle_wrap(-100.0) - (-100.0 + 32.0 * k_pi)) < 1e-9);
  assert_true(sim_angle_wrap(NAN) == 0.0);
}

// Stepping allocates nothing (the studies run billions of steps).
static void test_kin_step_allocates_nothing(void** state) {
  (void)state;
  sim_kin_limits_t lim;
  sim_kin_limits_default(&lim);
  sim_kin_state_t s;
  sim_kin_reset(&s, 0.0, 0.0, 0.0);
  alloc_counter_begin();
  sim_kin_run(&s, &lim, 0.3, 0.2, 0.1, 10000);
  assert_int_equal(alloc_counter_end(), 0);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_kin_straight_line_matches_closed_form),
      cmocka_unit_test(test_kin_pure_rotation_matches_closed_form),
      cmocka_unit_test(test_kin_arc_matches_discrete_closed_form),
      cmocka_unit_test(test_kin_arc_converges_to_continuous_closed_form),
      cmocka_unit_test(test_kin_accel_limit_ramps_to_command),
      cmocka_unit_test(test_kin_rot_accel_limit_applies_both_ways),
      cmocka_unit_test(test_kin_nonfinite_command_treated_as_zero),
      cmocka_unit_test(test_kin_angle_wrap_range_is_half_open),
      cmocka_unit_test(test_kin_step_allocates_nothing),
  };
  return cmocka_run_group_tests_name("sim.kinematic", tests, NULL, NULL);
}
