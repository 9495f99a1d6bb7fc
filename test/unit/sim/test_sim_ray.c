// SPDX-License-Identifier: MIT
// ODE ray casts of the plant against hand-computed geometry and the analytic ray caster.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#include "b21r_test/synthetic_world.h"
#include "sim/plant.h"
#include "sim/world.h"

#ifndef SIM_WORLDS_DIR
#error "SIM_WORLDS_DIR must name sim/worlds"
#endif

static const double k_pi = 3.14159265358979323846;
static sim_world_t g_world;

static sim_plant_t* make_plant(void) {
  sim_plant_config_t cfg;
  sim_plant_config_default(&cfg);
  sim_plant_t* p = sim_plant_create(&g_world, &cfg);
  assert_non_null(p);
  return p;
}

static void load(const char* file) {
  char path[512];
  (void)snprintf(path, sizeof(path), "%s/%s", SIM_WORLDS_DIR, file);
  char err[256];
  assert_int_equal(sim_world_load(path, &g_world, err, sizeof(err)), SIM_WORLD_OK);
}

// Corridor 10 m x 2 m, laser at (1.15, 0): hand-computed distances to the four walls.
static void test_ray_corridor_distances_match_hand_geometry(void** state) {
  (void)state;
  load("corridor10.world");
  sim_plant_t* p = make_plant();
  const double ox = 1.15, oy = 0.0;
  assert_true(fabs(sim_plant_ray(p, ox, oy, 0.0, 30.0) - 8.85) < 1e-9);           // end wall
  assert_true(fabs(sim_plant_ray(p, ox, oy, 0.5 * k_pi, 30.0) - 1.0) < 1e-9);     // left wall
  assert_true(fabs(sim_plant_ray(p, ox, oy, -0.5 * k_pi, 30.0) - 1.0) < 1e-9);    // right wall
  assert_true(fabs(sim_plant_ray(p, ox, oy, k_pi, 30.0) - 1.15) < 1e-9);          // start wall
  assert_true(fabs(sim_plant_ray(p, ox, oy, 0.25 * k_pi, 30.0) - sqrt(2.0)) < 1e-9);
  // From (2, 0.5) at -30 deg: the right wall y = -1 is 1.5 m below, so 1.5 / sin(30 deg) = 3.
  assert_true(fabs(sim_plant_ray(p, 2.0, 0.5, -k_pi / 6.0, 30.0) - 3.0) < 1e-9);
  // Beyond the maximum range nothing is reported.
  assert_true(isinf(sim_plant_ray(p, ox, oy, 0.0, 8.0)));
  sim_plant_destroy(p);
}

// A cylinder of radius 0.5 at (3, 0): a central ray meets it at 2.5, an offset ray (y = 0.3)
// at 3 - sqrt(0.25 - 0.09) = 2.6, a ray passing above (y = 0.6) misses.
static void test_ray_cylinder_distances_match_hand_geometry(void** state) {
  (void)state;
  sim_world_clear(&g_world);
  assert_int_equal(sim_world_add_cylinder(&g_world, 3.0, 0.0, 0.5), SIM_WORLD_OK);
  sim_plant_t* p = make_plant();
  assert_true(fabs(sim_plant_ray(p, 0.0, 0.0, 0.0, 30.0) - 2.5) < 1e-9);
  assert_true(fabs(sim_plant_ray(p, 0.0, 0.3, 0.0, 30.0) - 2.6) < 1e-9);
  assert_true(isinf(sim_plant_ray(p, 0.0, 0.6, 0.0, 30.0)));
  assert_true(isinf(sim_plant_ray(p, 0.0, 0.0, k_pi, 30.0)));
  // Diagonal: from (3 - 2, -2) at +45 deg the ray passes the centre; hit at 2 sqrt(2) - 0.5.
  assert_true(fabs(sim_plant_ray(p, 1.0, -2.0, 0.25 * k_pi, 30.0) - (2.0 * sqrt(2.0) - 0.5)) <
              1e-9);
  sim_plant_destroy(p);
}

// The robot never sees itself: a scan in an empty world reports no hit on every beam.
static void test_ray_scan_ignores_robot_body(void** state) {
  (void)state;
  sim_world_clear(&g_world);
  sim_plant_t* p = make_plant();
  double out[181];
  sim_plant_scan(p, -0.5 * k_pi, k_pi / 180.0, 181, 30.0, out);
  for (int i = 0; i < 181; ++i) {
    assert_true(isinf(out[i]));
  }
  sim_plant_destroy(p);
}

static void to_synth(const sim_world_t* w, synth_world_t* s) {
  synth_world_init(s);
  for (size_t i = 0; i < w->n_walls; ++i) {
    const sim_wall_t* wl = &w->walls[i];
    assert_int_equal(synth_world_add_segment(s, wl->x0_m, wl->y0_m, wl->x1_m, wl->y1_m), 0);
  }
  for (size_t i = 0; i < w->n_cylinders; ++i) {
    const sim_cylinder_t* c = &w->cylinders[i];
    assert_int_equal(synth_world_add_circle(s, c->x_m, c->y_m, c->radius_m), 0);
  }
}

// Full scans (181 and 361 beams) from many seeded poses in the shipped worlds equal the
// analytic ray caster (exact closed-form intersections) to 1e-9 m.
static void test_ray_scans_match_analytic_oracle(void** state) {
  (void)state;
  static const char* files[] = {"corridor10.world", "obstacle1.world", "obstacles3.world"};
  static synth_world_t synth;
  synth_rng_t rng;
  synth_rng_seed(&rng, 20020511U);
  int compared = 0;
  for (size_t f = 0; f < sizeof(files) / sizeof(files[0]); ++f) {
    load(files[f]);
    to_synth(&g_world, &synth);
    sim_plant_t* p = make_plant();
    for (int pose = 0; pose < 40; ++pose) {
      // Uniform pose inside the bounds, kept if the robot disc is free.
      const double x = g_world.bounds_min_x_m + 1.0 +
                       synth_rng_uniform(&rng) * (g_world.bounds_max_x_m - g_world.bounds_min_x_m - 2.0);
      const double y = g_world.bounds_min_y_m + 1.0 +
                       synth_rng_uniform(&rng) * (g_world.bounds_max_y_m - g_world.bounds_min_y_m - 2.0);
      const double th = (synth_rng_uniform(&rng) * 2.0 - 1.0) * k_pi;
      if (sim_world_disc_collides(&g_world, x, y, SIM_ROBOT_RADIUS_M + 0.05)) {
        continue;
      }
      sim_plant_reset(p, x, y, th);
      const size_t n = (pose % 2) ? 361U : 181U;
      const double inc = k_pi / (double)(n - 1U);
      double out[361];
      sim_plant_scan(p, -0.5 * k_pi, inc, n, 30.0, out);
      const double ox = x + SIM_LASER_X_DEFAULT_M * cos(th);
      const double oy = y + SIM_LASER_X_DEFAULT_M * sin(th);
      for (size_t i = 0; i < n; ++i) {
        const double dir = th - 0.5 * k_pi + (double)i * inc;
        double ref = synth_world_raycast(&synth, ox, oy, dir, NULL);
        if (ref > 30.0) {
          ref = INFINITY;
        }
        if (isinf(ref) || isinf(out[i])) {
          assert_true(isinf(ref) && isinf(out[i]));
        } else {
          if (fabs(out[i] - ref) >= 1e-9) {
            print_error("%s pose %d beam %zu: ode %.12f oracle %.12f\n", files[f], pose, i, out[i],
                        ref);
          }
          assert_true(fabs(out[i] - ref) < 1e-9);
        }
        ++compared;
      }
    }
    sim_plant_destroy(p);
  }
  assert_true(compared > 10000);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_ray_corridor_distances_match_hand_geometry),
      cmocka_unit_test(test_ray_cylinder_distances_match_hand_geometry),
      cmocka_unit_test(test_ray_scan_ignores_robot_body),
      cmocka_unit_test(test_ray_scans_match_analytic_oracle),
  };
  return cmocka_run_group_tests_name("sim.ray", tests, NULL, NULL);
}
