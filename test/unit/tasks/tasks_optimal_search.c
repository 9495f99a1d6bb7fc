// SPDX-License-Identifier: MIT
// Offline search for the "optimal" reference controllers: a grid over each task's control-law
// parameters, scored by the mean steps to the goal from the ten evaluation starts in the
// synthetic world (three sensor-noise seeds). A run that fails, or that brings the robot's edge
// within MIN_CLEARANCE_M of a wall or obstacle, disqualifies the parameters: the reference is
// the fastest controller that keeps a safety margin, as a careful driver would. The winners are
// baked into lib/tasks/src/drivers.c (the doorway's into lib/tasks/src/task_doorway.c). Usage:
// tasks_optimal_search [corridor|obstacles|doorway]
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "task_sim.h"

#include <tasks/decl.h>

#define MIN_CLEARANCE_M 0.10

// Mean steps over the evaluation starts and sensor seeds; +inf if any run fails.
static double score(const tasks_decl_t* task, const double law[TASKS_DRIVER_LAW_PARAMS]) {
  tasks_corridor_spec_t cs;
  tasks_corridor_spec_default(&cs);
  tasks_obstacles_spec_t os;
  tasks_obstacles_spec_default(&os);
  tasks_doorway_spec_t ds;
  tasks_doorway_spec_default(&ds);
  task_sim_opts_t o;
  task_sim_opts_default(&o);
  double sum = 0.0;
  int n = 0;
  for (uint64_t seed = 1U; seed <= 3U; ++seed) {
    o.sensor_seed = seed;
    for (uint32_t i = 0U; i < TASKS_N_EVAL_STARTS; ++i) {
      tasks_driver_t d;
      tasks_driver_begin_run(&d, TASKS_DRIVER_OPTIMAL, task, 1.0, seed);
      memcpy(d.law, law, sizeof d.law);
      const task_sim_result_t r =
          task == &tasks_corridor_decl    ? task_sim_corridor(&cs, tasks_corridor_eval_start(&cs, i), &d, &o)
          : task == &tasks_obstacles_decl ? task_sim_obstacles(&os, tasks_obstacles_eval_start(&os, i), &d, &o)
                                          : task_sim_doorway(&ds, tasks_doorway_eval_start(&ds, i), &d, &o);
      if (r.reason != TASKS_END_GOAL || r.min_clearance_m < MIN_CLEARANCE_M) {
        return INFINITY;
      }
      sum += (double)r.steps;
      ++n;
    }
  }
  return sum / (double)n;
}

static void search_corridor(void) {
  double best = INFINITY, bg = 0.0, bl = 0.0;
  for (double g = 0.5; g <= 4.01; g += 0.25) {
    for (double l = 0.25; l <= 3.01; l += 0.25) {
      const double law[TASKS_DRIVER_LAW_PARAMS] = {g, l, 0.0};
      const double s = score(&tasks_corridor_decl, law);
      if (s < best) {
        best = s;
        bg = g;
        bl = l;
      }
    }
  }
  printf("corridor: gain %.2f lookahead %.2f m -> mean %.2f steps\n", bg, bl, best);
}

static void search_obstacles(void) {
  double best = INFINITY, bg = 0.0, bc = 0.0, br = 0.0;
  for (double g = 1.0; g <= 8.01; g += 1.0) {
    for (double c = 0.30; c <= 0.751; c += 0.05) {
      for (double r = 1.0; r <= 2.51; r += 0.25) {
        const double law[TASKS_DRIVER_LAW_PARAMS] = {g, c, r};
        const double s = score(&tasks_obstacles_decl, law);
        if (s < best) {
          best = s;
          bg = g;
          bc = c;
          br = r;
        }
      }
    }
  }
  printf("obstacles: gain %.2f clearance %.2f m range %.2f m -> mean %.2f steps\n", bg, bc, br,
         best);
}

// The doorway's line-following law: gain and look-ahead onto the door's centre line.
static void search_doorway(void) {
  double best = INFINITY, bg = 0.0, bl = 0.0;
  for (double g = 0.5; g <= 4.01; g += 0.25) {
    for (double l = 0.25; l <= 3.01; l += 0.25) {
      const double law[TASKS_DRIVER_LAW_PARAMS] = {g, l, 0.0};
      const double s = score(&tasks_doorway_decl, law);
      if (s < best) {
        best = s;
        bg = g;
        bl = l;
      }
    }
  }
  printf("doorway: gain %.2f lookahead %.2f m -> mean %.2f steps\n", bg, bl, best);
}

int main(int argc, char** argv) {
  const int all = argc < 2;
  if (all || strcmp(argv[1], "corridor") == 0) search_corridor();
  if (all || strcmp(argv[1], "obstacles") == 0) search_obstacles();
  if (all || strcmp(argv[1], "doorway") == 0) search_doorway();
  return 0;
}
