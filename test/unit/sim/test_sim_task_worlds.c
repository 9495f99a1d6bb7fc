// SPDX-License-Identifier: MIT
// The shipped task worlds equal the worlds built from lib/tasks' default specifications.
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#include "sim/task_worlds.h"
#include "sim/world.h"

#ifndef SIM_WORLDS_DIR
#error "SIM_WORLDS_DIR must name sim/worlds"
#endif

static sim_world_t g_file, g_spec;

static void load(const char* name) {
  char path[512], err[256];
  (void)snprintf(path, sizeof(path), "%s/%s", SIM_WORLDS_DIR, name);
  assert_int_equal(sim_world_load(path, &g_file, err, sizeof(err)), SIM_WORLD_OK);
}

static void assert_same_geometry(double start_tol) {
  assert_int_equal(g_file.n_walls, g_spec.n_walls);
  assert_memory_equal(g_file.walls, g_spec.walls, g_file.n_walls * sizeof(sim_wall_t));
  assert_int_equal(g_file.n_cylinders, g_spec.n_cylinders);
  assert_memory_equal(g_file.cylinders, g_spec.cylinders, g_file.n_cylinders * sizeof(sim_cylinder_t));
  assert_int_equal(g_file.has_goal, g_spec.has_goal);
  if (g_file.has_goal) {
    assert_memory_equal(&g_file.goal, &g_spec.goal, sizeof(g_file.goal));
  }
  assert_int_equal(g_file.n_starts, TASKS_N_EVAL_STARTS);
  assert_int_equal(g_spec.n_starts, TASKS_N_EVAL_STARTS);
  for (size_t i = 0; i < TASKS_N_EVAL_STARTS; ++i) {
    assert_true(fabs(g_file.starts[i].x_m - g_spec.starts[i].x_m) <= start_tol);
    assert_true(fabs(g_file.starts[i].y_m - g_spec.starts[i].y_m) <= start_tol);
    assert_true(fabs(g_file.starts[i].theta_rad - g_spec.starts[i].theta_rad) <= start_tol);
  }
}

// corridor10.world is the default corridor spec: same walls, same ten start poses, exactly.
static void test_task_worlds_corridor_file_matches_spec(void** state) {
  (void)state;
  tasks_corridor_spec_t spec;
  tasks_corridor_spec_default(&spec);
  assert_int_equal(sim_world_from_task(&tasks_corridor_decl, &spec, &g_spec), SIM_WORLD_OK);
  load("corridor10.world");
  assert_same_geometry(0.0);
  assert_true(g_file.corridor_length_m == spec.length_m && g_file.corridor_width_m == spec.width_m);
  assert_string_equal(g_spec.name, "corridor10");
}

// obstacle1.world is the default obstacle spec (start poses written to 12 decimals).
static void test_task_worlds_obstacle_file_matches_spec(void** state) {
  (void)state;
  tasks_obstacles_spec_t spec;
  tasks_obstacles_spec_default(&spec);
  assert_int_equal(sim_world_from_task(&tasks_obstacles_decl, &spec, &g_spec), SIM_WORLD_OK);
  load("obstacle1.world");
  assert_same_geometry(1e-11);
  assert_true(g_file.goal.radius_m == spec.goal_radius_m);
}

// Every evaluation start leaves the robot clear of walls and obstacles, and bad specs fail.
static void test_task_worlds_starts_clear_and_bad_specs_fail(void** state) {
  (void)state;
  tasks_obstacles_spec_t spec;
  tasks_obstacles_spec_default(&spec);
  assert_int_equal(sim_world_from_task(&tasks_obstacles_decl, &spec, &g_spec), SIM_WORLD_OK);
  for (size_t i = 0; i < g_spec.n_starts; ++i) {
    assert_false(sim_world_disc_collides(&g_spec, g_spec.starts[i].x_m, g_spec.starts[i].y_m,
                                         TASKS_B21R_RADIUS_M + 0.1));
  }
  spec.arena_max_x_m = spec.arena_min_x_m;
  assert_int_equal(sim_world_from_task(&tasks_obstacles_decl, &spec, &g_spec), SIM_WORLD_ERR_INVALID_ARG);
  assert_int_equal(g_spec.n_walls, 0);
  tasks_corridor_spec_t cs;
  tasks_corridor_spec_default(&cs);
  cs.width_m = -1.0;
  assert_int_equal(sim_world_from_task(&tasks_corridor_decl, &cs, &g_spec), SIM_WORLD_ERR_INVALID_ARG);
  assert_int_equal(sim_world_from_task(&tasks_corridor_decl, NULL, &g_spec), SIM_WORLD_ERR_INVALID_ARG);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_task_worlds_corridor_file_matches_spec),
      cmocka_unit_test(test_task_worlds_obstacle_file_matches_spec),
      cmocka_unit_test(test_task_worlds_starts_clear_and_bad_specs_fail),
  };
  return cmocka_run_group_tests_name("sim.task_worlds", tests, NULL, NULL);
}
