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

#include <tasks/doorway.h>

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

// doorway.world is the default doorway spec; the declaration's walls (centred on their lines)
// become solids centred on the wall's plane, so the emulator's collision test is the task's.
static void test_task_worlds_doorway_file_matches_spec(void** state) {
  (void)state;
  tasks_doorway_spec_t spec;
  tasks_doorway_spec_default(&spec);
  assert_int_equal(sim_world_from_task(&tasks_doorway_decl, &spec, &g_spec), SIM_WORLD_OK);
  load("doorway.world");
  assert_same_geometry(0.0);
  assert_string_equal(g_spec.name, "doorway");
  const double r = spec.robot_radius_m;
  const double h = 0.5 * spec.wall_thickness_m;
  for (int side = -1; side <= 1; side += 2) {
    const double x = spec.wall_x_m + side * (h + r);
    assert_false(sim_world_disc_collides(&g_spec, x + side * 1e-3, -2.0, r));
    assert_true(sim_world_disc_collides(&g_spec, x - side * 1e-3, -2.0, r));
    assert_false(sim_world_disc_collides(&g_spec, x + side * 1e-3, 2.0, r));
    assert_true(sim_world_disc_collides(&g_spec, x - side * 1e-3, 2.0, r));
  }
  // The emulator and the task agree on what collides, across the door and the room.
  for (double x = spec.room_min_x_m; x <= spec.room_max_x_m; x += 0.0625) {
    for (double y = spec.room_min_y_m; y <= spec.room_max_y_m; y += 0.0625) {
      assert_int_equal(sim_world_disc_collides(&g_spec, x, y, r) != 0,
                       tasks_doorway_disc_collides(&spec, x, y, r) != 0);
    }
  }
  // The laser sees the jambs where they are: a ray along the door's edge from the robot's side
  // passes, one just inside the jamb meets its face at x = -h.
  const double half = 0.5 * spec.door_width_m;
  assert_true(isinf(sim_world_raycast(&g_spec, -2.0, half - 0.01, 0.0, 2.5)));
  assert_true(fabs(sim_world_raycast(&g_spec, -2.0, half + 0.01, 0.0, 10.0) - (2.0 - h)) < 1e-9);
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
      cmocka_unit_test(test_task_worlds_doorway_file_matches_spec),
      cmocka_unit_test(test_task_worlds_starts_clear_and_bad_specs_fail),
  };
  return cmocka_run_group_tests_name("sim.task_worlds", tests, NULL, NULL);
}
