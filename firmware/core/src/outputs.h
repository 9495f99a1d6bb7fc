// SPDX-License-Identifier: MIT
// The loop's messages (outputs.c): experience, pose, scan, evaluation block, status, text lines.
#ifndef FW_OUTPUTS_H
#define FW_OUTPUTS_H

#include "loop_state.h"

void fw_loop_log(fw_loop_t* L, int stream, const char* format, ...) __attribute__((format(printf, 3, 4)));
void fw_out_experience(fw_loop_t* L, const learn_experience_t* e);
void fw_out_pose(fw_loop_t* L);
void fw_out_scan(fw_loop_t* L);
void fw_out_eval(fw_loop_t* L, const learn_eval_block_t* block);
void fw_out_status(fw_loop_t* L);
/// B21R_CONFIG (once, at start-up).
void fw_out_config(fw_loop_t* L);
/// B21R_RUN of the run that ended, if one is waiting (after its last experience went out).
void fw_out_run_end(fw_loop_t* L);
void fw_out_notify(fw_loop_t* L);
int8_t fw_out_status_mode(const fw_loop_t* L);
/// Publishes the held reports whose runs are on disk (force: all of them now).
void fw_out_release_reports(fw_loop_t* L, bool force);

#endif  // FW_OUTPUTS_H
