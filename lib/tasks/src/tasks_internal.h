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

#endif  // B21R_TASKS_INTERNAL_H
