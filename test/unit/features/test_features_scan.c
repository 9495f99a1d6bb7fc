// SPDX-License-Identifier: MIT
// Scan geometry, angle wrapping and planar pose algebra of features/scan.h.
#include <b21r_test/alloc_counter.h>
#include <features/features.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#define PI 3.14159265358979323846

static int pose_near(features_pose_t a, features_pose_t b, double tol) {
  return fabs(a.x_m - b.x_m) < tol && fabs(a.y_m - b.y_m) < tol &&
         fabs(features_angle_wrap(a.theta_rad - b.theta_rad)) < tol;
}

// The LMS200 variants: 180° at 1°/0.5° and 100° at 1°/0.5°/0.25°, index 0 on the right.
static void test_scan_lms200_geometry_variants(void** state) {
  (void)state;
  features_scan_t scan;
  memset(&scan, 0, sizeof scan);
  assert_int_equal(features_scan_set_lms200_geometry(&scan, 180, 1.0), FEATURES_OK);
  assert_int_equal(scan.n_beams, 181);
  assert_true(fabs(scan.angle_min_rad + PI / 2.0) < 1e-15);
  assert_true(fabs(scan.angle_min_rad + 180 * scan.angle_increment_rad - PI / 2.0) < 1e-12);
  assert_int_equal(features_scan_set_lms200_geometry(&scan, 180, 0.5), FEATURES_OK);
  assert_int_equal(scan.n_beams, 361);
  assert_int_equal(features_scan_set_lms200_geometry(&scan, 100, 1.0), FEATURES_OK);
  assert_int_equal(scan.n_beams, 101);
  assert_true(fabs(scan.angle_min_rad + 50.0 * PI / 180.0) < 1e-15);
  assert_int_equal(features_scan_set_lms200_geometry(&scan, 100, 0.5), FEATURES_OK);
  assert_int_equal(scan.n_beams, 201);
  assert_int_equal(features_scan_set_lms200_geometry(&scan, 100, 0.25), FEATURES_OK);
  assert_int_equal(scan.n_beams, 401);
  // Unsupported combinations leave the scan unchanged.
  assert_int_equal(features_scan_set_lms200_geometry(&scan, 180, 0.25), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_scan_set_lms200_geometry(&scan, 90, 1.0), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_scan_set_lms200_geometry(&scan, 180, 2.0), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_scan_set_lms200_geometry(NULL, 180, 1.0), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(scan.n_beams, 401);
  features_scan_config_t cfg;
  features_scan_config_default(&cfg);
  assert_true(cfg.mount.x_m == FEATURES_LASER_X_DEFAULT_M && cfg.mount.y_m == 0.0);
  assert_true(cfg.max_range_m == FEATURES_LMS200_MAX_VALID_RANGE_M && cfg.max_range_m < 8.183);
}

// Angles wrap into (-pi, pi]; non-finite input gives 0.
static void test_scan_angle_wrap_range(void** state) {
  (void)state;
  assert_true(features_angle_wrap(PI) == PI);
  assert_true(fabs(features_angle_wrap(-PI) - PI) < 1e-15);
  assert_true(fabs(features_angle_wrap(3.0 * PI / 2.0) + PI / 2.0) < 1e-12);
  assert_true(fabs(features_angle_wrap(-7.0) - (-7.0 + 2.0 * PI)) < 1e-12);
  assert_true(fabs(features_angle_wrap(100.0) - (100.0 - 32.0 * PI)) < 1e-9);
  assert_true(features_angle_wrap(NAN) == 0.0);
  assert_true(features_angle_wrap(INFINITY) == 0.0);
  for (int i = -1000; i <= 1000; ++i) {
    const double a = features_angle_wrap(0.0137 * i * i);
    assert_true(a > -PI && a <= PI);
  }
}

// Compose/inverse/between are consistent, and odom_to_task moves a run's odometry into the
// task frame (the firmware's path from odometry to the features' pose argument).
static void test_scan_pose_algebra_consistent(void** state) {
  (void)state;
  const features_pose_t a = {1.0, -2.0, 0.7};
  const features_pose_t b = {0.5, 0.25, -2.9};
  const features_pose_t id = {0.0, 0.0, 0.0};
  assert_true(pose_near(features_pose_compose(a, features_pose_inverse(a)), id, 1e-12));
  assert_true(pose_near(features_pose_compose(features_pose_inverse(a), a), id, 1e-12));
  assert_true(pose_near(features_pose_compose(a, features_pose_between(a, b)), b, 1e-12));
  // A point 1 m ahead of a robot at (1, 2) facing +y is at (1, 3).
  const features_pose_t r = {1.0, 2.0, PI / 2.0};
  const features_pose_t ahead = {1.0, 0.0, 0.0};
  assert_true(pose_near(features_pose_compose(r, ahead), (features_pose_t){1.0, 3.0, PI / 2.0}, 1e-12));
  // Odometry started at (10, 10, pi) while the robot stood at the task's (1, 0, 0); it then
  // drove 2 m straight (odometry (8, 10, pi)) and turned left by 0.3 rad.
  const features_pose_t start_task = {1.0, 0.0, 0.0};
  const features_pose_t odom0 = {10.0, 10.0, PI};
  const features_pose_t odom1 = {8.0, 10.0, PI + 0.3};
  const features_pose_t now = features_odom_to_task(start_task, odom0, odom1);
  assert_true(pose_near(now, (features_pose_t){3.0, 0.0, 0.3}, 1e-12));
  alloc_counter_begin();
  for (int i = 0; i < 1000; ++i) (void)features_odom_to_task(start_task, odom0, odom1);
  assert_int_equal(alloc_counter_end(), 0);
}

// A decoded scan's arrays fill a features scan as given; bad calls leave it unchanged.
static void test_scan_fill_copies_and_refuses_bad_calls(void** state) {
  (void)state;
  static features_scan_t scan;
  float ranges[3] = {1.5f, 8.191f, 0.25f};
  uint8_t reasons[3] = {0U, 1U, 0U};
  assert_int_equal(features_scan_fill(&scan, -1.5, 0.0174, 3U, ranges, reasons), FEATURES_OK);
  assert_true(scan.angle_min_rad == -1.5 && scan.angle_increment_rad == 0.0174 && scan.n_beams == 3U);
  assert_memory_equal(scan.ranges_m, ranges, sizeof ranges);
  assert_memory_equal(scan.no_return, reasons, sizeof reasons);
  assert_int_equal(features_scan_fill(&scan, 0.0, 0.1, FEATURES_MAX_BEAMS + 1, ranges, reasons),
                   FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_scan_fill(&scan, 0.0, 0.1, 3U, NULL, reasons), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_scan_fill(NULL, 0.0, 0.1, 3U, ranges, reasons), FEATURES_ERR_INVALID_ARG);
  assert_true(scan.n_beams == 3U && scan.angle_min_rad == -1.5);
  assert_int_equal(features_scan_fill(&scan, 0.0, 0.1, 0U, NULL, NULL), FEATURES_OK);
  assert_int_equal(scan.n_beams, 0);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_scan_lms200_geometry_variants),
      cmocka_unit_test(test_scan_angle_wrap_range),
      cmocka_unit_test(test_scan_pose_algebra_consistent),
      cmocka_unit_test(test_scan_fill_copies_and_refuses_bad_calls),
  };
  return cmocka_run_group_tests_name("features.scan", tests, NULL, NULL);
}
