// SPDX-License-Identifier: MIT
/// sim/task_worlds.h — Emulator worlds built from the task specifications of lib/tasks, so that
/// the emulated geometry is exactly the one the tasks' rewards and features assume.
///
/// - Corridor (tasks_corridor_spec_t): `corridor length width 1` (closed at both ends, corridor
///   frame = world frame), the ten evaluation start poses in order; name "corridor<length>".
/// - Obstacles (tasks_obstacles_spec_t): `arena` of the spec's box, one cylinder per obstacle,
///   the goal disc, the ten evaluation start poses in order; name "obstacles<n>".
/// The shipped files sim/worlds/corridor10.world and sim/worlds/obstacle1.world equal the
/// worlds built from the default specs (tested by sim.task_worlds).
///
/// Memory: writes only *out. O(size of the spec).
#ifndef B21R_SIM_TASK_WORLDS_H
#define B21R_SIM_TASK_WORLDS_H

#include <tasks/tasks.h>

#include "sim/world.h"

#ifdef __cplusplus
extern "C" {
#endif

/// Builds the corridor world of spec into *out. SIM_WORLD_ERR_INVALID_ARG for a NULL or
/// non-positive geometry (then *out is empty).
sim_world_status_t sim_world_from_corridor_spec(const tasks_corridor_spec_t* spec, sim_world_t* out);

/// Builds the obstacle-task world of spec into *out. SIM_WORLD_ERR_INVALID_ARG for a NULL spec,
/// an empty arena or bad obstacles (then *out is empty).
sim_world_status_t sim_world_from_obstacles_spec(const tasks_obstacles_spec_t* spec,
                                                 sim_world_t* out);

#ifdef __cplusplus
}
#endif

#endif  // B21R_SIM_TASK_WORLDS_H
