// SPDX-License-Identifier: MIT
// The ODE plant: free-space motion equals the kinematic model; contacts stop the body, latch
// the collision and press the right bump panel; runs are reproducible bit for bit.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "sim/kinematic.h"
#include "sim/plant.h"
#include "sim/world.h"

static const double k_pi = 3.14159265358979323846;

static sim_world_t g_world;

static sim_plant_t* make_plant(void) {
  sim_plant_config_t cfg;
  sim_plant_config_default(&cfg);
  sim_plant_t* p = sim_plant_create(&g_world, &cfg);
  assert_non_null(p);
  return p;
}

// In free space the plant follows the kinematic model (same axis rule, heading first) to
// rounding, through acceleration ramps, turns and reversals.
static void test_plant_free_space_matches_kinematic_model(void** state) {
  (void)state;
  sim_world_clear(&g_world);
  sim_plant_t* p = make_plant();
  sim_plant_reset(p, 0.5, -0.2, 0.3);
  sim_kin_state_t k;
  sim_kin_reset(&k, 0.5, -0.2, 0.3);
  sim_kin_limits_t lim;
  sim_kin_limits_default(&lim);
  const double cmds[4][2] = {{0.6, 0.0}, {0.4, 0.8}, {-0.3, -0.5}, {0.0, 1.0}};
  for (int seg = 0; seg < 4; ++seg) {
    sim_plant_set_command(p, cmds[seg][0], cmds[seg][1]);
    for (int i = 0; i < 300; ++i) {
      sim_plant_step(p, 1);
      sim_kin_step(&k, &lim, cmds[seg][0], cmds[seg][1], 0.01);
    }
  }
  sim_plant_state_t s;
  sim_plant_get_state(p, &s);
  assert_true(fabs(s.x_m - k.x_m) < 1e-12);
  assert_true(fabs(s.y_m - k.y_m) < 1e-12);
  assert_true(s.theta_rad == k.theta_rad);
  assert_true(s.v_mps == k.v_mps && s.omega_radps == k.omega_radps);
  assert_int_equal(s.collided, 0);
  assert_int_equal(s.bumper_panel, -1);
  assert_true(fabs(s.t_s - 12.0) < 1e-12);
  sim_plant_destroy(p);
}

// Driving head-on into a wall: the body stops with its skirt at the wall face, the axis and the
// odometry stop, the collision latches and the front base panel (0) is pressed.
static void test_plant_wall_contact_stops_body_and_presses_front_panel(void** state) {
  (void)state;
  sim_world_clear(&g_world);
  assert_int_equal(sim_world_add_wall(&g_world, 2.0, -2.0, 2.0, 2.0, 0.1), SIM_WORLD_OK);
  sim_plant_t* p = make_plant();
  sim_plant_reset(p, 0.0, 0.0, 0.0);
  sim_plant_set_command(p, 0.5, 0.0);
  sim_plant_step(p, 600);  // 6 s at 0.5 m/s would carry it 2.75 m: well into the wall
  sim_plant_state_t s;
  sim_plant_get_state(p, &s);
  assert_true(s.collided && s.in_contact);
  assert_true(fabs(s.x_m - (2.0 - SIM_ROBOT_RADIUS_M)) < 0.01);
  assert_true(fabs(s.y_m) < 1e-6);
  assert_true(fabs(s.v_mps) < 0.02);
  assert_int_equal(s.bumper_panel, 0);
  assert_true(s.bumper_bits != 0);
  const double odo = s.odo_trans_m;
  assert_true(fabs(odo - s.x_m) < 0.02);  // wheel odometry followed the body, not the command
  sim_plant_step(p, 100);
  sim_plant_state_t s2;
  sim_plant_get_state(p, &s2);
  assert_true(fabs(s2.x_m - s.x_m) < 0.005);
  assert_true(fabs(s2.odo_trans_m - odo) < 0.005);
  // Backing away works and releases the bumper; the collision stays latched until a reset.
  sim_plant_set_command(p, -0.3, 0.0);
  sim_plant_step(p, 100);
  sim_plant_get_state(p, &s2);
  assert_true(s2.x_m < s.x_m - 0.1);
  assert_int_equal(s2.in_contact, 0);
  assert_int_equal(s2.bumper_panel, -1);
  assert_int_equal(s2.collided, 1);
  sim_plant_reset(p, 0.0, 0.0, 0.0);
  sim_plant_get_state(p, &s2);
  assert_int_equal(s2.collided, 0);
  sim_plant_destroy(p);
}

// The skirt keeps its orientation while the enclosure steers: after turning to +90 deg and
// driving into a wall on the left, base panel 2 (90 deg CCW from the skirt's front) is pressed;
// reversing into a wall behind presses panel 4.
static void test_plant_bumper_panel_follows_contact_bearing(void** state) {
  (void)state;
  sim_world_clear(&g_world);
  assert_int_equal(sim_world_add_wall(&g_world, 3.0, 1.0, -3.0, 1.0, 0.1), SIM_WORLD_OK);   // y = 1
  assert_int_equal(sim_world_add_wall(&g_world, -1.0, 3.0, -1.0, -3.0, 0.1), SIM_WORLD_OK);  // x = -1
  sim_plant_t* p = make_plant();
  sim_plant_reset(p, 0.0, 0.0, 0.0);
  sim_plant_set_command(p, 0.0, 0.5);
  while (1) {
    sim_plant_state_t s;
    sim_plant_get_state(p, &s);
    if (s.theta_rad >= 0.5 * k_pi - 0.003) {
      break;
    }
    sim_plant_step(p, 1);
  }
  sim_plant_set_command(p, 0.4, 0.0);
  sim_plant_step(p, 400);
  sim_plant_state_t s;
  sim_plant_get_state(p, &s);
  assert_true(s.in_contact);
  assert_int_equal(s.bumper_panel, 2);
  assert_true(fabs(s.y_m - (1.0 - SIM_ROBOT_RADIUS_M)) < 0.01);
  sim_plant_reset(p, 0.0, 0.0, 0.0);
  sim_plant_set_command(p, -0.4, 0.0);
  sim_plant_step(p, 400);
  sim_plant_get_state(p, &s);
  assert_true(s.in_contact);
  assert_int_equal(s.bumper_panel, 4);
  assert_true(fabs(s.x_m - (-1.0 + SIM_ROBOT_RADIUS_M)) < 0.01);
  sim_plant_destroy(p);
}

// A cylinder obstacle (cylinder-cylinder contact through libccd) stops the body at a centre
// distance of the two radii.
static void test_plant_cylinder_contact_stops_at_sum_of_radii(void** state) {
  (void)state;
  sim_world_clear(&g_world);
  assert_int_equal(sim_world_add_cylinder(&g_world, 2.0, 0.1, 0.25), SIM_WORLD_OK);
  sim_plant_t* p = make_plant();
  sim_plant_reset(p, 0.0, 0.0, 0.0);
  sim_plant_set_command(p, 0.5, 0.0);
  sim_plant_step(p, 600);
  sim_plant_state_t s;
  sim_plant_get_state(p, &s);
  assert_true(s.collided);
  const double d = hypot(s.x_m - 2.0, s.y_m - 0.1);
  assert_true(fabs(d - (0.25 + SIM_ROBOT_RADIUS_M)) < 0.01);
  assert_true(s.x_m < 2.0);
  assert_int_equal(s.bumper_panel, 0);
  sim_plant_destroy(p);
}

// Two plants given the same commands produce bit-identical states (contacts included).
static void test_plant_same_inputs_give_identical_states(void** state) {
  (void)state;
  char err[128];
  const char* text = "b21r-world 1\ncorridor 10 2 1\ncylinder 4 0.3 0.25\nstart 1 0 0.2\n";
  assert_int_equal(sim_world_parse(text, strlen(text), &g_world, err, sizeof(err)), SIM_WORLD_OK);
  sim_plant_state_t out[2];
  for (int run = 0; run < 2; ++run) {
    sim_plant_t* p = make_plant();
    for (int k = 0; k < 200; ++k) {
      sim_plant_set_command(p, 0.6, 0.4 * sin(0.05 * k));
      sim_plant_step(p, 10);
    }
    sim_plant_get_state(p, &out[run]);
    sim_plant_destroy(p);
  }
  assert_true(out[0].collided);  // the route hits something: contacts are part of the check
  assert_memory_equal(&out[0], &out[1], sizeof(out[0]));
}

// Invalid configurations are refused.
static void test_plant_create_invalid_config_returns_null(void** state) {
  (void)state;
  sim_world_clear(&g_world);
  sim_plant_config_t cfg;
  sim_plant_config_default(&cfg);
  cfg.dt_s = 0.0;
  assert_null(sim_plant_create(&g_world, &cfg));
  sim_plant_config_default(&cfg);
  cfg.robot_radius_m = NAN;
  assert_null(sim_plant_create(&g_world, &cfg));
  assert_null(sim_plant_create(NULL, &cfg));
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_plant_free_space_matches_kinematic_model),
      cmocka_unit_test(test_plant_wall_contact_stops_body_and_presses_front_panel),
      cmocka_unit_test(test_plant_bumper_panel_follows_contact_bearing),
      cmocka_unit_test(test_plant_cylinder_contact_stops_at_sum_of_radii),
      cmocka_unit_test(test_plant_same_inputs_give_identical_states),
      cmocka_unit_test(test_plant_create_invalid_config_returns_null),
  };
  return cmocka_run_group_tests_name("sim.plant", tests, NULL, NULL);
}
