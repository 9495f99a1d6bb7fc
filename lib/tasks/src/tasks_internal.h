// SPDX-License-Identifier: MIT
// Internal constants of lib/tasks shared between its sources.
#ifndef B21R_TASKS_INTERNAL_H
#define B21R_TASKS_INTERNAL_H

// Strict C11 has no M_PI.
#define TASKS_PI 3.14159265358979323846

/// Attempts of the training-start samplers before falling back.
#define TASKS_START_ATTEMPTS 64
/// A training start differs from its evaluation pose by at least this fraction of the jitter box.
#define TASKS_MIN_JITTER_NORM 0.25

#include "features/features.h"
#include "tasks/tasks.h"

#include <math.h>
#include <stdint.h>

/// 1 when the n values are all finite.
static inline int tasks_all_finite(const double* v, uint32_t n) {
  for (uint32_t i = 0U; i < n; ++i) {
    if (!isfinite(v[i])) {
      return 0;
    }
  }
  return 1;
}

/// The training-start sampler of every task: jitters evaluation start `index` (modulo
/// TASKS_N_EVAL_STARTS) within the box (jx, jy, jth) until the pose is both clearly different
/// from the evaluation pose (at least TASKS_MIN_JITTER_NORM of the box) and clear of the world
/// (`is_clear(spec, pose)`). Returns 1 with the pose in *out, or 0 after TASKS_START_ATTEMPTS
/// tries with *out = the last pose tried and *base_out = the evaluation start, so the caller can
/// apply its task's fallback. Three draws per attempt. O(TASKS_START_ATTEMPTS).
int tasks_jittered_start(const features_pose_t eval_starts[TASKS_N_EVAL_STARTS], uint32_t index, double jx,
                         double jy, double jth, int (*is_clear)(const void* spec, features_pose_t),
                         const void* spec, rng_t* rng, features_pose_t* out, features_pose_t* base_out);

/// The obstacle features an ideal laser gives at a pose in the arena: features_obstacles_from_pose
/// with spec's discs (the first TASKS_MAX_OBSTACLES) and the LMS200's 180° field of view. Shared
/// by tasks_episode_observe_pose and the obstacle rollouts (recovery.c). O(obstacles), pure.
features_status_t tasks_obstacles_features_at_pose(const tasks_obstacles_spec_t* spec,
                                                   const features_obstacles_config_t* fcfg, features_pose_t pose,
                                                   features_obstacles_t* out);

#endif  // B21R_TASKS_INTERNAL_H
