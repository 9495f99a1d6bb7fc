// SPDX-License-Identifier: MIT
// The world text format (parser, errors, shipped world files) and the analytic disc queries.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#include "sim/world.h"

#ifndef SIM_WORLDS_DIR
#error "SIM_WORLDS_DIR must name sim/worlds"
#endif

static sim_world_t g_world;  // large: keep it off the test's stack

static sim_world_status_t parse(const char* text, char* err, size_t cap) {
  return sim_world_parse(text, strlen(text), &g_world, err, cap);
}

// A file using every directive parses into the documented geometry.
static void test_world_parse_all_directives_builds_geometry(void** state) {
  (void)state;
  const char* text =
      "# comment line\n"
      "b21r-world 1\n"
      "name test_world   # trailing comment\n"
      "corridor 10 2 1\n"
      "wall 0 5 4 5 0.2\n"
      "cylinder 3 1.5 0.25\n"
      "goal 6 -1 0.4\n"
      "start 0.5 0 0\n"
      "start 1.0 0.2 -0.3\n";
  char err[128];
  assert_int_equal(parse(text, err, sizeof(err)), SIM_WORLD_OK);
  assert_string_equal(g_world.name, "test_world");
  assert_int_equal(g_world.has_corridor, 1);
  assert_true(g_world.corridor_length_m == 10.0 && g_world.corridor_width_m == 2.0);
  assert_int_equal(g_world.n_walls, 5);  // 4 corridor walls + 1
  // Right corridor wall: face y = -1 running +x, solid below it.
  assert_true(g_world.walls[0].y0_m == -1.0 && g_world.walls[0].y1_m == -1.0);
  assert_true(g_world.walls[0].x1_m > g_world.walls[0].x0_m);
  assert_true(g_world.walls[4].thickness_m == 0.2);
  assert_int_equal(g_world.n_cylinders, 1);
  assert_true(g_world.cylinders[0].radius_m == 0.25);
  assert_int_equal(g_world.has_goal, 1);
  assert_true(g_world.goal.x_m == 6.0 && g_world.goal.radius_m == 0.4);
  assert_int_equal(g_world.n_starts, 2);
  assert_true(g_world.starts[1].theta_rad == -0.3);
  assert_true(g_world.bounds_min_x_m < -0.1 && g_world.bounds_max_x_m > 10.0);
}

// Errors name the line and the problem; the output is left empty.
static void test_world_parse_errors_name_the_line(void** state) {
  (void)state;
  char err[128];
  assert_int_equal(parse("b21r-world 1\nwal 0 0 1 1\n", err, sizeof(err)), SIM_WORLD_ERR_SYNTAX);
  assert_non_null(strstr(err, "line 2"));
  assert_non_null(strstr(err, "wal"));
  assert_int_equal(g_world.n_walls, 0);
  assert_int_equal(parse("b21r-world 1\ncylinder 1 2\n", err, sizeof(err)), SIM_WORLD_ERR_SYNTAX);
  assert_non_null(strstr(err, "line 2"));
  assert_int_equal(parse("b21r-world 1\n\ncylinder 1 2 abc\n", err, sizeof(err)),
                   SIM_WORLD_ERR_SYNTAX);
  assert_non_null(strstr(err, "line 3"));
  assert_int_equal(parse("b21r-world 1\ncylinder 1 2 -1\n", err, sizeof(err)),
                   SIM_WORLD_ERR_INVALID_ARG);
  assert_int_equal(parse("cylinder 1 2 1\n", err, sizeof(err)), SIM_WORLD_ERR_SYNTAX);
  assert_non_null(strstr(err, "b21r-world"));
  assert_int_equal(parse("b21r-world 2\n", err, sizeof(err)), SIM_WORLD_ERR_SYNTAX);
  assert_int_equal(parse("b21r-world 1\nwall 1 1 1 1\n", err, sizeof(err)),
                   SIM_WORLD_ERR_INVALID_ARG);
  assert_int_equal(parse("b21r-world 1\nname bad/name\n", err, sizeof(err)), SIM_WORLD_ERR_SYNTAX);
  assert_int_equal(parse("", err, sizeof(err)), SIM_WORLD_ERR_SYNTAX);
  // Numbers beyond 1e6 in magnitude are refused (found by fuzz_world: a goal at x = 1e47 made
  // the drawing area's min and max equal after adding the margin).
  assert_int_equal(parse("b21r-world 1\ngoal 1e47 2 2\n", err, sizeof(err)), SIM_WORLD_ERR_SYNTAX);
  assert_non_null(strstr(err, "line 2"));
  assert_non_null(strstr(err, "magnitude at most 1e+06"));
  assert_int_equal(parse("b21r-world 1\nstart 0 0 -1000001\n", err, sizeof(err)), SIM_WORLD_ERR_SYNTAX);
  assert_int_equal(parse("b21r-world 1\narena -1e6 -1e6 1e6 1e6\n", err, sizeof(err)), SIM_WORLD_OK);
  assert_true(g_world.bounds_min_x_m < g_world.bounds_max_x_m);
}

// More entries than the capacity are rejected with SIM_WORLD_ERR_CAPACITY.
static void test_world_parse_too_many_cylinders_fails(void** state) {
  (void)state;
  static char text[8192];
  size_t n = (size_t)snprintf(text, sizeof(text), "b21r-world 1\n");
  for (int i = 0; i <= SIM_WORLD_MAX_CYLINDERS; ++i) {
    n += (size_t)snprintf(text + n, sizeof(text) - n, "cylinder %d 0 0.1\n", i);
  }
  char err[128];
  assert_int_equal(parse(text, err, sizeof(err)), SIM_WORLD_ERR_CAPACITY);
  assert_non_null(strstr(err, "cylinder"));
}

// Disc queries: against a thick wall (solid side and face side) and against a cylinder.
static void test_world_disc_collides_matches_geometry(void** state) {
  (void)state;
  sim_world_clear(&g_world);
  // Face y = 0 from x = 0 to 4, solid below (y in [-0.1, 0]).
  assert_int_equal(sim_world_add_wall(&g_world, 0.0, 0.0, 4.0, 0.0, 0.1), SIM_WORLD_OK);
  assert_int_equal(sim_world_add_cylinder(&g_world, 10.0, 0.0, 0.5), SIM_WORLD_OK);
  assert_false(sim_world_disc_collides(&g_world, 2.0, 0.27, 0.26));
  assert_true(sim_world_disc_collides(&g_world, 2.0, 0.25, 0.26));
  assert_false(sim_world_disc_collides(&g_world, 2.0, -0.37, 0.26));  // below the solid
  assert_true(sim_world_disc_collides(&g_world, 2.0, -0.35, 0.26));
  assert_false(sim_world_disc_collides(&g_world, 4.27, 0.0, 0.26));  // past the end
  assert_true(sim_world_disc_collides(&g_world, 10.0 - 0.75, 0.0, 0.26));
  assert_false(sim_world_disc_collides(&g_world, 10.0 - 0.77, 0.0, 0.26));
}

// The goal disc includes its rim; worlds without a goal never report it.
static void test_world_in_goal_uses_goal_disc(void** state) {
  (void)state;
  char err[64];
  assert_int_equal(parse("b21r-world 1\ngoal 1 1 0.5\n", err, sizeof(err)), SIM_WORLD_OK);
  assert_true(sim_world_in_goal(&g_world, 1.0, 1.5));
  assert_false(sim_world_in_goal(&g_world, 1.0, 1.51));
  sim_world_clear(&g_world);
  assert_false(sim_world_in_goal(&g_world, 0.0, 0.0));
}

// Every world file shipped in sim/worlds parses and starts the robot clear of obstacles.
static void test_world_shipped_files_parse_and_starts_are_free(void** state) {
  (void)state;
  static const char* files[] = {"corridor10.world", "obstacle1.world", "open.world"};
  for (size_t i = 0; i < sizeof(files) / sizeof(files[0]); ++i) {
    char path[512];
    (void)snprintf(path, sizeof(path), "%s/%s", SIM_WORLDS_DIR, files[i]);
    char err[256];
    const sim_world_status_t st = sim_world_load(path, &g_world, err, sizeof(err));
    if (st != SIM_WORLD_OK) {
      print_error("%s\n", err);
    }
    assert_int_equal(st, SIM_WORLD_OK);
    assert_true(g_world.n_starts > 0);
    for (size_t k = 0; k < g_world.n_starts; ++k) {
      assert_false(sim_world_disc_collides(&g_world, g_world.starts[k].x_m, g_world.starts[k].y_m,
                                           0.26));
    }
  }
  char err[256];
  assert_int_equal(sim_world_load("/nonexistent/x.world", &g_world, err, sizeof(err)),
                   SIM_WORLD_ERR_IO);
  assert_non_null(strstr(err, "/nonexistent/x.world"));
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_world_parse_all_directives_builds_geometry),
      cmocka_unit_test(test_world_parse_errors_name_the_line),
      cmocka_unit_test(test_world_parse_too_many_cylinders_fails),
      cmocka_unit_test(test_world_disc_collides_matches_geometry),
      cmocka_unit_test(test_world_in_goal_uses_goal_disc),
      cmocka_unit_test(test_world_shipped_files_parse_and_starts_are_free),
  };
  return cmocka_run_group_tests_name("sim.world", tests, NULL, NULL);
}
