// SPDX-License-Identifier: MIT
// The run lifecycle (run.c) around the learning framework.
#ifndef FW_RUN_H
#define FW_RUN_H

#include "loop_state.h"

bool fw_run_joystick_drives(const fw_loop_t* L);
bool fw_run_running(const fw_loop_t* L);
/// The pose of the run's odometry (run_odometry: (0, 0, 0) where the run started).
features_pose_t fw_run_odom_pose(const fw_loop_t* L);
/// Once per tick after base.odometry's update: run_starting restarts run_odometry at the
/// current counts; otherwise it integrates the same counts as base.odometry. O(1).
void fw_run_odometry_update(fw_loop_t* L, bool run_starting);
/// The state of the newest scan (features at the odometry pose, and the learner's state from
/// them); false when unusable. *finite: every value of the learner's state is finite.
bool fw_run_observe(fw_loop_t* L, bool* finite);
void fw_run_begin_repositioning(fw_loop_t* L);
/// Repositioning: requests the start pose, and starts the run once it stands (and the learner is
/// idle). Sets *v/*w and returns true when the run's first command was decided.
bool fw_run_reposition(fw_loop_t* L, bool state_ok, double* v, double* w);
/// One step of a running run (a new, usable state this tick); contact = the bumper fired.
void fw_run_step(fw_loop_t* L, uint8_t contact, double* v, double* w);
/// Ends a running run that has no terminal state: end_reason B21R_RUN_T_END_*, stop_reason the
/// fw_stop_reason_t of a safety stop (else 0), why a static string (kept by B21R_RUN).
void fw_run_abort(fw_loop_t* L, int8_t end_reason, int32_t stop_reason, const char* why);
/// While stopped for a bump in the emulator: asks for the next start pose once.
void fw_run_request_pose_while_stopped(fw_loop_t* L);

#endif  // FW_RUN_H
