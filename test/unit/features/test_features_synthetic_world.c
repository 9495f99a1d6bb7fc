// SPDX-License-Identifier: MIT
// The synthetic world that the feature and task tests (and the emulator's ray-cast checks) take
// as ground truth: exact ray casts, LMS200-like scans, the kinematic synchro-drive stepper.
#include <b21r_test/alloc_counter.h>
#include <b21r_test/synthetic_world.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#define PI 3.14159265358979323846

// Ray casts against hand-computed geometry: walls, circles, misses, starting inside a circle.
static void test_synth_raycast_exact_against_hand_geometry(void** state) {
  (void)state;
  synth_world_t w;
  synth_world_init(&w);
  assert_int_equal(synth_world_add_corridor(&w, 10.0, 2.0), 0);
  assert_int_equal(w.n_segments, 4U);
  synth_hit_t hit;
  // From (2, 0) straight left hits y = 1 at 1 m; at 45° at sqrt(2) m.
  assert_true(fabs(synth_world_raycast(&w, 2.0, 0.0, PI / 2.0, &hit) - 1.0) < 1e-12);
  assert_int_equal(hit.kind, SYNTH_HIT_SEGMENT);
  assert_true(fabs(synth_world_raycast(&w, 2.0, 0.0, PI / 4.0, NULL) - sqrt(2.0)) < 1e-12);
  assert_true(fabs(synth_world_raycast(&w, 2.0, 0.0, 0.0, NULL) - 8.0) < 1e-12);  // end wall
  assert_true(fabs(synth_world_raycast(&w, 2.0, 0.5, PI, NULL) - 2.0) < 1e-12);   // start wall
  // Grazing incidence: the distance follows 1 / sin(angle).
  for (int k = 1; k <= 10; ++k) {
    const double a = 0.01 * k;
    assert_true(fabs(synth_world_raycast(&w, 0.5, 0.0, a, NULL) - fmin(1.0 / sin(a), 9.5 / cos(a))) <
                1e-9);
  }
  assert_int_equal(synth_world_add_circle(&w, 5.0, 0.0, 0.5), 0);
  assert_true(fabs(synth_world_raycast(&w, 2.0, 0.0, 0.0, &hit) - 2.5) < 1e-12);
  assert_int_equal(hit.kind, SYNTH_HIT_CIRCLE);
  assert_int_equal(hit.index, 0U);
  // An oblique ray: the centre (3 m ahead) lies perp = 3 sin(a) off the ray, so the ray enters
  // the circle sqrt(r^2 - perp^2) before the foot of the perpendicular.
  const double a = atan2(0.3, 3.0);
  const double t = synth_world_raycast(&w, 2.0, 0.0, a, NULL);
  const double along = 3.0 * cos(a), perp = 3.0 * sin(a);
  assert_true(fabs(t - (along - sqrt(0.25 - perp * perp))) < 1e-12);
  assert_true(synth_world_raycast(&w, 5.0, 0.1, 1.0, NULL) == 0.0);  // inside the circle
  synth_world_t empty;
  synth_world_init(&empty);
  assert_true(isinf(synth_world_raycast(&empty, 0.0, 0.0, 0.3, &hit)));
  assert_int_equal(hit.kind, SYNTH_HIT_NONE);
}

// Clearance and collision of a disc; capacity and argument checks.
static void test_synth_clearance_and_capacity(void** state) {
  (void)state;
  synth_world_t w;
  synth_world_init(&w);
  assert_int_equal(synth_world_add_corridor(&w, 10.0, 2.0), 0);
  assert_int_equal(synth_world_add_circle(&w, 5.0, 0.0, 0.25), 0);
  assert_true(fabs(synth_world_clearance(&w, 2.0, 0.3) - 0.7) < 1e-12);
  assert_true(fabs(synth_world_clearance(&w, 4.0, 0.0) - 0.75) < 1e-12);
  assert_false(synth_world_collides(&w, 2.0, 0.3, 0.26));
  assert_true(synth_world_collides(&w, 2.0, 0.75, 0.26));
  assert_true(synth_world_collides(&w, 4.5, 0.0, 0.26));
  assert_int_equal(synth_world_add_circle(&w, 0.0, 0.0, 0.0), -1);
  assert_int_equal(synth_world_add_segment(&w, 1.0, 1.0, 1.0, 1.0), -1);
  assert_int_equal(synth_world_add_segment(&w, NAN, 1.0, 2.0, 1.0), -1);
  while (w.n_circles < SYNTH_MAX_CIRCLES) assert_int_equal(synth_world_add_circle(&w, 1, 1, 0.1), 0);
  assert_int_equal(synth_world_add_circle(&w, 1.0, 1.0, 0.1), -1);
  while (w.n_segments < SYNTH_MAX_SEGMENTS) assert_int_equal(synth_world_add_segment(&w, 0, 0, 1, 1), 0);
  assert_int_equal(synth_world_add_box(&w, 0, 0, 1, 1), -1);
}

// Scans: LMS200 beam layout (index 0 on the right), mount offset, max range -> no echo, raw
// codes, dropout rate, seeded noise with the stated sigma, determinism, no allocation.
static void test_synth_lidar_scan_properties(void** state) {
  (void)state;
  synth_world_t w;
  synth_world_init(&w);
  assert_int_equal(synth_world_add_corridor(&w, 10.0, 2.0), 0);
  synth_lidar_config_t cfg;
  assert_int_equal(synth_lidar_config_lms200(&cfg, 180, 1.0), 0);
  assert_int_equal(cfg.n_beams, 181);
  assert_int_equal(synth_lidar_config_lms200(&cfg, 180, 0.25), -1);
  assert_int_equal(synth_lidar_config_lms200(&cfg, 100, 0.25), 0);
  assert_int_equal(cfg.n_beams, 401);
  assert_int_equal(synth_lidar_config_lms200(&cfg, 180, 1.0), 0);
  cfg.noise_sigma_m = 0.0;
  cfg.quantum_m = 0.0;
  float r[SYNTH_MAX_BEAMS];
  uint8_t nr[SYNTH_MAX_BEAMS];
  // Robot at (1, 0) facing +x: laser at (1.15, 0). Beam 0 looks right (-y wall at 1 m), beam
  // 180 left, beam 90 ahead (end wall at 8.85 m > 8.183 m: no echo).
  assert_int_equal(synth_lidar_scan(&w, &cfg, NULL, 1.0, 0.0, 0.0, r, nr, SYNTH_MAX_BEAMS), 181);
  assert_true(fabsf(r[0] - 1.0f) < 1e-6f && nr[0] == 0U);
  assert_true(fabsf(r[180] - 1.0f) < 1e-6f && nr[180] == 0U);
  assert_int_equal(nr[90], SYNTH_NR_NO_ECHO);
  assert_true(r[90] == 0.0f);
  cfg.raw_error_codes = 1U;
  assert_int_equal(synth_lidar_scan(&w, &cfg, NULL, 1.0, 0.0, 0.0, r, nr, SYNTH_MAX_BEAMS), 181);
  assert_int_equal(nr[90], 0U);
  assert_true(fabsf(r[90] - 8.191f) < 1e-6f);
  cfg.raw_error_codes = 0U;
  assert_int_equal(synth_lidar_scan(&w, &cfg, NULL, 1.0, 0.0, 0.0, r, nr, 100U), -1);
  // Noise and dropouts need a generator; statistics match the configuration.
  cfg.noise_sigma_m = 0.01;
  cfg.dropout_prob = 0.1;
  assert_int_equal(synth_lidar_scan(&w, &cfg, NULL, 1.0, 0.0, 0.0, r, nr, SYNTH_MAX_BEAMS), -1);
  synth_rng_t rng;
  synth_rng_seed(&rng, 3U);
  double s1 = 0.0, s2 = 0.0;
  int n = 0, drops = 0, beams = 0;
  alloc_counter_begin();
  for (int k = 0; k < 200; ++k) {
    assert_int_equal(synth_lidar_scan(&w, &cfg, &rng, 1.0, 0.0, 0.0, r, nr, SYNTH_MAX_BEAMS), 181);
    for (int i = 0; i < 181; i += 180) {  // the two side beams see the walls at exactly 1 m
      ++beams;
      if (nr[i] == SYNTH_NR_DROPOUT) {
        ++drops;
        continue;
      }
      const double e = (double)r[i] - 1.0;
      s1 += e;
      s2 += e * e;
      ++n;
    }
  }
  assert_int_equal(alloc_counter_end(), 0);
  const double mean = s1 / n, sd = sqrt(s2 / n - mean * mean);
  assert_true(fabs(mean) < 0.003);
  assert_true(fabs(sd - 0.01) < 0.002);
  assert_true(drops > 20 && drops < 60);  // 10 % of 400
  // Same seed, same scan, bit for bit.
  float ra[SYNTH_MAX_BEAMS], rb[SYNTH_MAX_BEAMS];
  uint8_t na[SYNTH_MAX_BEAMS], nb[SYNTH_MAX_BEAMS];
  synth_rng_seed(&rng, 8U);
  (void)synth_lidar_scan(&w, &cfg, &rng, 3.0, 0.2, 0.4, ra, na, SYNTH_MAX_BEAMS);
  synth_rng_seed(&rng, 8U);
  (void)synth_lidar_scan(&w, &cfg, &rng, 3.0, 0.2, 0.4, rb, nb, SYNTH_MAX_BEAMS);
  assert_memory_equal(ra, rb, 181 * sizeof(float));
  assert_memory_equal(na, nb, 181);
}

// Kinematics: heading first, then translation along the new heading; acceleration limits.
static void test_synth_drive_heading_first_then_translate(void** state) {
  (void)state;
  synth_robot_t r = {0.0, 0.0, 0.0, 0.0, 0.0};
  synth_drive_step(&r, 1.0, PI / 2.0, 1.0, NULL);  // turn 90°, then move 1 m along +y
  assert_true(fabs(r.x_m) < 1e-12 && fabs(r.y_m - 1.0) < 1e-12);
  assert_true(fabs(r.theta_rad - PI / 2.0) < 1e-12);
  synth_robot_t s = {0.0, 0.0, 3.0, 0.0, 0.0};
  synth_drive_step(&s, 0.0, 1.0, 1.0, NULL);
  assert_true(s.theta_rad > -PI && s.theta_rad <= PI);
  assert_true(fabs(s.theta_rad - (4.0 - 2.0 * PI)) < 1e-12);
  const synth_drive_limits_t lim = {0.5, 2.0};
  synth_robot_t a = {0.0, 0.0, 0.0, 0.0, 0.0};
  synth_drive_step(&a, 1.0, 1.0, 0.1, &lim);
  assert_true(fabs(a.v_mps - 0.05) < 1e-12 && fabs(a.omega_radps - 0.2) < 1e-12);
  for (int i = 0; i < 30; ++i) synth_drive_step(&a, 1.0, 1.0, 0.1, &lim);
  assert_true(fabs(a.v_mps - 1.0) < 1e-12 && fabs(a.omega_radps - 1.0) < 1e-12);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_synth_raycast_exact_against_hand_geometry),
      cmocka_unit_test(test_synth_clearance_and_capacity),
      cmocka_unit_test(test_synth_lidar_scan_properties),
      cmocka_unit_test(test_synth_drive_heading_first_then_translate),
  };
  return cmocka_run_group_tests_name("features.synthetic_world", tests, NULL, NULL);
}
