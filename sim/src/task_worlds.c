// SPDX-License-Identifier: MIT
// Emulator worlds built from lib/tasks' task specifications.
#include "sim/task_worlds.h"

#include <stdio.h>

sim_world_status_t sim_world_from_corridor_spec(const tasks_corridor_spec_t* spec, sim_world_t* out) {
  if (out == NULL) {
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  sim_world_clear(out);
  if (spec == NULL) {
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  sim_world_status_t st = sim_world_add_corridor(out, spec->length_m, spec->width_m, 1);
  for (size_t i = 0; st == SIM_WORLD_OK && i < TASKS_N_EVAL_STARTS; ++i) {
    const features_pose_t* p = &spec->eval_starts[i];
    st = sim_world_add_start(out, p->x_m, p->y_m, p->theta_rad);
  }
  if (st != SIM_WORLD_OK) {
    sim_world_clear(out);
    return st;
  }
  (void)snprintf(out->name, sizeof(out->name), "corridor%g", spec->length_m);
  sim_world_compute_bounds(out);
  return SIM_WORLD_OK;
}

sim_world_status_t sim_world_from_obstacles_spec(const tasks_obstacles_spec_t* spec,
                                                 sim_world_t* out) {
  if (out == NULL) {
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  sim_world_clear(out);
  if (spec == NULL || spec->n_obstacles > TASKS_MAX_OBSTACLES || !(spec->goal_radius_m > 0.0)) {
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  sim_world_status_t st = sim_world_add_arena(out, spec->arena_min_x_m, spec->arena_min_y_m,
                                              spec->arena_max_x_m, spec->arena_max_y_m);
  for (uint32_t k = 0; st == SIM_WORLD_OK && k < spec->n_obstacles; ++k) {
    const tasks_circle_t* c = &spec->obstacles[k];
    st = sim_world_add_cylinder(out, c->x_m, c->y_m, c->radius_m);
  }
  for (size_t i = 0; st == SIM_WORLD_OK && i < TASKS_N_EVAL_STARTS; ++i) {
    const features_pose_t* p = &spec->eval_starts[i];
    st = sim_world_add_start(out, p->x_m, p->y_m, p->theta_rad);
  }
  if (st != SIM_WORLD_OK) {
    sim_world_clear(out);
    return st;
  }
  out->has_goal = 1;
  out->goal = (sim_cylinder_t){spec->goal_x_m, spec->goal_y_m, spec->goal_radius_m};
  (void)snprintf(out->name, sizeof(out->name), "obstacles%u", (unsigned)spec->n_obstacles);
  sim_world_compute_bounds(out);
  return SIM_WORLD_OK;
}
