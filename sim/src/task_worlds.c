// SPDX-License-Identifier: MIT
// Emulator worlds built from the declared tasks' specifications (sim/task_worlds.h): the
// declaration writes its world through a sink whose calls are the world file's directives.
#include "sim/task_worlds.h"

#include <math.h>
#include <stdio.h>

static int sink_corridor(void* user, double length_m, double width_m, int end) {
  return sim_world_add_corridor((sim_world_t*)user, length_m, width_m, end) != SIM_WORLD_OK;
}

static int sink_arena(void* user, double min_x, double min_y, double max_x, double max_y) {
  return sim_world_add_arena((sim_world_t*)user, min_x, min_y, max_x, max_y) != SIM_WORLD_OK;
}

// The declaration's wall is centred on its line (tasks/decl.h); a world's wall is its face with
// the solid to the right (sim/world.h): the face lies half the thickness to the line's left.
static int sink_wall(void* user, double x0, double y0, double x1, double y1, double thickness_m) {
  const double len = hypot(x1 - x0, y1 - y0);
  if (!(len > 0.0) || !isfinite(len)) {
    return 1;
  }
  const double h = 0.5 * thickness_m;
  const double lx = -(y1 - y0) / len;
  const double ly = (x1 - x0) / len;
  return sim_world_add_wall((sim_world_t*)user, x0 + h * lx, y0 + h * ly, x1 + h * lx, y1 + h * ly, thickness_m) !=
         SIM_WORLD_OK;
}

static int sink_cylinder(void* user, double x, double y, double radius_m) {
  return sim_world_add_cylinder((sim_world_t*)user, x, y, radius_m) != SIM_WORLD_OK;
}

static int sink_goal(void* user, double x, double y, double radius_m) {
  sim_world_t* w = (sim_world_t*)user;
  if (!(radius_m > 0.0)) {
    return 1;
  }
  w->has_goal = 1;
  w->goal = (sim_cylinder_t){x, y, radius_m};
  return 0;
}

static int sink_start(void* user, features_pose_t p) {
  return sim_world_add_start((sim_world_t*)user, p.x_m, p.y_m, p.theta_rad) != SIM_WORLD_OK;
}

static int sink_name(void* user, const char* name) {
  sim_world_t* w = (sim_world_t*)user;
  (void)snprintf(w->name, sizeof(w->name), "%s", name);
  return 0;
}

sim_world_status_t sim_world_from_task(const tasks_decl_t* decl, const void* spec, sim_world_t* out) {
  if (out == NULL) {
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  sim_world_clear(out);
  if (decl == NULL || spec == NULL) {
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  const tasks_world_sink_t sink = {out,          sink_corridor, sink_arena, sink_wall,
                                   sink_cylinder, sink_goal,     sink_start, sink_name};
  if (decl->world(spec, &sink) != 0) {
    sim_world_clear(out);
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  sim_world_compute_bounds(out);
  return SIM_WORLD_OK;
}
