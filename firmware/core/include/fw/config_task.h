// SPDX-License-Identifier: MIT
/// fw/config_task.h — What a configuration (fw/config.h) makes of the declared task and of the
/// learning framework: the task as a robot runs it (its declaration, specification, parameters,
/// evaluation poses, command limits), the task as the learner sees it, and the framework's
/// settings. The controller's loop, b21r-train, b21r-experiment and the Python package derive
/// them here, so that one configuration means one learner everywhere.
///
/// Pure functions of the configuration (no allocation, O(parameters)); only
/// fw_config_print_task_params writes, to the stream it is given.
#ifndef FW_CONFIG_TASK_H
#define FW_CONFIG_TASK_H

#include "fw/config.h"

#include <learn/learn.h>
#include <tasks/episode.h>

#include <stddef.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

/// The configured task in *ep: the declaration of cfg->task with its specification's defaults,
/// then the control period (tick_rate_hz), the action bound (max_rotation_radps), the step limit
/// (max_steps_per_run, when > 0), corridor_length_m (a task with a length_m parameter) and
/// task_params, and the evaluation poses (eval_poses); *limits (may be NULL) the command limits.
/// Returns 0, or -1 with a message (an undeclared task, a bad parameter).
int fw_config_task(const fw_config_t* cfg, tasks_episode_t* ep, tasks_command_limits_t* limits, char* err,
                   size_t err_cap);

/// The task as the learning framework sees it: the declaration's state dimension, scales and
/// ranges (under ep's specification), the action bounds (+-max_rotation_radps) and scale, the
/// discount and step limit, the wider second search.
void fw_config_learn_task(const fw_config_t* cfg, const tasks_episode_t* ep, learn_task_t* out);

/// The framework's settings from the configuration (learner, schedule, exploration, seeds from
/// cfg->seed as the controller derives them).
void fw_config_learn_settings(const fw_config_t* cfg, learn_config_t* out);

/// The HEDGER configuration the controller derives from cfg (state dimension, action bounds, input
/// scales, capacity, ...), for offline tools that build compatible HEDGER states or read
/// checkpoints (learner = lwa: local_model = HEDGER_LOCAL_LWA; learner = tabular uses no HEDGER,
/// and this is the configuration HEDGER would have). An undeclared task or a bad task_params
/// gives the corridor's defaults (validate cfg first). O(parameters).
void fw_config_hedger(const fw_config_t* cfg, hedger_config_t* out);

/// The seeds the controller derives from cfg->seed, in this order: the training start poses,
/// exploration, HEDGER's eviction generator, the drivers' per-run streams, the actor's initial
/// weights and query draws (the last added: the others are what they were before it).
typedef struct fw_config_seeds {
  uint64_t pose, explore, learner, driver, actor;
} fw_config_seeds_t;
fw_config_seeds_t fw_config_derive_seeds(uint64_t root);

/// Prints every declared task with its parameters (name, range, default, help): what task and
/// task_params accept (b21r-controller --print-task-params). O(tasks * parameters).
void fw_config_print_task_params(FILE* out);

#ifdef __cplusplus
}
#endif

#endif  // FW_CONFIG_TASK_H
