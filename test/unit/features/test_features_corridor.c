// SPDX-License-Identifier: MIT
// Corridor features against the exact geometry of a synthetic corridor: many seeded random poses,
// LMS200 noise, clutter (a person), dropouts and error codes, drifting odometry.
#include <b21r_test/alloc_counter.h>
#include <b21r_test/synthetic_world.h>
#include <features/features.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#include "scan_fill.h"

#define PI 3.14159265358979323846
#define LENGTH_M 10.0
#define WIDTH_M 2.0
#define ROBOT_R_M 0.26

// Stated tolerances (nominal conditions: 1° or 0.5° beams, sigma 1 cm, mm quantum, up to 10 %
// dropouts and 2 % error codes, one person in the corridor, odometry heading error <= 0.1 rad).
#define TOL_OFFSET_M 0.02       // lateral offset from the centre line
#define TOL_FRAC 0.01          // lateral fraction (= offset / width)
#define TOL_HEADING_RAD 0.025   // heading relative to the corridor axis (1.4°)
#define TOL_TARGET_RAD 0.025     // target angle
#define TOL_END_LASER_M 0.02    // end distance when the end wall is measured
#define TOL_WIDTH_M 0.03        // measured width
#define MIN_WALL_RATE 0.99      // fraction of poses whose walls are found

typedef struct sweep_opts {
  uint64_t seed;
  int n_poses;
  double resolution_deg;
  double noise_m;
  double dropout;
  double codes;
  uint8_t raw_codes;
  int person;
  double odom_heading_err_rad;  // uniform +- on the odometry prior's heading
  double odom_x_err_m;          // uniform +- on the odometry prior's x
  double x_min_m, x_max_m;      // robot positions along the corridor
  int no_odometry;              // pass NULL instead of the odometry pose
  double tol_scale;             // multiplies every tolerance (1 = the stated ones)
} sweep_opts_t;

typedef struct sweep_stats {
  int n;
  int walls_found;
  int both_walls;
  int end_laser;
  int end_visible_truth;  // poses where the end wall is within 7.5 m and ahead
  double max_offset_err, max_frac_err, max_heading_err, max_target_err, max_end_err, max_width_err;
  double sum_sq_heading_err;
  int bad_lateral;        // lateral source laser but error beyond tolerance
  int nonfinite;
} sweep_stats_t;

static double urange(synth_rng_t* r, double lo, double hi) {
  return lo + (hi - lo) * synth_rng_uniform(r);
}

static void build_corridor(synth_world_t* w) {
  synth_world_init(w);
  assert_int_equal(synth_world_add_corridor(w, LENGTH_M, WIDTH_M), 0);
}

static int all_finite(const features_corridor_t* f) {
  return isfinite(f->end_distance_m) && isfinite(f->lateral_frac) && isfinite(f->target_angle_rad) &&
         isfinite(f->offset_m) && isfinite(f->heading_rad) && isfinite(f->width_m) &&
         isfinite(f->fit_rms_m);
}

static void sweep(const sweep_opts_t* o, sweep_stats_t* st) {
  memset(st, 0, sizeof *st);
  synth_rng_t rng;
  synth_rng_seed(&rng, o->seed);
  synth_lidar_config_t lidar;
  assert_int_equal(synth_lidar_config_lms200(&lidar, 180, o->resolution_deg), 0);
  lidar.noise_sigma_m = o->noise_m;
  lidar.dropout_prob = o->dropout;
  lidar.error_code_prob = o->codes;
  lidar.raw_error_codes = o->raw_codes;
  features_corridor_config_t cfg;
  features_corridor_config_default(&cfg);
  static features_scan_t scan;
  for (int k = 0; k < o->n_poses; ++k) {
    synth_world_t w;
    build_corridor(&w);
    features_pose_t p;
    p.x_m = urange(&rng, o->x_min_m, o->x_max_m);
    p.y_m = urange(&rng, -0.6, 0.6);
    p.theta_rad = urange(&rng, -1.2, 1.2);
    if (o->person) {
      // A person (radius 0.2 m) somewhere in the corridor ahead, not overlapping the robot.
      for (int tries = 0; tries < 20; ++tries) {
        const double px = urange(&rng, p.x_m + 0.8, p.x_m + 4.0);
        const double py = urange(&rng, -0.7, 0.7);
        if (px < LENGTH_M - 0.3) {
          assert_int_equal(synth_world_add_circle(&w, px, py, 0.2), 0);
          break;
        }
      }
    }
    assert_true(scan_fill(&scan, &w, &lidar, &rng, p) > 0);
    features_pose_t odo = p;
    odo.theta_rad += urange(&rng, -o->odom_heading_err_rad, o->odom_heading_err_rad);
    odo.x_m += urange(&rng, -o->odom_x_err_m, o->odom_x_err_m);
    features_corridor_t f, truth;
    assert_int_equal(features_corridor_compute(&cfg, &scan, o->no_odometry ? NULL : &odo, &f),
                     FEATURES_OK);
    assert_int_equal(features_corridor_from_pose(&cfg, p, &truth), FEATURES_OK);
    ++st->n;
    if (!all_finite(&f)) {
      ++st->nonfinite;
      continue;
    }
    if (f.lateral_source == FEATURES_SOURCE_LASER) {
      ++st->walls_found;
      st->both_walls += f.walls_seen == 2U;
      const double eo = fabs(f.offset_m - truth.offset_m);
      const double ef = fabs(f.lateral_frac - truth.lateral_frac);
      const double eh = fabs(features_angle_wrap(f.heading_rad - truth.heading_rad));
      const double et = fabs(features_angle_wrap(f.target_angle_rad - truth.target_angle_rad));
      st->max_offset_err = fmax(st->max_offset_err, eo);
      st->max_frac_err = fmax(st->max_frac_err, ef);
      st->max_heading_err = fmax(st->max_heading_err, eh);
      st->max_target_err = fmax(st->max_target_err, et);
      st->sum_sq_heading_err += eh * eh;
      if (f.walls_seen == 2U) {
        st->max_width_err = fmax(st->max_width_err, fabs(f.width_m - WIDTH_M));
      }
      const double ks = o->tol_scale;
      if (eo > ks * TOL_OFFSET_M || ef > ks * TOL_FRAC || eh > ks * TOL_HEADING_RAD ||
          et > ks * TOL_TARGET_RAD) {
        ++st->bad_lateral;
        printf("  out of tolerance: pose (%.3f, %.3f, %.3f) odo (%.3f, %.3f) offset %.3f/%.3f "
               "heading %.3f/%.3f walls %u/%u points %u/%u end %u\n",
               p.x_m, p.y_m, p.theta_rad, odo.x_m, odo.theta_rad, f.offset_m, truth.offset_m,
               f.heading_rad, truth.heading_rad, f.left_wall_seen, f.right_wall_seen,
               f.left_points, f.right_points, f.end_wall_seen);
      }
    }
    if (f.valid == 0U && !o->no_odometry) {
      ++st->nonfinite;  // with odometry the state is always valid
    }
    if (f.end_source == FEATURES_SOURCE_LASER) {
      ++st->end_laser;
      st->max_end_err = fmax(st->max_end_err, fabs(f.end_distance_m - truth.end_distance_m));
    }
    if (truth.end_distance_m < 7.5 && fabs(p.theta_rad) < 0.6) {
      ++st->end_visible_truth;
    }
  }
}

static void print_stats(const char* name, const sweep_stats_t* st) {
  printf("[ corridor ] %-24s n=%d walls=%d both=%d end_laser=%d (in plain view %d) | max err: "
         "offset %.4f m, frac %.4f, heading %.4f rad (rms %.4f), target %.4f rad, end %.4f m, "
         "width %.4f m | out of tol %d, bad %d\n",
         name, st->n, st->walls_found, st->both_walls, st->end_laser, st->end_visible_truth,
         st->max_offset_err, st->max_frac_err, st->max_heading_err,
         st->walls_found > 0 ? sqrt(st->sum_sq_heading_err / st->walls_found) : 0.0,
         st->max_target_err, st->max_end_err, st->max_width_err, st->bad_lateral, st->nonfinite);
}

static void check_stats(const sweep_opts_t* o, const sweep_stats_t* st) {
  assert_int_equal(st->nonfinite, 0);
  assert_true((double)st->walls_found >= MIN_WALL_RATE * (double)st->n);
  assert_int_equal(st->bad_lateral, 0);
  assert_true(st->max_end_err <= o->tol_scale * TOL_END_LASER_M);
  assert_true(st->max_width_err <= o->tol_scale * TOL_WIDTH_M);
}

// The nominal sweep: the whole run from the start to the goal line (end distance >= 0.8 m).
#define X_MIN_M 0.5
#define X_MAX_M 9.2

// Clean scans (noise only), 1° beams: every quantity within the stated tolerances, and the end
// wall measured wherever it is plainly in view.
static void test_corridor_clean_random_poses_within_tolerance(void** state) {
  (void)state;
  const sweep_opts_t o = {.seed = 1, .n_poses = 400, .resolution_deg = 1.0, .noise_m = 0.01,
                          .x_min_m = X_MIN_M, .x_max_m = X_MAX_M, .tol_scale = 1.0};
  sweep_stats_t st;
  sweep(&o, &st);
  print_stats("clean 1deg", &st);
  check_stats(&o, &st);
  assert_true(st.end_laser >= st.end_visible_truth);
}

// 0.5° beams, a person in the corridor, 10 % dropouts, 2 % error codes, odometry off by up to
// 0.1 rad and 0.3 m.
static void test_corridor_clutter_and_dropouts_within_tolerance(void** state) {
  (void)state;
  const sweep_opts_t o = {.seed = 2, .n_poses = 400, .resolution_deg = 0.5, .noise_m = 0.01,
                          .dropout = 0.10, .codes = 0.02, .person = 1,
                          .odom_heading_err_rad = 0.1, .odom_x_err_m = 0.3,
                          .x_min_m = X_MIN_M, .x_max_m = X_MAX_M, .tol_scale = 1.0};
  sweep_stats_t st;
  sweep(&o, &st);
  print_stats("person+dropouts 0.5deg", &st);
  check_stats(&o, &st);
}

// Raw millimetre-mode error codes passed through as ranges (8.19 m) never become walls.
static void test_corridor_raw_error_codes_rejected(void** state) {
  (void)state;
  const sweep_opts_t o = {.seed = 3, .n_poses = 200, .resolution_deg = 1.0, .noise_m = 0.01,
                          .dropout = 0.05, .codes = 0.05, .raw_codes = 1, .person = 1,
                          .odom_heading_err_rad = 0.05, .x_min_m = X_MIN_M, .x_max_m = X_MAX_M,
                          .tol_scale = 1.0};
  sweep_stats_t st;
  sweep(&o, &st);
  print_stats("raw codes", &st);
  check_stats(&o, &st);
}

// Without odometry the whole half-turn is searched; headings within +-1.2 rad still resolve
// while the end wall is at least 2 m away (closer, one side wall and the end wall form an L that
// the laser alone cannot orient; see features/corridor.h).
static void test_corridor_no_odometry_within_tolerance(void** state) {
  (void)state;
  const sweep_opts_t o = {.seed = 4, .n_poses = 300, .resolution_deg = 1.0, .noise_m = 0.01,
                          .dropout = 0.05, .person = 1, .no_odometry = 1, .x_min_m = X_MIN_M,
                          .x_max_m = LENGTH_M - 2.0, .tol_scale = 1.0};
  sweep_stats_t st;
  sweep(&o, &st);
  print_stats("no odometry", &st);
  check_stats(&o, &st);
}

// Past the goal line (0.4..0.8 m from the end wall, where a run has already ended) most of the
// side walls are out of view: the state stays finite and valid, within four times the stated
// tolerances (heading 0.1 rad), or falls back to odometry.
static void test_corridor_beyond_goal_line_degrades_gracefully(void** state) {
  (void)state;
  const sweep_opts_t o = {.seed = 5, .n_poses = 200, .resolution_deg = 0.5, .noise_m = 0.01,
                          .dropout = 0.05, .person = 1, .x_min_m = X_MAX_M, .x_max_m = 9.6,
                          .tol_scale = 4.0};
  sweep_stats_t st;
  sweep(&o, &st);
  print_stats("beyond goal line", &st);
  assert_int_equal(st.nonfinite, 0);
  assert_int_equal(st.bad_lateral, 0);
}

// The state of an exactly known pose follows the documented definitions, including the paper's
// theta = atan(L/d) + phi - pi/2 for d > 0.
static void test_corridor_from_pose_matches_paper_formula(void** state) {
  (void)state;
  features_corridor_config_t cfg;
  features_corridor_config_default(&cfg);
  const double L = cfg.lookahead_m;
  for (int i = 0; i < 50; ++i) {
    const features_pose_t p = {1.0 + 0.15 * i, 0.02 + 0.015 * i, -0.5 + 0.02 * i};
    features_corridor_t f;
    assert_int_equal(features_corridor_from_pose(&cfg, p, &f), FEATURES_OK);
    const double d = p.y_m;           // left of centre
    const double phi = -p.theta_rad;  // corridor axis in the robot frame
    const double paper = atan(L / d) + phi - PI / 2.0;
    assert_true(fabs(features_angle_wrap(f.target_angle_rad - paper)) < 1e-12);
    assert_true(fabs(f.end_distance_m - (LENGTH_M - p.x_m)) < 1e-12);
    assert_true(fabs(f.lateral_frac - (WIDTH_M / 2.0 - p.y_m) / WIDTH_M) < 1e-12);
    assert_int_equal(f.valid, 1);
    assert_int_equal(f.lateral_source, FEATURES_SOURCE_ODOMETRY);
  }
  // Continuous through the centre line (the paper's form jumps there).
  features_corridor_t a, b;
  const features_pose_t pa = {5.0, 1e-9, 0.0}, pb = {5.0, -1e-9, 0.0};
  assert_int_equal(features_corridor_from_pose(&cfg, pa, &a), FEATURES_OK);
  assert_int_equal(features_corridor_from_pose(&cfg, pb, &b), FEATURES_OK);
  assert_true(fabs(a.target_angle_rad - b.target_angle_rad) < 1e-6);
  // Left of centre, heading along the axis: the target is to the right (negative angle).
  const features_pose_t pl = {5.0, 0.5, 0.0};
  assert_int_equal(features_corridor_from_pose(&cfg, pl, &a), FEATURES_OK);
  assert_true(a.target_angle_rad < 0.0);
}

static void fill_blind(features_scan_t* scan) {
  memset(scan, 0, sizeof *scan);
  assert_int_equal(features_scan_set_lms200_geometry(scan, 180, 1.0), FEATURES_OK);
  for (int i = 0; i < scan->n_beams; ++i) {
    scan->ranges_m[i] = 0.0f;
    scan->no_return[i] = 1U;
  }
}

// A scan without a single return: odometry carries the state (flagged), or, without odometry,
// the state is invalid with neutral, finite values.
static void test_corridor_blind_scan_flags_fallback(void** state) {
  (void)state;
  features_corridor_config_t cfg;
  features_corridor_config_default(&cfg);
  static features_scan_t scan;
  fill_blind(&scan);
  const features_pose_t p = {3.0, 0.2, 0.1};
  features_corridor_t f;
  assert_int_equal(features_corridor_compute(&cfg, &scan, &p, &f), FEATURES_OK);
  assert_int_equal(f.valid, 1);
  assert_int_equal(f.walls_seen, 0);
  assert_int_equal(f.lateral_source, FEATURES_SOURCE_ODOMETRY);
  assert_int_equal(f.end_source, FEATURES_SOURCE_ODOMETRY);
  assert_true(fabs(f.end_distance_m - 7.0) < 1e-12);
  assert_int_equal(features_corridor_compute(&cfg, &scan, NULL, &f), FEATURES_OK);
  assert_int_equal(f.valid, 0);
  assert_int_equal(f.lateral_source, FEATURES_SOURCE_NONE);
  assert_true(f.end_distance_m == LENGTH_M && f.lateral_frac == 0.5 && f.target_angle_rad == 0.0);
}

// Garbage in the ranges (NaN, infinities, negative, beyond the sensor) is discarded, never
// propagated.
static void test_corridor_nonfinite_ranges_never_nan(void** state) {
  (void)state;
  features_corridor_config_t cfg;
  features_corridor_config_default(&cfg);
  synth_world_t w;
  build_corridor(&w);
  synth_lidar_config_t lidar;
  assert_int_equal(synth_lidar_config_lms200(&lidar, 180, 1.0), 0);
  lidar.noise_sigma_m = 0.0;
  static features_scan_t scan;
  const features_pose_t p = {4.0, -0.2, 0.3};
  assert_true(scan_fill(&scan, &w, &lidar, NULL, p) > 0);
  const float junk[4] = {NAN, INFINITY, -1.0f, 100.0f};
  for (int i = 0; i < scan.n_beams; i += 3) {
    scan.ranges_m[i] = junk[(i / 3) % 4];
  }
  features_corridor_t f, truth;
  assert_int_equal(features_corridor_compute(&cfg, &scan, &p, &f), FEATURES_OK);
  assert_int_equal(features_corridor_from_pose(&cfg, p, &truth), FEATURES_OK);
  assert_true(all_finite(&f));
  assert_int_equal(f.lateral_source, FEATURES_SOURCE_LASER);
  assert_true(fabs(f.offset_m - truth.offset_m) < TOL_OFFSET_M);
  assert_true(fabs(f.heading_rad - truth.heading_rad) < TOL_HEADING_RAD);
  // Every beam NaN: no walls, odometry fallback, still finite.
  for (int i = 0; i < scan.n_beams; ++i) scan.ranges_m[i] = NAN;
  assert_int_equal(features_corridor_compute(&cfg, &scan, &p, &f), FEATURES_OK);
  assert_true(all_finite(&f));
  assert_int_equal(f.walls_seen, 0);
}

// Bad calls are refused and leave a neutral, finite output.
static void test_corridor_invalid_arguments_rejected(void** state) {
  (void)state;
  features_corridor_config_t cfg;
  features_corridor_config_default(&cfg);
  static features_scan_t scan;
  fill_blind(&scan);
  features_corridor_t f;
  assert_int_equal(features_corridor_compute(NULL, &scan, NULL, &f), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(f.valid, 0);
  assert_int_equal(features_corridor_compute(&cfg, NULL, NULL, &f), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_corridor_compute(&cfg, &scan, NULL, NULL), FEATURES_ERR_INVALID_ARG);
  scan.n_beams = FEATURES_MAX_BEAMS + 1;
  assert_int_equal(features_corridor_compute(&cfg, &scan, NULL, &f), FEATURES_ERR_INVALID_ARG);
  assert_true(all_finite(&f));
  fill_blind(&scan);
  scan.angle_increment_rad = 0.0;
  assert_int_equal(features_corridor_compute(&cfg, &scan, NULL, &f), FEATURES_ERR_INVALID_ARG);
  scan.angle_increment_rad = NAN;
  assert_int_equal(features_corridor_compute(&cfg, &scan, NULL, &f), FEATURES_ERR_INVALID_ARG);
  fill_blind(&scan);
  features_corridor_config_t bad = cfg;
  bad.lookahead_m = 0.0;
  assert_int_equal(features_corridor_compute(&bad, &scan, NULL, &f), FEATURES_ERR_INVALID_ARG);
  bad = cfg;
  bad.width_m = NAN;
  assert_int_equal(features_corridor_compute(&bad, &scan, NULL, &f), FEATURES_ERR_INVALID_ARG);
  assert_true(all_finite(&f));
  const features_pose_t nan_pose = {NAN, 0.0, 0.0};
  assert_int_equal(features_corridor_from_pose(&cfg, nan_pose, &f), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(f.valid, 0);
  assert_true(all_finite(&f));
}

// A closed door across the corridor 3 m ahead is not taken for the end wall 8 m ahead: the
// odometry gate rejects it and the end distance comes from odometry.
static void test_corridor_cross_wall_rejected_by_odometry_gate(void** state) {
  (void)state;
  features_corridor_config_t cfg;
  features_corridor_config_default(&cfg);
  synth_world_t w;
  build_corridor(&w);
  assert_int_equal(synth_world_add_segment(&w, 5.0, -1.0, 5.0, 1.0), 0);
  synth_lidar_config_t lidar;
  assert_int_equal(synth_lidar_config_lms200(&lidar, 180, 1.0), 0);
  lidar.noise_sigma_m = 0.0;
  static features_scan_t scan;
  const features_pose_t p = {2.0, 0.1, 0.05};
  assert_true(scan_fill(&scan, &w, &lidar, NULL, p) > 0);
  features_corridor_t f;
  assert_int_equal(features_corridor_compute(&cfg, &scan, &p, &f), FEATURES_OK);
  assert_int_equal(f.end_wall_seen, 0);
  assert_int_equal(f.end_source, FEATURES_SOURCE_ODOMETRY);
  assert_true(fabs(f.end_distance_m - 8.0) < 1e-9);
  // With the gate off the door is measured (3 m ahead): the gate is what made the difference.
  cfg.end_gate_m = 0.0;
  assert_int_equal(features_corridor_compute(&cfg, &scan, &p, &f), FEATURES_OK);
  assert_int_equal(f.end_wall_seen, 1);
  assert_true(fabs(f.end_distance_m - 3.0) < 0.02);
}

// Same inputs, bit-identical outputs; no heap allocation over a thousand calls.
static void test_corridor_deterministic_and_allocation_free(void** state) {
  (void)state;
  features_corridor_config_t cfg;
  features_corridor_config_default(&cfg);
  synth_world_t w;
  build_corridor(&w);
  assert_int_equal(synth_world_add_circle(&w, 4.0, 0.3, 0.2), 0);
  synth_lidar_config_t lidar;
  assert_int_equal(synth_lidar_config_lms200(&lidar, 180, 0.5), 0);
  lidar.dropout_prob = 0.05;
  synth_rng_t rng;
  synth_rng_seed(&rng, 77);
  static features_scan_t scan;
  const features_pose_t p = {2.5, -0.3, 0.4};
  assert_true(scan_fill(&scan, &w, &lidar, &rng, p) > 0);
  features_corridor_t a, b;
  memset(&a, 0xA5, sizeof a);
  memset(&b, 0x5A, sizeof b);
  assert_int_equal(features_corridor_compute(&cfg, &scan, &p, &a), FEATURES_OK);
  alloc_counter_begin();
  for (int i = 0; i < 1000; ++i) {
    assert_int_equal(features_corridor_compute(&cfg, &scan, &p, &b), FEATURES_OK);
  }
  assert_int_equal(alloc_counter_end(), 0);
  assert_memory_equal(&a.end_distance_m, &b.end_distance_m, sizeof(double));
  assert_memory_equal(&a.lateral_frac, &b.lateral_frac, sizeof(double));
  assert_memory_equal(&a.target_angle_rad, &b.target_angle_rad, sizeof(double));
  assert_memory_equal(&a.heading_rad, &b.heading_rad, sizeof(double));
  assert_int_equal(a.left_points, b.left_points);
  assert_int_equal(a.right_points, b.right_points);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_corridor_clean_random_poses_within_tolerance),
      cmocka_unit_test(test_corridor_clutter_and_dropouts_within_tolerance),
      cmocka_unit_test(test_corridor_raw_error_codes_rejected),
      cmocka_unit_test(test_corridor_no_odometry_within_tolerance),
      cmocka_unit_test(test_corridor_beyond_goal_line_degrades_gracefully),
      cmocka_unit_test(test_corridor_from_pose_matches_paper_formula),
      cmocka_unit_test(test_corridor_blind_scan_flags_fallback),
      cmocka_unit_test(test_corridor_nonfinite_ranges_never_nan),
      cmocka_unit_test(test_corridor_invalid_arguments_rejected),
      cmocka_unit_test(test_corridor_cross_wall_rejected_by_odometry_gate),
      cmocka_unit_test(test_corridor_deterministic_and_allocation_free),
  };
  return cmocka_run_group_tests_name("features.corridor", tests, NULL, NULL);
}
