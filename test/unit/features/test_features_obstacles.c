// SPDX-License-Identifier: MIT
// Obstacle-task features against the exact geometry of a synthetic arena: goal from odometry,
// obstacles segmented from seeded noisy LMS200 scans, walls never reported as obstacles.
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

// Stated tolerances for a visible obstacle (1° or 0.5° beams, sigma 1 cm, dropouts <= 10 %):
// distance from the robot centre to the obstacle's nearest visible surface point, and its
// bearing. (The visible nearest point is within 0.03 m / 0.1 rad of the true nearest point when
// the obstacle is beside the robot, because the laser sits 0.15 m ahead of the centre.)
#define TOL_DIST_M 0.04
#define TOL_BEARING_RAD 0.05
// Beside the robot (|bearing| > 1.1 rad) the nearest visible point is where the laser's view of
// the obstacle is cut off; the returns near it are one-sided, so the bearing is looser there.
#define TOL_BEARING_SIDE_RAD 0.1
#define SIDE_BEARING_RAD 1.1
#define MIN_DETECT_RATE 0.99  // obstacles with >= 6 beams on them that are reported

// The arena of the obstacle task (tasks spec defaults): walls of a 7 m x 7 m room.
#define ARENA_MIN_X -5.0
#define ARENA_MAX_X 2.0
#define ARENA_MIN_Y -3.5
#define ARENA_MAX_Y 3.5

static double urange(synth_rng_t* r, double lo, double hi) {
  return lo + (hi - lo) * synth_rng_uniform(r);
}

static int all_finite(const features_obstacles_t* f) {
  int ok = isfinite(f->goal_bearing_rad) && isfinite(f->goal_distance_m) &&
           isfinite(f->nearest_any_m) && isfinite(f->nearest_any_bearing_rad);
  for (int k = 0; k < FEATURES_MAX_OBSTACLES; ++k) {
    const features_obstacle_t* o = &f->obstacle[k];
    ok = ok && isfinite(o->bearing_rad) && isfinite(o->distance_m) && isfinite(o->width_m) &&
         isfinite(o->centre_x_m) && isfinite(o->centre_y_m);
  }
  return ok;
}

// Beams of the scan that hit circle `index` first (exact ray casts, no noise), and the hit point
// nearest to the robot centre: the visible part of the obstacle nearest to the robot. (The laser
// sits ahead of the centre, so for an obstacle beside the robot the surface point nearest to the
// centre can be hidden from it; features can only report what the laser sees.)
static int beams_on_circle(const synth_world_t* w, const synth_lidar_config_t* lidar,
                           features_pose_t p, uint32_t index, double* near_d, double* near_b) {
  const double lx = p.x_m + cos(p.theta_rad) * lidar->mount_x_m;
  const double ly = p.y_m + sin(p.theta_rad) * lidar->mount_x_m;
  int n = 0;
  *near_d = INFINITY;
  *near_b = 0.0;
  for (int i = 0; i < lidar->n_beams; ++i) {
    synth_hit_t hit;
    const double a = p.theta_rad + lidar->angle_min_rad + i * lidar->angle_increment_rad;
    const double r = synth_world_raycast(w, lx, ly, a, &hit);
    if (hit.kind == SYNTH_HIT_CIRCLE && hit.index == index && r < lidar->max_range_m) {
      ++n;
      const double hx = lx + r * cos(a) - p.x_m, hy = ly + r * sin(a) - p.y_m;
      if (hypot(hx, hy) < *near_d) {
        *near_d = hypot(hx, hy);
        *near_b = features_angle_wrap(atan2(hy, hx) - p.theta_rad);
      }
    }
  }
  return n;
}

typedef struct sweep_stats {
  int n, eligible, detected, false_pos, nonfinite;
  double max_dist_err, max_bearing_err, max_side_bearing_err, max_goal_err;
  int bad;
} sweep_stats_t;

// Random robot poses in the arena, one obstacle (radius 0.15..0.35 m) placed 0.5..4 m away
// within +-80° of the heading; the goal somewhere in the arena.
static void sweep(uint64_t seed, int n_poses, double res_deg, double dropout, double codes,
                  sweep_stats_t* st) {
  memset(st, 0, sizeof *st);
  synth_rng_t rng;
  synth_rng_seed(&rng, seed);
  synth_lidar_config_t lidar;
  assert_int_equal(synth_lidar_config_lms200(&lidar, 180, res_deg), 0);
  lidar.dropout_prob = dropout;
  lidar.error_code_prob = codes;
  features_obstacles_config_t cfg;
  features_obstacles_config_default(&cfg);
  static features_scan_t scan;
  for (int k = 0; k < n_poses; ++k) {
    features_pose_t p = {urange(&rng, -4.0, 1.0), urange(&rng, -2.5, 2.5), urange(&rng, -PI, PI)};
    const double rad = urange(&rng, 0.15, 0.35);
    const double dist = urange(&rng, 0.5, 4.0);
    const double brg = urange(&rng, -1.4, 1.4);
    const double cx = p.x_m + (dist + rad) * cos(p.theta_rad + brg);
    const double cy = p.y_m + (dist + rad) * sin(p.theta_rad + brg);
    const double gx = urange(&rng, -4.5, 1.5), gy = urange(&rng, -3.0, 3.0);
    synth_world_t w;
    synth_world_init(&w);
    assert_int_equal(synth_world_add_box(&w, ARENA_MIN_X, ARENA_MIN_Y, ARENA_MAX_X, ARENA_MAX_Y), 0);
    // Keep the obstacle inside the room and clear of the walls by 0.6 m (a gap the robot fits).
    const int placed = cx - rad > ARENA_MIN_X + 0.6 && cx + rad < ARENA_MAX_X - 0.6 &&
                       cy - rad > ARENA_MIN_Y + 0.6 && cy + rad < ARENA_MAX_Y - 0.6;
    if (placed) {
      assert_int_equal(synth_world_add_circle(&w, cx, cy, rad), 0);
    }
    assert_true(scan_fill(&scan, &w, &lidar, &rng, p) > 0);
    features_obstacles_t f;
    assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, gx, gy, &f), FEATURES_OK);
    ++st->n;
    if (!all_finite(&f) || f.valid != 1U) {
      ++st->nonfinite;
      continue;
    }
    const double gd = hypot(gx - p.x_m, gy - p.y_m);
    const double gb = features_angle_wrap(atan2(gy - p.y_m, gx - p.x_m) - p.theta_rad);
    st->max_goal_err = fmax(st->max_goal_err, fmax(fabs(f.goal_distance_m - gd),
                                                   fabs(features_angle_wrap(f.goal_bearing_rad - gb))));
    double true_d = 0.0, true_b = 0.0;
    const int on = placed ? beams_on_circle(&w, &lidar, p, 0U, &true_d, &true_b) : 0;
    if (on >= 6) {
      ++st->eligible;
      if (f.obstacle[0].visible) {
        ++st->detected;
        const double ed = fabs(f.obstacle[0].distance_m - true_d);
        const double eb = fabs(features_angle_wrap(f.obstacle[0].bearing_rad - true_b));
        const double tol_b = fabs(true_b) > SIDE_BEARING_RAD ? TOL_BEARING_SIDE_RAD : TOL_BEARING_RAD;
        st->max_dist_err = fmax(st->max_dist_err, ed);
        if (fabs(true_b) > SIDE_BEARING_RAD) {
          st->max_side_bearing_err = fmax(st->max_side_bearing_err, eb);
        } else {
          st->max_bearing_err = fmax(st->max_bearing_err, eb);
        }
        if (ed > TOL_DIST_M || eb > tol_b) {
          ++st->bad;
          printf("  out of tolerance: pose (%.3f, %.3f, %.3f) obstacle (%.3f, %.3f, r %.2f) "
                 "dist %.3f/%.3f bearing %.3f/%.3f\n", p.x_m, p.y_m, p.theta_rad, cx, cy, rad,
                 f.obstacle[0].distance_m, true_d, f.obstacle[0].bearing_rad, true_b);
        }
      }
    }
    // Anything reported beyond the one obstacle is a wall mistaken for an obstacle.
    const int expected = on >= 1 ? 1 : 0;
    if (f.n_visible > expected) {
      ++st->false_pos;
      printf("  false obstacle: pose (%.3f, %.3f, %.3f) reported %u, slot0 %.3f m @ %.3f\n",
             p.x_m, p.y_m, p.theta_rad, f.n_visible, f.obstacle[0].distance_m,
             f.obstacle[0].bearing_rad);
    }
  }
}

static void report(const char* name, const sweep_stats_t* st) {
  printf("[ obstacles ] %-18s n=%d eligible=%d detected=%d false=%d | max err: distance %.4f m, "
         "bearing %.4f rad (beside the robot %.4f rad), goal %.2e\n",
         name, st->n, st->eligible, st->detected, st->false_pos, st->max_dist_err,
         st->max_bearing_err, st->max_side_bearing_err, st->max_goal_err);
}

static void check(const sweep_stats_t* st) {
  assert_int_equal(st->nonfinite, 0);
  assert_true((double)st->detected >= MIN_DETECT_RATE * (double)st->eligible);
  assert_int_equal(st->bad, 0);
  assert_true(st->max_dist_err <= TOL_DIST_M);
  assert_true(st->max_bearing_err <= TOL_BEARING_RAD);
  assert_true(st->max_side_bearing_err <= TOL_BEARING_SIDE_RAD);
  assert_true(st->max_goal_err <= 1e-9);
  assert_int_equal(st->false_pos, 0);
}

// Clean 1° scans: every well-seen obstacle found, within tolerance; walls never reported.
static void test_obstacles_random_poses_within_tolerance(void** state) {
  (void)state;
  sweep_stats_t st;
  sweep(11, 500, 1.0, 0.0, 0.0, &st);
  report("1deg", &st);
  check(&st);
}

// 0.5° beams with 10 % dropouts and 2 % error codes.
static void test_obstacles_dropouts_within_tolerance(void** state) {
  (void)state;
  sweep_stats_t st;
  sweep(12, 500, 0.5, 0.10, 0.02, &st);
  report("0.5deg dropouts", &st);
  check(&st);
}

static features_pose_t pose(double x, double y, double th) {
  features_pose_t p = {x, y, th};
  return p;
}

static void scan_of(features_scan_t* scan, const synth_world_t* w, features_pose_t p) {
  synth_lidar_config_t lidar;
  assert_int_equal(synth_lidar_config_lms200(&lidar, 180, 1.0), 0);
  lidar.noise_sigma_m = 0.0;
  assert_true(scan_fill(scan, w, &lidar, NULL, p) > 0);
}

// Two obstacles are reported nearest first; a person in front of a wall is still found.
static void test_obstacles_two_obstacles_nearest_first(void** state) {
  (void)state;
  synth_world_t w;
  synth_world_init(&w);
  assert_int_equal(synth_world_add_box(&w, -5.0, -3.5, 2.0, 3.5), 0);
  assert_int_equal(synth_world_add_circle(&w, 1.0, 0.8, 0.2), 0);    // far, left (0.5 m off the wall)
  assert_int_equal(synth_world_add_circle(&w, -1.0, -0.6, 0.25), 0); // near, right
  static features_scan_t scan;
  const features_pose_t p = pose(-2.5, 0.0, 0.0);
  scan_of(&scan, &w, p);
  features_obstacles_config_t cfg;
  features_obstacles_config_default(&cfg);
  features_obstacles_t f;
  assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, 0.0, 0.0, &f), FEATURES_OK);
  assert_int_equal(f.n_visible, 2);
  assert_true(f.obstacle[0].visible && f.obstacle[1].visible);
  assert_true(f.obstacle[0].distance_m < f.obstacle[1].distance_m);
  assert_true(fabs(f.obstacle[0].distance_m - (hypot(1.5, 0.6) - 0.25)) < TOL_DIST_M);
  assert_true(f.obstacle[0].bearing_rad < 0.0);  // right of the heading
  assert_true(fabs(f.obstacle[1].distance_m - (hypot(3.5, 0.8) - 0.2)) < TOL_DIST_M);
  assert_true(f.obstacle[1].bearing_rad > 0.0);
  double s[6];
  assert_int_equal(features_obstacles_state(&f, 2U, s, 6U), 6U);
  assert_true(s[2] == f.obstacle[0].bearing_rad && s[5] == f.obstacle[1].distance_m);
}

// Nothing but walls in view: both slots empty with the documented convention (pi, 8 m).
static void test_obstacles_none_visible_uses_convention(void** state) {
  (void)state;
  synth_world_t w;
  synth_world_init(&w);
  assert_int_equal(synth_world_add_box(&w, -5.0, -3.5, 2.0, 3.5), 0);
  static features_scan_t scan;
  const features_pose_t p = pose(-1.0, 1.0, 0.7);
  scan_of(&scan, &w, p);
  features_obstacles_config_t cfg;
  features_obstacles_config_default(&cfg);
  features_obstacles_t f;
  assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, 0.0, 0.0, &f), FEATURES_OK);
  assert_int_equal(f.n_visible, 0);
  assert_true(f.n_wall_clusters >= 1U);
  for (int k = 0; k < FEATURES_MAX_OBSTACLES; ++k) {
    assert_int_equal(f.obstacle[k].visible, 0);
    assert_true(f.obstacle[k].bearing_rad == PI);
    assert_true(f.obstacle[k].distance_m == cfg.no_obstacle_distance_m);
  }
  assert_int_equal(f.scan_valid, 1);
  assert_true(f.nearest_any_m < 3.0);  // the nearest wall
  double s[4];
  assert_int_equal(features_obstacles_state(&f, 1U, s, 4U), 4U);
  assert_true(s[2] == PI && s[3] == cfg.no_obstacle_distance_m);
  assert_int_equal(features_obstacles_state(&f, 1U, s, 3U), 0U);  // too small: nothing written
  assert_int_equal(features_obstacles_state(&f, 0U, s, 4U), 0U);
  assert_int_equal(features_obstacles_state(&f, 3U, s, 8U), 0U);
}

// Goal bearing and distance from odometry; no pose = invalid goal part, finite values.
static void test_obstacles_goal_from_odometry(void** state) {
  (void)state;
  features_obstacles_config_t cfg;
  features_obstacles_config_default(&cfg);
  static features_scan_t scan;
  memset(&scan, 0, sizeof scan);
  assert_int_equal(features_scan_set_lms200_geometry(&scan, 180, 0.5), FEATURES_OK);
  for (int i = 0; i < scan.n_beams; ++i) scan.no_return[i] = 1U;
  features_obstacles_t f;
  const features_pose_t p = pose(-3.0, 0.0, 0.0);
  assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, 0.0, 3.0, &f), FEATURES_OK);
  assert_int_equal(f.valid, 1);
  assert_int_equal(f.scan_valid, 0);
  assert_true(fabs(f.goal_distance_m - hypot(3.0, 3.0)) < 1e-12);
  assert_true(fabs(f.goal_bearing_rad - PI / 4.0) < 1e-12);
  const features_pose_t q = pose(0.0, 0.0, 3.0);  // goal behind-left: bearing wraps to (-pi, pi]
  assert_int_equal(features_obstacles_compute(&cfg, &scan, &q, -1.0, 0.0, &f), FEATURES_OK);
  assert_true(fabs(f.goal_bearing_rad - (PI - 3.0)) < 1e-12);
  assert_int_equal(features_obstacles_compute(&cfg, &scan, NULL, 0.0, 0.0, &f), FEATURES_OK);
  assert_int_equal(f.valid, 0);
  assert_true(all_finite(&f));
  assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, NAN, 0.0, &f), FEATURES_OK);
  assert_int_equal(f.valid, 0);
  assert_true(all_finite(&f));
}

// Bad calls are refused with a finite empty output; garbage ranges are ignored.
static void test_obstacles_invalid_input_rejected(void** state) {
  (void)state;
  features_obstacles_config_t cfg;
  features_obstacles_config_default(&cfg);
  static features_scan_t scan;
  synth_world_t w;
  synth_world_init(&w);
  assert_int_equal(synth_world_add_box(&w, -5.0, -3.5, 2.0, 3.5), 0);
  assert_int_equal(synth_world_add_circle(&w, -1.0, 0.0, 0.25), 0);
  const features_pose_t p = pose(-3.0, 0.0, 0.0);
  scan_of(&scan, &w, p);
  features_obstacles_t f;
  assert_int_equal(features_obstacles_compute(NULL, &scan, &p, 0, 0, &f), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_obstacles_compute(&cfg, NULL, &p, 0, 0, &f), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, 0, 0, NULL), FEATURES_ERR_INVALID_ARG);
  features_obstacles_config_t bad = cfg;
  bad.cluster_gap_m = -1.0;
  assert_int_equal(features_obstacles_compute(&bad, &scan, &p, 0, 0, &f), FEATURES_ERR_INVALID_ARG);
  assert_true(all_finite(&f));
  scan.n_beams = FEATURES_MAX_BEAMS + 1;
  assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, 0, 0, &f), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(f.valid, 0);
  scan_of(&scan, &w, p);
  const float junk[4] = {NAN, INFINITY, -2.0f, 1e6f};
  for (int i = 0; i < scan.n_beams; i += 7) scan.ranges_m[i] = junk[(i / 7) % 4];
  assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, 0, 0, &f), FEATURES_OK);
  assert_true(all_finite(&f));
  assert_int_equal(f.n_visible, 1);
  assert_true(fabs(f.obstacle[0].distance_m - 1.75) < TOL_DIST_M);
}

// Same inputs give bit-identical outputs; no allocation over a thousand calls.
static void test_obstacles_deterministic_and_allocation_free(void** state) {
  (void)state;
  features_obstacles_config_t cfg;
  features_obstacles_config_default(&cfg);
  synth_world_t w;
  synth_world_init(&w);
  assert_int_equal(synth_world_add_box(&w, -5.0, -3.5, 2.0, 3.5), 0);
  assert_int_equal(synth_world_add_circle(&w, -1.5, 0.1, 0.25), 0);
  synth_lidar_config_t lidar;
  assert_int_equal(synth_lidar_config_lms200(&lidar, 180, 0.5), 0);
  lidar.dropout_prob = 0.05;
  synth_rng_t rng;
  synth_rng_seed(&rng, 5);
  static features_scan_t scan;
  const features_pose_t p = pose(-3.0, -0.2, 0.1);
  assert_true(scan_fill(&scan, &w, &lidar, &rng, p) > 0);
  features_obstacles_t a, b;
  memset(&a, 0x11, sizeof a);
  memset(&b, 0x22, sizeof b);
  assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, 0.0, 0.0, &a), FEATURES_OK);
  alloc_counter_begin();
  for (int i = 0; i < 1000; ++i) {
    assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, 0.0, 0.0, &b), FEATURES_OK);
  }
  assert_int_equal(alloc_counter_end(), 0);
  assert_memory_equal(&a.goal_bearing_rad, &b.goal_bearing_rad, sizeof(double));
  assert_memory_equal(&a.obstacle[0].distance_m, &b.obstacle[0].distance_m, sizeof(double));
  assert_memory_equal(&a.obstacle[0].bearing_rad, &b.obstacle[0].bearing_rad, sizeof(double));
  assert_int_equal(a.n_visible, b.n_visible);
}

// The exact state of a known pose (the kinematic model's observation) agrees with what the
// features measure in a noise-free scan of the same scene: the goal part bit for bit, a visible
// obstacle within the features' stated tolerances; invalid calls are refused.
static void test_obstacles_from_pose_agrees_with_scan(void** state) {
  (void)state;
  features_obstacles_config_t cfg;
  features_obstacles_config_default(&cfg);
  static features_scan_t scan;
  synth_rng_t rng;
  synth_rng_seed(&rng, 77);
  int compared = 0;
  int agree_visible = 0;
  for (int k = 0; k < 300; ++k) {
    const features_pose_t p = pose(urange(&rng, -4.0, 1.0), urange(&rng, -2.5, 2.5), urange(&rng, -PI, PI));
    const double rad = urange(&rng, 0.15, 0.35);
    const double dist = urange(&rng, 0.5, 3.0);
    const double brg = urange(&rng, -1.4, 1.4);
    const features_disc_t d = {p.x_m + (dist + rad) * cos(p.theta_rad + brg),
                               p.y_m + (dist + rad) * sin(p.theta_rad + brg), rad};
    if (d.x_m - rad < ARENA_MIN_X + 0.6 || d.x_m + rad > ARENA_MAX_X - 0.6 || d.y_m - rad < ARENA_MIN_Y + 0.6 ||
        d.y_m + rad > ARENA_MAX_Y - 0.6) {
      continue;
    }
    synth_world_t w;
    synth_world_init(&w);
    assert_int_equal(synth_world_add_box(&w, ARENA_MIN_X, ARENA_MIN_Y, ARENA_MAX_X, ARENA_MAX_Y), 0);
    assert_int_equal(synth_world_add_circle(&w, d.x_m, d.y_m, d.radius_m), 0);
    scan_of(&scan, &w, p);
    features_obstacles_t measured, exact;
    assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, 0.5, -0.5, &measured), FEATURES_OK);
    assert_int_equal(features_obstacles_from_pose(&cfg, p, 0.5, -0.5, &d, 1U, PI, &exact), FEATURES_OK);
    assert_true(all_finite(&exact));
    assert_memory_equal(&measured.goal_bearing_rad, &exact.goal_bearing_rad, sizeof(double));
    assert_memory_equal(&measured.goal_distance_m, &exact.goal_distance_m, sizeof(double));
    assert_int_equal(exact.valid, 1);
    ++compared;
    if (measured.obstacle[0].visible != exact.obstacle[0].visible) {
      continue;
    }
    ++agree_visible;
    if (exact.obstacle[0].visible) {
      const double tol_b = fabs(exact.obstacle[0].bearing_rad) > SIDE_BEARING_RAD ? TOL_BEARING_SIDE_RAD : TOL_BEARING_RAD;
      assert_true(fabs(measured.obstacle[0].distance_m - exact.obstacle[0].distance_m) < TOL_DIST_M);
      assert_true(fabs(features_angle_wrap(measured.obstacle[0].bearing_rad - exact.obstacle[0].bearing_rad)) < tol_b);
      assert_true(fabs(exact.obstacle[0].width_m - 2.0 * rad) < 1e-12);
    } else {
      assert_true(exact.obstacle[0].bearing_rad == PI && exact.obstacle[0].distance_m == cfg.no_obstacle_distance_m);
    }
  }
  print_message("from_pose vs scan: %d scenes, visibility agrees in %d\n", compared, agree_visible);
  assert_true(compared > 100);
  assert_true(agree_visible >= compared * 95 / 100);
  // Behind the robot: not visible. Two discs: nearest first. Bad calls: refused, empty output.
  const features_disc_t two[2] = {{3.0, 0.0, 0.2}, {1.5, 0.2, 0.3}};
  features_obstacles_t f;
  assert_int_equal(features_obstacles_from_pose(&cfg, pose(0.0, 0.0, PI), 0, 0, two, 2U, PI, &f), FEATURES_OK);
  assert_int_equal(f.n_visible, 0);
  assert_int_equal(features_obstacles_from_pose(&cfg, pose(0.0, 0.0, 0.0), 0, 0, two, 2U, PI, &f), FEATURES_OK);
  assert_int_equal(f.n_visible, 2);
  assert_true(fabs(f.obstacle[0].distance_m - (hypot(1.5, 0.2) - 0.3)) < 1e-12);
  assert_true(fabs(f.obstacle[1].distance_m - 2.8) < 1e-12);
  assert_true(fabs(f.obstacle[0].bearing_rad - atan2(0.2, 1.5)) < 1e-12);
  const features_disc_t bad = {1.0, 0.0, -0.1};
  assert_int_equal(features_obstacles_from_pose(&cfg, pose(0, 0, 0), 0, 0, &bad, 1U, PI, &f), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(f.valid, 0);
  assert_int_equal(features_obstacles_from_pose(&cfg, pose((double)NAN, 0, 0), 0, 0, two, 2U, PI, &f), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_obstacles_from_pose(&cfg, pose(0, 0, 0), 0, 0, NULL, 1U, PI, &f), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_obstacles_from_pose(&cfg, pose(0, 0, 0), 0, 0, two, 2U, 0.0, &f), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_obstacles_from_pose(NULL, pose(0, 0, 0), 0, 0, two, 2U, PI, &f), FEATURES_ERR_INVALID_ARG);
}

// ---- The memory of the nearest obstacle seen (features_obstacles_remember) -------------------

// The test's own record of the last sighting of the single obstacle of a scene: the disc it makes
// of it in the world and its age, advanced by the documented rule.
typedef struct sighting {
  int held;
  double x_m, y_m, r_m;
  uint32_t age, n_points;
} sighting_t;

static int slot_equal(const features_obstacle_t* a, const features_obstacle_t* b) {
  return a->bearing_rad == b->bearing_rad && a->distance_m == b->distance_m && a->width_m == b->width_m &&
         a->visible == b->visible && a->n_points == b->n_points;
}

static void assert_known_empty(const features_obstacles_config_t* cfg, const features_obstacles_t* f) {
  assert_int_equal(f->known.visible, 0);
  assert_true(f->known.bearing_rad == PI);
  assert_true(f->known.distance_m == cfg->no_obstacle_distance_m);
  assert_int_equal(f->known_age, cfg->memory_max_age);
}

// Checks f->known after features_obstacles_remember at pose p against the record (one obstacle
// in the scene, so a seen one always replaces the remembered one), then advances the record.
// Returns 1 when the known obstacle is a remembered one, 0 when seen or none.
static int check_known(const features_obstacles_config_t* cfg, sighting_t* s, features_pose_t p,
                       const features_obstacles_t* f) {
  double d = 0.0;
  if (s->held) {
    ++s->age;
    d = fmax(hypot(s->x_m - p.x_m, s->y_m - p.y_m) - s->r_m, 0.0);
    if (s->age > cfg->memory_max_age || d >= cfg->no_obstacle_distance_m) s->held = 0;
  }
  if (f->obstacle[0].visible) {
    assert_int_equal(f->known_age, 0);
    assert_true(slot_equal(&f->known, &f->obstacle[0]));
    const double ux = cos(p.theta_rad + f->obstacle[0].bearing_rad), uy = sin(p.theta_rad + f->obstacle[0].bearing_rad);
    const double px = p.x_m + f->obstacle[0].distance_m * ux, py = p.y_m + f->obstacle[0].distance_m * uy;
    const int same = s->held && hypot(px - s->x_m, py - s->y_m) <= s->r_m + cfg->cluster_gap_m;
    if (!same || f->obstacle[0].n_points >= s->n_points) {
      const double r = 0.5 * f->obstacle[0].width_m;
      s->x_m = px + r * ux;
      s->y_m = py + r * uy;
      s->r_m = r;
      s->n_points = f->obstacle[0].n_points;
    }
    s->held = 1;
    s->age = 0U;
    return 0;
  }
  if (!s->held) {
    assert_known_empty(cfg, f);
    return 0;
  }
  assert_int_equal(f->known.visible, 0);
  assert_int_equal(f->known_age, s->age);
  assert_true(fabs(f->known.distance_m - d) < 1e-12);
  const double b = atan2(s->y_m - p.y_m, s->x_m - p.x_m) - p.theta_rad;
  assert_true(fabs(features_angle_wrap(f->known.bearing_rad - b)) < 1e-12);
  assert_true(f->known.width_m == 2.0 * s->r_m);
  return 1;
}

// The centre of the known obstacle in the world, from the pose and its bearing, distance and
// width (its centre is half its width beyond its nearest point, along the bearing).
static void known_centre(features_pose_t p, const features_obstacles_t* f, double* x, double* y) {
  const double d = f->known.distance_m + 0.5 * f->known.width_m;
  *x = p.x_m + d * cos(p.theta_rad + f->known.bearing_rad);
  *y = p.y_m + d * sin(p.theta_rad + f->known.bearing_rad);
}

static void arena_with(synth_world_t* w, double cx, double cy, double r) {
  synth_world_init(w);
  assert_int_equal(synth_world_add_box(w, ARENA_MIN_X, ARENA_MIN_Y, ARENA_MAX_X, ARENA_MAX_Y), 0);
  assert_int_equal(synth_world_add_circle(w, cx, cy, r), 0);
}

// Passing an obstacle on the left in synthetic scans: while it is seen the known obstacle is the
// seen one; when it has left the 180° view it is remembered where it was last seen, carried by the
// pose: beside and then behind the robot (bearing beyond 90°), its centre within 0.08 m of the
// true one and its distance within 0.05 m of the true surface distance (from the best view of
// it: a chord of a near disc is a little narrower than its diameter), its bearing turning with the robot's rotation and its distance
// unchanged by it; the age counts the observations; after memory_max_age the state says "no
// obstacle". Without memory (limit 0) the known obstacle is only ever the seen one.
static void test_obstacles_memory_keeps_passed_obstacle(void** state) {
  (void)state;
  const double cx = -1.5, cy = 0.55, rad = 0.25;  // the robot's skirt passes 0.04 m clear
  synth_world_t w;
  arena_with(&w, cx, cy, rad);
  static features_scan_t scan;
  for (int with_memory = 1; with_memory >= 0; --with_memory) {
    features_obstacles_config_t cfg;
    features_obstacles_config_default(&cfg);
    assert_int_equal(cfg.memory_max_age, 30);
    if (!with_memory) cfg.memory_max_age = 0U;
    features_obstacle_memory_t mem;
    memset(&mem, 0x5a, sizeof mem);
    features_obstacle_memory_reset(&mem);
    sighting_t rec = {0, 0.0, 0.0, 0.0, 0U, 0U};
    features_pose_t p = pose(-3.5, 0.0, 0.0);
    int seen = 0, unseen_steps = 0, remembered = 0, behind = 0, turned = 0, expired = 0;
    double prev_b = 0.0, prev_d = 0.0, worst_centre = 0.0, worst_distance = 0.0;
    int prev_remembered = 0;
    for (int k = 0; k < 200; ++k) {
      // Straight on until the obstacle has been out of view for 12 steps, then turn right (away
      // from it) in place by 0.05 rad a step for 10 steps, then straight on at 0.03 m a step.
      const int turning = unseen_steps >= 12 && unseen_steps < 22;
      if (k > 0) {
        if (turning) {
          p.theta_rad -= 0.05;
        } else {
          p.x_m += 0.03 * cos(p.theta_rad);
          p.y_m += 0.03 * sin(p.theta_rad);
        }
      }
      scan_of(&scan, &w, p);
      features_obstacles_t f;
      assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, 0.0, 0.0, &f), FEATURES_OK);
      assert_int_equal(features_obstacles_remember(&cfg, &mem, p, &f), FEATURES_OK);
      assert_true(all_finite(&f) && isfinite(f.known.bearing_rad) && isfinite(f.known.distance_m));
      if (f.obstacle[0].visible) {
        ++seen;
        assert_int_equal(unseen_steps, 0);  // it never comes back into view on this path
      } else if (seen > 0) {
        ++unseen_steps;
      }
      const int is_remembered = check_known(&cfg, &rec, p, &f);
      if (is_remembered) {
        ++remembered;
        assert_true(with_memory);
        // The remembered disc is the obstacle, on the robot's left, about as near as it is.
        double kx, ky;
        known_centre(p, &f, &kx, &ky);
        const double surface = hypot(p.x_m - cx, p.y_m - cy) - rad;
        worst_centre = fmax(worst_centre, hypot(kx - cx, ky - cy));
        worst_distance = fmax(worst_distance, fabs(f.known.distance_m - surface));
        assert_true(hypot(kx - cx, ky - cy) < 0.08);
        assert_true(fabs(f.known.distance_m - surface) < 0.05);
        assert_true(f.known.bearing_rad > 0.0);
        if (unseen_steps == 1) {
          assert_true(surface < 0.45);  // it just left the view beside the robot
          assert_true(f.known.bearing_rad > 1.0);
        }
        if (f.known.bearing_rad > 0.5 * PI) ++behind;
        if (turning && prev_remembered) {
          // A rotation in place turns the bearing by the rotation and keeps the distance.
          ++turned;
          assert_true(fabs(features_angle_wrap(f.known.bearing_rad - prev_b - 0.05)) < 1e-9);
          assert_true(fabs(f.known.distance_m - prev_d) < 1e-9);
        }
        prev_b = f.known.bearing_rad;
        prev_d = f.known.distance_m;
      } else if (!f.obstacle[0].visible && seen > 0) {
        if (with_memory) assert_int_equal(unseen_steps, 31);  // forgotten when older than 30
        ++expired;
        break;
      }
      prev_remembered = is_remembered;
    }
    print_message("memory %u: seen %d, remembered %d (behind %d, turning %d), expired %d; remembered within %.3f m "
                  "of the centre, %.3f m of the surface distance\n", cfg.memory_max_age, seen, remembered, behind, turned,
                  expired, worst_centre, worst_distance);
    assert_true(seen > 20);
    assert_int_equal(expired, 1);
    if (with_memory) {
      assert_int_equal(remembered, 30);
      assert_true(behind >= 10);
      assert_int_equal(turned, 10);
    } else {
      assert_int_equal(remembered, 0);
    }
  }
}

// A remembered obstacle is forgotten when it is as far as no_obstacle_distance_m (beyond the
// state's sensing), whatever its age.
static void test_obstacles_memory_expires_beyond_range(void** state) {
  (void)state;
  synth_world_t w;
  arena_with(&w, -1.5, 0.55, 0.25);
  static features_scan_t scan;
  features_obstacles_config_t cfg;
  features_obstacles_config_default(&cfg);
  cfg.memory_max_age = 1000U;
  cfg.no_obstacle_distance_m = 1.0;
  features_obstacle_memory_t mem;
  features_obstacle_memory_reset(&mem);
  sighting_t rec = {0, 0.0, 0.0, 0.0, 0U, 0U};
  int remembered = 0, expired = 0;
  for (int k = 0; k < 150 && !expired; ++k) {
    const features_pose_t p = pose(-3.5 + 0.03 * k, 0.0, 0.0);
    scan_of(&scan, &w, p);
    features_obstacles_t f;
    assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, 0.0, 0.0, &f), FEATURES_OK);
    assert_int_equal(features_obstacles_remember(&cfg, &mem, p, &f), FEATURES_OK);
    const int was = remembered;
    if (check_known(&cfg, &rec, p, &f)) {
      ++remembered;
      assert_true(f.known.distance_m < 1.0);
    } else if (was > 0) {
      assert_known_empty(&cfg, &f);
      assert_true(mem.age < 1000U);
      expired = 1;
    }
  }
  print_message("remembered for %d steps within 1 m\n", remembered);
  assert_true(remembered > 10);
  assert_int_equal(expired, 1);
}

// A newly seen obstacle replaces the remembered one when it is not farther than it by more than
// memory_margin_m: a person steps in ahead of a robot that has just passed an obstacle. One seen
// farther ahead does not: the obstacle beside the robot stays the known one until the seen one is
// as near (within the margin), then the seen one takes over for good.
static void test_obstacles_memory_replaced_by_new_obstacle(void** state) {
  (void)state;
  static features_scan_t scan;
  features_obstacles_config_t cfg;
  features_obstacles_config_default(&cfg);
  // 1. Someone steps in: nearer than the remembered obstacle, or about as near.
  {
    synth_world_t w;
    arena_with(&w, -1.5, 0.55, 0.25);
    features_obstacle_memory_t mem;
    features_obstacle_memory_reset(&mem);
    int unseen = 0, replaced = 0;
    double remembered_d = 0.0;
    for (int k = 0; k < 120 && !replaced; ++k) {
      const features_pose_t p = pose(-3.5 + 0.03 * k, 0.0, 0.0);
      if (unseen == 5) {
        assert_int_equal(synth_world_add_circle(&w, p.x_m + 0.55, p.y_m - 0.05, 0.2), 0);  // 0.35 m ahead
      }
      scan_of(&scan, &w, p);
      features_obstacles_t f;
      assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, 0.0, 0.0, &f), FEATURES_OK);
      assert_int_equal(features_obstacles_remember(&cfg, &mem, p, &f), FEATURES_OK);
      if (unseen < 5) {
        if (!f.obstacle[0].visible && k > 0) {
          ++unseen;
          assert_int_equal(f.known_age, unseen);
          remembered_d = f.known.distance_m;
        }
        continue;
      }
      // The newcomer, seen now, is the known obstacle.
      assert_true(f.obstacle[0].visible);
      assert_true(f.obstacle[0].distance_m <= remembered_d + 0.03 + cfg.memory_margin_m);
      assert_int_equal(f.known_age, 0);
      assert_true(slot_equal(&f.known, &f.obstacle[0]));
      assert_true(fabs(f.known.bearing_rad) < 0.3);
      replaced = 1;
    }
    assert_int_equal(replaced, 1);
  }
  // 2. Another obstacle in view farther ahead on the right.
  {
    synth_world_t w;
    arena_with(&w, -1.5, 0.55, 0.25);
    assert_int_equal(synth_world_add_circle(&w, 0.0, -1.0, 0.25), 0);
    cfg.memory_max_age = 60U;  // the other one comes as near only after 3 s
    features_obstacle_memory_t mem;
    features_obstacle_memory_reset(&mem);
    int phase = 0;  // 0: the first one seen, 1: remembered while the other one is seen, 2: the other one
    int kept = 0;
    sighting_t rec = {0, 0.0, 0.0, 0.0, 0U, 0U};  // of the first obstacle
    for (int k = 0; k < 115; ++k) {
      const features_pose_t p = pose(-3.5 + 0.03 * k, 0.0, 0.0);
      scan_of(&scan, &w, p);
      features_obstacles_t f;
      assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, 0.0, 0.0, &f), FEATURES_OK);
      assert_int_equal(features_obstacles_remember(&cfg, &mem, p, &f), FEATURES_OK);
      assert_true(f.obstacle[0].visible);  // one of the two is always in view
      if (phase == 0) {
        if (f.obstacle[0].bearing_rad > 0.0) {  // the first one, on the left
          (void)check_known(&cfg, &rec, p, &f);
          continue;
        }
        phase = 1;  // the first one has left the view: only the other one is seen
      }
      const double d_first = hypot(rec.x_m - p.x_m, rec.y_m - p.y_m) - rec.r_m;
      if (phase == 1 && f.obstacle[0].distance_m > d_first + cfg.memory_margin_m) {
        // The one beside the robot stays the known one, remembered.
        assert_int_equal(f.known.visible, 0);
        assert_true(f.known_age > 0U);
        assert_true(fabs(f.known.distance_m - d_first) < 1e-12);
        assert_true(f.known.bearing_rad > 0.0);
        ++kept;
        continue;
      }
      phase = 2;
      assert_int_equal(f.known_age, 0);
      assert_true(slot_equal(&f.known, &f.obstacle[0]));
      assert_true(f.known.bearing_rad < 0.0);
    }
    print_message("remembered beside the robot while another was seen farther: %d steps\n", kept);
    assert_true(kept >= 3 && kept <= 60);
    assert_int_equal(phase, 2);
  }
}

// The exact features of the kinematic model get the same memory from the same sequence of poses:
// the same rule (checked against the record for both), and the same obstacle remembered: exactly
// the disc from the exact features, within 0.08 m (centre) and 0.05 m (distance) of it from the
// scans (the ideal laser of from_pose loses sight of it a little earlier than the scan).
static void test_obstacles_memory_same_from_pose_and_scan(void** state) {
  (void)state;
  const double cx = -1.5, cy = 0.55, rad = 0.25;
  synth_world_t w;
  arena_with(&w, cx, cy, rad);
  const features_disc_t disc = {cx, cy, rad};
  static features_scan_t scan;
  features_obstacles_config_t cfg;
  features_obstacles_config_default(&cfg);
  features_obstacle_memory_t m_scan, m_pose;
  features_obstacle_memory_reset(&m_scan);
  features_obstacle_memory_reset(&m_pose);
  sighting_t r_scan = {0, 0.0, 0.0, 0.0, 0U, 0U}, r_pose = {0, 0.0, 0.0, 0.0, 0U, 0U};
  int both = 0;
  alloc_counter_begin();
  for (int k = 0; k < 110; ++k) {
    const features_pose_t p = pose(-3.5 + 0.03 * k, 0.02 * sin(0.1 * k), 0.05 * sin(0.07 * k));
    scan_of(&scan, &w, p);
    features_obstacles_t fs, fp;
    assert_int_equal(features_obstacles_compute(&cfg, &scan, &p, 0.0, 0.0, &fs), FEATURES_OK);
    assert_int_equal(features_obstacles_from_pose(&cfg, p, 0.0, 0.0, &disc, 1U, PI, &fp), FEATURES_OK);
    assert_int_equal(features_obstacles_remember(&cfg, &m_scan, p, &fs), FEATURES_OK);
    assert_int_equal(features_obstacles_remember(&cfg, &m_pose, p, &fp), FEATURES_OK);
    const int rs = check_known(&cfg, &r_scan, p, &fs);
    const int rp = check_known(&cfg, &r_pose, p, &fp);
    if (rs && rp) {
      ++both;
      double xs, ys, xp, yp;
      known_centre(p, &fs, &xs, &ys);
      known_centre(p, &fp, &xp, &yp);
      const double surface = hypot(p.x_m - cx, p.y_m - cy) - rad;
      assert_true(hypot(xp - cx, yp - cy) < 1e-9 && fabs(fp.known.width_m - 2.0 * rad) < 1e-12);
      assert_true(fabs(fp.known.distance_m - surface) < 1e-9);
      assert_true(hypot(xs - cx, ys - cy) < 0.08 && fabs(fs.known.distance_m - surface) < 0.05);
    }
  }
  assert_int_equal(alloc_counter_end(), 0);
  print_message("both remembered for %d steps\n", both);
  assert_true(both >= 15);
}

// The rule on given features; the state vector with the memory; reset; refused calls.
static void test_obstacles_memory_rule_state_and_invalid(void** state) {
  (void)state;
  features_obstacles_config_t cfg;
  features_obstacles_config_default(&cfg);
  cfg.memory_max_age = 3U;
  features_obstacles_t f;
  const features_pose_t origin = pose(0.0, 0.0, 0.0);
  // Seen at 1 m straight ahead of a robot at the origin facing +x.
  const features_disc_t ahead = {1.3, 0.0, 0.3};
  assert_int_equal(features_obstacles_from_pose(&cfg, origin, 5.0, 0.0, &ahead, 1U, PI, &f), FEATURES_OK);
  assert_int_equal(f.known_age, 0);  // without memory: the seen one
  features_obstacle_memory_t mem;
  features_obstacle_memory_reset(&mem);
  assert_int_equal(features_obstacles_remember(&cfg, &mem, origin, &f), FEATURES_OK);
  assert_true(mem.held == 1U && fabs(mem.x_m - 1.3) < 1e-12 && fabs(mem.y_m) < 1e-12 && mem.radius_m == 0.3);
  assert_int_equal(mem.age, 0);
  double s[FEATURES_OBSTACLES_MEMORY_STATE_DIM];
  assert_int_equal(features_obstacles_memory_state(&f, 0.1, s, 5U), 5U);
  assert_true(s[0] == 0.0 && s[1] == 5.0 && s[2] == f.obstacle[0].bearing_rad && s[3] == 1.0 && s[4] == 0.0);
  // Turned around (nothing in view): remembered 1 m behind (the disc's surface), age 1 = 0.1 s.
  const features_pose_t back = pose(0.0, 0.0, PI);
  assert_int_equal(features_obstacles_from_pose(&cfg, back, 5.0, 0.0, NULL, 0U, PI, &f), FEATURES_OK);
  assert_known_empty(&cfg, &f);  // without memory: none
  assert_int_equal(features_obstacles_remember(&cfg, &mem, back, &f), FEATURES_OK);
  assert_true(fabs(fabs(f.known.bearing_rad) - PI) < 1e-12 && fabs(f.known.distance_m - 1.0) < 1e-12);
  assert_int_equal(features_obstacles_memory_state(&f, 0.1, s, 5U), 5U);
  assert_true(s[3] == f.known.distance_m && s[4] == 0.1);
  // Farther than the remembered one by more than the margin: not taken; within it: taken.
  const features_disc_t far_one = {-1.5, 0.0, 0.3};  // 1.2 m ahead of `back`
  assert_int_equal(features_obstacles_from_pose(&cfg, back, 5.0, 0.0, &far_one, 1U, PI, &f), FEATURES_OK);
  assert_int_equal(features_obstacles_remember(&cfg, &mem, back, &f), FEATURES_OK);
  assert_true(f.known_age == 2U && f.known.visible == 0U && fabs(f.known.distance_m - 1.0) < 1e-12);
  const features_disc_t near_one = {-1.35, 0.0, 0.3};  // 1.05 m: within 0.1 m of 1 m
  assert_int_equal(features_obstacles_from_pose(&cfg, back, 5.0, 0.0, &near_one, 1U, PI, &f), FEATURES_OK);
  assert_int_equal(features_obstacles_remember(&cfg, &mem, back, &f), FEATURES_OK);
  assert_true(f.known_age == 0U && f.known.visible == 1U && fabs(f.known.distance_m - 1.05) < 1e-12);
  assert_true(fabs(mem.x_m + 1.35) < 1e-12 && mem.radius_m == 0.3);
  // Measured views (n_points > 0): the same obstacle seen with fewer returns than before keeps
  // the disc of the better view; with as many or more it takes the new one; one seen elsewhere
  // gets its own.
  features_obstacles_t g = f;
  g.obstacle[0].width_m = 0.5;
  g.obstacle[0].distance_m = 1.0;
  g.obstacle[0].bearing_rad = 0.0;
  g.obstacle[0].n_points = 40U;
  assert_int_equal(features_obstacles_remember(&cfg, &mem, back, &g), FEATURES_OK);
  assert_true(mem.radius_m == 0.25 && fabs(mem.x_m + 1.25) < 1e-12 && mem.n_points == 40U);
  g.obstacle[0].width_m = 0.2;
  g.obstacle[0].bearing_rad = 0.1;  // its nearest return on the remembered disc's edge
  g.obstacle[0].n_points = 12U;
  assert_int_equal(features_obstacles_remember(&cfg, &mem, back, &g), FEATURES_OK);
  assert_true(mem.radius_m == 0.25 && fabs(mem.x_m + 1.25) < 1e-12 && mem.n_points == 40U && mem.age == 0U);
  assert_true(f.known_age == 0U);
  g.obstacle[0].n_points = 40U;
  assert_int_equal(features_obstacles_remember(&cfg, &mem, back, &g), FEATURES_OK);
  assert_true(mem.radius_m == 0.1 && fabs(hypot(mem.x_m + 1.1 * cos(0.1), mem.y_m + 1.1 * sin(0.1))) < 1e-12);
  g.obstacle[0].bearing_rad = 1.0;  // 1 m away on the left: another obstacle, seen less well
  g.obstacle[0].n_points = 5U;
  assert_int_equal(features_obstacles_remember(&cfg, &mem, back, &g), FEATURES_OK);
  assert_true(mem.radius_m == 0.1 && mem.n_points == 5U && fabs(hypot(mem.x_m + 1.1 * cos(1.0), mem.y_m + 1.1 * sin(1.0))) < 1e-12);
  g.obstacle[0].width_m = 5.0;  // wider than an obstacle can be: capped
  g.obstacle[0].n_points = 50U;
  assert_int_equal(features_obstacles_remember(&cfg, &mem, back, &g), FEATURES_OK);
  assert_true(mem.radius_m == 0.5 * cfg.max_obstacle_width_m);
  assert_int_equal(features_obstacles_from_pose(&cfg, back, 5.0, 0.0, &near_one, 1U, PI, &f), FEATURES_OK);
  assert_int_equal(features_obstacles_remember(&cfg, &mem, back, &f), FEATURES_OK);
  assert_true(fabs(mem.x_m + 1.35) < 1e-12 && mem.radius_m == 0.3);
  // Nothing in view for 3 observations: remembered; the 4th: forgotten, age saturated at 3.
  for (uint32_t k = 1U; k <= 4U; ++k) {
    assert_int_equal(features_obstacles_from_pose(&cfg, origin, 5.0, 0.0, NULL, 0U, PI, &f), FEATURES_OK);
    assert_int_equal(features_obstacles_remember(&cfg, &mem, origin, &f), FEATURES_OK);
    if (k <= 3U) {
      assert_true(f.known_age == k && fabs(fabs(f.known.bearing_rad) - PI) < 1e-12);
    } else {
      assert_known_empty(&cfg, &f);
      assert_int_equal(mem.held, 0);
    }
  }
  assert_int_equal(features_obstacles_memory_state(&f, 0.1, s, 5U), 5U);
  assert_true(s[2] == PI && s[3] == cfg.no_obstacle_distance_m && fabs(s[4] - 0.3) < 1e-12);
  // Refused: nothing changed.
  assert_int_equal(features_obstacles_from_pose(&cfg, origin, 5.0, 0.0, &ahead, 1U, PI, &f), FEATURES_OK);
  const features_obstacle_memory_t before = mem;
  assert_int_equal(features_obstacles_remember(NULL, &mem, origin, &f), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_obstacles_remember(&cfg, NULL, origin, &f), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_obstacles_remember(&cfg, &mem, origin, NULL), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_obstacles_remember(&cfg, &mem, pose((double)NAN, 0.0, 0.0), &f), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_obstacles_remember(&cfg, &mem, pose(0.0, 0.0, (double)INFINITY), &f),
                   FEATURES_ERR_INVALID_ARG);
  features_obstacles_config_t bad = cfg;
  bad.memory_margin_m = -0.1;
  assert_int_equal(features_obstacles_remember(&bad, &mem, origin, &f), FEATURES_ERR_INVALID_ARG);
  assert_int_equal(features_obstacles_from_pose(&bad, origin, 5.0, 0.0, &ahead, 1U, PI, &f), FEATURES_ERR_INVALID_ARG);
  assert_memory_equal(&mem, &before, sizeof mem);
  // The state vector: refused for a small capacity or a bad period; reset forgets.
  assert_int_equal(features_obstacles_memory_state(&f, 0.1, s, 4U), 0U);
  assert_int_equal(features_obstacles_memory_state(&f, 0.0, s, 5U), 0U);
  assert_int_equal(features_obstacles_memory_state(&f, (double)NAN, s, 5U), 0U);
  assert_int_equal(features_obstacles_memory_state(NULL, 0.1, s, 5U), 0U);
  features_obstacle_memory_reset(&mem);
  assert_int_equal(mem.held, 0);
  assert_int_equal(features_obstacles_from_pose(&cfg, back, 5.0, 0.0, NULL, 0U, PI, &f), FEATURES_OK);
  assert_int_equal(features_obstacles_remember(&cfg, &mem, back, &f), FEATURES_OK);
  assert_known_empty(&cfg, &f);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_obstacles_random_poses_within_tolerance),
      cmocka_unit_test(test_obstacles_dropouts_within_tolerance),
      cmocka_unit_test(test_obstacles_two_obstacles_nearest_first),
      cmocka_unit_test(test_obstacles_none_visible_uses_convention),
      cmocka_unit_test(test_obstacles_goal_from_odometry),
      cmocka_unit_test(test_obstacles_invalid_input_rejected),
      cmocka_unit_test(test_obstacles_deterministic_and_allocation_free),
      cmocka_unit_test(test_obstacles_from_pose_agrees_with_scan),
      cmocka_unit_test(test_obstacles_memory_keeps_passed_obstacle),
      cmocka_unit_test(test_obstacles_memory_expires_beyond_range),
      cmocka_unit_test(test_obstacles_memory_replaced_by_new_obstacle),
      cmocka_unit_test(test_obstacles_memory_same_from_pose_and_scan),
      cmocka_unit_test(test_obstacles_memory_rule_state_and_invalid),
  };
  return cmocka_run_group_tests_name("features.obstacles", tests, NULL, NULL);
}
