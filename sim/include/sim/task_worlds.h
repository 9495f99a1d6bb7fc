// SPDX-License-Identifier: MIT
/// sim/task_worlds.h — Emulator worlds built from a declared task's specification (lib/tasks,
/// tasks/decl.h: each declaration writes its own world), so that the emulated geometry is exactly
/// the one the task's rewards and features assume. E.g.
/// - corridor: `corridor length width 1` (closed at both ends, corridor frame = world frame), the
///   ten evaluation start poses in order; name "corridor<length>";
/// - obstacles: `arena` of the spec's box, one cylinder per obstacle, the goal disc, the ten
///   evaluation start poses in order; name "obstacles<n>";
/// - doorway: `arena` of the room, the dividing wall as two `wall`s on either side of the door
///   (a declaration's wall is centred on its line; the world's face is moved half the thickness
///   to the line's left so that its solid, to the face's right, is centred), the goal disc, the
///   ten evaluation start poses; name "doorway".
/// The shipped files in sim/worlds/ equal the worlds built from the default specifications
/// (tested by sim.task_worlds).
///
/// Memory: writes only *out. O(size of the world).
#ifndef B21R_SIM_TASK_WORLDS_H
#define B21R_SIM_TASK_WORLDS_H

#include <tasks/decl.h>

#include "sim/world.h"

#ifdef __cplusplus
extern "C" {
#endif

/// Builds the world of task decl with specification spec (decl->spec_size bytes) into *out.
/// SIM_WORLD_ERR_INVALID_ARG for NULL arguments or a geometry the world refuses (then *out is
/// empty).
sim_world_status_t sim_world_from_task(const tasks_decl_t* decl, const void* spec, sim_world_t* out);

#ifdef __cplusplus
}
#endif

#endif  // B21R_SIM_TASK_WORLDS_H
