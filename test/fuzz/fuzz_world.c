// SPDX-License-Identifier: MIT
// libFuzzer target: the emulator's world-file parser (sim/world.h) and the analytic queries on
// what it accepts. An accepted world holds only finite geometry within the capacities, with a
// finite drawing area, so the ODE plant, the ray caster and the picture get usable numbers.
#include "sim/world.h"
#include "fuzz_util.h"

#include <math.h>

static void check_world(const sim_world_t* w) {
  FUZZ_CHECK(memchr(w->name, '\0', sizeof w->name) != NULL && w->name[0] != '\0');
  FUZZ_CHECK(w->n_walls <= SIM_WORLD_MAX_WALLS && w->n_cylinders <= SIM_WORLD_MAX_CYLINDERS &&
             w->n_starts <= SIM_WORLD_MAX_STARTS);
  FUZZ_CHECK(isfinite(w->bounds_min_x_m) && isfinite(w->bounds_max_x_m) && isfinite(w->bounds_min_y_m) &&
             isfinite(w->bounds_max_y_m));
  FUZZ_CHECK(w->bounds_min_x_m < w->bounds_max_x_m && w->bounds_min_y_m < w->bounds_max_y_m);
  FUZZ_CHECK(isfinite(w->bounds_max_x_m - w->bounds_min_x_m) && isfinite(w->bounds_max_y_m - w->bounds_min_y_m));
  for (size_t i = 0; i < w->n_walls; ++i) {
    const sim_wall_t* l = &w->walls[i];
    const double len = hypot(l->x1_m - l->x0_m, l->y1_m - l->y0_m);
    FUZZ_CHECK(isfinite(len) && len > 0.0);
    FUZZ_CHECK(isfinite(l->thickness_m) && l->thickness_m > 0.0);
  }
  for (size_t i = 0; i < w->n_cylinders; ++i) {
    const sim_cylinder_t* c = &w->cylinders[i];
    FUZZ_CHECK(isfinite(c->x_m) && isfinite(c->y_m) && isfinite(c->radius_m) && c->radius_m > 0.0);
    FUZZ_CHECK(isfinite(c->x_m + c->radius_m) && isfinite(c->x_m - c->radius_m));
  }
  for (size_t i = 0; i < w->n_starts; ++i) {
    const sim_pose_t* s = &w->starts[i];
    FUZZ_CHECK(isfinite(s->x_m) && isfinite(s->y_m) && isfinite(s->theta_rad));
    (void)sim_world_disc_collides(w, s->x_m, s->y_m, 0.26);
    (void)sim_world_in_goal(w, s->x_m, s->y_m);
  }
  if (w->has_goal) {
    FUZZ_CHECK(isfinite(w->goal.x_m) && isfinite(w->goal.y_m) && w->goal.radius_m > 0.0);
    FUZZ_CHECK(sim_world_in_goal(w, w->goal.x_m, w->goal.y_m));
  }
  if (w->has_corridor) {
    FUZZ_CHECK(w->corridor_length_m > 0.0 && w->corridor_width_m > 0.0);
  }
  // Queries over the drawing area, corners and centre.
  const double xs[3] = {w->bounds_min_x_m, 0.5 * (w->bounds_min_x_m + w->bounds_max_x_m), w->bounds_max_x_m};
  const double ys[3] = {w->bounds_min_y_m, 0.5 * (w->bounds_min_y_m + w->bounds_max_y_m), w->bounds_max_y_m};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      (void)sim_world_disc_collides(w, xs[i], ys[j], 0.26);
    }
  }
}

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static sim_world_t w;
  char err[256];
  err[0] = 'x';
  const sim_world_status_t st = sim_world_parse((const char*)data, size, &w, err, sizeof err);
  if (st == SIM_WORLD_OK) {
    check_world(&w);
  } else {
    FUZZ_CHECK(st == SIM_WORLD_ERR_SYNTAX || st == SIM_WORLD_ERR_INVALID_ARG || st == SIM_WORLD_ERR_CAPACITY);
    FUZZ_CHECK(err[0] != '\0' && memchr(err, '\0', sizeof err) != NULL);
    FUZZ_CHECK(w.n_walls == 0 && w.n_cylinders == 0 && w.n_starts == 0);  // an empty world on failure
  }
  return 0;
}
