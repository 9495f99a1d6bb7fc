// SPDX-License-Identifier: MIT
// The learning framework inside the loop (learning.c): set-up, the step's update, between-run work, checkpoints.
#ifndef FW_LEARNING_H
#define FW_LEARNING_H

#include "loop_state.h"

/// Sets up the framework for the configured task in one block allocated here (the only
/// allocation); -1 with a message.
int fw_learning_init(fw_loop_t* L, char* err, size_t err_cap);
void fw_learning_free(fw_loop_t* L);
/// After the command: the queued step's update (or prediction) and its experience message, and a
/// slice of between-run work (the framework's replay, then the checkpoint).
void fw_learning_after_command(fw_loop_t* L);
/// A run ended (its last transition is queued): its reports wait until its journal record (sent
/// after this tick's update) or a checkpoint is on disk; a training run's replay and checkpoint follow.
void fw_learning_run_ended(fw_loop_t* L, const learn_run_end_t* e);
/// True when no between-run work is left (a run may start).
bool fw_learning_idle(const fw_loop_t* L);
/// Finishes all between-run work at once (shutdown; not for the tick): the replay (at most
/// hedger_replay_passes × the run's length updates), so that the checkpoint holds it.
void fw_learning_finish_now(fw_loop_t* L);
/// Serialises the learned state and the schedule's progress into the writer at once (shutdown).
void fw_learning_checkpoint_now(fw_loop_t* L);

#endif  // FW_LEARNING_H
