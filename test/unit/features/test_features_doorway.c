// SPDX-License-Identifier: MIT
// Doorway features against the exact geometry of a synthetic room: a 0.1 m thick dividing wall
// with a 1 m door, seeded noisy LMS200 scans, a jamb hidden behind an obstacle, the odometry
// fallback after the door, without odometry, and the contract (invalid input, determinism, no
// allocation).
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

// The header's stated accuracy of the laser's values (1 cm noise): the offset depends on where
// the jambs' edges fall between beams, so it is looser with dropouts (a missing beam next to a
// jamb widens the interval the edge is known to lie in) and with one jamb hidden.
#define TOL_WALL_M 0.01
#define TOL_OFFSET_M 0.03
#define TOL_OFFSET_DROPOUT_M 0.06
#define TOL_HEADING_RAD 0.015
#define TOL_OFFSET_ONE_JAMB_M 0.06
// Poses in front of the door whose gap the laser sees: the laser's values must be used for at
// least this fraction of them (the rest fall back to odometry, never to nonsense).
#define MIN_LASER_RATE 0.95

// The room of the doorway task's defaults: walls of a 7.5 m x 6 m box, the dividing wall at
// x = 0 (0.1 m thick) with the door's gap |y| < 0.5.
#define ROOM_MIN_X -4.5
#define ROOM_MAX_X 3.0
#define ROOM_HALF_Y 3.0
#define WALL_T 0.1
#define DOOR_W 1.0

static double urange(synth_rng_t* r, double lo, double hi) { return lo + (hi - lo) * synth_rng_uniform(r); }

static void room(synth_world_t* w) {
  synth_world_init(w);
  assert_int_equal(synth_world_add_box(w, ROOM_MIN_X, -ROOM_HALF_Y, ROOM_MAX_X, ROOM_HALF_Y), 0);
  // The dividing wall as two solid blocks (faces, far faces and the jambs' end faces).
  assert_int_equal(synth_world_add_box(w, -0.5 * WALL_T, -ROOM_HALF_Y, 0.5 * WALL_T, -0.5 * DOOR_W), 0);
  assert_int_equal(synth_world_add_box(w, -0.5 * WALL_T, 0.5 * DOOR_W, 0.5 * WALL_T, ROOM_HALF_Y), 0);
}

static int finite_all(const features_doorway_t* f) {
  return isfinite(f->wall_distance_m) && isfinite(f->offset_m) && isfinite(f->heading_rad) &&
         isfinite(f->jamb_distance_m) && isfinite(f->gap_bearing_rad) && isfinite(f->gap_distance_m) &&
         isfinite(f->width_m);
}

// The exact state of a pose: the door frame is the task frame here (door at the origin, normal +x).
static void truth(features_pose_t p, features_doorway_t* f) {
  features_doorway_config_t cfg;
  features_doorway_config_default(&cfg);
  assert_int_equal(features_doorway_from_pose(&cfg, p, f), FEATURES_OK);
}

// The exact values from a pose, by hand: wall distance, offset, heading, jamb distance, and the
// gap's bearing and distance.
static void test_doorway_from_pose_exact(void** state) {
  (void)state;
  features_doorway_config_t cfg;
  features_doorway_config_default(&cfg);
  features_doorway_t f;
  const features_pose_t p = {-2.0, 0.8, -0.3};
  assert_int_equal(features_doorway_from_pose(&cfg, p, &f), FEATURES_OK);
  assert_int_equal(f.valid, 1);
  assert_int_equal(f.source, FEATURES_SOURCE_ODOMETRY);
  assert_true(fabs(f.wall_distance_m - 2.0) < 1e-12);
  assert_true(fabs(f.offset_m - 0.8) < 1e-12);
  assert_true(fabs(f.heading_rad + 0.3) < 1e-12);
  // The nearer jamb: the left one's end face, x in [-0.05, 0.05] at y = 0.5.
  assert_true(fabs(f.jamb_distance_m - hypot(1.95, 0.3)) < 1e-12);
  assert_true(fabs(f.gap_distance_m - hypot(2.0, 0.8)) < 1e-12);
  assert_true(fabs(f.gap_bearing_rad - (atan2(-0.8, 2.0) + 0.3)) < 1e-12);
  double s[FEATURES_DOORWAY_STATE_DIM];
  features_doorway_state(&f, s);
  assert_true(s[0] == f.wall_distance_m && s[1] == f.offset_m && s[2] == f.heading_rad &&
              s[3] == f.jamb_distance_m);

  // A door placed elsewhere in the task frame, facing +y: the same robot relative to it gives the
  // same values.
  cfg.door_x_m = 5.0;
  cfg.door_y_m = -1.0;
  cfg.normal_rad = 0.5 * PI;
  const features_pose_t q = {5.0 - 0.8, -1.0 - 2.0, 0.5 * PI - 0.3};
  features_doorway_t g;
  assert_int_equal(features_doorway_from_pose(&cfg, q, &g), FEATURES_OK);
  assert_true(fabs(g.wall_distance_m - f.wall_distance_m) < 1e-12 && fabs(g.offset_m - f.offset_m) < 1e-12 &&
              fabs(g.heading_rad - f.heading_rad) < 1e-12 && fabs(g.jamb_distance_m - f.jamb_distance_m) < 1e-12 &&
              fabs(g.gap_bearing_rad - f.gap_bearing_rad) < 1e-12);

  // In the doorway the nearer jamb is beside the robot; beyond the wall the distance is negative.
  assert_true(fabs(features_doorway_jamb_distance(0.0, 0.1, DOOR_W, WALL_T) - 0.4) < 1e-12);
  assert_true(fabs(features_doorway_jamb_distance(0.0, -0.3, DOOR_W, WALL_T) - 0.2) < 1e-12);
  assert_true(fabs(features_doorway_jamb_distance(1.05, 0.5, DOOR_W, WALL_T) - 1.0) < 1e-12);
  cfg.door_x_m = 0.0;
  cfg.door_y_m = 0.0;
  cfg.normal_rad = 0.0;
  assert_int_equal(features_doorway_from_pose(&cfg, (features_pose_t){1.2, 0.0, 0.0}, &f), FEATURES_OK);
  assert_true(fabs(f.wall_distance_m + 1.2) < 1e-12 && fabs(fabs(f.gap_bearing_rad) - PI) < 1e-12);
}

typedef struct sweep_stats {
  int n, laser, two_jambs, bad_fallback;
  double max_wall_err, max_offset_err, max_heading_err, max_jamb_err;
} sweep_stats_t;

// Random poses 1-4 m before the wall, |offset| <= 1.5 m, heading within +-0.7 rad of the normal;
// odometry off by up to 0.1 m and 0.05 rad (the laser measures, it does not copy odometry).
static void sweep(uint64_t seed, int n_poses, double res_deg, double dropout, int with_odometry,
                  sweep_stats_t* st) {
  memset(st, 0, sizeof *st);
  synth_rng_t rng;
  synth_rng_seed(&rng, seed);
  synth_lidar_config_t lidar;
  assert_int_equal(synth_lidar_config_lms200(&lidar, 180, res_deg), 0);
  lidar.dropout_prob = dropout;
  features_doorway_config_t cfg;
  features_doorway_config_default(&cfg);
  synth_world_t w;
  room(&w);
  static features_scan_t scan;
  for (int k = 0; k < n_poses; ++k) {
    const features_pose_t p = {-urange(&rng, 1.0, 4.0), urange(&rng, -1.5, 1.5), urange(&rng, -0.7, 0.7)};
    const features_pose_t odo = {p.x_m + urange(&rng, -0.1, 0.1), p.y_m + urange(&rng, -0.1, 0.1),
                                 p.theta_rad + urange(&rng, -0.05, 0.05)};
    assert_true(scan_fill(&scan, &w, &lidar, &rng, p) > 0);
    features_doorway_t f, t;
    assert_int_equal(features_doorway_compute(&cfg, &scan, with_odometry ? &odo : NULL, &f), FEATURES_OK);
    truth(p, &t);
    assert_true(finite_all(&f));
    if (with_odometry) {
      assert_int_equal(f.valid, 1);
    }
    ++st->n;
    if (f.source == FEATURES_SOURCE_LASER) {
      ++st->laser;
      if (f.jambs_seen == 2) ++st->two_jambs;
      st->max_wall_err = fmax(st->max_wall_err, fabs(f.wall_distance_m - t.wall_distance_m));
      st->max_offset_err = fmax(st->max_offset_err, fabs(f.offset_m - t.offset_m));
      st->max_heading_err = fmax(st->max_heading_err, fabs(features_angle_wrap(f.heading_rad - t.heading_rad)));
      st->max_jamb_err = fmax(st->max_jamb_err, fabs(f.jamb_distance_m - t.jamb_distance_m));
    } else if (with_odometry && f.source != FEATURES_SOURCE_ODOMETRY) {
      ++st->bad_fallback;
    }
  }
}

static void check_sweep(const sweep_stats_t* st, const char* what, double tol_offset_m) {
  printf("%s: %d poses, laser %d (both jambs %d), max errors: wall %.4f m, offset %.4f m, heading %.4f rad, "
         "jamb %.4f m\n",
         what, st->n, st->laser, st->two_jambs, st->max_wall_err, st->max_offset_err, st->max_heading_err,
         st->max_jamb_err);
  assert_true((double)st->laser >= MIN_LASER_RATE * (double)st->n);
  assert_int_equal(st->bad_fallback, 0);
  assert_true(st->max_wall_err <= TOL_WALL_M);
  assert_true(st->max_offset_err <= tol_offset_m);
  assert_true(st->max_heading_err <= TOL_HEADING_RAD);
  assert_true(st->max_jamb_err <= TOL_WALL_M + tol_offset_m);
}

// With 1 cm noise at 1° and 0.5°, with and without dropouts, the laser's door frame is within
// the stated tolerances of the truth, and used from nearly every pose.
static void test_doorway_laser_matches_truth_with_noise(void** state) {
  (void)state;
  sweep_stats_t st;
  sweep(11U, 400, 1.0, 0.0, 1, &st);
  check_sweep(&st, "1 deg", TOL_OFFSET_M);
  sweep(12U, 300, 0.5, 0.0, 1, &st);
  check_sweep(&st, "0.5 deg", TOL_OFFSET_M);
  sweep(13U, 400, 1.0, 0.10, 1, &st);
  check_sweep(&st, "1 deg, 10 % dropouts", TOL_OFFSET_DROPOUT_M);
}

// Without odometry the wall is searched over the whole front half-turn: the door is still found.
static void test_doorway_without_odometry_finds_the_door(void** state) {
  (void)state;
  sweep_stats_t st;
  sweep(21U, 300, 1.0, 0.05, 0, &st);
  check_sweep(&st, "no odometry", TOL_OFFSET_DROPOUT_M);
}

// One jamb hidden behind a person standing in front of it: the door is found from the other jamb
// and the door's nominal width (jambs_seen = 1), the offset within its stated tolerance.
static void test_doorway_occluded_jamb_uses_the_other(void** state) {
  (void)state;
  synth_lidar_config_t lidar;
  assert_int_equal(synth_lidar_config_lms200(&lidar, 180, 1.0), 0);
  features_doorway_config_t cfg;
  features_doorway_config_default(&cfg);
  static features_scan_t scan;
  int one = 0;
  for (int side = -1; side <= 1; side += 2) {
    for (uint64_t seed = 1U; seed <= 20U; ++seed) {
      synth_rng_t rng;
      synth_rng_seed(&rng, seed);
      synth_world_t w;
      room(&w);
      // The robot 2.5 m before the wall, off to one side; a person (r 0.2 m) 0.6 m in front of
      // the jamb on the robot's own side, in the line of sight to that jamb.
      const features_pose_t p = {-2.5, side * urange(&rng, 0.6, 1.0), -side * urange(&rng, 0.1, 0.3)};
      const double jx = -0.5 * WALL_T, jy = side * 0.5 * DOOR_W;
      const double lx = p.x_m + cos(p.theta_rad) * lidar.mount_x_m;
      const double ly = p.y_m + sin(p.theta_rad) * lidar.mount_x_m;
      const double d = hypot(jx - lx, jy - ly);
      assert_int_equal(synth_world_add_circle(&w, jx + (lx - jx) * 0.6 / d, jy + (ly - jy) * 0.6 / d, 0.2), 0);
      assert_true(scan_fill(&scan, &w, &lidar, &rng, p) > 0);
      features_doorway_t f, t;
      assert_int_equal(features_doorway_compute(&cfg, &scan, &p, &f), FEATURES_OK);
      truth(p, &t);
      assert_int_equal(f.source, FEATURES_SOURCE_LASER);
      assert_int_equal(f.jambs_seen, 1);
      ++one;
      assert_true(fabs(f.offset_m - t.offset_m) <= TOL_OFFSET_ONE_JAMB_M);
      assert_true(fabs(f.wall_distance_m - t.wall_distance_m) <= TOL_WALL_M);
      assert_true(fabs(features_angle_wrap(f.heading_rad - t.heading_rad)) <= TOL_HEADING_RAD);
    }
  }
  assert_int_equal(one, 40);
}

// Past the door (and while passing it, and facing away from it) the laser cannot see the gap:
// every value comes from odometry, exactly features_doorway_from_pose's.
static void test_doorway_fallback_to_odometry(void** state) {
  (void)state;
  synth_lidar_config_t lidar;
  assert_int_equal(synth_lidar_config_lms200(&lidar, 180, 1.0), 0);
  features_doorway_config_t cfg;
  features_doorway_config_default(&cfg);
  synth_world_t w;
  room(&w);
  synth_rng_t rng;
  synth_rng_seed(&rng, 5U);
  static features_scan_t scan;
  const features_pose_t poses[] = {
      {1.0, 0.1, 0.2}, {0.0, 0.05, 0.0}, {-0.2, 0.0, 0.1}, {-0.34, 0.05, 0.0}, {-2.0, 0.0, PI}};
  for (size_t k = 0; k < sizeof poses / sizeof poses[0]; ++k) {
    assert_true(scan_fill(&scan, &w, &lidar, &rng, poses[k]) > 0);
    features_doorway_t f, t;
    assert_int_equal(features_doorway_compute(&cfg, &scan, &poses[k], &f), FEATURES_OK);
    truth(poses[k], &t);
    assert_int_equal(f.valid, 1);
    assert_int_equal(f.source, FEATURES_SOURCE_ODOMETRY);
    assert_true(f.wall_distance_m == t.wall_distance_m && f.offset_m == t.offset_m &&
                f.heading_rad == t.heading_rad && f.jamb_distance_m == t.jamb_distance_m);
  }
  // Without odometry and with no door in sight, nothing is valid; with no points at all too.
  assert_true(scan_fill(&scan, &w, &lidar, &rng, poses[4]) > 0);
  features_doorway_t f;
  assert_int_equal(features_doorway_compute(&cfg, &scan, NULL, &f), FEATURES_OK);
  assert_int_equal(f.valid, 0);
  assert_int_equal(f.source, FEATURES_SOURCE_NONE);
  assert_true(finite_all(&f));
  for (uint16_t i = 0; i < scan.n_beams; ++i) scan.no_return[i] = 1U;
  assert_int_equal(features_doorway_compute(&cfg, &scan, NULL, &f), FEATURES_OK);
  assert_int_equal(f.valid, 0);
  assert_int_equal(f.n_points, 0);
}

// A wall without a door, or odometry that disagrees with what the laser sees by more than the
// gate: the laser's values are not used.
static void test_doorway_no_gap_or_gate_rejects_laser(void** state) {
  (void)state;
  synth_lidar_config_t lidar;
  assert_int_equal(synth_lidar_config_lms200(&lidar, 180, 1.0), 0);
  features_doorway_config_t cfg;
  features_doorway_config_default(&cfg);
  synth_rng_t rng;
  synth_rng_seed(&rng, 9U);
  static features_scan_t scan;
  synth_world_t closed;
  synth_world_init(&closed);
  assert_int_equal(synth_world_add_box(&closed, ROOM_MIN_X, -ROOM_HALF_Y, ROOM_MAX_X, ROOM_HALF_Y), 0);
  assert_int_equal(synth_world_add_box(&closed, -0.5 * WALL_T, -ROOM_HALF_Y, 0.5 * WALL_T, ROOM_HALF_Y), 0);
  const features_pose_t p = {-2.0, 0.3, 0.1};
  assert_true(scan_fill(&scan, &closed, &lidar, &rng, p) > 0);
  features_doorway_t f;
  assert_int_equal(features_doorway_compute(&cfg, &scan, &p, &f), FEATURES_OK);
  assert_int_equal(f.source, FEATURES_SOURCE_ODOMETRY);
  assert_int_equal(f.wall_seen, 1);
  assert_int_equal(f.jambs_seen, 0);

  synth_world_t w;
  room(&w);
  assert_true(scan_fill(&scan, &w, &lidar, &rng, p) > 0);
  assert_int_equal(features_doorway_compute(&cfg, &scan, &p, &f), FEATURES_OK);
  assert_int_equal(f.source, FEATURES_SOURCE_LASER);
  // Odometry 0.8 m off sideways: the gap the laser sees is not where odometry expects it.
  const features_pose_t off = {p.x_m, p.y_m + 0.8, p.theta_rad};
  assert_int_equal(features_doorway_compute(&cfg, &scan, &off, &f), FEATURES_OK);
  assert_int_equal(f.source, FEATURES_SOURCE_ODOMETRY);
  assert_true(fabs(f.offset_m - off.y_m) < 1e-12);
  // With the gate off, the laser's values are taken as found.
  cfg.gate_m = 0.0;
  assert_int_equal(features_doorway_compute(&cfg, &scan, &off, &f), FEATURES_OK);
  assert_int_equal(f.source, FEATURES_SOURCE_LASER);
  assert_true(fabs(f.offset_m - p.y_m) <= TOL_OFFSET_M);
}

// Bad arguments are refused with the neutral state; the same input gives bit-identical output;
// nothing is allocated.
static void test_doorway_contract(void** state) {
  (void)state;
  features_doorway_config_t cfg;
  features_doorway_config_default(&cfg);
  static features_scan_t scan;
  synth_lidar_config_t lidar;
  assert_int_equal(synth_lidar_config_lms200(&lidar, 180, 0.5), 0);
  synth_world_t w;
  room(&w);
  synth_rng_t rng;
  synth_rng_seed(&rng, 3U);
  const features_pose_t p = {-3.0, -0.7, 0.2};
  assert_true(scan_fill(&scan, &w, &lidar, &rng, p) > 0);
  features_doorway_t a, b;
  assert_int_equal(features_doorway_compute(NULL, &scan, &p, &a), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(a.valid, 0);
  assert_int_equal(features_doorway_compute(&cfg, NULL, &p, &a), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_doorway_compute(&cfg, &scan, &p, NULL), FEATURES_ERR_INVALID_ARG);
  features_doorway_config_t bad = cfg;
  bad.split_gap_m = 0.9;  // not below door_width - width_tolerance
  assert_int_equal(features_doorway_compute(&bad, &scan, &p, &a), FEATURES_ERR_INVALID_ARG);
  assert_true(finite_all(&a));
  bad = cfg;
  bad.door_width_m = NAN;
  assert_int_equal(features_doorway_from_pose(&bad, p, &a), FEATURES_ERR_INVALID_ARG);
  assert_true(finite_all(&a) && a.valid == 0);
  assert_int_equal(features_doorway_from_pose(&cfg, (features_pose_t){NAN, 0.0, 0.0}, &a),
                   FEATURES_ERR_INVALID_ARG);
  features_scan_t* bad_scan = &scan;
  const uint16_t n = scan.n_beams;
  bad_scan->n_beams = FEATURES_MAX_BEAMS + 1;
  assert_int_equal(features_doorway_compute(&cfg, bad_scan, &p, &a), FEATURES_ERR_INVALID_ARG);
  bad_scan->n_beams = n;
  // Non-finite ranges are discarded, never propagated.
  scan.ranges_m[100] = NAN;
  scan.ranges_m[101] = INFINITY;

  alloc_counter_begin();
  memset(&a, 0xA5, sizeof a);
  memset(&b, 0x5A, sizeof b);
  assert_int_equal(features_doorway_compute(&cfg, &scan, &p, &a), FEATURES_OK);
  assert_int_equal(features_doorway_compute(&cfg, &scan, &p, &b), FEATURES_OK);
  assert_int_equal(features_doorway_compute(&cfg, &scan, NULL, &b), FEATURES_OK);
  assert_int_equal(features_doorway_compute(&cfg, &scan, &p, &b), FEATURES_OK);
  assert_int_equal(alloc_counter_end(), 0);
  assert_int_equal(a.source, FEATURES_SOURCE_LASER);
  assert_true(finite_all(&a));
  assert_true(a.wall_distance_m == b.wall_distance_m && a.offset_m == b.offset_m && a.heading_rad == b.heading_rad &&
              a.jamb_distance_m == b.jamb_distance_m && a.gap_bearing_rad == b.gap_bearing_rad &&
              a.width_m == b.width_m && a.wall_points == b.wall_points && a.jambs_seen == b.jambs_seen);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_doorway_from_pose_exact),
      cmocka_unit_test(test_doorway_laser_matches_truth_with_noise),
      cmocka_unit_test(test_doorway_without_odometry_finds_the_door),
      cmocka_unit_test(test_doorway_occluded_jamb_uses_the_other),
      cmocka_unit_test(test_doorway_fallback_to_odometry),
      cmocka_unit_test(test_doorway_no_gap_or_gate_rejects_laser),
      cmocka_unit_test(test_doorway_contract),
  };
  return cmocka_run_group_tests_name("features.doorway", tests, NULL, NULL);
}
